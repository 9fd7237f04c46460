/* omniscan trigger controller for the ATmega328P: docs/PROTOCOL.md over USART0, encoder and
 * trigger timing in scan.c. Wiring and timing: firmware/README.md. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include "proto.h"
#include "scan.h"
#include "uart.h"


int main(void)
{
    MCUSR = 0;
    wdt_enable(WDTO_250MS); /* a hung main loop resets the chip: outputs float, lasers off */
    scan_init();
    uart_init();
    set_sleep_mode(SLEEP_MODE_IDLE);
    sei();
    for (;;) {
        /* Kept short: the loop runs after every interrupt, i.e. on every encoder count. */
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
        if (scan_status_due()) {
            enum run_state st = scan_state();
            if (st == RUN_RUNNING || st == RUN_WAITING_INDEX)
                proto_send_status();
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
