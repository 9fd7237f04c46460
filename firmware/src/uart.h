/* USART0 at 115200 8N1, interrupt-driven both ways. */
#ifndef OMNI_UART_H
#define OMNI_UART_H
#include <stdint.h>
void uart_init(void);
/* Next received byte, or -1. */
int16_t uart_getc(void);
/* Queues a byte; waits while the transmit buffer is full. */
void uart_putc(uint8_t c);
void uart_puts(const char *s);
/* 1 if no received byte waits (call with interrupts off). */
uint8_t uart_rx_empty(void);
#endif
