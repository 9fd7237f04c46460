#include <avr/pgmspace.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "proto.h"
#include "uart.h"

#define LINE_MAX 128U /* bytes before the \n */
#define REMEMBERED_IDS 64U
#define MAX_WORDS 8U
#define LIST_MAX 64U

enum nak { ACK = 0, NAK_SYNTAX = 1, NAK_UNKNOWN = 2, NAK_BAD_ARG = 3, NAK_STATE = 4, NAK_RATE = 5 };

#define STR_(x) #x
#define STR(x) STR_(x)

/* Reasons of executed commands, replayed on a retry: kept as an index into this table. */
static const char r_none[] PROGMEM = "";
static const char r_running[] PROGMEM = "running: STOP first";
static const char r_angles[] PROGMEM = "angles must increase and stay below "; /* + PER_FACET */
static const char r_range[] PROGMEM = "range needs step>0, start<stop<="; /* + PER_FACET */
static const char r_too_many[] PROGMEM = "more than " STR(MAX_ANGLES) " angles";
static const char r_facets[] PROGMEM = "facets must increase and stay below " STR(FACETS);
static const char r_lasers[] PROGMEM = "lasers must increase and stay below " STR(LASERS);
static const char r_speed[] PROGMEM = "speed must be 0 or at least 0.001 rpm";
static const char r_not_armed[] PROGMEM = "not armed";
static const char r_already[] PROGMEM = "already running";
static const char r_no_angles[] PROGMEM = "no trigger angles";
static const char r_rate[] PROGMEM = "speed exceeds the rate limit of " STR(MAX_HZ) " Hz";
static const char r_syntax[] PROGMEM = "the words of the command do not parse";
static const char r_unknown[] PROGMEM = "unknown command";
enum reason { R_NONE, R_RUNNING, R_ANGLES, R_RANGE, R_TOO_MANY, R_FACETS, R_LASERS, R_SPEED,
              R_NOT_ARMED, R_ALREADY, R_NO_ANGLES, R_RATE, R_SYNTAX, R_UNKNOWN };
static PGM_P const reasons[] PROGMEM = {r_none, r_running, r_angles, r_range, r_too_many, r_facets,
                                        r_lasers, r_speed, r_not_armed, r_already, r_no_angles, r_rate,
                                        r_syntax, r_unknown};

struct answer {
    uint32_t id;
    uint8_t code;
    uint8_t reason;
};
static struct answer answered[REMEMBERED_IDS];
static uint8_t n_answered, next_answer;

static char line[LINE_MAX + 1];
static uint8_t line_len;
static uint8_t line_bad; /* too long or a byte outside printable ASCII */
static uint32_t crc_errors;
static uint32_t half_period; /* motor, 0.5 µs ticks, after ARM; rpm = 1e6 / half_period */
static uint8_t lasers_cfg = (uint8_t)((1U << LASERS) - 1U);
static uint8_t ambient_cfg;
static uint8_t facets_all = 1;
static float rpm_requested;

uint16_t crc16_ccitt_false(const uint8_t *p, size_t n)
{
    uint16_t crc = 0xFFFF;
    while (n--) {
        crc ^= (uint16_t)(*p++) << 8;
        for (uint8_t i = 0; i < 8; i++)
            crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

/* ---- output lines ---- */

static char out[LINE_MAX + 1];
static uint8_t out_len;

static void out_c(char c)
{
    if (out_len < LINE_MAX - 5U)
        out[out_len++] = c;
}
static void out_P(PGM_P s)
{
    char c;
    while ((c = (char)pgm_read_byte(s++)))
        out_c(c);
}
static void out_u64(uint64_t v)
{
    char d[21];
    uint8_t n = 0;
    do {
        d[n++] = (char)('0' + (uint8_t)(v % 10U));
        v /= 10U;
    } while (v);
    while (n)
        out_c(d[--n]);
}
static void out_u32(uint32_t v) { out_u64(v); }
static void out_mask(uint8_t mask)
{
    if (!mask) {
        out_P(PSTR("NONE"));
        return;
    }
    uint8_t first = 1;
    for (uint8_t j = 0; j < 8; j++)
        if (mask & (1U << j)) {
            if (!first)
                out_c(',');
            out_c((char)('0' + j));
            first = 0;
        }
}
static void out_end(void)
{
    static const char hex[] PROGMEM = "0123456789ABCDEF";
    uint16_t crc = crc16_ccitt_false((const uint8_t *)out, out_len);
    out[out_len] = 0;
    uart_puts(out);
    uart_putc('*');
    for (int8_t s = 12; s >= 0; s -= 4)
        uart_putc(pgm_read_byte(&hex[(crc >> s) & 0xF]));
    uart_putc('\n');
    out_len = 0;
}

static uint64_t now_us(void) { return clock_ticks() / TICKS_PER_US; }

static void send_reply(uint32_t id, uint8_t code, uint8_t reason)
{
    if (code == ACK) {
        out_P(PSTR("ACK "));
        out_u32(id);
    } else {
        out_P(PSTR("NAK "));
        out_u32(id);
        out_c(' ');
        out_c((char)('0' + code));
        out_c(' ');
        out_P((PGM_P)pgm_read_word(&reasons[reason]));
        if (reason == R_ANGLES || reason == R_RANGE)
            out_u32(PER_FACET);
    }
    out_end();
}

static void send_hello(void)
{
    out_P(PSTR("HELLO proto=1 fw=" FW_VERSION " cpr=" STR(CPR) " facets=" STR(FACETS)
               " lasers=" STR(LASERS) " max_hz=" STR(MAX_HZ)));
    out_end();
}

static void out_rpm(void)
{
    if (!half_period) {
        out_c('0');
        return;
    }
    uint64_t micro = (1000000000000ULL + half_period / 2U) / half_period;
    out_u64(micro / 1000000U);
    out_c('.');
    uint32_t frac = (uint32_t)(micro % 1000000U);
    for (uint32_t div = 100000U; div; div /= 10U)
        out_c((char)('0' + (uint8_t)(frac / div % 10U)));
}

void proto_send_status(void)
{
    enum run_state st = scan_state();
    out_P(PSTR("STS state="));
    out_P(st == RUN_IDLE ? PSTR("idle") : st == RUN_ARMED ? PSTR("armed") : PSTR("running"));
    out_P(PSTR(" fired="));
    out_u32(scan_fired());
    out_P(PSTR(" overruns="));
    out_u32(scan_overruns());
    out_P(PSTR(" crc="));
    out_u32(crc_errors);
    out_P(PSTR(" rpm="));
    out_rpm();
    out_P(PSTR(" t="));
    out_u64(now_us());
    out_P(PSTR(" slips="));
    out_u32(scan_slips());
    if (scan_fault() == FAULT_STALL)
        out_P(PSTR(" fault=stall"));
    out_end();
}

void proto_send_trigger(const struct trigger_event *ev)
{
    uint64_t ticks = ((uint64_t)ev->ticks_hi << 16) | ev->ticks_lo;
    out_P(PSTR("TRG seq="));
    out_u32(ev->seq);
    out_P(PSTR(" enc="));
    out_u32(ev->enc);
    out_P(PSTR(" facet="));
    out_u32(ev->facet);
    out_P(PSTR(" rev="));
    out_u32(ev->rev);
    out_P(PSTR(" t="));
    out_u64(ticks / TICKS_PER_US);
    out_P(PSTR(" las="));
    out_mask(ev->lasers);
    out_end();
}

void proto_send_done(uint32_t fired)
{
    out_P(PSTR("DONE fired="));
    out_u32(fired);
    out_P(PSTR(" t="));
    out_u64(now_us());
    out_end();
}

/* ---- parsing ---- */

/* A decimal without sign; 0 if not one or above `max`. */
static uint8_t parse_u64(const char *w, uint64_t max, uint64_t *v)
{
    uint64_t x = 0;
    if (!*w)
        return 0;
    for (; *w; w++) {
        if (*w < '0' || *w > '9')
            return 0;
        uint8_t d = (uint8_t)(*w - '0');
        if (x > (max - d) / 10U)
            return 0;
        x = x * 10U + d;
    }
    *v = x;
    return 1;
}

/* `NONE` or comma-separated u32s; values above 0xFFFF are kept as 0xFFFF (out of every range). */
static uint8_t parse_list(char *w, uint16_t *vals, uint8_t *n)
{
    *n = 0;
    if (strcmp_P(w, PSTR("NONE")) == 0)
        return 1;
    for (;;) {
        char *comma = strchr(w, ',');
        if (comma)
            *comma = 0;
        uint64_t v;
        if (*n >= LIST_MAX || !parse_u64(w, 0xFFFFFFFFULL, &v))
            return 0;
        vals[(*n)++] = v > 0xFFFFU ? 0xFFFFU : (uint16_t)v;
        if (!comma)
            return 1;
        w = comma + 1;
    }
}

static uint8_t increasing_below(const uint16_t *v, uint16_t n, uint16_t below)
{
    for (uint16_t i = 0; i < n; i++)
        if (v[i] >= below || (i > 0 && v[i] <= v[i - 1]))
            return 0;
    return 1;
}

static void disarm(void)
{
    half_period = 0;
    scan_disarm();
}

/* Smallest gap between consecutive triggers of a revolution, wrap included (counts). */
static uint16_t min_gap_counts(void)
{
    uint16_t gap = CPR, prev = 0, first = 0;
    uint8_t any = 0;
    for (uint8_t k = 0; k < sched.n_facets; k++)
        for (uint16_t i = 0; i < sched.n_counts; i++) {
            uint16_t pos = (uint16_t)(sched.facets[k] * PER_FACET + sched.counts[i]);
            if (!any)
                first = pos;
            else if ((uint16_t)(pos - prev) < gap)
                gap = (uint16_t)(pos - prev);
            prev = pos;
            any = 1;
        }
    uint16_t wrap = (uint16_t)(CPR - prev + first);
    if (wrap < gap)
        gap = wrap;
    return gap ? gap : 1;
}

static uint8_t arm(uint8_t *reason)
{
    if (sched.n_counts == 0) {
        *reason = R_NO_ANGLES;
        return NAK_STATE;
    }
    if (facets_all) {
        for (uint8_t k = 0; k < FACETS; k++)
            sched.facets[k] = k;
        sched.n_facets = FACETS;
    }
    sched.lasers = lasers_cfg;
    sched.ambient = ambient_cfg;
    uint16_t gap = min_gap_counts();
    /* Fastest: consecutive triggers 1/MAX_HZ apart; rpm = 60 * MAX_HZ * gap / CPR = 1e6 / half. */
    uint64_t den = 60ULL * MAX_HZ * gap;
    uint32_t fastest_half = (uint32_t)((1000000ULL * CPR + den - 1U) / den);
    uint32_t half = fastest_half;
    if (rpm_requested != 0.0f) {
        float max_rpm = 60.0f * MAX_HZ * gap / CPR;
        if (rpm_requested > max_rpm * (1.0f + 1e-6f)) {
            *reason = R_RATE;
            return NAK_RATE;
        }
        float h = 1e6f / rpm_requested + 0.5f;
        half = h >= 4.0e9f ? 4000000000UL : (uint32_t)h;
        if (half < fastest_half)
            half = fastest_half;
    }
    half_period = half;
    scan_arm();
    motor_set(half);
    return ACK;
}

static uint8_t set_angles(const uint16_t *vals, uint8_t n, uint8_t append, uint8_t *reason)
{
    uint16_t base = append ? sched.n_counts : 0;
    if (base + n > MAX_ANGLES) {
        *reason = R_TOO_MANY;
        return NAK_BAD_ARG;
    }
    if (!increasing_below(vals, n, PER_FACET) || (base && n && vals[0] <= sched.counts[base - 1])) {
        *reason = R_ANGLES;
        return NAK_BAD_ARG;
    }
    memcpy(&sched.counts[base], vals, n * sizeof vals[0]);
    sched.n_counts = base + n;
    return ACK;
}

static uint8_t set_range(uint32_t start, uint32_t stop, uint32_t step, uint8_t *reason)
{
    if (step == 0 || start >= stop || stop > PER_FACET) {
        *reason = R_RANGE;
        return NAK_BAD_ARG;
    }
    if ((stop - start + step - 1U) / step > MAX_ANGLES) {
        *reason = R_TOO_MANY;
        return NAK_BAD_ARG;
    }
    uint16_t n = 0;
    for (uint32_t c = start; c < stop; c += step)
        sched.counts[n++] = (uint16_t)c;
    sched.n_counts = n;
    return ACK;
}

enum verb { V_HELLO, V_ANGLES, V_FACETS, V_LASERS, V_AMBIENT, V_SPEED, V_ARM, V_START, V_STOP, V_STATUS };

/* A parsed command, its arguments checked for syntax only. */
struct command {
    enum verb verb;
    uint32_t id;
    uint8_t sub; /* ANGLES: 0 SET, 1 ADD, 2 RANGE; FACETS: 1 = ALL; AMBIENT: value */
    uint16_t list[LIST_MAX];
    uint8_t n;
    uint32_t a[3];
    float rpm;
};

static uint8_t parse_command(char **w, uint8_t nw, struct command *c)
{
    static const char verbs[] PROGMEM = "HELLO\0ANGLES\0FACETS\0LASERS\0AMBIENT\0SPEED\0ARM\0START\0STOP\0STATUS\0";
    uint8_t nargs = (uint8_t)(nw - 2U);
    char **arg = w + 2;
    PGM_P v = verbs;
    uint8_t k = 0;
    while (pgm_read_byte(v) && strcmp_P(w[0], v) != 0) {
        v += strlen_P(v) + 1;
        k++;
    }
    if (!pgm_read_byte(v))
        return NAK_UNKNOWN;
    c->verb = (enum verb)k;
    uint64_t x;
    switch (c->verb) {
    case V_HELLO: case V_ARM: case V_STOP: case V_STATUS:
        return nargs == 0 ? ACK : NAK_SYNTAX;
    case V_START:
        if (nargs < 1 || !parse_u64(arg[0], UINT64_MAX, &x))
            return NAK_SYNTAX;
        c->a[0] = x > 0xFFFFFFFFULL ? 0xFFFFFFFFUL : (uint32_t)x; /* 2^32 revolutions: until STOP */
        return ACK;
    case V_SPEED: {
        char *end;
        if (nargs < 1)
            return NAK_SYNTAX;
        c->rpm = (float)strtod(arg[0], &end);
        return (end != arg[0] && *end == 0) ? ACK : NAK_SYNTAX;
    }
    case V_AMBIENT:
        if (nargs != 1 || (strcmp_P(arg[0], PSTR("0")) && strcmp_P(arg[0], PSTR("1"))))
            return NAK_SYNTAX;
        c->sub = (uint8_t)(arg[0][0] - '0');
        return ACK;
    case V_LASERS:
        return (nargs == 1 && parse_list(arg[0], c->list, &c->n)) ? ACK : NAK_SYNTAX;
    case V_FACETS:
        if (nargs != 1)
            return NAK_SYNTAX;
        c->sub = strcmp_P(arg[0], PSTR("ALL")) == 0;
        return (c->sub || parse_list(arg[0], c->list, &c->n)) ? ACK : NAK_SYNTAX;
    case V_ANGLES:
        if (nargs == 2 && (!strcmp_P(arg[0], PSTR("SET")) || !strcmp_P(arg[0], PSTR("ADD")))) {
            c->sub = arg[0][0] == 'A';
            return parse_list(arg[1], c->list, &c->n) ? ACK : NAK_SYNTAX;
        }
        if (nargs == 4 && !strcmp_P(arg[0], PSTR("RANGE"))) {
            c->sub = 2;
            for (uint8_t i = 0; i < 3; i++) {
                if (!parse_u64(arg[1 + i], 0xFFFFFFFFULL, &x))
                    return NAK_SYNTAX;
                c->a[i] = (uint32_t)x;
            }
            return ACK;
        }
        return NAK_SYNTAX;
    }
    return NAK_SYNTAX;
}

static uint8_t execute(const struct command *c, uint8_t *reason)
{
    enum run_state st = scan_state();
    uint8_t running = st == RUN_RUNNING || st == RUN_WAITING_INDEX;
    uint8_t configuring = c->verb != V_HELLO && c->verb != V_STATUS && c->verb != V_STOP && c->verb != V_START;
    uint8_t code = ACK;
    *reason = R_NONE;
    if (configuring && running) {
        *reason = R_RUNNING;
        return NAK_STATE;
    }
    switch (c->verb) {
    case V_HELLO: case V_STATUS:
        return ACK;
    case V_ANGLES:
        code = c->sub == 2 ? set_range(c->a[0], c->a[1], c->a[2], reason)
                           : set_angles(c->list, c->n, c->sub, reason);
        break;
    case V_FACETS:
        if (!c->sub && (c->n == 0 || !increasing_below(c->list, c->n, FACETS))) {
            *reason = R_FACETS;
            return NAK_BAD_ARG;
        }
        facets_all = c->sub;
        for (uint8_t k = 0; k < c->n; k++)
            sched.facets[k] = (uint8_t)c->list[k];
        sched.n_facets = c->n;
        break;
    case V_LASERS:
        if (!increasing_below(c->list, c->n, LASERS)) {
            *reason = R_LASERS;
            return NAK_BAD_ARG;
        }
        lasers_cfg = 0;
        for (uint8_t k = 0; k < c->n; k++)
            lasers_cfg |= (uint8_t)(1U << c->list[k]);
        break;
    case V_AMBIENT:
        ambient_cfg = c->sub;
        break;
    case V_SPEED:
        if (!(isfinite(c->rpm) && (c->rpm == 0.0f || c->rpm >= 0.001f))) {
            *reason = R_SPEED;
            return NAK_BAD_ARG;
        }
        rpm_requested = c->rpm;
        break;
    case V_ARM:
        return arm(reason);
    case V_START:
        if (running) {
            *reason = R_ALREADY;
            return NAK_STATE;
        }
        if (st != RUN_ARMED) {
            *reason = R_NOT_ARMED;
            return NAK_STATE;
        }
        scan_start(c->a[0]);
        return ACK;
    case V_STOP:
        if (running) {
            scan_stop(); /* DONE follows from the main loop */
        } else {
            disarm();
        }
        return ACK;
    }
    if (code == ACK)
        disarm(); /* any configuration disarms */
    return code;
}

static struct answer *remembered(uint32_t id)
{
    for (uint8_t i = 0; i < n_answered; i++)
        if (answered[i].id == id)
            return &answered[i];
    return 0;
}

static void remember(uint32_t id, uint8_t code, uint8_t reason)
{
    answered[next_answer] = (struct answer){id, code, reason};
    next_answer = (uint8_t)((next_answer + 1U) % REMEMBERED_IDS);
    if (n_answered < REMEMBERED_IDS)
        n_answered++;
}

static void query_lines(enum verb v)
{
    if (v == V_HELLO)
        send_hello();
    else if (v == V_STATUS)
        proto_send_status();
}

static void handle_body(char *body)
{
    static struct command cmd; /* static: too big for the stack */
    char *w[MAX_WORDS];
    uint8_t nw = 0;
    /* Words separated by single spaces; an empty word fails the syntax like any bad word. */
    w[nw++] = body;
    for (char *p = body; *p; p++)
        if (*p == ' ') {
            *p = 0;
            if (nw == MAX_WORDS)
                break;
            w[nw++] = p + 1;
        }
    uint64_t id;
    if (nw < 2 || !parse_u64(w[1], 0xFFFFFFFFULL, &id))
        return; /* no id: cannot be answered, the host retries */
    cmd.id = (uint32_t)id;
    uint8_t code = parse_command(w, nw, &cmd);
    if (code != ACK) {
        send_reply(cmd.id, code, code == NAK_UNKNOWN ? R_UNKNOWN : R_SYNTAX);
        return;
    }
    struct answer *old = remembered(cmd.id);
    if (old) {
        query_lines(cmd.verb);
        send_reply(old->id, old->code, old->reason);
        return;
    }
    uint8_t reason;
    code = execute(&cmd, &reason);
    remember(cmd.id, code, reason);
    query_lines(cmd.verb);
    send_reply(cmd.id, code, reason);
}

static uint8_t hex_value(char c)
{
    if (c >= '0' && c <= '9')
        return (uint8_t)(c - '0');
    if (c >= 'A' && c <= 'F')
        return (uint8_t)(c - 'A' + 10);
    if (c >= 'a' && c <= 'f')
        return (uint8_t)(c - 'a' + 10);
    return 0xFF;
}

static void end_of_line(void)
{
    uint8_t n = line_len;
    if (n && line[n - 1] == '\r')
        n--;
    if (line_bad || n == 0 || n < 5 || line[n - 5] != '*')
        return;
    uint16_t crc = 0;
    for (uint8_t i = n - 4; i < n; i++) {
        uint8_t h = hex_value(line[i]);
        if (h == 0xFF)
            return;
        crc = (uint16_t)((crc << 4) | h);
    }
    uint8_t body_len = (uint8_t)(n - 5U);
    if (memchr(line, '*', body_len))
        return;
    if (crc16_ccitt_false((const uint8_t *)line, body_len) != crc) {
        crc_errors++;
        return;
    }
    line[body_len] = 0;
    handle_body(line);
}

void proto_rx_byte(uint8_t c)
{
    if (c == '\n') {
        end_of_line();
        line_len = 0;
        line_bad = 0;
        return;
    }
    if (line_len >= LINE_MAX) {
        line_bad = 1; /* too long: dropped at the \n */
        return;
    }
    if ((c < 0x20 || c > 0x7E) && c != '\r')
        line_bad = 1;
    line[line_len++] = (char)c;
}
