/* Encoder, trigger timeline, clock, motor reference and host-present line (see scan.h).
 *
 * Two interrupt levels keep the encoder interrupt short (it runs on every count, 4 per line):
 *  - PCINT2 (A, B and Z on port D, any change) decodes x4 and, when the count reaches `target`, raise the
 *    laser enables and the trigger at once and latch Timer1. That is all they do: the trigger
 *    lags the encoder edge by the interrupt entry only (firmware/README.md has the numbers).
 *  - Raising the trigger pin (PB1, PCINT1) requests the pin-change interrupt PCINT0, which does
 *    the bookkeeping with interrupts enabled (the encoder keeps preempting it): the event for the
 *    host, the pulse end on Timer1 compare A, the next target, revolutions and the run's end.
 * The Timer1 overflow (every 32.768 ms) also watches a running run: an encoder count that stays
 * the same for the run's stall limit faults it (stall: trigger and lasers off, nothing fires). */
#include <avr/interrupt.h>
#include <avr/io.h>
#include "scan.h"

#define ENC_A (1 << PD2)  /* PCINT18 */
#define ENC_B (1 << PD3)  /* PCINT19 */
#define ENC_Z (1 << PD4)  /* PCINT20 */
#define HOST_DTR (1 << PB0) /* PCINT0, DTR#: low = host has the port open */
#define TRIGGER (1 << PB1)
#define MOTOR_CLK (1 << PB2)
#define LASER_MASK ((uint8_t)((1U << LASERS) - 1U)) /* PC0.. */
#define NO_TARGET 0xFFFFU
#define PULSE_TICKS ((uint16_t)(PULSE_US * TICKS_PER_US))
#define QUEUE_LEN 8U /* power of two */
#define TRIGGER_PCINT (1 << PCINT1)

struct schedule sched;

static volatile uint32_t ticks_hi;
/* Shared with the encoder interrupt (8- and 16-bit: one or two instructions to read). */
static volatile uint16_t count;
static volatile uint16_t target = NO_TARGET;       /* next count to fire at */
static volatile uint16_t start_target = NO_TARGET; /* taken at each revolution's count 0 */
static volatile uint8_t las_next, las_next_rev;    /* lasers of the next trigger / revolution */
static volatile uint8_t homed;
static volatile uint8_t rev_pending, fire_pending;
static volatile uint16_t fire_tcnt, fire_count;
static uint8_t enc_prev, z_prev;
static int8_t quad_delta[16];
/* Bookkeeping (PCINT0 level and main loop). */
static volatile enum run_state state;
static uint16_t facet_base[FACETS];
static uint16_t i_count;
static uint8_t i_facet;
static uint32_t rev;
static uint32_t revs_wanted;
static volatile uint32_t seq;
static volatile uint32_t fired;
static volatile uint32_t overruns;
static volatile uint32_t slips;
static volatile uint8_t done_flag;
static volatile uint8_t booking;
static volatile uint32_t motor_half;
static volatile uint8_t fault;
static volatile uint8_t status_due;
static uint16_t stall_checks;   /* overflows without a count change that make a stall */
static uint16_t silent_checks;  /* overflows so far without one */
static uint16_t watched_count;  /* the count at the last overflow */
static uint32_t motor_left;
static struct trigger_event queue[QUEUE_LEN];
static volatile uint8_t q_head, q_tail;

/* Quadrature position 0..3 of pins (A, B): forward is A leading B, 00 -> 10 -> 11 -> 01 in (A,B)
 * reading order, i.e. the Gray sequence 0, 1, 3, 2 of A + 2B... see gray_position. */
static uint8_t gray_position(uint8_t a, uint8_t b)
{
    static const uint8_t pos[4] = {0, 1, 3, 2}; /* index a | b << 1 */
    return pos[a | (uint8_t)(b << 1)];
}

static void build_decoder(void)
{
    for (uint8_t prev = 0; prev < 4; prev++)
        for (uint8_t now = 0; now < 4; now++) {
            uint8_t d = (uint8_t)((gray_position(now & 1, now >> 1) - gray_position(prev & 1, prev >> 1)) & 3);
            /* +2: one edge came before the previous one was served; the polygon turns forward. */
            quad_delta[(uint8_t)(prev << 2) | now] = d == 3 ? -1 : (int8_t)d;
        }
}

void scan_init(void)
{
    DDRB |= TRIGGER | MOTOR_CLK;
    /* No internal pull-ups on the inputs: the encoder and the USB-serial bridge drive them
     * push-pull (open-collector encoders need external 2.2 kΩ pull-ups, firmware/README.md). */
    DDRC |= LASER_MASK;
    build_decoder();
    TCCR1A = 0;
    TCCR1B = (1 << CS11); /* F_CPU / 8: 0.5 µs ticks */
    TIMSK1 = (1 << TOIE1);
    PCMSK2 = (1 << PCINT18) | (1 << PCINT19) | (1 << PCINT20); /* A, B, Z */
    PCMSK0 = (1 << PCINT0) | TRIGGER_PCINT;
    PCICR = (1 << PCIE2) | (1 << PCIE0);
    enc_prev = (uint8_t)((PIND & (ENC_A | ENC_B)) >> 2);
    z_prev = PIND & ENC_Z;
}

static void stall(void);

/* Every 32.768 ms; 30 of them (0.98 s) make the status period while running. Watches the run:
 * the count unchanged at `stall_checks` overflows in a row is a stalled polygon (or a dead
 * encoder). Not before the first index (RUN_WAITING_INDEX): the motor may still spin up. */
ISR(TIMER1_OVF_vect)
{
    static uint8_t overflows;
    ticks_hi++;
    if (++overflows == 30) {
        overflows = 0;
        status_due = 1;
    }
    uint16_t c = count;
    if (state != RUN_RUNNING || fault || c != watched_count) {
        watched_count = c;
        silent_checks = 0;
    } else if (++silent_checks >= stall_checks) {
        stall();
    }
}

uint8_t scan_status_due(void)
{
    uint8_t due = status_due;
    status_due = 0;
    return due;
}

/* The clock with interrupts already off: an overflow not yet counted shows as a pending flag. */
static void latch_ticks(uint32_t *hi, uint16_t *lo)
{
    uint16_t t = TCNT1;
    uint32_t h = ticks_hi;
    if ((TIFR1 & (1 << TOV1)) && t < 0x8000U)
        h++;
    *hi = h;
    *lo = t;
}

uint64_t clock_ticks(void)
{
    uint32_t hi;
    uint16_t lo;
    uint8_t sreg = SREG;
    cli();
    latch_ticks(&hi, &lo);
    SREG = sreg;
    return ((uint64_t)hi << 16) | lo;
}

/* ---- the encoder level ---- */

/* Count 0 of a revolution (wrap or index): the revolution's first target and lasers. */
static inline __attribute__((always_inline)) void at_count_zero(void)
{
    target = start_target;
    las_next = las_next_rev;
    if (start_target != NO_TARGET)
        rev_pending++; /* a revolution of the run: booked with its first trigger */
}

/* Fires if this step of `delta` counts reached or passed the target. */
static inline __attribute__((always_inline)) void fire_if_due(uint16_t c, uint8_t delta)
{
    uint16_t t = target;
    if (t != NO_TARGET && (uint16_t)(c - t) < delta) {
        PORTC |= las_next;
        PORTB |= TRIGGER; /* also requests PCINT0: the bookkeeping */
        fire_tcnt = TCNT1;
        fire_count = c;
        target = NO_TARGET;
        fire_pending++;
    }
}

/* Index rising edge: homes the count; later a check that no edge was missed or invented. */
static inline __attribute__((always_inline)) void at_index(void)
{
    uint16_t c = count;
    if (homed && c == 0)
        return;
    if (homed)
        slips++;
    count = 0;
    /* Not homed yet, or behind (the wrap to 0 was not seen): this is count 0 now. */
    if (!homed || c >= CPR / 2U) {
        homed = 1;
        at_count_zero();
        fire_if_due(0, 1);
    }
}

/* A, B or Z changed (pin-change interrupt of port D). */
ISR(PCINT2_vect)
{
    uint8_t pins = PIND;
    uint8_t now = (uint8_t)((pins & (ENC_A | ENC_B)) >> 2);
    int8_t delta = quad_delta[(uint8_t)(enc_prev << 2) | now];
    enc_prev = now;
    if (delta > 0) {
        uint16_t c = count + (uint8_t)delta;
        if (c >= CPR) {
            c -= CPR;
            if (homed)
                at_count_zero();
        }
        count = c;
        fire_if_due(c, (uint8_t)delta);
    } else if (delta < 0) {
        count = count == 0 ? CPR - 1U : count - 1U;
    }
    uint8_t z = pins & ENC_Z;
    if (z && !z_prev)
        at_index();
    z_prev = z;
}

/* The end of the trigger pulse. */
ISR(TIMER1_COMPA_vect)
{
    PORTB &= (uint8_t)~TRIGGER;
    PORTC &= (uint8_t)~LASER_MASK;
    TIMSK1 &= (uint8_t)~(1 << OCIE1A);
}

/* ---- the bookkeeping level ---- */

static uint8_t lasers_of(uint32_t r)
{
    return (sched.ambient && (r & 1U) == 0) ? 0 : sched.lasers;
}

static uint16_t position_of(uint8_t k, uint16_t i) { return (uint16_t)(facet_base[k] + sched.counts[i]); }

/* Ends the run; `cut` switches trigger and lasers off now (STOP, host gone) instead of letting
 * the last pulse end on time. Interrupts off. */
static void end_run(uint8_t cut)
{
    if (cut) {
        PORTC &= (uint8_t)~LASER_MASK;
        PORTB &= (uint8_t)~TRIGGER;
        TIMSK1 &= (uint8_t)~(1 << OCIE1A);
    }
    start_target = NO_TARGET;
    target = NO_TARGET;
    rev_pending = 0;
    fire_pending = 0;
    state = RUN_IDLE;
    done_flag = 1;
}

/* The encoder stopped during a run: trigger and lasers off now (a pulse in progress is cut),
 * and nothing fires any more, also if the polygon turns again; the run stays running with the
 * fault until STOP or the host leaving ends it; STS reports it at once. Interrupts off. */
static void stall(void)
{
    PORTC &= (uint8_t)~LASER_MASK;
    PORTB &= (uint8_t)~TRIGGER;
    TIMSK1 &= (uint8_t)~(1 << OCIE1A);
    start_target = NO_TARGET;
    target = NO_TARGET;
    fault = FAULT_STALL;
    status_due = 1;
}

static void book_revolution(void)
{
    if (state == RUN_WAITING_INDEX) {
        state = RUN_RUNNING;
        rev = 0;
    } else if (state == RUN_RUNNING) {
        rev++;
    } else {
        return;
    }
    i_count = 0;
    i_facet = 0;
    las_next_rev = lasers_of(rev + 1U);
}

/* Books the trigger just fired. Runs with interrupts on (the encoder preempts it); the few
 * accesses shared with the encoder and timer interrupts are made with interrupts off. */
static void book_trigger(void)
{
    /* The encoder cannot fire again before `target` is set below: these are stable. */
    uint16_t tcnt = fire_tcnt, at = fire_count;
    uint32_t hi;
    uint16_t lo;
    cli();
    latch_ticks(&hi, &lo);
    /* The pulse ends PULSE_TICKS after the edge (at once if that already passed). */
    if ((uint16_t)(lo - tcnt) >= PULSE_TICKS) {
        PORTB &= (uint8_t)~TRIGGER;
        PORTC &= (uint8_t)~LASER_MASK;
    } else {
        OCR1A = (uint16_t)(tcnt + PULSE_TICKS);
        TIFR1 = (1 << OCF1A);
        TIMSK1 |= (1 << OCIE1A);
    }
    sei();
    if (lo < tcnt)
        hi--; /* Timer1 overflowed between the edge and now */
    if (state != RUN_RUNNING)
        return;
    uint16_t scheduled = position_of(i_facet, i_count);
    if (at != scheduled)
        overruns++; /* an edge came before the previous one was served: fired one count late */
    uint8_t next = (uint8_t)((q_head + 1U) & (QUEUE_LEN - 1U));
    if (next == q_tail) {
        overruns++; /* the main loop fell behind: the event is lost, the host places it */
    } else {
        struct trigger_event *ev = &queue[q_head];
        ev->ticks_hi = hi;
        ev->ticks_lo = tcnt;
        ev->seq = seq;
        ev->rev = rev;
        ev->enc = scheduled;
        ev->facet = sched.facets[i_facet];
        ev->lasers = lasers_of(rev);
        q_head = next;
    }
    seq++;
    fired++;
    if (++i_count == sched.n_counts) {
        i_count = 0;
        i_facet++;
    }
    if (i_facet < sched.n_facets) {
        uint8_t las = lasers_of(rev);
        uint16_t t = position_of(i_facet, i_count);
        cli();
        las_next = las;
        if (!fault)
            target = t;
        sei();
    } else if (revs_wanted != 0 && rev + 1U >= revs_wanted) {
        cli();
        end_run(0); /* the last pulse still ends on time */
        sei();
    } /* else: the next revolution's count 0 sets the target */
}

/* Trigger raised (bookkeeping) or DTR changed. Runs with interrupts on; never nests itself: a
 * nested call finds `booking` set and leaves the work to the loop below. */
ISR(PCINT0_vect, ISR_NOBLOCK)
{
    cli();
    if ((PINB & HOST_DTR) && (state == RUN_RUNNING || state == RUN_WAITING_INDEX))
        end_run(1); /* the host closed the port: no run without a host, lasers off at once */
    if (booking)
        return;
    booking = 1;
    for (;;) {
        cli();
        if (rev_pending) {
            rev_pending--;
            sei();
            book_revolution();
        } else if (fire_pending) {
            fire_pending--;
            sei();
            book_trigger();
        } else {
            booking = 0;
            return; /* reti enables interrupts */
        }
    }
}

uint8_t host_present(void) { return !(PINB & HOST_DTR); }

/* The motor reference clock: a toggle every half period, longer periods in steps under 2^16. */
ISR(TIMER1_COMPB_vect)
{
    if (motor_left == 0) {
        PORTB ^= MOTOR_CLK;
        motor_left = motor_half;
    }
    uint16_t step = motor_left > 0xF000U ? 0xF000U : (uint16_t)motor_left;
    OCR1B += step;
    motor_left -= step;
}

void motor_set(uint32_t half_period_ticks)
{
    cli();
    motor_half = half_period_ticks;
    if (half_period_ticks == 0) {
        TIMSK1 &= (uint8_t)~(1 << OCIE1B);
    } else if (!(TIMSK1 & (1 << OCIE1B))) {
        motor_left = 0;
        OCR1B = (uint16_t)(TCNT1 + 64U);
        TIFR1 = (1 << OCF1B);
        TIMSK1 |= (1 << OCIE1B);
    }
    sei();
}

void scan_arm(void)
{
    cli();
    for (uint8_t k = 0; k < sched.n_facets; k++)
        facet_base[k] = (uint16_t)(sched.facets[k] * PER_FACET);
    seq = 0;
    fired = 0;
    overruns = 0;
    q_head = q_tail = 0;
    done_flag = 0;
    fault = FAULT_NONE;
    target = start_target = NO_TARGET;
    state = RUN_ARMED;
    sei();
}

void scan_disarm(void)
{
    cli();
    if (state == RUN_ARMED)
        state = RUN_IDLE;
    sei();
}

/* Timer1 overflows in STALL_COUNTS count periods of the motor speed (half-period ticks): a count
 * period is 2 * MOTOR_PPR * half / CPR ticks. */
static uint16_t stall_checks_for(uint32_t half)
{
    uint64_t ticks = (uint64_t)STALL_COUNTS * 2U * MOTOR_PPR * half / CPR;
    uint64_t checks = (ticks + 0xFFFFU) >> 16;
    if (checks < STALL_MIN_CHECKS)
        checks = STALL_MIN_CHECKS;
    return checks > 0xFFFFU ? 0xFFFFU : (uint16_t)checks;
}

void scan_start(uint32_t revs)
{
    uint16_t checks = stall_checks_for(motor_half);
    cli();
    stall_checks = checks;
    silent_checks = 0;
    revs_wanted = revs;
    target = NO_TARGET;
    rev_pending = fire_pending = 0;
    las_next_rev = lasers_of(0);
    start_target = position_of(0, 0);
    state = RUN_WAITING_INDEX;
    sei();
}

void scan_stop(void)
{
    cli();
    if (state == RUN_RUNNING || state == RUN_WAITING_INDEX)
        end_run(1);
    else
        state = RUN_IDLE;
    sei();
}

enum run_state scan_state(void) { return state; }
enum fault scan_fault(void) { return (enum fault)fault; }

uint8_t scan_pop_event(struct trigger_event *ev)
{
    uint8_t got = 0;
    cli();
    if (q_tail != q_head) {
        *ev = queue[q_tail];
        q_tail = (uint8_t)((q_tail + 1U) & (QUEUE_LEN - 1U));
        got = 1;
    }
    sei();
    return got;
}

uint8_t scan_idle(void)
{
    return q_tail == q_head && !(done_flag && q_tail == q_head);
}

uint8_t scan_take_done(uint32_t *n)
{
    uint8_t d;
    cli();
    d = done_flag && q_tail == q_head; /* DONE after the run's last event */
    if (d) {
        done_flag = 0;
        *n = fired;
    }
    sei();
    return d;
}

static uint32_t read32(volatile uint32_t *v)
{
    uint8_t sreg = SREG;
    cli();
    uint32_t x = *v;
    SREG = sreg;
    return x;
}

uint32_t scan_fired(void) { return read32(&fired); }
uint32_t scan_overruns(void) { return read32(&overruns); }
uint32_t scan_slips(void) { return read32(&slips); }
