/* docs/PROTOCOL.md version 1: framing, CRC-16/CCITT-FALSE, commands with id memory, replies. */
#ifndef OMNI_PROTO_H
#define OMNI_PROTO_H
#include <stddef.h>
#include <stdint.h>
#include "scan.h"

uint16_t crc16_ccitt_false(const uint8_t *p, size_t n);
/* Feeds one received byte; a complete verified line is executed and answered. */
void proto_rx_byte(uint8_t c);
void proto_send_trigger(const struct trigger_event *ev);
void proto_send_done(uint32_t fired);
void proto_send_status(void);
#endif
