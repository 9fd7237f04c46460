/* Encoder, trigger timeline, clock, motor reference and host-present line (see scan.h).
 *
 * Timing: the encoder's A and B edges interrupt (INT0/INT1, any change) and are decoded x4; the
 * interrupt that brings the count onto a scheduled count raises the trigger and the laser enables
 * at once and latches Timer1, so the edge lags the encoder edge only by the interrupt entry
 * (firmware/README.md gives the measured numbers). Timer1's compare A ends the pulse. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include "scan.h"

#define ENC_A (1 << PD2)  /* INT0 */
#define ENC_B (1 << PD3)  /* INT1 */
#define ENC_Z (1 << PD4)  /* PCINT20 */
#define HOST_DTR (1 << PB0) /* PCINT0, low = host has the port open */
#define TRIGGER (1 << PB1)
#define MOTOR_CLK (1 << PB2)
#define LASER_MASK ((uint8_t)((1U << LASERS) - 1U)) /* PC0.. */
#define NO_TARGET 0xFFFFU
#define PULSE_TICKS ((uint16_t)(PULSE_US * TICKS_PER_US))
#define QUEUE_LEN 8U /* power of two */

struct schedule sched;

static volatile uint32_t ticks_hi;
static volatile uint16_t count;
static volatile uint8_t homed;
static uint8_t enc_state;
static volatile enum run_state state;
static uint16_t target = NO_TARGET;
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
static volatile uint32_t motor_half;
static uint32_t motor_left;
static struct trigger_event queue[QUEUE_LEN];
static volatile uint8_t q_head, q_tail;

/* Forward is A leading B: states (A,B) 00 -> 01 -> 11 -> 10 count up. Index: prev<<2 | new. */
static const int8_t quad_step[16] = {0, 1, -1, 0, -1, 0, 0, 1, 1, 0, 0, -1, 0, -1, 1, 0};

void scan_init(void)
{
    DDRB |= TRIGGER | MOTOR_CLK;
    PORTB |= HOST_DTR; /* pull-up: no adapter = no host */
    DDRC |= LASER_MASK;
    PORTD |= ENC_A | ENC_B | ENC_Z; /* pull-ups for open-collector encoders */
    TCCR1A = 0;
    TCCR1B = (1 << CS11); /* F_CPU / 8: 0.5 µs ticks */
    TIMSK1 = (1 << TOIE1);
    EICRA = (1 << ISC00) | (1 << ISC10); /* any change on A and B */
    EIMSK = (1 << INT0) | (1 << INT1);
    PCMSK2 = (1 << PCINT20);
    PCMSK0 = (1 << PCINT0);
    PCICR = (1 << PCIE2) | (1 << PCIE0);
    enc_state = (uint8_t)(((PIND & ENC_A) ? 2 : 0) | ((PIND & ENC_B) ? 1 : 0));
}

ISR(TIMER1_OVF_vect) { ticks_hi++; }

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

static uint8_t lasers_of(uint32_t r)
{
    return (sched.ambient && (r & 1U) == 0) ? 0 : sched.lasers;
}

static void first_target(void)
{
    i_count = 0;
    i_facet = 0;
    target = facet_base[0] + sched.counts[0];
}

static void finish_run(void)
{
    PORTC &= (uint8_t)~LASER_MASK;
    PORTB &= (uint8_t)~TRIGGER;
    TIMSK1 &= (uint8_t)~(1 << OCIE1A);
    target = NO_TARGET;
    state = RUN_IDLE;
    done_flag = 1;
}

static void fire(void)
{
    uint8_t las = lasers_of(rev);
    if (PORTB & TRIGGER) {
        overruns++; /* the previous pulse is still high: this trigger cannot be given */
    } else {
        PORTC = (uint8_t)((PORTC & (uint8_t)~LASER_MASK) | las);
        PORTB |= TRIGGER;
        OCR1A = (uint16_t)(TCNT1 + PULSE_TICKS);
        TIFR1 = (1 << OCF1A);
        TIMSK1 |= (1 << OCIE1A);
    }
    uint8_t next = (uint8_t)((q_head + 1U) & (QUEUE_LEN - 1U));
    if (next == q_tail) {
        overruns++; /* the main loop fell behind: the event is lost, the host places it */
    } else {
        struct trigger_event *ev = &queue[q_head];
        latch_ticks(&ev->ticks_hi, &ev->ticks_lo);
        ev->seq = seq;
        ev->rev = rev;
        ev->enc = target;
        ev->facet = sched.facets[i_facet];
        ev->lasers = las;
        q_head = next;
    }
    seq++;
    fired++;
    if (++i_count < sched.n_counts) {
        target = facet_base[i_facet] + sched.counts[i_count];
        return;
    }
    i_count = 0;
    if (++i_facet < sched.n_facets) {
        target = facet_base[i_facet] + sched.counts[0];
        return;
    }
    target = NO_TARGET; /* until the next index */
    if (revs_wanted != 0 && rev + 1U >= revs_wanted)
        finish_run();
}

static void on_revolution(void)
{
    if (state == RUN_WAITING_INDEX) {
        state = RUN_RUNNING;
        rev = 0;
        first_target();
    } else if (state == RUN_RUNNING) {
        rev++;
        first_target();
    }
}

static inline void check_target(void)
{
    if (state != RUN_RUNNING || target == NO_TARGET || count < target)
        return;
    if (count != target)
        overruns++; /* encoder edges were skipped: fired late, still at its place in the order */
    fire();
}

ISR(INT0_vect)
{
    uint8_t pins = PIND;
    uint8_t now = (uint8_t)(((pins & ENC_A) ? 2 : 0) | ((pins & ENC_B) ? 1 : 0));
    int8_t step = quad_step[(uint8_t)(enc_state << 2) | now];
    enc_state = now;
    if (step > 0) {
        uint16_t c = count + 1U;
        if (c >= CPR)
            c = 0;
        count = c;
        if (c == 0 && homed)
            on_revolution();
        check_target();
    } else if (step < 0) {
        count = count == 0 ? CPR - 1U : count - 1U;
    }
}

ISR(INT1_vect, ISR_ALIASOF(INT0_vect));

/* Index (rising edge): homes the count; later a check that no edge was missed or invented. */
ISR(PCINT2_vect)
{
    if (!(PIND & ENC_Z))
        return;
    if (!homed) {
        homed = 1;
        count = 0;
        on_revolution();
        check_target();
    } else if (count != 0) {
        slips++;
        uint8_t behind = count >= CPR / 2U; /* the wrap to 0 was not seen yet */
        count = 0;
        if (behind) {
            on_revolution();
            check_target();
        }
    }
}

/* The end of the trigger pulse. */
ISR(TIMER1_COMPA_vect)
{
    PORTB &= (uint8_t)~TRIGGER;
    PORTC &= (uint8_t)~LASER_MASK;
    TIMSK1 &= (uint8_t)~(1 << OCIE1A);
}

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

/* The host closed the port (DTR released): no run without a host, lasers off at once. */
ISR(PCINT0_vect)
{
    if ((PINB & HOST_DTR) && (state == RUN_RUNNING || state == RUN_WAITING_INDEX))
        finish_run();
}

uint8_t host_present(void) { return !(PINB & HOST_DTR); }

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
    target = NO_TARGET;
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

void scan_start(uint32_t revs)
{
    cli();
    revs_wanted = revs;
    target = NO_TARGET;
    state = RUN_WAITING_INDEX;
    sei();
}

void scan_stop(void)
{
    cli();
    if (state == RUN_RUNNING || state == RUN_WAITING_INDEX)
        finish_run();
    else
        state = RUN_IDLE;
    sei();
}

enum run_state scan_state(void) { return state; }

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
