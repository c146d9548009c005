/*
 * rhonn_runner - the identifier firmware application on Linux.
 *
 * A periodic loop on an absolute schedule (clock_nanosleep, TIMER_ABSTIME,
 * CLOCK_MONOTONIC) that, every period, takes the frames waiting on a raw
 * SocketCAN CAN FD socket and hands them to the application (fw_app), which
 * answers with estimate frames. On exit (cycle count reached, --duration
 * elapsed, SIGINT or SIGTERM) it prints cyclictest-style statistics: wake-up
 * latency and step time min / avg / p99 / p99.9 / max, overruns, frames in,
 * out and rejected.
 *
 *   rhonn_runner --interface vcan0 [--period-us 300] [--cycles N | --duration S]
 *                [--fifo PRIO] [--json FILE]
 *   rhonn_runner --bus-less [--cycles N] ...     timing without a bus
 *
 * --bus-less feeds the application one measurement frame per period from a
 * test vector built at start-up (the LIM identifier's six states and two
 * inputs as slow sinusoids in the DBC's scaling) and discards its output, so
 * the loop's timing can be measured where there is no CAN at all.
 *
 * SCHED_FIFO is requested with --fifo (and memory locked); when the system
 * refuses, the runner says so and keeps the default policy. This file is the
 * platform layer: POSIX and Linux calls live here, never in the app.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <net/if.h>
#include <sched.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/raw.h>

#include "fw_app.h"
#include "lim_identifier.h"
#include "rhonn_id.h"

/* ---------------------------------------------------------------- stats */

/* Durations in a histogram of 100 ns bins up to 20 ms (longer ones land in
 * the last bin), as cyclictest keeps them: percentiles without storing every
 * sample, whatever the cycle count. */
#define HIST_BIN_NS 100u
#define HIST_BINS 200000u

typedef struct {
    const char *name;
    uint64_t count, sum_ns, min_ns, max_ns;
    uint32_t bins[HIST_BINS];
} histogram;

static void hist_add(histogram *h, uint64_t ns)
{
    uint64_t bin = ns / HIST_BIN_NS;
    h->bins[bin < HIST_BINS ? bin : HIST_BINS - 1u] += 1u;
    h->sum_ns += ns;
    h->min_ns = h->count == 0 || ns < h->min_ns ? ns : h->min_ns;
    h->max_ns = ns > h->max_ns ? ns : h->max_ns;
    h->count += 1u;
}

/* Upper edge of the bin holding the q-quantile (capped by the maximum). */
static uint64_t hist_quantile(const histogram *h, double q)
{
    uint64_t need = (uint64_t)ceil(q * (double)h->count), seen = 0;
    uint32_t b;
    if (h->count == 0) {
        return 0;
    }
    for (b = 0; b < HIST_BINS; ++b) {
        seen += h->bins[b];
        if (seen >= need) {
            uint64_t edge = (uint64_t)(b + 1u) * HIST_BIN_NS;
            return edge < h->max_ns ? edge : h->max_ns;
        }
    }
    return h->max_ns;
}

static void hist_print(const histogram *h)
{
    if (h->count == 0) {
        printf("%-9s %10s\n", h->name, "no samples");
        return;
    }
    printf("%-9s %10.2f %10.2f %10.2f %10.2f %10.2f %12llu\n", h->name, (double)h->min_ns / 1e3,
           (double)h->sum_ns / (double)h->count / 1e3, (double)hist_quantile(h, 0.99) / 1e3,
           (double)hist_quantile(h, 0.999) / 1e3, (double)h->max_ns / 1e3, (unsigned long long)h->count);
}

static void hist_json(FILE *f, const histogram *h)
{
    fprintf(f, "\"%s\": {\"count\": %llu, \"min_us\": %.3f, \"avg_us\": %.3f, \"p99_us\": %.3f, "
               "\"p999_us\": %.3f, \"max_us\": %.3f}",
            h->name, (unsigned long long)h->count, (double)h->min_ns / 1e3,
            h->count ? (double)h->sum_ns / (double)h->count / 1e3 : 0.0, (double)hist_quantile(h, 0.99) / 1e3,
            (double)hist_quantile(h, 0.999) / 1e3, (double)h->max_ns / 1e3);
}

/* ----------------------------------------------------------------- time */

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static struct timespec to_timespec(uint64_t ns)
{
    struct timespec ts;
    ts.tv_sec = (time_t)(ns / 1000000000u);
    ts.tv_nsec = (long)(ns % 1000000000u);
    return ts;
}

/* ------------------------------------------------------------------ HAL */

typedef struct {
    int fd;                 /* raw CAN FD socket, or -1 bus-less */
    uint64_t sent, send_errors;
    int last_errno;         /* of the last failed socket call */
} platform;

static fw_status hal_send(void *ctx, const fw_frame *frame)
{
    platform *p = (platform *)ctx;
    struct canfd_frame cf;
    ssize_t n;
    if (p->fd < 0) {
        p->sent += 1u; /* bus-less: the estimate is computed, then dropped */
        return FW_OK;
    }
    memset(&cf, 0, sizeof cf);
    cf.can_id = frame->id;
    cf.len = frame->len;
    cf.flags = (uint8_t)((frame->flags & FW_FRAME_BRS) ? CANFD_BRS : 0);
    memcpy(cf.data, frame->data, frame->len);
    n = write(p->fd, &cf, (frame->flags & FW_FRAME_FD) ? CANFD_MTU : CAN_MTU);
    if (n < 0) {
        p->send_errors += 1u;
        p->last_errno = errno;
        return FW_E_HAL;
    }
    p->sent += 1u;
    return FW_OK;
}

static fw_status hal_receive(void *ctx, fw_frame *frame)
{
    platform *p = (platform *)ctx;
    struct canfd_frame cf;
    ssize_t n;
    if (p->fd < 0) {
        return FW_E_EMPTY;
    }
    n = read(p->fd, &cf, sizeof cf);
    if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK) {
            return FW_E_EMPTY;
        }
        p->last_errno = errno; /* e.g. ENETDOWN: the interface went down */
        return FW_E_HAL;
    }
    if (n != CANFD_MTU && n != CAN_MTU) {
        return FW_E_HAL;
    }
    frame->id = cf.can_id;
    frame->len = cf.len > FW_MAX_FRAME_LEN ? (uint8_t)FW_MAX_FRAME_LEN : cf.len;
    frame->flags = (uint8_t)((n == CANFD_MTU ? FW_FRAME_FD : 0u) | ((cf.flags & CANFD_BRS) ? FW_FRAME_BRS : 0u));
    memcpy(frame->data, cf.data, frame->len);
    return FW_OK;
}

static fw_status hal_now(void *ctx, uint64_t *ns)
{
    (void)ctx;
    *ns = now_ns();
    return FW_OK;
}

/* Open a raw CAN FD socket on the interface, non-blocking. Returns the fd,
 * or -1 after printing why (no SocketCAN, no such interface, no CAN FD). */
static int open_can(const char *ifname)
{
    struct sockaddr_can addr;
    struct ifreq ifr;
    int fd, on = 1;

    fd = socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK, CAN_RAW);
    if (fd < 0) {
        if (errno == EAFNOSUPPORT || errno == EPROTONOSUPPORT || errno == EINVAL) {
            fprintf(stderr, "rhonn_runner: this kernel has no SocketCAN (socket(PF_CAN): %s); "
                            "load the can and can_raw modules, or use --bus-less\n", strerror(errno));
        } else {
            fprintf(stderr, "rhonn_runner: socket(PF_CAN): %s\n", strerror(errno));
        }
        return -1;
    }
    if (strlen(ifname) >= sizeof ifr.ifr_name) {
        fprintf(stderr, "rhonn_runner: interface name too long: %s\n", ifname);
        close(fd);
        return -1;
    }
    memset(&ifr, 0, sizeof ifr);
    strcpy(ifr.ifr_name, ifname);
    if (ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
        fprintf(stderr, "rhonn_runner: no CAN interface named '%s' (%s); create one with e.g. "
                        "'ip link add dev %s type vcan && ip link set up %s'\n",
                ifname, strerror(errno), ifname, ifname);
        close(fd);
        return -1;
    }
    if (setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) < 0) {
        fprintf(stderr, "rhonn_runner: %s does not take CAN FD frames: %s\n", ifname, strerror(errno));
        close(fd);
        return -1;
    }
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifr.ifr_ifindex;
    if (bind(fd, (struct sockaddr *)&addr, sizeof addr) < 0) {
        fprintf(stderr, "rhonn_runner: bind to %s: %s\n", ifname, strerror(errno));
        close(fd);
        return -1;
    }
    return fd;
}

/* ------------------------------------------------------------ bus-less */

/* One Measurement frame of the bus-less test vector: the LIM's states and
 * inputs as slow sinusoids inside the DBC's ranges, all valid. */
static void vector_frame(uint32_t k, fw_frame *f)
{
    struct rhonn_id_measurement_t m;
    const double t = 3e-4 * (double)k;
    memset(&m, 0, sizeof m);
    m.seq = rhonn_id_measurement_seq_encode((double)(k & 0xFFFFu));
    m.valid_qm = m.valid_v = m.valid_lambda_a = m.valid_lambda_b = m.valid_ia = m.valid_ib = 1u;
    m.qm = rhonn_id_measurement_qm_encode(0.5 + 0.4 * sin(0.7 * t));
    m.v = rhonn_id_measurement_v_encode(0.4 * cos(0.7 * t));
    m.lambda_a = rhonn_id_measurement_lambda_a_encode(0.8 * sin(9.0 * t));
    m.lambda_b = rhonn_id_measurement_lambda_b_encode(0.8 * cos(9.0 * t));
    m.ia = rhonn_id_measurement_ia_encode(20.0 * sin(9.0 * t + 0.3));
    m.ib = rhonn_id_measurement_ib_encode(20.0 * cos(9.0 * t + 0.3));
    m.ua = rhonn_id_measurement_ua_encode(150.0 * cos(9.0 * t));
    m.ub = rhonn_id_measurement_ub_encode(150.0 * sin(9.0 * t));
    f->id = RHONN_ID_MEASUREMENT_FRAME_ID;
    f->flags = FW_FRAME_FD | FW_FRAME_BRS;
    f->len = (uint8_t)RHONN_ID_MEASUREMENT_LENGTH;
    (void)rhonn_id_measurement_pack(f->data, &m, sizeof f->data);
}

/* ----------------------------------------------------------------- main */

static volatile sig_atomic_t stop_requested = 0;

static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static void usage(FILE *f)
{
    fprintf(f, "usage: rhonn_runner (--interface IF | --bus-less) [--period-us US] [--cycles N]\n"
               "                    [--duration S] [--fifo PRIO] [--json FILE] [--quiet]\n");
}

static histogram wake_hist = {"wake-up", 0, 0, 0, 0, {0}};
static histogram step_hist = {"step", 0, 0, 0, 0, {0}};
static fw_app app;

int main(int argc, char **argv)
{
    static const struct option options[] = {
        {"interface", required_argument, 0, 'i'}, {"bus-less", no_argument, 0, 'b'},
        {"period-us", required_argument, 0, 'p'}, {"cycles", required_argument, 0, 'n'},
        {"duration", required_argument, 0, 'd'},  {"fifo", required_argument, 0, 'f'},
        {"json", required_argument, 0, 'j'},      {"quiet", no_argument, 0, 'q'},
        {"help", no_argument, 0, 'h'},            {0, 0, 0, 0}};
    const char *ifname = NULL, *json_path = NULL;
    int bus_less = 0, fifo = 0, quiet = 0, opt;
    double period_us = 300.0, duration_s = 0.0;
    unsigned long long max_cycles = 0;
    const char *policy = "SCHED_OTHER";
    platform plat = {-1, 0, 0, 0};
    int bus_failed = 0;
    fw_hal hal;
    fw_app_config cfg;
    fw_counters c;
    fw_status st;
    uint64_t period_ns, start, next, end_at, cycle = 0, overruns = 0, late_ns;
    struct sigaction sa;
    char *endp;

    while ((opt = getopt_long(argc, argv, "i:bp:n:d:f:j:qh", options, NULL)) != -1) {
        switch (opt) {
        case 'i': ifname = optarg; break;
        case 'b': bus_less = 1; break;
        case 'p':
            period_us = strtod(optarg, &endp);
            if (*endp != '\0' || !(period_us >= 10.0 && period_us <= 1e6)) {
                fprintf(stderr, "rhonn_runner: --period-us must be a number in 10..1000000, got '%s'\n", optarg);
                return 2;
            }
            break;
        case 'n':
            max_cycles = strtoull(optarg, &endp, 10);
            if (*endp != '\0' || max_cycles == 0 || optarg[0] == '-') {
                fprintf(stderr, "rhonn_runner: --cycles must be a positive integer, got '%s'\n", optarg);
                return 2;
            }
            break;
        case 'd':
            duration_s = strtod(optarg, &endp);
            if (*endp != '\0' || !(duration_s > 0.0 && duration_s < 1e7)) {
                fprintf(stderr, "rhonn_runner: --duration must be a positive number of seconds, got '%s'\n",
                        optarg);
                return 2;
            }
            break;
        case 'f':
            fifo = (int)strtol(optarg, &endp, 10);
            if (*endp != '\0' || fifo < 1 || fifo > 99) {
                fprintf(stderr, "rhonn_runner: --fifo takes a priority in 1..99, got '%s'\n", optarg);
                return 2;
            }
            break;
        case 'j': json_path = optarg; break;
        case 'q': quiet = 1; break;
        case 'h': usage(stdout); return 0;
        default: usage(stderr); return 2;
        }
    }
    if (optind != argc || (ifname == NULL) == (bus_less == 0)) {
        fprintf(stderr, "rhonn_runner: give exactly one of --interface IF or --bus-less\n");
        usage(stderr);
        return 2;
    }
    if (!bus_less) {
        plat.fd = open_can(ifname);
        if (plat.fd < 0) {
            return 1;
        }
    }

    hal.ctx = &plat;
    hal.send = hal_send;
    hal.receive = hal_receive;
    hal.now = hal_now;
    period_ns = (uint64_t)llround(period_us * 1e3);
    cfg.identifier = &LIM_IDENTIFIER;
    cfg.deadline_ns = (uint32_t)period_ns;
    cfg.diag_period = 1000;
    st = fw_app_init(&app, &cfg, &hal);
    if (st != FW_OK) {
        fprintf(stderr, "rhonn_runner: fw_app_init: %s\n", fw_status_name(st));
        return 1;
    }

    if (fifo) {
        struct sched_param sp;
        memset(&sp, 0, sizeof sp);
        sp.sched_priority = fifo;
        if (sched_setscheduler(0, SCHED_FIFO, &sp) == 0) {
            policy = "SCHED_FIFO";
            (void)mlockall(MCL_CURRENT | MCL_FUTURE);
        } else {
            fprintf(stderr, "rhonn_runner: SCHED_FIFO %d refused (%s); running with SCHED_OTHER\n", fifo,
                    strerror(errno));
        }
    }

    /* Wake on time: the default 50 us timer slack of SCHED_OTHER threads
     * would otherwise show up as wake-up latency (cyclictest does the same). */
    (void)prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);

    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);

    start = now_ns();
    next = start;
    end_at = duration_s > 0.0 ? start + (uint64_t)llround(duration_s * 1e9) : UINT64_MAX;
    while (!stop_requested && (max_cycles == 0 || cycle < max_cycles)) {
        struct timespec ts;
        uint64_t woke, done;
        uint32_t before;
        int rc;

        next += period_ns;
        if (next > end_at) {
            break;
        }
        ts = to_timespec(next);
        do {
            rc = clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
        } while (rc == EINTR && !stop_requested);
        if (stop_requested) {
            break;
        }
        woke = now_ns();
        hist_add(&wake_hist, woke > next ? woke - next : 0u);

        (void)fw_app_get_counters(&app, &c);
        before = c.measurements + c.step_errors;
        if (bus_less) {
            fw_frame f;
            vector_frame((uint32_t)cycle, &f);
            woke = now_ns();
            (void)fw_app_on_frame(&app, f.id, f.data, f.len, woke);
        } else {
            uint32_t handled = 0;
            st = fw_app_poll(&app, 64u, &handled);
            if (st == FW_E_HAL) {
                fprintf(stderr, "rhonn_runner: the CAN interface %s failed (%s); stopping\n", ifname,
                        strerror(plat.last_errno));
                bus_failed = 1;
                break;
            }
        }
        done = now_ns();
        (void)fw_app_get_counters(&app, &c);
        if (c.measurements + c.step_errors != before) {
            hist_add(&step_hist, done - woke);
        }
        /* Overrun: this cycle's work ran into the next slot. Slots already
         * missed are skipped, keeping the absolute schedule. */
        if (done > next + period_ns) {
            overruns += 1u;
            (void)fw_app_note_overrun(&app);
            late_ns = done - next;
            next += (late_ns / period_ns) * period_ns;
        }
        cycle += 1u;
    }

    (void)fw_app_get_counters(&app, &c);
    if (!quiet) {
        printf("rhonn_runner: %s, period %.1f us, %llu cycles, %s\n", bus_less ? "bus-less" : ifname, period_us,
               (unsigned long long)cycle, policy);
        printf("%-9s %10s %10s %10s %10s %10s %12s\n", "(us)", "min", "avg", "p99", "p99.9", "max", "samples");
        hist_print(&wake_hist);
        hist_print(&step_hist);
        printf("overruns %llu (%.4f %%), frames in %u, out %u, rejected %u, step errors %u\n",
               (unsigned long long)overruns, cycle ? 100.0 * (double)overruns / (double)cycle : 0.0,
               c.frames_in, c.frames_out, c.rejected, c.step_errors);
    }
    if (json_path != NULL) {
        FILE *f = fopen(json_path, "w");
        if (f == NULL) {
            fprintf(stderr, "rhonn_runner: cannot write %s: %s\n", json_path, strerror(errno));
            return 1;
        }
        fprintf(f, "{\"mode\": \"%s\", \"interface\": \"%s\", \"period_us\": %.3f, \"cycles\": %llu, "
                   "\"policy\": \"%s\", \"overruns\": %llu, ",
                bus_less ? "bus-less" : "socketcan", bus_less ? "" : ifname, period_us, (unsigned long long)cycle,
                policy, (unsigned long long)overruns);
        hist_json(f, &wake_hist);
        fprintf(f, ", ");
        hist_json(f, &step_hist);
        fprintf(f, ", \"frames_in\": %u, \"frames_out\": %u, \"rejected\": %u, \"step_errors\": %u}\n",
                c.frames_in, c.frames_out, c.rejected, c.step_errors);
        fclose(f);
    }
    if (plat.fd >= 0) {
        close(plat.fd);
    }
    return bus_failed ? 1 : 0;
}
