/* The real-time part: encoder decoding, the trigger timeline of a run, the clock, the motor
 * reference clock and the host-present line. Everything here runs in interrupts; the main loop
 * talks to it through these functions and the event queue. */
#ifndef OMNI_SCAN_H
#define OMNI_SCAN_H
#include <stdint.h>
#include "config.h"

/* One fired trigger, as latched in the encoder interrupt. */
struct trigger_event {
    uint32_t seq;
    uint32_t rev;
    uint32_t ticks_hi; /* Timer1 overflows */
    uint16_t ticks_lo; /* TCNT1 at the edge */
    uint16_t enc;
    uint8_t facet;
    uint8_t lasers; /* bit j = laser j on */
};

/* A validated schedule (set by the protocol layer before scan_arm). */
struct schedule {
    uint16_t counts[MAX_ANGLES];
    uint16_t n_counts;
    uint8_t facets[FACETS];
    uint8_t n_facets;
    uint8_t lasers; /* bit mask */
    uint8_t ambient;
};

enum run_state { RUN_IDLE = 0, RUN_ARMED, RUN_WAITING_INDEX, RUN_RUNNING };
/* FAULT_STALL: the encoder stopped while running; the run stays running, firing nothing, until
 * STOP (or the host leaving) ends it. Cleared by the next ARM. */
enum fault { FAULT_NONE = 0, FAULT_STALL };

extern struct schedule sched;

void scan_init(void);
/* Clock in Timer1 ticks (0.5 µs) since power-up. */
uint64_t clock_ticks(void);
/* Starts the motor reference clock (half-period in ticks; 0 = stopped). */
void motor_set(uint32_t half_period_ticks);
/* Resets counters and sequence for a new armed schedule. */
void scan_arm(void);
void scan_disarm(void);
/* Starts triggering at the next index for `revs` revolutions (0 = until stopped); the stall
 * watch uses the speed of the last motor_set. */
void scan_start(uint32_t revs);
/* Ends the run now: trigger and lasers off. */
void scan_stop(void);
enum run_state scan_state(void);
/* Takes the oldest queued event; 0 if none. */
uint8_t scan_pop_event(struct trigger_event *ev);
/* Set once when a run ended (revolutions done, stopped, host gone); cleared by reading. */
uint8_t scan_take_done(uint32_t *fired);
/* 1 once every 0.98 s (Timer1 overflows), then cleared. */
uint8_t scan_status_due(void);
/* 1 if there is no event and no end of run to report (call with interrupts off). */
uint8_t scan_idle(void);
enum fault scan_fault(void);
uint32_t scan_fired(void);
uint32_t scan_overruns(void);
/* Index pulses that found the count off zero (missed or extra encoder edges). */
uint32_t scan_slips(void);
/* 1 while the host holds DTR (the port is open). */
uint8_t host_present(void);
#endif
