/* fw-harness: runs the real firmware ELF on simavr (ATmega328P, 16 MHz) in real time, with
 *   - its UART on a pseudo-terminal (the port path is the first line on stdout, as
 *     `omni-trigger emulate` prints it), the host's open/close driving the DTR input;
 *   - a polygon turning at the speed of the firmware's motor reference clock (a PLL-locked
 *     polygon motor), as quadrature encoder A/B edges with jitter plus an index pulse at count 0;
 *   - every trigger and laser pin edge recorded with the simulator's cycle count (--edges, JSON
 *     Lines), and a camera frame per trigger rising edge written into --frames with its
 *     modification time at the edge, its ground truth appended to --truth (the emulator's
 *     TruthRecord: path, trigger_seq = edge number, true alpha_deg, facet, lasers);
 *   - line faults in both directions: --bad-crc P (a CRC digit changed), --garbage P (junk bytes
 *     before a line);
 *   - a stalled polygon: --stall-after N (the encoder stops at the rising edge of trigger N) or
 *     --stall-at-ms T (at T ms of simulated time); the stall and every line the firmware sends
 *     are recorded in --edges too.
 * Usage: fw-harness --firmware ELF --frames DIR [--truth FILE] [--edges FILE] [options]; --help. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "avr_extint.h"
#include "avr_ioport.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_cycle_timers.h"
#include "sim_elf.h"
#include "sim_irq.h"

#define F_CPU 16000000ULL
#define MOTOR_PPR 60 /* firmware/src/config.h */
#define LINE_MAX 512
#define QUEUE_MAX 8192

static const char *usage =
    "fw-harness: the omniscan firmware on an emulated ATmega328P, served on a pseudo-terminal.\n"
    "usage: fw-harness --firmware ELF --frames DIR [options]\n"
    "  --truth FILE        append one JSON line of ground truth per frame\n"
    "  --edges FILE        JSON lines: every trigger pulse, laser edge and host (DTR) change\n"
    "  --cpr N --facets N --lasers N   must match the firmware build (36000 12 2)\n"
    "  --jitter F          encoder edge jitter, fraction of a count period (0..0.45, default 0.2)\n"
    "  --speed-scale K     polygon turns K x the commanded speed (stress test, default 1)\n"
    "  --start-count N     encoder count at power-up (default 35000: the index comes soon)\n"
    "  --bad-crc P         probability per line (both directions) of a corrupted CRC\n"
    "  --garbage P         probability per line (both directions) of junk bytes before it\n"
    "  --fault-seed N      seed of the fault and jitter generator\n"
    "  --stall-after N     the polygon stops (no more encoder edges) at the rising edge of trigger N\n"
    "  --stall-at-ms T     the polygon stops T ms (simulated) after power-up\n"
    "  --persist           keep running after the host closes the port (else exit 50 ms later)\n"
    "Prints the port path on the first line of stdout; everything else goes to stderr.\n";

/* ---- options and state ---- */
static struct {
    const char *firmware, *frames, *truth, *edges;
    unsigned cpr, facets, lasers;
    double jitter, speed_scale, bad_crc, garbage;
    uint64_t seed;
    long start_count;
    int persist;
    unsigned long stall_after; /* trigger number from 1; 0 = never */
    double stall_at_ms;        /* 0 = never */
} opt = {.cpr = 36000, .facets = 12, .lasers = 2, .jitter = 0.2, .speed_scale = 1.0, .start_count = 35000};

static avr_t *avr;
static FILE *truth_f, *edges_f;
static int master_fd = -1;
static int connected, ever_connected;
static volatile sig_atomic_t quit;
static struct timespec wall0_mono, wall0_real;

/* SplitMix64 streams: encoder jitter, faults on the firmware's lines, faults on the host's lines
 * (separate, so that the faults do not depend on how many encoder edges came between lines). */
enum { RNG_JITTER, RNG_TO_HOST, RNG_TO_FW };
static uint64_t rng_state[3];
static int rng_stream;
static uint64_t rng_next(void)
{
    uint64_t z = (rng_state[rng_stream] += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}
static double rng_unit(void) { return (double)(rng_next() >> 11) / 9007199254740992.0; }

static double us_of(avr_cycle_count_t c) { return (double)c * 1e6 / (double)F_CPU; }

static void die(const char *fmt, const char *arg)
{
    fprintf(stderr, "fw-harness: ");
    fprintf(stderr, fmt, arg);
    fputc('\n', stderr);
    exit(1);
}

/* ---- the polygon: encoder A/B/Z ---- */
static avr_irq_t *pin_a, *pin_b, *pin_z, *pin_dtr;
static int64_t enc_pos;                 /* counts since power-up (+ start offset) */
static double count_cycles;             /* cycles per count; 0 = not turning */
static double anchor_cycle;             /* nominal time of count anchor_pos */
static int64_t anchor_pos;
static avr_cycle_count_t last_enc_edge; /* when the current count was reached */
static avr_cycle_count_t last_motor_toggle;
static double motor_half_cycles;
static int encoder_running;
static int stalled; /* the polygon stopped for good (--stall-after, --stall-at-ms) */

static const uint8_t gray[4] = {0, 2, 3, 1}; /* (A<<1)|B for count mod 4: A leads B */

/* Drives A, B and Z for the current count; only pins that change are driven (each change is
 * a pin-change interrupt). */
static void set_encoder_pins(void)
{
    static int level[3] = {-1, -1, -1};
    uint8_t s = gray[((enc_pos % 4) + 4) % 4];
    int now[3] = {(s >> 1) & 1, s & 1, ((enc_pos % opt.cpr) + opt.cpr) % opt.cpr == 0};
    avr_irq_t *pins[3] = {pin_a, pin_b, pin_z};
    for (int i = 0; i < 3; i++)
        if (now[i] != level[i]) {
            level[i] = now[i];
            avr_raise_irq(pins[i], (uint32_t)now[i]);
        }
}

static avr_cycle_count_t next_edge_time(void)
{
    double nominal = anchor_cycle + (double)(enc_pos + 1 - anchor_pos) * count_cycles;
    rng_stream = RNG_JITTER;
    double j = (2.0 * rng_unit() - 1.0) * opt.jitter * count_cycles;
    avr_cycle_count_t t = (avr_cycle_count_t)llround(nominal + j);
    return t > avr->cycle ? t : avr->cycle + 1;
}

static avr_cycle_count_t encoder_edge(avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)a;
    (void)param;
    enc_pos++;
    last_enc_edge = when;
    set_encoder_pins();
    return next_edge_time();
}

/* The polygon stops: no encoder edge after the last one (the pins keep their levels). */
static void stall_polygon(const char *why)
{
    if (stalled)
        return;
    stalled = 1;
    if (encoder_running)
        avr_cycle_timer_cancel(avr, encoder_edge, NULL);
    encoder_running = 0;
    if (edges_f) {
        fprintf(edges_f,
                "{\"kind\":\"stall\",\"why\":\"%s\",\"cycle\":%llu,\"t_us\":%.4f,\"last_count_cycle\":%llu,"
                "\"count\":%ld}\n",
                why, (unsigned long long)avr->cycle, us_of(avr->cycle), (unsigned long long)last_enc_edge,
                (long)(((enc_pos % opt.cpr) + opt.cpr) % opt.cpr));
        fflush(edges_f);
    }
    fprintf(stderr, "fw-harness: the polygon stalls (%s)\n", why);
}

static avr_cycle_count_t stall_timer(avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)a;
    (void)when;
    (void)param;
    stall_polygon("time");
    return 0;
}

/* The motor reference clock toggled: lock the polygon to its frequency. */
static void motor_clock(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    (void)param;
    avr_cycle_count_t now = avr->cycle;
    static double prev_half;
    if (last_motor_toggle && !stalled) {
        double half = (double)(now - last_motor_toggle);
        /* Lock when two half periods agree; the firmware toggles in an interrupt, so ignore its
         * few cycles of latency jitter. */
        int steady = fabs(half - prev_half) < 0.01 * half;
        prev_half = half;
        if (steady && fabs(half - motor_half_cycles) > 0.01 * half) {
            motor_half_cycles = half;
            double cycles = 2.0 * half * MOTOR_PPR / opt.cpr / opt.speed_scale;
            anchor_pos = enc_pos;
            anchor_cycle = encoder_running ? (double)last_enc_edge : (double)now;
            count_cycles = cycles;
            if (!encoder_running) {
                encoder_running = 1;
                avr_cycle_timer_register(avr, next_edge_time() - now, encoder_edge, NULL);
            }
            fprintf(stderr, "fw-harness: polygon at %.4f rpm (%.3f us per count)\n",
                    60.0 * F_CPU / (2.0 * half * MOTOR_PPR) * opt.speed_scale, us_of((avr_cycle_count_t)cycles));
        }
    }
    last_motor_toggle = now;
}

/* ---- trigger and lasers ---- */
static uint8_t laser_level;
static uint64_t edge_n;
static avr_cycle_count_t rise_cycle;
static long rise_count;
static double rise_since_us, rise_period_us;
static uint8_t rise_lasers;
static int pulse_high;

static void json_lasers(FILE *f, uint8_t mask)
{
    fputc('[', f);
    int first = 1;
    for (unsigned j = 0; j < 8; j++)
        if (mask & (1u << j)) {
            fprintf(f, first ? "%u" : ",%u", j);
            first = 0;
        }
    fputc(']', f);
}

static const uint8_t blank_png[] = {
    0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00,
    0x00, 0x08, 0x00, 0x00, 0x00, 0x08, 0x08, 0x00, 0x00, 0x00, 0x00, 0xe1, 0x64, 0xe1, 0x57, 0x00, 0x00, 0x00,
    0x0e, 0x49, 0x44, 0x41, 0x54, 0x78, 0xda, 0x63, 0xd0, 0x80, 0x02, 0x06, 0xca, 0x18, 0x00, 0x68, 0x57, 0x0a,
    0x01, 0x06, 0xcf, 0xdb, 0x47, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};

/* The camera exposes at the edge: the frame's mtime is that instant on the wall clock. */
static void write_frame(uint64_t n, avr_cycle_count_t cycle, long count, uint8_t lasers)
{
    char name[64], tmp[4096], path[4096];
    snprintf(name, sizeof name, "frame_%06llu.png", (unsigned long long)n);
    snprintf(path, sizeof path, "%s/%s", opt.frames, name);
    snprintf(tmp, sizeof tmp, "%s/.%s.tmp", opt.frames, name);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0 || write(fd, blank_png, sizeof blank_png) != (ssize_t)sizeof blank_png)
        die("cannot write %s", tmp);
    uint64_t ns = (uint64_t)wall0_real.tv_nsec + cycle * 1000ULL / (F_CPU / 1000000ULL);
    struct timespec times[2] = {{wall0_real.tv_sec + (time_t)(ns / 1000000000ULL), (long)(ns % 1000000000ULL)}};
    times[1] = times[0];
    if (futimens(fd, times) != 0 || close(fd) != 0 || rename(tmp, path) != 0)
        die("cannot finish %s", path);
    if (truth_f) {
        unsigned per_facet = opt.cpr / opt.facets;
        fprintf(truth_f, "{\"path\":\"%s\",\"trigger_seq\":%llu,\"alpha_deg\":%.17g,\"facet\":%u,\"lasers\":", name,
                (unsigned long long)n, (double)(count % per_facet) * 360.0 / opt.cpr, (unsigned)(count / per_facet));
        json_lasers(truth_f, lasers);
        fputs("}\n", truth_f);
        fflush(truth_f);
    }
}

static void trigger_pin(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    avr_cycle_count_t now = avr->cycle;
    if (value) {
        pulse_high = 1;
        rise_cycle = now;
        rise_count = (long)(((enc_pos % opt.cpr) + opt.cpr) % opt.cpr);
        rise_since_us = us_of(now - last_enc_edge);
        rise_period_us = count_cycles / (F_CPU / 1e6);
        rise_lasers = laser_level;
        write_frame(edge_n, now, rise_count, rise_lasers);
        if (opt.stall_after && edge_n + 1 == opt.stall_after)
            stall_polygon("trigger");
        return;
    }
    if (!pulse_high)
        return; /* the pin's reset state */
    pulse_high = 0;
    if (edges_f) {
        fprintf(edges_f,
                "{\"kind\":\"trigger\",\"edge\":%llu,\"cycle\":%llu,\"t_us\":%.4f,\"count\":%ld,"
                "\"since_count_us\":%.4f,\"count_period_us\":%.4f,\"width_us\":%.4f,\"lasers\":",
                (unsigned long long)edge_n, (unsigned long long)rise_cycle, us_of(rise_cycle), rise_count,
                rise_since_us, rise_period_us, us_of(now - rise_cycle));
        json_lasers(edges_f, rise_lasers);
        fputs("}\n", edges_f);
        fflush(edges_f);
    }
    edge_n++;
}

static void laser_pin(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    unsigned j = (unsigned)(uintptr_t)param;
    uint8_t before = laser_level;
    laser_level = value ? (uint8_t)(laser_level | (1u << j)) : (uint8_t)(laser_level & ~(1u << j));
    if (edges_f && before != laser_level) {
        fprintf(edges_f, "{\"kind\":\"laser\",\"laser\":%u,\"on\":%s,\"cycle\":%llu,\"t_us\":%.4f}\n", j,
                value ? "true" : "false", (unsigned long long)avr->cycle, us_of(avr->cycle));
        fflush(edges_f);
    }
}

/* ---- the serial line ---- */
static avr_irq_t *uart_in;
static uint8_t to_fw[QUEUE_MAX];
static size_t to_fw_len;
static char fw_line[LINE_MAX], host_line[LINE_MAX];
static size_t fw_line_len, host_line_len;

/* A whole line (ending in \n) with the configured faults, into `out`; returns its length. */
static size_t with_faults(const char *line, size_t n, char *out)
{
    size_t k = 0;
    if (rng_unit() < opt.garbage) {
        size_t junk = 1 + rng_next() % 24;
        for (size_t i = 0; i < junk; i++) {
            char b = (char)(rng_next() & 0xFF);
            out[k++] = b == '\n' ? '#' : b;
        }
        if (rng_unit() < 0.5)
            out[k++] = '\n';
    }
    memcpy(out + k, line, n);
    if (n >= 3 && rng_unit() < opt.bad_crc) {
        size_t i = k + n - 2; /* the last CRC digit */
        out[i] = out[i] == '0' ? '1' : '0';
    }
    return k + n;
}

/* A line from the firmware, as sent (before the faults), with the cycle of its first byte. */
static void log_line(const char *line, size_t n, avr_cycle_count_t first_byte)
{
    if (!edges_f)
        return;
    fprintf(edges_f, "{\"kind\":\"line\",\"cycle\":%llu,\"t_us\":%.4f,\"text\":\"", (unsigned long long)first_byte,
            us_of(first_byte));
    for (size_t i = 0; i < n; i++) {
        unsigned char c = (unsigned char)line[i];
        if (c == '"' || c == '\\')
            fprintf(edges_f, "\\%c", c);
        else if (c >= 0x20 && c < 0x7F)
            fputc(c, edges_f);
        else if (c != '\n')
            fprintf(edges_f, "\\u%04x", c);
    }
    fputs("\"}\n", edges_f);
    fflush(edges_f);
}

static void uart_out(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    static avr_cycle_count_t first_byte;
    if (fw_line_len == 0)
        first_byte = avr->cycle;
    if (fw_line_len < LINE_MAX)
        fw_line[fw_line_len++] = (char)value;
    if (value != '\n' && fw_line_len < LINE_MAX)
        return;
    log_line(fw_line, fw_line_len, first_byte);
    char buf[2 * LINE_MAX];
    rng_stream = RNG_TO_HOST;
    size_t n = with_faults(fw_line, fw_line_len, buf);
    fw_line_len = 0;
    if (connected && write(master_fd, buf, n) < 0 && errno != EAGAIN)
        connected = 0; /* seen as a hang-up on the next poll */
}

static void from_host(const uint8_t *b, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        if (host_line_len < LINE_MAX)
            host_line[host_line_len++] = (char)b[i];
        if (b[i] != '\n' && host_line_len < LINE_MAX)
            continue;
        char buf[2 * LINE_MAX];
        rng_stream = RNG_TO_FW;
        size_t k = with_faults(host_line, host_line_len, buf);
        host_line_len = 0;
        if (to_fw_len + k <= QUEUE_MAX) {
            memcpy(to_fw + to_fw_len, buf, k);
            to_fw_len += k;
        }
    }
}

/* One byte per UART frame time (10 bits at 115200 baud), as the wire delivers them; a byte that
 * arrives while the receiver is off or full is lost, as on the wire (the host retries). */
static void feed_uart(void)
{
    static avr_cycle_count_t next_byte;
    if (to_fw_len == 0 || avr->cycle < next_byte)
        return;
    avr_raise_irq(uart_in, to_fw[0]);
    memmove(to_fw, to_fw + 1, to_fw_len - 1);
    to_fw_len--;
    next_byte = avr->cycle + F_CPU * 10 / 115200;
}

static void set_connected(int now_connected)
{
    static int initialised;
    if (initialised && now_connected == connected)
        return;
    initialised = 1;
    connected = now_connected;
    ever_connected |= now_connected;
    avr_raise_irq(pin_dtr, connected ? 0 : 1); /* DTR# low while the port is open */
    if (edges_f) {
        fprintf(edges_f, "{\"kind\":\"host\",\"connected\":%s,\"cycle\":%llu,\"t_us\":%.4f}\n",
                connected ? "true" : "false", (unsigned long long)avr->cycle, us_of(avr->cycle));
        fflush(edges_f);
    }
}

static void poll_host(void)
{
    struct pollfd p = {.fd = master_fd, .events = POLLIN};
    if (poll(&p, 1, 0) < 0)
        return;
    if (p.revents & POLLHUP) {
        set_connected(0);
        return;
    }
    set_connected(1);
    if (p.revents & POLLIN) {
        uint8_t buf[512];
        ssize_t n = read(master_fd, buf, sizeof buf);
        if (n > 0)
            from_host(buf, (size_t)n);
    }
}

/* ---- setup and main loop ---- */
static void parse_args(int argc, char **argv)
{
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            fputs(usage, stdout);
            exit(0);
        } else if (!strcmp(a, "--persist")) {
            opt.persist = 1;
            continue;
        }
        if (!v)
            die("%s needs a value (see --help)", a);
        char *end = NULL;
        if (!strcmp(a, "--firmware")) opt.firmware = v;
        else if (!strcmp(a, "--frames")) opt.frames = v;
        else if (!strcmp(a, "--truth")) opt.truth = v;
        else if (!strcmp(a, "--edges")) opt.edges = v;
        else if (!strcmp(a, "--cpr")) opt.cpr = (unsigned)strtoul(v, &end, 10);
        else if (!strcmp(a, "--facets")) opt.facets = (unsigned)strtoul(v, &end, 10);
        else if (!strcmp(a, "--lasers")) opt.lasers = (unsigned)strtoul(v, &end, 10);
        else if (!strcmp(a, "--jitter")) opt.jitter = strtod(v, &end);
        else if (!strcmp(a, "--speed-scale")) opt.speed_scale = strtod(v, &end);
        else if (!strcmp(a, "--start-count")) opt.start_count = strtol(v, &end, 10);
        else if (!strcmp(a, "--bad-crc")) opt.bad_crc = strtod(v, &end);
        else if (!strcmp(a, "--garbage")) opt.garbage = strtod(v, &end);
        else if (!strcmp(a, "--fault-seed")) opt.seed = strtoull(v, &end, 10);
        else if (!strcmp(a, "--stall-after")) opt.stall_after = strtoul(v, &end, 10);
        else if (!strcmp(a, "--stall-at-ms")) opt.stall_at_ms = strtod(v, &end);
        else die("unknown option %s (see --help)", a);
        if (end && *end)
            die("bad value %s (see --help)", v);
        i++;
    }
    if (!opt.firmware || !opt.frames)
        die("%s", "--firmware and --frames are required (see --help)");
    if (!(opt.stall_at_ms >= 0))
        die("%s", "bad --stall-at-ms (see --help)");
    if (!(opt.jitter >= 0 && opt.jitter <= 0.45) || !(opt.speed_scale > 0) || opt.facets == 0 ||
        opt.cpr % opt.facets || opt.cpr % 4 || opt.lasers == 0 || opt.lasers > 4)
        die("%s", "bad --jitter, --speed-scale, --cpr, --facets or --lasers (see --help)");
}

static FILE *open_append(const char *path)
{
    FILE *f = path ? fopen(path, "a") : NULL;
    if (path && !f)
        die("cannot open %s", path);
    return f;
}

/* The firmware sleeps between interrupts: simavr then skips to the next event; pace() keeps real
 * time (simavr's default would sleep the whole interval again on top). */
static void no_sleep(avr_t *a, avr_cycle_count_t how_long)
{
    (void)a;
    (void)how_long;
}

static void on_signal(int s)
{
    (void)s;
    quit = 1;
}

/* stdout before main moved it to stderr: only the port path goes there. */
static int port_out = -1;

static void open_pty(void)
{
    master_fd = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
    if (master_fd < 0 || grantpt(master_fd) || unlockpt(master_fd))
        die("%s", "cannot create a pseudo-terminal");
    const char *name = ptsname(master_fd);
    /* Raw line: no echo, no newline translation (the host sets the same on its side). */
    int slave = open(name, O_RDWR | O_NOCTTY);
    if (slave >= 0) {
        struct termios t;
        if (tcgetattr(slave, &t) == 0) {
            cfmakeraw(&t);
            tcsetattr(slave, TCSANOW, &t);
        }
        close(slave);
    }
    dprintf(port_out, "%s\n", name);
    close(port_out);
}

static void pace(void)
{
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    double wall = (double)(now.tv_sec - wall0_mono.tv_sec) + (double)(now.tv_nsec - wall0_mono.tv_nsec) * 1e-9;
    double sim = (double)avr->cycle / (double)F_CPU;
    /* Frames carry the simulated time on the wall clock: a simulation that falls behind real
     * time (a loaded machine) makes them look early to the host, which then cannot pair them. */
    static double last_warning;
    if (wall - sim > 0.005 && wall - last_warning > 1.0) {
        last_warning = wall;
        fprintf(stderr, "fw-harness: warning: the simulation is %.0f ms behind real time (machine too busy)\n",
                (wall - sim) * 1e3);
    }
    if (sim > wall + 0.001) {
        double d = sim - wall;
        struct timespec ts = {(time_t)d, (long)((d - floor(d)) * 1e9)};
        nanosleep(&ts, NULL);
    }
}

int main(int argc, char **argv)
{
    parse_args(argc, argv);
    port_out = dup(1);
    dup2(2, 1); /* simavr's own messages go to stderr */
    for (int i = 0; i < 3; i++)
        rng_state[i] = opt.seed * 3 + (uint64_t)i;
    if (mkdir(opt.frames, 0755) != 0 && errno != EEXIST)
        die("cannot create %s", opt.frames);
    truth_f = open_append(opt.truth);
    edges_f = open_append(opt.edges);
    if (edges_f && ftell(edges_f) == 0)
        fprintf(edges_f, "{\"format\":\"omniscan.fw_edges\",\"version\":1,\"f_cpu_hz\":%llu,\"cpr\":%u,\"facets\":%u}\n",
                (unsigned long long)F_CPU, opt.cpr, opt.facets);
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (access(opt.firmware, R_OK) != 0 || elf_read_firmware(opt.firmware, &fw) != 0)
        die("cannot read the firmware %s (build it: make -C firmware)", opt.firmware);
    avr = avr_make_mcu_by_name("atmega328p");
    if (!avr)
        die("%s", "simavr has no atmega328p");
    avr_init(avr);
    avr->frequency = (uint32_t)F_CPU;
    avr_load_firmware(avr, &fw);
    avr->sleep = no_sleep;
    /* The encoder's A and B pins are also INT0/INT1, which the firmware leaves masked at their
     * reset low-level sense; simavr's strict level emulation samples such a pin on every cycle
     * while it is low, which would cost the harness its real time for nothing. */
    avr_extint_set_strict_lvl_trig(avr, 0, 0);
    avr_extint_set_strict_lvl_trig(avr, 1, 0);

    uint32_t flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);

    pin_a = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 2);
    pin_b = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 3);
    pin_z = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 4);
    pin_dtr = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 0);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 1), trigger_pin, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 2), motor_clock, NULL);
    for (unsigned j = 0; j < opt.lasers; j++)
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('C'), (int)j), laser_pin,
                                (void *)(uintptr_t)j);
    enc_pos = opt.start_count;
    set_encoder_pins();
    if (opt.stall_at_ms > 0)
        avr_cycle_timer_register(avr, (avr_cycle_count_t)llround(opt.stall_at_ms * 1e-3 * (double)F_CPU), stall_timer,
                                 NULL);

    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    signal(SIGPIPE, SIG_IGN);
    open_pty();
    set_connected(0);
    clock_gettime(CLOCK_MONOTONIC, &wall0_mono);
    clock_gettime(CLOCK_REALTIME, &wall0_real);
    avr_cycle_count_t linger_until = 0;
    unsigned long long runs = 0, sleeping = 0;
    while (!quit) {
        avr_cycle_count_t slice_end = avr->cycle + F_CPU / 10000; /* 100 µs of simulated time */
        while (avr->cycle < slice_end) {
            int st = avr_run(avr);
            runs++;
            sleeping += st == cpu_Sleeping;
            if (st == cpu_Done || st == cpu_Crashed)
                die("%s", st == cpu_Crashed ? "the firmware crashed (watchdog or bad opcode)" : "the firmware stopped");
        }
        poll_host();
        feed_uart();
        if (ever_connected && !connected && !opt.persist && !linger_until)
            linger_until = avr->cycle + F_CPU / 20; /* 50 ms: let the firmware's reaction be recorded */
        if (linger_until && avr->cycle >= linger_until)
            break;
        pace();
    }
    if (getenv("FW_DEBUG"))
        fprintf(stderr, "fw-harness: %llu cycles, %llu steps, %llu asleep\n", (unsigned long long)avr->cycle, runs,
                sleeping);
    if (edges_f)
        fclose(edges_f);
    if (truth_f)
        fclose(truth_f);
    return 0;
}
