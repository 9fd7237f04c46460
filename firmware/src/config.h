/* Build-time properties of the controller (override with make CPR=... FACETS=... MAX_HZ=...).
 * Pins are fixed by the ATmega328P's peripherals; firmware/README.md has the wiring table. */
#ifndef OMNI_CONFIG_H
#define OMNI_CONFIG_H

#ifndef F_CPU
#define F_CPU 16000000UL
#endif
/* Encoder counts per polygon revolution (quadrature x4: 4 x lines); a multiple of FACETS, < 65536. */
#ifndef CPR
#define CPR 36000
#endif
#ifndef FACETS
#define FACETS 12
#endif
/* Lasers on PC0..PC(LASERS-1); at most 4. */
#ifndef LASERS
#define LASERS 2
#endif
/* Highest trigger rate of the camera (Hz, integer). */
#ifndef MAX_HZ
#define MAX_HZ 50
#endif
/* Trigger pulse width (µs); the lasers stay on for the pulse. */
#ifndef PULSE_US
#define PULSE_US 200
#endif
/* Motor reference clock: pulses per polygon revolution (a PLL polygon-motor driver's CLK input).
 * With 60, rpm = 1e6 / half-period in 0.5 µs ticks. */
#define MOTOR_PPR 60U
/* Stall watch while running: the run faults (trigger and lasers off, STS fault=stall) when the
 * encoder count has not changed for STALL_COUNTS count periods at the run's speed, and for at
 * least STALL_MIN_CHECKS Timer1 overflows (32.768 ms each, the period of the check). */
#define STALL_COUNTS 16U
#define STALL_MIN_CHECKS 2U
#define FW_VERSION "omni-avr-0.1.0"

#define PER_FACET ((uint16_t)(CPR / FACETS))
#define MAX_ANGLES 192
#define TICKS_PER_US 2U /* Timer1 at F_CPU / 8 */

/* Plain decimals (no U suffix): HELLO prints them as they are written. */
#if CPR % FACETS != 0 || CPR > 65535 || FACETS > 16 || LASERS > 4 || LASERS < 1
#error "CPR must be a multiple of FACETS below 65536, FACETS <= 16, 1 <= LASERS <= 4"
#endif
#endif
