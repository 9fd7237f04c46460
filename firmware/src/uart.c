#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/wdt.h>
#include "config.h"
#include "uart.h"

#define BAUD 115200UL
#define RX_LEN 64U /* powers of two */
#define TX_LEN 128U

static volatile uint8_t rx_buf[RX_LEN];
static volatile uint8_t rx_head, rx_tail;
static volatile uint8_t tx_buf[TX_LEN];
static volatile uint8_t tx_head, tx_tail;

void uart_init(void)
{
    UCSR0A = (1 << U2X0);
    UBRR0 = (uint16_t)((F_CPU + 4UL * BAUD) / (8UL * BAUD) - 1UL);
    UCSR0C = (1 << UCSZ01) | (1 << UCSZ00);
    UCSR0B = (1 << RXEN0) | (1 << TXEN0) | (1 << RXCIE0);
}

ISR(USART_RX_vect)
{
    uint8_t c = UDR0;
    uint8_t next = (uint8_t)((rx_head + 1U) & (RX_LEN - 1U));
    if (next != rx_tail) { /* a full buffer drops the byte: the line fails its CRC */
        rx_buf[rx_head] = c;
        rx_head = next;
    }
}

ISR(USART_UDRE_vect)
{
    if (tx_tail == tx_head) {
        UCSR0B &= (uint8_t)~(1 << UDRIE0);
        return;
    }
    UDR0 = tx_buf[tx_tail];
    tx_tail = (uint8_t)((tx_tail + 1U) & (TX_LEN - 1U));
}

int16_t uart_getc(void)
{
    if (rx_tail == rx_head)
        return -1;
    uint8_t c = rx_buf[rx_tail];
    rx_tail = (uint8_t)((rx_tail + 1U) & (RX_LEN - 1U));
    return c;
}

void uart_putc(uint8_t c)
{
    uint8_t next = (uint8_t)((tx_head + 1U) & (TX_LEN - 1U));
    while (next == tx_tail)
        wdt_reset();
    tx_buf[tx_head] = c;
    tx_head = next;
    UCSR0B |= (1 << UDRIE0);
}

void uart_puts(const char *s)
{
    while (*s)
        uart_putc((uint8_t)*s++);
}

uint8_t uart_rx_empty(void) { return rx_tail == rx_head; }
