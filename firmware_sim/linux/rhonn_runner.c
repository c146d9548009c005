/*
 * rhonn_runner - the identifier firmware application on Linux.
 *
 * A periodic loop on an absolute schedule (clock_nanosleep, TIMER_ABSTIME,
 * CLOCK_MONOTONIC) that takes the frames waiting on its bus and hands them to
 * the application (fw_app), which answers with estimate frames. On exit
 * (cycle count reached, --duration elapsed, SIGINT or SIGTERM) it prints
 * cyclictest-style statistics: wake-up latency and step time min / avg /
 * p99 / p99.9 / max, overruns, frames in, out and rejected.
 *
 *   rhonn_runner --interface vcan0 [--period-us 300] [--cycles N | --duration S]
 *                [--fifo PRIO] [--json FILE] [--rx tick|arrival] [--spin-us N] [--diag-period N]
 *                [--rcvbuf BYTES]
 *   rhonn_runner --udp-multicast GROUP:PORT [--multicast-ttl N] ...  python-can's udp_multicast bus
 *   rhonn_runner --bus-less [--cycles N] ...     timing without a bus
 *   ... [--xcp-udp [ADDR:]PORT | --xcp-can IFACE[,CMD_ID,RES_ID]]   an XCP slave beside the bus
 *
 * Buses. --interface: a raw SocketCAN CAN FD socket. --udp-multicast: the
 * wire protocol of python-can's udp_multicast interface (one msgpack map per
 * datagram, udp_can.h) on an IPv4 group (239.74.163.2:33110) or an IPv6
 * one ([ff15::1]:33110), with python-can's socket options (SO_REUSEADDR,
 * SO_REUSEPORT, multicast loop on, hop limit 1), so it shares the port with
 * python-can processes on the same host. The group hands every member its
 * own datagrams back: frames carrying the firmware's own identifiers
 * (Estimate, ControlAck, Diagnostics, Health) are skipped, and malformed
 * datagrams are counted by reason and dropped (the application never sees
 * them).
 *
 * Who may talk to it (udp_multicast). The socket is bound to the group
 * address itself, not to the wildcard: the kernel hands it only datagrams
 * addressed to the group, so a unicast datagram to one of the host's
 * addresses and the port (127.0.0.1, a LAN address) never reaches the
 * firmware. Its own frames leave with a multicast TTL (hop limit) of 1 by
 * default, so they do not cross a router; --multicast-ttl 0 keeps them on
 * this host. Loopback stays on, so the rig may run on the same host.
 *
 * Lost frames. SO_RXQ_OVFL is set on the bus socket (SocketCAN and
 * udp_multicast): every datagram or frame read carries the kernel's
 * cumulative count of frames its receive queue dropped, and the increase
 * goes to the application (fw_app_note_rx_drops: Diagnostics.RxDrops).
 * --rcvbuf BYTES sets the receive queue's size (SO_RCVBUF; the kernel
 * doubles it and caps it at net.core.rmem_max; default 4 MiB on
 * udp_multicast, the system's default on SocketCAN).
 *
 * Reception (--rx). tick (the default on --interface): the frames waiting
 * are taken once per period, right after the wake-up. arrival (the default
 * on --udp-multicast): between two ticks the runner waits on the bus
 * (ppoll, up to the next deadline) and handles every frame as it arrives,
 * so an estimate leaves within the handling time instead of up to a period
 * later; the ticks still keep the schedule, the wake-up statistics and the
 * overrun count. --spin-us N (arrival only): from N us before the next
 * Measurement is due (one period after the last) until it came or N us
 * after, the runner busy-polls instead of sleeping, so a frame on schedule
 * is taken without a wake-up latency (what a CAN RX interrupt gives on the
 * target), for about 2N / period of a CPU at most; 0 (default): never.
 * With a bus, "listening on ..." is printed (and flushed) once the socket
 * is ready.
 *
 * --diag-period N: a Diagnostics frame every N accepted measurements
 * (default 1000; 0: only on DiagRequest, as hil's Python firmware node).
 *
 * --bus-less feeds the application one measurement frame per period from a
 * test vector built at start-up (the LIM identifier's six states and two
 * inputs as slow sinusoids in the DBC's scaling) and discards its output, so
 * the loop's timing can be measured where there is no CAN at all.
 *
 * --xcp-udp [ADDR:]PORT: an XCP slave on UDP (fw_xcp.h) beside the bus, for
 * a calibration and measurement tool (firmware_sim/tools/make_a2l.py writes
 * its A2L). ADDR defaults to 127.0.0.1 (only this host); PORT 0 takes a free
 * port, printed as "xcp: udp ADDR:PORT". Framing is XCP on Ethernet: each
 * packet is preceded by LEN and CTR (2 bytes each, little-endian); a
 * datagram may hold several. The master is the sender of the datagram that
 * connected; while it is connected, datagrams from anyone else are dropped
 * and counted, except a CONNECT, which takes the session over (locked
 * again: a master that vanished does not lock the others out). XCP
 * addresses are offsets from __executable_start, the load address of this
 * image (a PIE or not): the A2L's addresses are the symbols' values minus
 * that of __executable_start, as nm shows them.
 *
 * --xcp-can IFACE[,CMD_ID,RES_ID]: the same slave on XCP on CAN FD instead
 * (one or the other, not both): each XCP packet is one CAN FD frame's data,
 * without a header; commands come on CMD_ID, responses, errors and DAQ
 * packets go out on RES_ID (11-bit; defaults 0x7F0 and 0x7F1, above the
 * application's identifiers, so the measurement loop wins arbitration),
 * padded with 0x00 to the next CAN FD length. Its own raw socket receives
 * only CMD_ID (a kernel filter). When IFACE is also --interface, the bus
 * socket skips both identifiers (counted): XCP frames never reach the
 * application.
 *
 * SCHED_FIFO is requested with --fifo (and memory locked); when the system
 * refuses, the runner says so and keeps the default policy. This file is the
 * platform layer: POSIX and Linux calls live here, never in the app.
 */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <net/if.h>
#include <netinet/in.h>
#include <poll.h>
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
#include "fw_xcp.h"
/* The identifier: the LIM's, or another one's header (static const rhonn_config FW_IDENTIFIER, as
 * pyrhonn.export writes it) named by -DFW_IDENTIFIER_HEADER (firmware_sim/linux/build_runner.py --config). */
#ifdef FW_IDENTIFIER_HEADER
#include FW_IDENTIFIER_HEADER
#else
#include "lim_identifier.h"
#define FW_IDENTIFIER LIM_IDENTIFIER
#endif
#include "rhonn_id.h"
#include "udp_can.h"

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
            /* the last bin holds everything beyond 20 ms: its only honest bound is the maximum */
            uint64_t edge = (uint64_t)(b + 1u) * HIST_BIN_NS;
            return b == HIST_BINS - 1u || edge > h->max_ns ? h->max_ns : edge;
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

typedef enum { BUS_NONE, BUS_SOCKETCAN, BUS_UDP } bus_kind;

#define UDP_RX_BUFFER 4096u     /* python-can's max_buffer: longer datagrams are malformed here */
#define UDP_RX_BURST 256u       /* datagrams one hal_receive call may drop before it returns */

typedef struct {
    bus_kind kind;
    int fd;                 /* raw CAN FD socket or UDP socket, or -1 bus-less */
    uint64_t sent, send_errors;
    int last_errno;         /* of the last failed socket call */
    /* udp_multicast */
    struct sockaddr_storage group;  /* where frames are sent */
    socklen_t group_len;
    uint64_t datagrams;             /* datagrams read */
    uint64_t own_skipped;           /* our own frames, handed back by the group */
    uint64_t malformed;             /* datagrams rejected by the codec, or longer than UDP_RX_BUFFER */
    uint64_t oversized;
    uint64_t malformed_by[UDP_CAN_N_STATUS];
    uint32_t rxq_ovfl;              /* the kernel's last SO_RXQ_OVFL count (cumulative) */
    uint64_t rx_drops;              /* its increases since the socket was opened */
    /* SocketCAN shared with --xcp-can: the XCP identifiers are the slave's, not the application's */
    uint32_t xcp_ids[2];
    int xcp_shared;
    uint64_t xcp_skipped;           /* XCP frames the bus socket saw and skipped */
    uint8_t rx[UDP_RX_BUFFER];
} platform;

/* Time a datagram waited in the socket before the runner took it (kernel
 * receive timestamp to hand-over), histogram defined with the others below. */
static void note_rx_wait(uint64_t ns);

/* The firmware's own identifiers: the group hands them back to us. */
static int own_frame(const udp_can_msg *m)
{
    return !m->is_extended_id && (m->arbitration_id == RHONN_ID_ESTIMATE_FRAME_ID ||
                                  m->arbitration_id == RHONN_ID_CONTROL_ACK_FRAME_ID ||
                                  m->arbitration_id == RHONN_ID_DIAGNOSTICS_FRAME_ID ||
                                  m->arbitration_id == RHONN_ID_HEALTH_FRAME_ID);
}

/* Frames the kernel dropped since the last look: SO_RXQ_OVFL carries its
 * cumulative uint32 count (sk_drops) with each frame read; the increase,
 * modulo 2^32, is what was lost in between. */
static void note_rxq_ovfl(platform *p, struct msghdr *mh);

static uint64_t realtime_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static fw_status udp_send(platform *p, const fw_frame *frame)
{
    udp_can_msg m;
    uint8_t out[UDP_CAN_MAX_ENCODED];
    size_t n = 0;
    ssize_t w;
    memset(&m, 0, sizeof m);
    m.timestamp = (double)realtime_ns() / 1e9;
    m.is_extended_id = (frame->id & FW_CAN_EFF_FLAG) != 0u;
    m.is_remote_frame = (frame->id & FW_CAN_RTR_FLAG) != 0u;
    m.is_error_frame = (frame->id & FW_CAN_ERR_FLAG) != 0u;
    m.arbitration_id = frame->id & (m.is_extended_id ? CAN_EFF_MASK : CAN_SFF_MASK);
    m.is_fd = (frame->flags & FW_FRAME_FD) != 0u;
    m.bitrate_switch = (frame->flags & FW_FRAME_BRS) != 0u;
    m.dlc = frame->len;
    m.len = m.is_remote_frame ? 0u : frame->len;
    memcpy(m.data, frame->data, m.len <= sizeof m.data ? m.len : sizeof m.data);
    if (udp_can_encode(&m, out, sizeof out, &n) != UDP_CAN_OK) {
        p->send_errors += 1u;
        p->last_errno = EINVAL;
        return FW_E_HAL;
    }
    do {
        w = sendto(p->fd, out, n, 0, (const struct sockaddr *)&p->group, p->group_len);
    } while (w < 0 && errno == EINTR);
    if (w != (ssize_t)n) {
        p->send_errors += 1u;
        p->last_errno = w < 0 ? errno : EMSGSIZE;
        return FW_E_HAL;
    }
    p->sent += 1u;
    return FW_OK;
}

/* The next well-formed datagram that is not our own, as a frame. Malformed
 * datagrams and our own frames are counted and skipped. */
static fw_status udp_receive(platform *p, fw_frame *frame)
{
    unsigned burst;
    for (burst = 0; burst < UDP_RX_BURST; ++burst) {
        union {
            char buf[CMSG_SPACE(sizeof(struct timespec)) + CMSG_SPACE(sizeof(uint32_t))];
            struct cmsghdr align;
        } ctl;
        struct iovec iov;
        struct msghdr mh;
        struct cmsghdr *cm;
        udp_can_msg m;
        udp_can_status st;
        ssize_t n;

        iov.iov_base = p->rx;
        iov.iov_len = sizeof p->rx;
        memset(&mh, 0, sizeof mh);
        mh.msg_iov = &iov;
        mh.msg_iovlen = 1;
        mh.msg_control = ctl.buf;
        mh.msg_controllen = sizeof ctl.buf;
        n = recvmsg(p->fd, &mh, MSG_DONTWAIT);
        if (n < 0) {
            if (errno == EAGAIN || errno == EWOULDBLOCK) {
                return FW_E_EMPTY;
            }
            if (errno == EINTR) {
                continue;
            }
            p->last_errno = errno;
            return FW_E_HAL;
        }
        p->datagrams += 1u;
        note_rxq_ovfl(p, &mh); /* whatever the datagram holds: the count is the socket's */
        if (mh.msg_flags & MSG_TRUNC) {
            p->malformed += 1u;
            p->oversized += 1u;
            continue;
        }
        st = udp_can_decode(p->rx, (size_t)n, &m);
        if (st != UDP_CAN_OK) {
            p->malformed += 1u;
            p->malformed_by[st] += 1u;
            continue;
        }
        if (own_frame(&m)) {
            p->own_skipped += 1u;
            continue;
        }
        for (cm = CMSG_FIRSTHDR(&mh); cm != NULL; cm = CMSG_NXTHDR(&mh, cm)) {
            if (cm->cmsg_level == SOL_SOCKET && cm->cmsg_type == SCM_TIMESTAMPNS) {
                struct timespec ts;
                uint64_t at, now = realtime_ns();
                memcpy(&ts, CMSG_DATA(cm), sizeof ts);
                at = (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
                note_rx_wait(now > at ? now - at : 0u);
            }
        }
        frame->id = m.arbitration_id | (m.is_extended_id ? FW_CAN_EFF_FLAG : 0u) |
                    (m.is_remote_frame ? FW_CAN_RTR_FLAG : 0u) | (m.is_error_frame ? FW_CAN_ERR_FLAG : 0u);
        frame->len = m.len;
        frame->flags = (uint8_t)((m.is_fd ? FW_FRAME_FD : 0u) | (m.bitrate_switch ? FW_FRAME_BRS : 0u));
        memcpy(frame->data, m.data, m.len);
        return FW_OK;
    }
    return FW_E_EMPTY; /* a flood: the rest waits for the next call */
}

static fw_status hal_send(void *ctx, const fw_frame *frame)
{
    platform *p = (platform *)ctx;
    struct canfd_frame cf;
    ssize_t n;
    if (p->kind == BUS_NONE) {
        p->sent += 1u; /* bus-less: the estimate is computed, then dropped */
        return FW_OK;
    }
    if (p->kind == BUS_UDP) {
        return udp_send(p, frame);
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
    union {
        char buf[CMSG_SPACE(sizeof(uint32_t))];
        struct cmsghdr align;
    } ctl;
    struct iovec iov;
    struct msghdr mh;
    ssize_t n;
    unsigned burst;
    if (p->kind == BUS_NONE) {
        return FW_E_EMPTY;
    }
    if (p->kind == BUS_UDP) {
        return udp_receive(p, frame);
    }
    for (burst = 0;; ++burst) {
        if (burst == UDP_RX_BURST) {
            return FW_E_EMPTY; /* a flood of XCP frames: the rest waits for the next call */
        }
        iov.iov_base = &cf;
        iov.iov_len = sizeof cf;
        memset(&mh, 0, sizeof mh);
        mh.msg_iov = &iov;
        mh.msg_iovlen = 1;
        mh.msg_control = ctl.buf;
        mh.msg_controllen = sizeof ctl.buf;
        n = recvmsg(p->fd, &mh, 0); /* the socket is non-blocking */
        if (n >= 0) {
            note_rxq_ovfl(p, &mh);
        }
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
        /* XCP on the same interface: the master's commands (the slave's socket has its own copy)
         * and the slave's own packets, looped back */
        if (!(p->xcp_shared && (cf.can_id == p->xcp_ids[0] || cf.can_id == p->xcp_ids[1]))) {
            break;
        }
        p->xcp_skipped += 1u;
    }
    frame->id = cf.can_id;
    frame->len = cf.len > FW_MAX_FRAME_LEN ? (uint8_t)FW_MAX_FRAME_LEN : cf.len;
    frame->flags = (uint8_t)((n == CANFD_MTU ? FW_FRAME_FD : 0u) | ((cf.flags & CANFD_BRS) ? FW_FRAME_BRS : 0u));
    memcpy(frame->data, cf.data, frame->len);
    return FW_OK;
}

static fw_app app;

static void note_rxq_ovfl(platform *p, struct msghdr *mh)
{
    struct cmsghdr *cm;
    for (cm = CMSG_FIRSTHDR(mh); cm != NULL; cm = CMSG_NXTHDR(mh, cm)) {
        if (cm->cmsg_level == SOL_SOCKET && cm->cmsg_type == SO_RXQ_OVFL) {
            uint32_t count, more;
            memcpy(&count, CMSG_DATA(cm), sizeof count);
            more = count - p->rxq_ovfl;
            p->rxq_ovfl = count;
            if (more != 0u) {
                p->rx_drops += more;
                (void)fw_app_note_rx_drops(&app, more);
            }
        }
    }
}

static fw_status hal_now(void *ctx, uint64_t *ns)
{
    (void)ctx;
    *ns = now_ns();
    return FW_OK;
}

/* Open a raw CAN FD socket on the interface, non-blocking. Returns the fd,
 * or -1 after printing why (no SocketCAN, no such interface, no CAN FD). */
static int open_can(const char *ifname, int rcvbuf)
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
    if (setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on) < 0 ||
        (rcvbuf > 0 && setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf) < 0)) {
        fprintf(stderr, "rhonn_runner: %s: %s: %s\n", ifname, rcvbuf > 0 ? "SO_RXQ_OVFL/SO_RCVBUF" : "SO_RXQ_OVFL",
                strerror(errno));
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

/* Parse "GROUP:PORT" (IPv4) or "[GROUP]:PORT" (IPv6) into p->group. 0, or
 * -1 after printing why. */
static int parse_group(const char *spec, platform *p)
{
    char host[INET6_ADDRSTRLEN + 2];
    const char *colon;
    size_t hlen;
    long port;
    char *endp;
    int v6 = spec[0] == '[';

    colon = v6 ? strstr(spec, "]:") : strrchr(spec, ':');
    if (colon == NULL || colon == spec) {
        fprintf(stderr, "rhonn_runner: --udp-multicast takes GROUP:PORT (e.g. 239.74.163.2:33110 or "
                        "[ff15::1]:33110), got '%s'\n", spec);
        return -1;
    }
    hlen = (size_t)(colon - spec) - (v6 ? 1u : 0u);
    if (hlen == 0 || hlen >= sizeof host) {
        fprintf(stderr, "rhonn_runner: --udp-multicast: no multicast group in '%s'\n", spec);
        return -1;
    }
    memcpy(host, spec + (v6 ? 1 : 0), hlen);
    host[hlen] = '\0';
    colon += v6 ? 2 : 1;
    errno = 0;
    port = strtol(colon, &endp, 10);
    if (*colon == '\0' || *endp != '\0' || errno != 0 || port < 1 || port > 65535) {
        fprintf(stderr, "rhonn_runner: --udp-multicast: port must be 1..65535, got '%s'\n", colon);
        return -1;
    }
    memset(&p->group, 0, sizeof p->group);
    if (!v6) {
        struct sockaddr_in *a = (struct sockaddr_in *)&p->group;
        if (inet_pton(AF_INET, host, &a->sin_addr) != 1 || !IN_MULTICAST(ntohl(a->sin_addr.s_addr))) {
            fprintf(stderr, "rhonn_runner: --udp-multicast: '%s' is not an IPv4 multicast address "
                            "(224.0.0.0/4; IPv6 groups go in brackets: [ff15::1]:PORT)\n", host);
            return -1;
        }
        a->sin_family = AF_INET;
        a->sin_port = htons((uint16_t)port);
        p->group_len = (socklen_t)sizeof *a;
    } else {
        struct sockaddr_in6 *a = (struct sockaddr_in6 *)&p->group;
        if (inet_pton(AF_INET6, host, &a->sin6_addr) != 1 || !IN6_IS_ADDR_MULTICAST(&a->sin6_addr)) {
            fprintf(stderr, "rhonn_runner: --udp-multicast: '%s' is not an IPv6 multicast address (ff00::/8)\n",
                    host);
            return -1;
        }
        a->sin6_family = AF_INET6;
        a->sin6_port = htons((uint16_t)port);
        p->group_len = (socklen_t)sizeof *a;
    }
    return 0;
}

/* A UDP socket bound to p->group itself (address and port: only datagrams
 * addressed to the group arrive), member of the group, configured as
 * python-can configures its own except for the multicast TTL (ttl).
 * Returns the fd, or -1 after printing why. */
static int open_udp(platform *p, const char *spec, int ttl, int rcvbuf)
{
    const int on = 1, hops = ttl;
    int fd, af = p->group.ss_family;
    const char *step;
    if (af == AF_INET) {
        struct ip_mreq mreq;
        const struct sockaddr_in *g = (const struct sockaddr_in *)&p->group;
        fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
        if (fd < 0) {
            step = "socket";
            goto fail;
        }
        memset(&mreq, 0, sizeof mreq);
        mreq.imr_multiaddr = g->sin_addr;
        mreq.imr_interface.s_addr = htonl(INADDR_ANY);
        if ((step = "IP_MULTICAST_TTL", setsockopt(fd, IPPROTO_IP, IP_MULTICAST_TTL, &hops, sizeof hops)) < 0 ||
            (step = "IP_MULTICAST_LOOP", setsockopt(fd, IPPROTO_IP, IP_MULTICAST_LOOP, &on, sizeof on)) < 0 ||
            (step = "SO_REUSEADDR", setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on)) < 0 ||
            (step = "SO_REUSEPORT", setsockopt(fd, SOL_SOCKET, SO_REUSEPORT, &on, sizeof on)) < 0 ||
            (step = "SO_TIMESTAMPNS", setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on)) < 0 ||
            (step = "SO_RXQ_OVFL", setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on)) < 0 ||
            (step = "bind", bind(fd, (const struct sockaddr *)g, sizeof *g)) < 0 ||
            (step = "IP_ADD_MEMBERSHIP", setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, sizeof mreq)) < 0) {
            goto fail;
        }
    } else {
        struct ipv6_mreq mreq;
        const struct sockaddr_in6 *g = (const struct sockaddr_in6 *)&p->group;
        fd = socket(AF_INET6, SOCK_DGRAM | SOCK_CLOEXEC, 0);
        if (fd < 0) {
            step = "socket";
            goto fail;
        }
        memset(&mreq, 0, sizeof mreq);
        mreq.ipv6mr_multiaddr = g->sin6_addr;
        mreq.ipv6mr_interface = 0;
        if ((step = "IPV6_MULTICAST_HOPS", setsockopt(fd, IPPROTO_IPV6, IPV6_MULTICAST_HOPS, &hops, sizeof hops)) < 0 ||
            (step = "IPV6_MULTICAST_LOOP", setsockopt(fd, IPPROTO_IPV6, IPV6_MULTICAST_LOOP, &on, sizeof on)) < 0 ||
            (step = "SO_REUSEADDR", setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on)) < 0 ||
            (step = "SO_REUSEPORT", setsockopt(fd, SOL_SOCKET, SO_REUSEPORT, &on, sizeof on)) < 0 ||
            (step = "SO_TIMESTAMPNS", setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on)) < 0 ||
            (step = "SO_RXQ_OVFL", setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on)) < 0 ||
            (step = "bind", bind(fd, (const struct sockaddr *)g, sizeof *g)) < 0 ||
            (step = "IPV6_JOIN_GROUP", setsockopt(fd, IPPROTO_IPV6, IPV6_JOIN_GROUP, &mreq, sizeof mreq)) < 0) {
            goto fail;
        }
    }
    /* room for bursts (best effort: capped by net.core.rmem_max) */
    (void)setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    return fd;
fail:
    fprintf(stderr, "rhonn_runner: cannot open the udp_multicast group %s (%s: %s)%s\n", spec, step,
            strerror(errno), errno == ENODEV || errno == ENETUNREACH
                                  ? "; this host has no multicast route (add one, e.g. 'ip route add 224.0.0.0/4 dev lo')"
                                  : "");
    if (fd >= 0) {
        close(fd);
    }
    return -1;
}

/* ------------------------------------------------------------ bus-less */

#ifdef FW_IDENTIFIER_HEADER
/* One Measurement frame of the bus-less test vector of another identifier:
 * every state valid and every value 0 (inside any range the export writes). */
static void vector_frame(uint32_t k, fw_frame *f)
{
    struct rhonn_id_measurement_t m;
    memset(&m, 0, sizeof m);
    m.seq = rhonn_id_measurement_seq_encode((double)(k & 0xFFFFu));
    FW_MEASUREMENT_ALL_VALID(m);
#else
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
#endif
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

/* A whole number in lo..hi written as plain decimal digits: no sign, no
 * spaces, no hex, nothing strtoull would wrap (" -1" is ULLONG_MAX to it). */
static int parse_count(const char *text, unsigned long long lo, unsigned long long hi, unsigned long long *out)
{
    unsigned long long v;
    char *endp;
    size_t i;
    if (text[0] == '\0') {
        return -1;
    }
    for (i = 0; text[i] != '\0'; ++i) {
        if (text[i] < '0' || text[i] > '9') {
            return -1;
        }
    }
    errno = 0;
    v = strtoull(text, &endp, 10);
    if (errno != 0 || *endp != '\0' || v < lo || v > hi) {
        return -1;
    }
    *out = v;
    return 0;
}

/* ------------------------------------------------------------ XCP on UDP */

/* The regions the A2L names (make_a2l.py reads these symbols). */
fw_xcp_signals rhonn_xcp_signals;
fw_xcp_calibration rhonn_xcp_calibration;
extern char __executable_start[]; /* the linker's: where this image is loaded */

#define XCP_HEADER 4u
#define XCP_RX_BUFFER 2048u

static fw_xcp xcp;
static struct {
    int fd;                             /* -1: no XCP */
    struct sockaddr_in local;
    struct sockaddr_in peer;            /* the master */
    int have_peer;
    uint16_t ctr;                       /* the slave's packet counter (CTR) */
    uint64_t datagrams, commands, errors, ignored, malformed, foreign, takeovers, send_errors;
    uint8_t rx[XCP_RX_BUFFER];
    uint8_t tx[XCP_HEADER + FW_XCP_MAX_DTO];
} xu;

static fw_status xcp_udp_send(void *ctx, const uint8_t *packet, size_t len)
{
    (void)ctx;
    if (!xu.have_peer || len > FW_XCP_MAX_DTO) {
        return FW_E_HAL;
    }
    xu.tx[0] = (uint8_t)(len & 0xFFu);
    xu.tx[1] = (uint8_t)(len >> 8);
    xu.tx[2] = (uint8_t)(xu.ctr & 0xFFu);
    xu.tx[3] = (uint8_t)(xu.ctr >> 8);
    memcpy(xu.tx + XCP_HEADER, packet, len);
    if (sendto(xu.fd, xu.tx, XCP_HEADER + len, MSG_DONTWAIT, (const struct sockaddr *)&xu.peer, sizeof xu.peer) < 0) {
        xu.send_errors += 1u;
        return FW_E_HAL; /* fw_xcp counts a DTO lost */
    }
    xu.ctr = (uint16_t)(xu.ctr + 1u);
    return FW_OK;
}

/* "[ADDR:]PORT" -> the local address; -1 after printing why. */
static int parse_xcp_spec(const char *spec)
{
    char host[64];
    const char *colon = strrchr(spec, ':');
    const char *port = colon != NULL ? colon + 1 : spec;
    unsigned long long v;
    memset(&xu.local, 0, sizeof xu.local);
    xu.local.sin_family = AF_INET;
    if (parse_count(port, 0u, 65535u, &v) < 0) {
        fprintf(stderr, "rhonn_runner: --xcp-udp takes [ADDR:]PORT with PORT in 0..65535, got '%s'\n", spec);
        return -1;
    }
    xu.local.sin_port = htons((uint16_t)v);
    if (colon == NULL) {
        xu.local.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        return 0;
    }
    if ((size_t)(colon - spec) >= sizeof host) {
        fprintf(stderr, "rhonn_runner: --xcp-udp: address too long in '%s'\n", spec);
        return -1;
    }
    memcpy(host, spec, (size_t)(colon - spec));
    host[colon - spec] = '\0';
    if (inet_pton(AF_INET, host, &xu.local.sin_addr) != 1) {
        fprintf(stderr, "rhonn_runner: --xcp-udp: '%s' is not an IPv4 address\n", host);
        return -1;
    }
    return 0;
}

/* The protocol layer, the same for every transport: the slave on the two
 * regions, hooked into the application. 0, or -1 after printing why. */
static int start_xcp(fw_status (*send)(void *ctx, const uint8_t *packet, size_t len))
{
    fw_xcp_config config;
    fw_status st;
    config.transport.ctx = NULL;
    config.transport.send = send;
    config.signals = &rhonn_xcp_signals;
    config.calibration = &rhonn_xcp_calibration;
    config.address_base = (uintptr_t)__executable_start;
    st = fw_xcp_init(&xcp, &config);
    if (st == FW_OK) {
        st = fw_xcp_attach(&xcp, &app);
    }
    if (st != FW_OK) {
        fprintf(stderr, "rhonn_runner: XCP slave: %s\n", fw_status_name(st));
        return -1;
    }
    return 0;
}

static int open_xcp(const char *spec)
{
    socklen_t n = sizeof xu.local;
    xu.fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (xu.fd < 0 || bind(xu.fd, (const struct sockaddr *)&xu.local, sizeof xu.local) < 0 ||
        getsockname(xu.fd, (struct sockaddr *)&xu.local, &n) < 0) {
        fprintf(stderr, "rhonn_runner: --xcp-udp %s: %s\n", spec, strerror(errno));
        return -1;
    }
    return start_xcp(xcp_udp_send);
}

static int same_peer(const struct sockaddr_in *a, const struct sockaddr_in *b)
{
    return a->sin_addr.s_addr == b->sin_addr.s_addr && a->sin_port == b->sin_port;
}

/* Take the waiting XCP datagrams (at most a burst) and hand each packet to
 * the slave. */
static void take_xcp(void)
{
    unsigned burst;
    if (xu.fd < 0) {
        return;
    }
    for (burst = 0; burst < 64u; ++burst) {
        struct sockaddr_in from;
        socklen_t fl = sizeof from;
        ssize_t n = recvfrom(xu.fd, xu.rx, sizeof xu.rx, MSG_DONTWAIT, (struct sockaddr *)&from, &fl);
        size_t pos = 0;
        if (n < 0) {
            return; /* EAGAIN: nothing more */
        }
        xu.datagrams += 1u;
        if (fl != sizeof from || from.sin_family != AF_INET) {
            xu.malformed += 1u;
            continue;
        }
        if (xcp.connected && xu.have_peer && !same_peer(&from, &xu.peer)) {
            /* another master while one is connected: only a CONNECT is taken, and it takes the
             * session over (locked again, DAQ stopped), so a master that vanished without
             * DISCONNECT does not lock everyone out */
            if (!(n >= (ssize_t)(XCP_HEADER + 1u) && xu.rx[XCP_HEADER] == 0xFFu)) {
                xu.foreign += 1u;
                continue;
            }
            xu.takeovers += 1u;
        }
        xu.peer = from;
        xu.have_peer = 1;
        while ((size_t)n - pos >= XCP_HEADER) {
            size_t len = (size_t)xu.rx[pos] | ((size_t)xu.rx[pos + 1] << 8);
            fw_status st;
            if (len == 0u || len > (size_t)n - pos - XCP_HEADER) {
                xu.malformed += 1u; /* the rest of the datagram cannot be framed */
                break;
            }
            st = fw_xcp_on_command(&xcp, &app, xu.rx + pos + XCP_HEADER, len, now_ns());
            pos += XCP_HEADER + len;
            xu.commands += 1u;
            xu.errors += st == FW_E_RANGE;
            xu.ignored += st == FW_E_STATE;
        }
        if (pos != (size_t)n && (size_t)n - pos < XCP_HEADER) {
            xu.malformed += 1u;
        }
    }
}

/* ---------------------------------------------------------- XCP on CAN FD */

/* XCP on CAN (ASAM XCP Part 3, CAN FD): one XCP packet per frame, no header;
 * the master's commands on CMD_ID, the slave's responses, errors and DAQ
 * packets on RES_ID. 11-bit identifiers; the defaults sit above the
 * application's (0x100..0x131), so the measurement loop wins arbitration. */
#define XCP_CAN_CMD_ID 0x7F0u
#define XCP_CAN_RES_ID 0x7F1u
#define XCP_CAN_PAD 0x00u   /* fill bytes up to the next CAN FD length */

static struct {
    int fd;                 /* -1: no XCP on CAN */
    char ifname[IFNAMSIZ];
    uint32_t cmd_id, res_id;
    uint64_t frames, commands, errors, ignored, malformed, send_errors;
} xc = {-1, "", XCP_CAN_CMD_ID, XCP_CAN_RES_ID, 0, 0, 0, 0, 0, 0};

/* The shortest CAN FD data length (0..8, 12, 16, 20, 24, 32, 48, 64) that holds len bytes. */
static uint8_t canfd_length(size_t len)
{
    static const uint8_t sizes[] = {8u, 12u, 16u, 20u, 24u, 32u, 48u, 64u};
    size_t i;
    if (len <= 8u) {
        return (uint8_t)len;
    }
    for (i = 1; i < sizeof sizes; ++i) {
        if (len <= sizes[i]) {
            break;
        }
    }
    return sizes[i < sizeof sizes ? i : sizeof sizes - 1u];
}

static fw_status xcp_can_send(void *ctx, const uint8_t *packet, size_t len)
{
    struct canfd_frame cf;
    (void)ctx;
    if (len == 0u || len > FW_XCP_MAX_DTO || len > CANFD_MAX_DLEN) {
        return FW_E_HAL;
    }
    memset(&cf, 0, sizeof cf);
    memset(cf.data, XCP_CAN_PAD, sizeof cf.data);
    cf.can_id = xc.res_id;
    cf.len = canfd_length(len);
    cf.flags = CANFD_BRS;
    memcpy(cf.data, packet, len);
    if (send(xc.fd, &cf, CANFD_MTU, MSG_DONTWAIT) != (ssize_t)CANFD_MTU) {
        xc.send_errors += 1u;
        return FW_E_HAL; /* fw_xcp counts a DTO lost */
    }
    return FW_OK;
}

/* One identifier of --xcp-can: 0x-hex or decimal, 11 bits. -1 when not. */
static int parse_can_id(const char *text, uint32_t *id)
{
    unsigned long long v;
    int hex = text[0] == '0' && (text[1] == 'x' || text[1] == 'X');
    const char *digits = hex ? text + 2 : text;
    size_t i;
    if (digits[0] == '\0' || strlen(digits) > 8u) {
        return -1;
    }
    for (i = 0; digits[i] != '\0'; ++i) {
        if (hex ? !strchr("0123456789abcdefABCDEF", digits[i]) : (digits[i] < '0' || digits[i] > '9')) {
            return -1;
        }
    }
    v = strtoull(digits, NULL, hex ? 16 : 10);
    if (v > CAN_SFF_MASK) {
        return -1;
    }
    *id = (uint32_t)v;
    return 0;
}

/* "IFACE[,CMD_ID,RES_ID]" -> xc; -1 after printing why. */
static int parse_xcp_can_spec(const char *spec)
{
    static const uint32_t app_ids[] = {RHONN_ID_MEASUREMENT_FRAME_ID, RHONN_ID_ESTIMATE_FRAME_ID,
                                       RHONN_ID_CONTROL_FRAME_ID, RHONN_ID_CONTROL_ACK_FRAME_ID,
                                       RHONN_ID_WEIGHT_LOAD_FRAME_ID, RHONN_ID_DIAGNOSTICS_FRAME_ID,
                                       RHONN_ID_HEALTH_FRAME_ID};
    const char *c1 = strchr(spec, ','), *c2 = c1 != NULL ? strchr(c1 + 1, ',') : NULL;
    size_t n = c1 != NULL ? (size_t)(c1 - spec) : strlen(spec), i;
    char id[16];
    if (n == 0u || n >= sizeof xc.ifname || memchr(spec, '/', n) != NULL) {
        fprintf(stderr, "rhonn_runner: --xcp-can takes IFACE[,CMD_ID,RES_ID] with a CAN interface name of "
                        "1..%u characters, got '%s'\n", (unsigned)sizeof xc.ifname - 1u, spec);
        return -1;
    }
    memcpy(xc.ifname, spec, n);
    xc.ifname[n] = '\0';
    if (c1 == NULL) {
        return 0; /* the default identifiers */
    }
    if (c2 == NULL || strchr(c2 + 1, ',') != NULL) {
        fprintf(stderr, "rhonn_runner: --xcp-can takes IFACE or IFACE,CMD_ID,RES_ID (both identifiers), "
                        "got '%s'\n", spec);
        return -1;
    }
    if ((size_t)(c2 - c1 - 1) >= sizeof id || (memcpy(id, c1 + 1, (size_t)(c2 - c1 - 1)),
                                               id[c2 - c1 - 1] = '\0', parse_can_id(id, &xc.cmd_id)) < 0) {
        fprintf(stderr, "rhonn_runner: --xcp-can: CMD_ID must be an 11-bit identifier (0..0x7FF, hex with 0x or "
                        "decimal), got '%.*s'\n", (int)(c2 - c1 - 1), c1 + 1);
        return -1;
    }
    if (parse_can_id(c2 + 1, &xc.res_id) < 0) {
        fprintf(stderr, "rhonn_runner: --xcp-can: RES_ID must be an 11-bit identifier (0..0x7FF, hex with 0x or "
                        "decimal), got '%s'\n", c2 + 1);
        return -1;
    }
    if (xc.cmd_id == xc.res_id) {
        fprintf(stderr, "rhonn_runner: --xcp-can: CMD_ID and RES_ID must differ, both are 0x%X\n",
                (unsigned)xc.cmd_id);
        return -1;
    }
    for (i = 0; i < sizeof app_ids / sizeof app_ids[0]; ++i) {
        if (xc.cmd_id == app_ids[i] || xc.res_id == app_ids[i]) {
            fprintf(stderr, "rhonn_runner: --xcp-can: %s 0x%X is one of the application's identifiers "
                            "(rhonn_id.dbc: 0x100, 0x101, 0x110, 0x111, 0x120, 0x130, 0x131)\n", xc.cmd_id == app_ids[i] ? "CMD_ID" : "RES_ID",
                    (unsigned)app_ids[i]);
            return -1;
        }
    }
    return 0;
}

/* A raw CAN FD socket on xc.ifname that receives only CMD_ID (11-bit data
 * frames: the kernel filters the rest). 0, or -1 after printing why. */
static int open_xcp_can(void)
{
    struct can_filter filter;
    filter.can_id = xc.cmd_id;
    filter.can_mask = CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_SFF_MASK;
    xc.fd = open_can(xc.ifname, 0);
    if (xc.fd < 0) {
        return -1;
    }
    if (setsockopt(xc.fd, SOL_CAN_RAW, CAN_RAW_FILTER, &filter, sizeof filter) < 0) {
        fprintf(stderr, "rhonn_runner: --xcp-can %s: CAN_RAW_FILTER: %s\n", xc.ifname, strerror(errno));
        return -1;
    }
    return start_xcp(xcp_can_send);
}

/* Take the waiting XCP frames (at most a burst) and hand each packet to the
 * slave. A frame's whole payload is the packet: a master's fill bytes past
 * the command are ignored by the slave. */
static void take_xcp_can(void)
{
    unsigned burst;
    for (burst = 0; burst < 64u; ++burst) {
        struct canfd_frame cf;
        fw_status st;
        ssize_t n = recv(xc.fd, &cf, sizeof cf, MSG_DONTWAIT);
        if (n < 0) {
            return; /* EAGAIN: nothing more */
        }
        xc.frames += 1u;
        if ((n != CANFD_MTU && n != CAN_MTU) || cf.len == 0u || cf.len > CANFD_MAX_DLEN) {
            xc.malformed += 1u;
            continue;
        }
        st = fw_xcp_on_command(&xcp, &app, cf.data, cf.len, now_ns());
        xc.commands += 1u;
        xc.errors += st == FW_E_RANGE;
        xc.ignored += st == FW_E_STATE;
    }
}

/* The XCP packets waiting on whichever transport the slave has. */
static void serve_xcp(void)
{
    if (xu.fd >= 0) {
        take_xcp();
    } else if (xc.fd >= 0) {
        take_xcp_can();
    }
}

static void usage(FILE *f)
{
    fprintf(f, "usage: rhonn_runner (--interface IF | --udp-multicast GROUP:PORT | --bus-less)\n"
               "                    [--period-us US] [--cycles N] [--duration S] [--rx tick|arrival]\n"
               "                    [--spin-us N] [--diag-period N] [--fifo PRIO] [--json FILE] [--quiet]\n"
               "                    [--rcvbuf BYTES] [--multicast-ttl N]\n"
               "                    [--xcp-udp [ADDR:]PORT | --xcp-can IFACE[,CMD_ID,RES_ID]]\n");
}

static histogram wake_hist = {"wake-up", 0, 0, 0, 0, {0}};
static histogram step_hist = {"step", 0, 0, 0, 0, {0}};
static histogram rx_wait_hist = {"rx-wait", 0, 0, 0, 0, {0}};   /* datagram queued -> taken (udp) */
static histogram interval_hist = {"interval", 0, 0, 0, 0, {0}}; /* between measurement hand-overs */
static platform plat;
static uint64_t last_measurement_ns;
static uint64_t period_ns_now;      /* the loop's period */
static uint64_t spin_ns;            /* --spin-us: busy-poll margin around the next expected Measurement */
static uint64_t expect_ns;          /* when the next Measurement is expected (0: not known yet) */
static uint64_t spin_total_ns;      /* time spent busy-polling */

static void note_rx_wait(uint64_t ns)
{
    hist_add(&rx_wait_hist, ns);
}

/* Take the frames waiting on the bus and hand them to the application;
 * woke: when the runner started on them. 0, or -1 when the bus failed. */
static int take_frames(uint64_t woke)
{
    fw_counters c;
    uint32_t before, handled = 0;
    uint64_t done;
    fw_status st;
    (void)fw_app_get_counters(&app, &c);
    before = c.measurements + c.step_errors;
    st = fw_app_poll(&app, 64u, &handled);
    done = now_ns();
    (void)fw_app_get_counters(&app, &c);
    if (c.measurements + c.step_errors != before) {
        hist_add(&step_hist, done - woke);
        if (last_measurement_ns != 0u) {
            hist_add(&interval_hist, woke - last_measurement_ns);
        }
        last_measurement_ns = woke;
        expect_ns = woke + period_ns_now; /* the rig sends one per period */
    }
    return st == FW_E_HAL ? -1 : 0;
}

/* --rx arrival: handle frames as they arrive until the deadline (or a
 * signal). With --spin-us, the runner busy-polls from spin_ns before the
 * next expected Measurement until it came or spin_ns after (then it blocks
 * again): no wake-up latency for a frame on schedule, for about
 * 2 * spin_ns / period of a CPU. 0, or -1 when the bus failed. */
static int serve_until(uint64_t deadline)
{
    for (;;) {
        struct pollfd pfd[2];
        struct timespec rel;
        uint64_t t = now_ns(), wake = deadline;
        int rc, spinning;
        if (t >= deadline || stop_requested) {
            return 0;
        }
        spinning = spin_ns != 0u && expect_ns != 0u && t + spin_ns >= expect_ns && t < expect_ns + spin_ns;
        if (!spinning && spin_ns != 0u && expect_ns > t + spin_ns && expect_ns - spin_ns < wake) {
            wake = expect_ns - spin_ns;
        }
        rel = to_timespec(spinning ? 0u : wake - t);
        pfd[0].fd = plat.fd;
        pfd[0].events = POLLIN;
        pfd[0].revents = 0;
        pfd[1].fd = xu.fd >= 0 ? xu.fd : xc.fd; /* -1 without XCP: poll skips it */
        pfd[1].events = POLLIN;
        pfd[1].revents = 0;
        rc = ppoll(pfd, 2, &rel, NULL);
        if (rc < 0) {
            if (errno == EINTR) {
                continue;
            }
            plat.last_errno = errno;
            return -1;
        }
        if (spinning) {
            spin_total_ns += now_ns() - t;
        }
        if (rc > 0 && (pfd[1].revents & POLLIN)) {
            serve_xcp();
        }
        if (rc > 0 && (pfd[0].revents & ~POLLNVAL) && take_frames(now_ns()) < 0) {
            return -1;
        }
    }
}

/* The identifier's filter health, per neuron (rhonn_get_health): the
 * values the Health frames carry. */
static void print_health(FILE *f)
{
    const rhonn_t *net;
    rhonn_health h;
    size_t i;
    if (fw_app_get_identifier(&app, &net) != FW_OK) {
        return;
    }
    fprintf(f, "health:  neuron %12s %12s %12s %10s %8s %6s %7s %8s %8s\n", "innovation", "e^2/s", "trace P",
            "updates", "refused", "resets", "bounded", "gated", "fail run");
    for (i = 0; rhonn_get_health(net, i, &h) == RHONN_OK; ++i) {
        fprintf(f, "         %6zu %12.4g %12.4g %12.4g %10u %8u %6u %7u %8u %8u\n", i, (double)h.innovation,
                (double)h.nis, (double)h.trace_p, h.updates, h.rejected, h.resets, h.bounded, h.gated,
                (unsigned)h.fail_run);
    }
}

/* A number for JSON: non-finite values (not JSON) as null. */
static void json_number(FILE *f, double v)
{
    if (isfinite(v)) {
        fprintf(f, "%.9g", v);
    } else {
        fprintf(f, "null");
    }
}

static void json_health(FILE *f)
{
    const rhonn_t *net;
    rhonn_health h;
    size_t i;
    fprintf(f, "\"health\": [");
    if (fw_app_get_identifier(&app, &net) == FW_OK) {
        for (i = 0; rhonn_get_health(net, i, &h) == RHONN_OK; ++i) {
            fprintf(f, "%s{\"neuron\": %zu, \"innovation\": ", i ? ", " : "", i);
            json_number(f, (double)h.innovation);
            fprintf(f, ", \"nis\": ");
            json_number(f, (double)h.nis);
            fprintf(f, ", \"trace_p\": ");
            json_number(f, (double)h.trace_p);
            fprintf(f, ", \"updates\": %u, \"rejected\": %u, \"resets\": %u, \"bounded\": %u, \"gated\": %u, "
                    "\"fail_run\": %u}", h.updates, h.rejected, h.resets, h.bounded, h.gated, (unsigned)h.fail_run);
        }
    }
    fprintf(f, "]");
}

static void json_string(FILE *f, const char *s)
{
    fputc('"', f);
    for (; *s != '\0'; ++s) {
        if (*s == '"' || *s == '\\') {
            fputc('\\', f);
        }
        if ((unsigned char)*s >= 0x20u) {
            fputc(*s, f);
        }
    }
    fputc('"', f);
}

int main(int argc, char **argv)
{
    static const struct option options[] = {
        {"interface", required_argument, 0, 'i'}, {"bus-less", no_argument, 0, 'b'},
        {"udp-multicast", required_argument, 0, 'u'}, {"rx", required_argument, 0, 'r'},
        {"diag-period", required_argument, 0, 'D'}, {"spin-us", required_argument, 0, 'S'},
        {"period-us", required_argument, 0, 'p'}, {"cycles", required_argument, 0, 'n'},
        {"duration", required_argument, 0, 'd'},  {"fifo", required_argument, 0, 'f'},
        {"json", required_argument, 0, 'j'},      {"quiet", no_argument, 0, 'q'},
        {"rcvbuf", required_argument, 0, 'R'},    {"multicast-ttl", required_argument, 0, 'T'},
        {"xcp-udp", required_argument, 0, 'X'},   {"xcp-can", required_argument, 0, 'C'},
        {"help", no_argument, 0, 'h'},            {0, 0, 0, 0}};
    const char *xcp_spec = NULL;
    const char *ifname = NULL, *udp_spec = NULL, *json_path = NULL, *where = "bus-less", *mode = "bus-less";
    int bus_less = 0, fifo = 0, quiet = 0, opt, rx_arrival = -1;
    long diag_period = 1000;
    int rcvbuf = 0, ttl = 1;
    double spin_us = 0.0;
    double period_us = 300.0, duration_s = 0.0;
    unsigned long long max_cycles = 0, count = 0;
    const char *policy = "SCHED_OTHER";
    FILE *json_file = NULL;
    int json_failed = 0;
    unsigned char seen[128] = {0};
    int bus_failed = 0;
    fw_hal hal;
    fw_app_config cfg;
    fw_counters c;
    fw_status st;
    uint64_t period_ns, start, next, end_at, cycle = 0, overruns = 0, late_ns, elapsed;
    struct sigaction sa;
    char *endp;
    unsigned k;

    memset(&plat, 0, sizeof plat);
    xu.fd = -1;
    plat.kind = BUS_NONE;
    plat.fd = -1;
    while ((opt = getopt_long(argc, argv, "i:bu:r:D:S:p:n:d:f:j:qR:T:X:C:h", options, NULL)) != -1) {
        /* an option given twice is a mistake in a script, not "the last one wins" */
        if (opt > 0 && opt < 128 && opt != '?' && opt != 'h') {
            if (seen[opt]) {
                const struct option *o = options;
                while (o->name != NULL && o->val != opt) {
                    ++o;
                }
                fprintf(stderr, "rhonn_runner: --%s is given twice\n", o->name != NULL ? o->name : "?");
                return 2;
            }
            seen[opt] = 1;
        }
        switch (opt) {
        case 'i': ifname = optarg; break;
        case 'b': bus_less = 1; break;
        case 'u': udp_spec = optarg; break;
        case 'r':
            if (strcmp(optarg, "tick") == 0 || strcmp(optarg, "arrival") == 0) {
                rx_arrival = optarg[0] == 'a';
            } else {
                fprintf(stderr, "rhonn_runner: --rx takes tick or arrival, got '%s'\n", optarg);
                return 2;
            }
            break;
        case 'D':
            if (parse_count(optarg, 0u, 65535u, &count) < 0) {
                fprintf(stderr, "rhonn_runner: --diag-period takes 0..65535 measurements, got '%s'\n", optarg);
                return 2;
            }
            diag_period = (long)count;
            break;
        case 'S':
            spin_us = strtod(optarg, &endp);
            if (*optarg == '\0' || *endp != '\0' || !(spin_us >= 0.0 && spin_us <= 1e5)) {
                fprintf(stderr, "rhonn_runner: --spin-us takes a number of microseconds, got '%s'\n", optarg);
                return 2;
            }
            break;
        case 'p':
            period_us = strtod(optarg, &endp);
            if (*endp != '\0' || !(period_us >= 10.0 && period_us <= 1e6)) {
                fprintf(stderr, "rhonn_runner: --period-us must be a number in 10..1000000, got '%s'\n", optarg);
                return 2;
            }
            break;
        case 'n':
            if (parse_count(optarg, 1u, 1000000000000ull, &max_cycles) < 0) { /* 1e12: 3.5 days at 0.3 ms */
                fprintf(stderr, "rhonn_runner: --cycles must be a whole number in 1..1000000000000, got '%s'\n", optarg);
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
            if (parse_count(optarg, 1u, 99u, &count) < 0) {
                fprintf(stderr, "rhonn_runner: --fifo takes a priority in 1..99, got '%s'\n", optarg);
                return 2;
            }
            fifo = (int)count;
            break;
        case 'j': json_path = optarg; break;
        case 'q': quiet = 1; break;
        case 'R':
            if (parse_count(optarg, 1u, 1073741824u, &count) < 0) {
                fprintf(stderr, "rhonn_runner: --rcvbuf takes a number of bytes in 1..1073741824, got '%s'\n", optarg);
                return 2;
            }
            rcvbuf = (int)count;
            break;
        case 'T':
            if (parse_count(optarg, 0u, 255u, &count) < 0) {
                fprintf(stderr, "rhonn_runner: --multicast-ttl takes 0..255, got '%s'\n", optarg);
                return 2;
            }
            ttl = (int)count;
            break;
        case 'X':
            xcp_spec = optarg;
            if (parse_xcp_spec(optarg) < 0) {
                return 2;
            }
            break;
        case 'C':
            if (parse_xcp_can_spec(optarg) < 0) {
                return 2;
            }
            break;
        case 'h': usage(stdout); return 0;
        default: usage(stderr); return 2;
        }
    }
    if (optind != argc || (ifname != NULL) + (udp_spec != NULL) + bus_less != 1) {
        fprintf(stderr, "rhonn_runner: give exactly one of --interface IF, --udp-multicast GROUP:PORT or --bus-less\n");
        usage(stderr);
        return 2;
    }
    if (seen['X'] && seen['C']) {
        fprintf(stderr, "rhonn_runner: give --xcp-udp or --xcp-can, not both (the slave serves one master)\n");
        return 2;
    }
    if (seen['n'] && seen['d']) {
        fprintf(stderr, "rhonn_runner: give --cycles or --duration, not both\n");
        return 2;
    }
    if (bus_less && rx_arrival == 1) {
        fprintf(stderr, "rhonn_runner: --rx arrival needs a bus (--interface or --udp-multicast)\n");
        return 2;
    }
    if (udp_spec != NULL && parse_group(udp_spec, &plat) < 0) {
        return 2;
    }
    if (seen['T'] && udp_spec == NULL) {
        fprintf(stderr, "rhonn_runner: --multicast-ttl is an option of --udp-multicast\n");
        return 2;
    }
    if (seen['R'] && bus_less) {
        fprintf(stderr, "rhonn_runner: --rcvbuf needs a bus (--interface or --udp-multicast)\n");
        return 2;
    }
    if (rx_arrival < 0) {
        rx_arrival = udp_spec != NULL; /* the udp_multicast rig waits for its answer; SocketCAN keeps the tick */
    }
    if (spin_us > 0.0 && (rx_arrival == 0 || bus_less || !(2.0 * spin_us < period_us))) {
        fprintf(stderr, "rhonn_runner: --spin-us needs --rx arrival on a bus, and less than half the period\n");
        return 2;
    }
    /* opened before the run: a path that cannot be written is found now, not after an hour's run */
    if (json_path != NULL && (json_file = fopen(json_path, "w")) == NULL) {
        fprintf(stderr, "rhonn_runner: --json: cannot write %s: %s\n", json_path, strerror(errno));
        return 2;
    }
    if (ifname != NULL) {
        plat.fd = open_can(ifname, rcvbuf);
        if (plat.fd < 0) {
            return 1;
        }
        plat.kind = BUS_SOCKETCAN;
        where = ifname;
        mode = "socketcan";
    } else if (udp_spec != NULL) {
        plat.fd = open_udp(&plat, udp_spec, ttl, rcvbuf > 0 ? rcvbuf : 4 << 20);
        if (plat.fd < 0) {
            return 1;
        }
        plat.kind = BUS_UDP;
        where = udp_spec;
        mode = "udp_multicast";
    }

    hal.ctx = &plat;
    hal.send = hal_send;
    hal.receive = hal_receive;
    hal.now = hal_now;
    period_ns = (uint64_t)llround(period_us * 1e3);
    period_ns_now = period_ns;
    spin_ns = (uint64_t)llround(spin_us * 1e3);
    cfg.identifier = &FW_IDENTIFIER;
    cfg.deadline_ns = (uint32_t)period_ns;
    cfg.diag_period = (uint16_t)diag_period;
    st = fw_app_init(&app, &cfg, &hal);
    if (st != FW_OK) {
        fprintf(stderr, "rhonn_runner: fw_app_init: %s\n", fw_status_name(st));
        return 1;
    }

    if (xcp_spec != NULL) {
        char text[INET_ADDRSTRLEN];
        if (open_xcp(xcp_spec) < 0) {
            return 1;
        }
        if (!quiet) {
            printf("xcp: udp %s:%u, A2L %s\n", inet_ntop(AF_INET, &xu.local.sin_addr, text, sizeof text),
                   (unsigned)ntohs(xu.local.sin_port), FW_XCP_A2L_NAME);
            fflush(stdout);
        }
    }
    if (seen['C']) {
        if (open_xcp_can() < 0) {
            return 1;
        }
        if (ifname != NULL && strcmp(ifname, xc.ifname) == 0) {
            plat.xcp_ids[0] = xc.cmd_id; /* one interface for both: XCP's frames are not the application's */
            plat.xcp_ids[1] = xc.res_id;
            plat.xcp_shared = 1;
        }
        if (!quiet) {
            printf("xcp: can %s, command 0x%X, response 0x%X, A2L %s\n", xc.ifname, (unsigned)xc.cmd_id,
                   (unsigned)xc.res_id, FW_XCP_A2L_NAME);
            fflush(stdout);
        }
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

    if (!bus_less && !quiet) {
        printf("rhonn_runner: listening on %s %s, rx %s\n", mode, where, rx_arrival ? "arrival" : "tick");
        fflush(stdout);
    }

    start = now_ns();
    next = start;
    end_at = duration_s > 0.0 ? start + (uint64_t)llround(duration_s * 1e9) : UINT64_MAX;
    while (!stop_requested && (max_cycles == 0 || cycle < max_cycles)) {
        struct timespec ts;
        uint64_t woke, done;
        int rc;

        next += period_ns;
        if (next > end_at) {
            break;
        }
        if (rx_arrival) {
            /* frames as they come, up to the deadline; then the tick */
            if (serve_until(next) < 0) {
                bus_failed = 1;
                break;
            }
            if (stop_requested) {
                break;
            }
            woke = now_ns();
            hist_add(&wake_hist, woke > next ? woke - next : 0u);
            done = woke;
        } else {
            ts = to_timespec(next);
            do {
                rc = clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
            } while (rc == EINTR && !stop_requested);
            if (stop_requested) {
                break;
            }
            woke = now_ns();
            hist_add(&wake_hist, woke > next ? woke - next : 0u);

            serve_xcp();
            if (bus_less) {
                fw_frame f;
                uint32_t before;
                (void)fw_app_get_counters(&app, &c);
                before = c.measurements + c.step_errors;
                vector_frame((uint32_t)cycle, &f);
                woke = now_ns();
                (void)fw_app_on_frame(&app, f.id, f.data, f.len, woke);
                done = now_ns();
                (void)fw_app_get_counters(&app, &c);
                if (c.measurements + c.step_errors != before) {
                    hist_add(&step_hist, done - woke);
                }
            } else {
                if (take_frames(woke) < 0) {
                    bus_failed = 1;
                    break;
                }
                done = now_ns();
            }
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
    elapsed = now_ns() - start;
    if (bus_failed) {
        fprintf(stderr, "rhonn_runner: the %s %s failed (%s); stopping\n",
                plat.kind == BUS_UDP ? "udp_multicast socket on" : "CAN interface", where,
                strerror(plat.last_errno));
    }

    (void)fw_app_get_counters(&app, &c);
    if (!quiet) {
        printf("rhonn_runner: %s, period %.1f us, %llu cycles, %s\n", bus_less ? "bus-less" : where, period_us,
               (unsigned long long)cycle, policy);
        printf("%-9s %10s %10s %10s %10s %10s %12s\n", "(us)", "min", "avg", "p99", "p99.9", "max", "samples");
        hist_print(&wake_hist);
        hist_print(&step_hist);
        if (plat.kind == BUS_UDP) {
            hist_print(&rx_wait_hist);
        }
        if (rx_arrival) {
            hist_print(&interval_hist);
        }
        printf("overruns %llu (%.4f %%), frames in %u, out %u, rejected %u, step errors %u, "
               "commands failing authentication %u, replayed or stale %u\n",
               (unsigned long long)overruns, cycle ? 100.0 * (double)overruns / (double)cycle : 0.0,
               c.frames_in, c.frames_out, c.rejected, c.step_errors, c.rejected_auth, c.rejected_freshness);
        printf("sequence: measurements %u, lost %u in %u gaps, seq rejected %u (jump) %u (repeat), restarts %u, "
               "kernel drops %u\n",
               c.measurements, c.lost_frames, c.seq_gaps, c.rejected_seq_jump, c.rejected_seq_repeat, c.restarts,
               c.rx_drops);
        print_health(stdout);
        if (plat.kind == BUS_UDP) {
            printf("udp: datagrams %llu, own skipped %llu, malformed %llu", (unsigned long long)plat.datagrams,
                   (unsigned long long)plat.own_skipped, (unsigned long long)plat.malformed);
            for (k = 0; k < UDP_CAN_N_STATUS; ++k) {
                if (plat.malformed_by[k] != 0u) {
                    printf(" %s=%llu", udp_can_status_name((udp_can_status)k),
                           (unsigned long long)plat.malformed_by[k]);
                }
            }
            if (plat.oversized != 0u) {
                printf(" oversized=%llu", (unsigned long long)plat.oversized);
            }
            printf(", send errors %llu\n", (unsigned long long)plat.send_errors);
        }
        if (xu.fd >= 0) {
            printf("xcp: datagrams %llu, commands %llu, errors %llu, ignored %llu, malformed %llu, other masters %llu "
                   "(%llu took over), step events %u, DAQ packets sent %u, lost %u\n",
                   (unsigned long long)xu.datagrams, (unsigned long long)xu.commands, (unsigned long long)xu.errors,
                   (unsigned long long)xu.ignored, (unsigned long long)xu.malformed, (unsigned long long)xu.foreign,
                   (unsigned long long)xu.takeovers,
                   rhonn_xcp_signals.events, rhonn_xcp_signals.daq_dto_sent, rhonn_xcp_signals.daq_dto_lost);
        }
        if (xc.fd >= 0) {
            printf("xcp: can frames %llu, commands %llu, errors %llu, ignored %llu, malformed %llu, send errors %llu, "
                   "skipped on the bus %llu, step events %u, DAQ packets sent %u, lost %u\n",
                   (unsigned long long)xc.frames, (unsigned long long)xc.commands, (unsigned long long)xc.errors,
                   (unsigned long long)xc.ignored, (unsigned long long)xc.malformed,
                   (unsigned long long)xc.send_errors, (unsigned long long)plat.xcp_skipped,
                   rhonn_xcp_signals.events, rhonn_xcp_signals.daq_dto_sent, rhonn_xcp_signals.daq_dto_lost);
        }
        if (spin_ns != 0u) {
            printf("spin: %.1f us around each expected measurement, %.1f %% of the time\n", spin_us,
                   elapsed ? 100.0 * (double)spin_total_ns / (double)elapsed : 0.0);
        }
    }
    if (json_file != NULL) {
        FILE *f = json_file;
        fprintf(f, "{\"mode\": \"%s\", \"interface\": ", mode);
        json_string(f, bus_less ? "" : where);
        fprintf(f, ", \"rx\": \"%s\", \"period_us\": %.3f, \"cycles\": %llu, \"policy\": \"%s\", \"overruns\": %llu, "
                   "\"spin_us\": %.3f, \"spin_share\": %.6f, ",
                bus_less ? "vector" : rx_arrival ? "arrival" : "tick", period_us, (unsigned long long)cycle, policy,
                (unsigned long long)overruns, spin_us,
                elapsed ? (double)spin_total_ns / (double)elapsed : 0.0);
        hist_json(f, &wake_hist);
        fprintf(f, ", ");
        hist_json(f, &step_hist);
        fprintf(f, ", ");
        hist_json(f, &rx_wait_hist);
        fprintf(f, ", ");
        hist_json(f, &interval_hist);
        fprintf(f, ", \"frames_in\": %u, \"frames_out\": %u, \"rejected\": %u, \"step_errors\": %u, "
                   "\"rejected_auth\": %u, \"rejected_freshness\": %u, \"send_errors\": %llu, \"bus_failed\": %s",
                c.frames_in, c.frames_out, c.rejected, c.step_errors, c.rejected_auth, c.rejected_freshness,
                (unsigned long long)plat.send_errors, bus_failed ? "true" : "false");
        fprintf(f, ", \"measurements\": %u, \"lost_frames\": %u, \"seq_gaps\": %u, \"rejected_seq_jump\": %u, "
                   "\"rejected_seq_repeat\": %u, \"restarts\": %u, \"rx_drops\": %u, \"multicast_ttl\": %d, ",
                c.measurements, c.lost_frames, c.seq_gaps, c.rejected_seq_jump, c.rejected_seq_repeat, c.restarts,
                c.rx_drops, plat.kind == BUS_UDP ? ttl : -1);
        json_health(f);
        if (plat.kind == BUS_UDP) {
            fprintf(f, ", \"udp\": {\"datagrams\": %llu, \"own_skipped\": %llu, \"malformed\": %llu, "
                       "\"oversized\": %llu, \"malformed_by\": {",
                    (unsigned long long)plat.datagrams, (unsigned long long)plat.own_skipped,
                    (unsigned long long)plat.malformed, (unsigned long long)plat.oversized);
            for (k = UDP_CAN_E_TRUNCATED; k < UDP_CAN_N_STATUS; ++k) {
                if (k != UDP_CAN_E_SPACE) { /* an encoder status: never a decoding outcome */
                    fprintf(f, "%s\"%s\": %llu", k > UDP_CAN_E_TRUNCATED ? ", " : "",
                            udp_can_status_name((udp_can_status)k), (unsigned long long)plat.malformed_by[k]);
                }
            }
            fprintf(f, "}}");
        }
        if (xu.fd >= 0) {
            fprintf(f, ", \"xcp\": {\"transport\": \"udp\", \"datagrams\": %llu, \"commands\": %llu, \"errors\": %llu, \"ignored\": %llu, "
                       "\"malformed\": %llu, \"other_masters\": %llu, \"takeovers\": %llu, \"step_events\": %u, "
                       "\"daq_dto_sent\": %u, \"daq_dto_lost\": %u}",
                    (unsigned long long)xu.datagrams, (unsigned long long)xu.commands, (unsigned long long)xu.errors,
                    (unsigned long long)xu.ignored, (unsigned long long)xu.malformed, (unsigned long long)xu.foreign,
                    (unsigned long long)xu.takeovers,
                    rhonn_xcp_signals.events, rhonn_xcp_signals.daq_dto_sent, rhonn_xcp_signals.daq_dto_lost);
        }
        if (xc.fd >= 0) {
            fprintf(f, ", \"xcp\": {\"transport\": \"can\", \"interface\": ");
            json_string(f, xc.ifname);
            fprintf(f, ", \"cmd_id\": %u, \"res_id\": %u, \"frames\": %llu, \"commands\": %llu, \"errors\": %llu, "
                       "\"ignored\": %llu, \"malformed\": %llu, \"send_errors\": %llu, \"bus_skipped\": %llu, "
                       "\"step_events\": %u, \"daq_dto_sent\": %u, \"daq_dto_lost\": %u}",
                    (unsigned)xc.cmd_id, (unsigned)xc.res_id, (unsigned long long)xc.frames,
                    (unsigned long long)xc.commands, (unsigned long long)xc.errors, (unsigned long long)xc.ignored,
                    (unsigned long long)xc.malformed, (unsigned long long)xc.send_errors,
                    (unsigned long long)plat.xcp_skipped, rhonn_xcp_signals.events, rhonn_xcp_signals.daq_dto_sent,
                    rhonn_xcp_signals.daq_dto_lost);
        }
        fprintf(f, "}\n");
        if (ferror(f) | fclose(f)) { /* a full disk or /dev/full: the statistics are not there */
            fprintf(stderr, "rhonn_runner: --json: writing %s failed: %s\n", json_path, strerror(errno));
            json_failed = 1;
        }
    }
    if (plat.fd >= 0) {
        close(plat.fd);
    }
    if (xu.fd >= 0) {
        close(xu.fd);
    }
    if (xc.fd >= 0) {
        close(xc.fd);
    }
    return bus_failed || json_failed ? 1 : 0;
}
