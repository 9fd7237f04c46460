/* omniscan trigger controller for the ATmega328P: docs/PROTOCOL.md over USART0, encoder and
 * trigger timing in scan.c. Wiring and timing: firmware/README.md. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include "proto.h"
#include "scan.h"
#include "uart.h"

#define STATUS_PERIOD_TICKS (1000000ULL * TICKS_PER_US)

int main(void)
{
    MCUSR = 0;
    wdt_enable(WDTO_250MS); /* a hung main loop resets the chip: outputs float, lasers off */
    scan_init();
    uart_init();
    set_sleep_mode(SLEEP_MODE_IDLE);
    sei();
    uint64_t last_status = 0;
    for (;;) {
        wdt_reset();
        int16_t c;
        while ((c = uart_getc()) >= 0)
            proto_rx_byte((uint8_t)c);
        struct trigger_event ev;
        while (scan_pop_event(&ev))
            proto_send_trigger(&ev);
        uint32_t fired;
        if (scan_take_done(&fired))
            proto_send_done(fired);
        enum run_state st = scan_state();
        uint64_t now = clock_ticks();
        if (st == RUN_RUNNING || st == RUN_WAITING_INDEX) {
            if (now - last_status >= STATUS_PERIOD_TICKS) {
                last_status = now;
                proto_send_status();
            }
        } else {
            last_status = now;
        }
        /* Idle sleep until the next interrupt (byte, encoder, timer): the timers, the UART and the
         * pin changes keep running; checked with interrupts off so no wake-up is missed. */
        cli();
        if (uart_rx_empty() && scan_idle()) {
            sleep_enable();
            sei();
            sleep_cpu();
            sleep_disable();
        }
        sei();
    }
}
