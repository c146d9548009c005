/* The XCP slave (fw_xcp) on the Cortex-M4F under QEMU, for its cost:
 * bench/bench_xcp.py estimates the cycles of what this image runs
 * (cycles.py).
 *
 *   xcp_m4.elf plain N     the Measurements among the first N frames of the
 *                          recorded stream (frames.h, make_frames.py: the
 *                          LIM at the rig's period), the application alone
 *   xcp_m4.elf connected N the slave attached and a master connected, no DAQ
 *   xcp_m4.elf daq N       the slave attached, connected, unlocked, one DAQ
 *                          list running on the step event (the measurement
 *                          counter, the 29 weights, NIS and trace P of every
 *                          neuron: 3 ODTs), then the same Measurements
 *   xcp_m4.elf deferred N  the same list, its sample deferred
 *                          (fw_xcp_set_deferred): the step event notes it and
 *                          fw_xcp_poll, called after each frame, sends it
 *   xcp_m4.elf commands N  after the same set-up, N commands, cycling through
 *                          SHORT_UPLOAD of 4 and of 56 bytes, SET_MTA,
 *                          DOWNLOAD of 1 byte, GET_STATUS
 *
 * The frames are handed over by feed() and the commands by command(): the
 * cycle estimate's units, which
 * nothing else calls. The transport only counts the packets (a driver's
 * copy is not part of the figure). Prints the sizes of the objects in RAM
 * and the packets sent. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fw_app.h"
#include "fw_hal_mem.h"
#include "fw_secoc_key.h"
#include "fw_xcp.h"
#include "frames.h"
#include "lim_identifier.h"
#include "rhonn_id.h"

static fw_app app;
static fw_mem_hal mem;
static fw_xcp xcp;
static fw_xcp_signals signals;
static fw_xcp_calibration calibration;
static uint32_t packets;
static uint8_t last[FW_XCP_MAX_DTO];

static fw_status count_packet(void *ctx, const uint8_t *p, size_t len)
{
    (void)ctx;
    ++packets;
    last[0] = p[0];
    last[1] = len > 1u ? p[1] : 0u;
    return FW_OK;
}

__attribute__((noinline)) fw_status feed(uint32_t k);
__attribute__((noinline)) fw_status command(const uint8_t *c, size_t len);

fw_status feed(uint32_t k)
{
    mem.now_ns = frame_time_ns[k];
    return fw_app_on_frame(&app, frame_id[k], frame_data[k], frame_len[k], frame_time_ns[k]);
}

fw_status command(const uint8_t *c, size_t len)
{
    return fw_xcp_on_command(&xcp, &app, c, len, mem.now_ns);
}

static void put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static int expect_ok(const uint8_t *c, size_t len)
{
    if (fw_xcp_on_command(&xcp, &app, c, len, 0) != FW_OK) {
        printf("error command 0x%02x: 0x%02x\n", (unsigned)c[0], (unsigned)last[1]);
        return -1;
    }
    return 0;
}

static int unlock(uint8_t resource)
{
    static const uint8_t key_bytes[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
    uint8_t seed_cmd[3] = {0xF8, 0x00, 0};
    uint8_t un[2 + FW_XCP_KEY_LEN] = {0xF7, FW_XCP_KEY_LEN};
    fw_cmac_key k;
    seed_cmd[2] = resource;
    if (expect_ok(seed_cmd, sizeof seed_cmd) < 0) {
        return -1;
    }
    (void)fw_cmac_init(&k, key_bytes);
    (void)fw_cmac(&k, xcp.seed, FW_XCP_SEED_LEN, un + 2); /* the seed just sent */
    return expect_ok(un, sizeof un);
}

/* The one DAQ list: the measurement counter, every weight, NIS and trace P
 * of every neuron (41 values, 164 bytes), packed greedily into ODTs that
 * each fit a DTO (the first after its 4-byte timestamp): 3 ODTs. */
#define LIST_MAX 48u
static int program_daq(void)
{
    static const uint8_t connect[] = {0xFF, 0x00};
    static const uint8_t free_daq[] = {0xD6};
    static const uint8_t alloc_daq[] = {0xD5, 0, 1, 0};
    static const uint8_t mode[8] = {0xE0, 0x10, 0, 0, 0, 0, 1, 0};
    static const uint8_t start[4] = {0xDE, 0x01, 0, 0};
    const uint32_t base = (uint32_t)(uintptr_t)&signals;
    uint32_t addr[LIST_MAX];
    uint8_t size[LIST_MAX], odt_of[LIST_MAX], per_odt[FW_XCP_MAX_ODT] = {0};
    uint8_t c[8];
    unsigned n = 0, k, i, t, n_odt = 1, used = 0;
    addr[n] = base + FW_XCP_OFF_MEASUREMENTS; size[n++] = 4;
    for (i = 0; i < FW_N_STATES; ++i) {
        for (t = 0; t < LIM_IDENTIFIER.neurons[i].n_terms; ++t) {
            addr[n] = base + FW_XCP_OFF_WEIGHTS + 4u * (i * FW_XCP_TERMS + t); size[n++] = 4;
        }
    }
    addr[n] = base + FW_XCP_OFF_NIS; size[n++] = 4u * FW_N_STATES;
    addr[n] = base + FW_XCP_OFF_TRACE_P; size[n++] = 4u * FW_N_STATES;
    for (k = 0; k < n; ++k) { /* greedy: the next ODT when this one is full */
        unsigned room = FW_XCP_MAX_DTO - 1u - (n_odt == 1u ? 4u : 0u);
        if (used + size[k] > room) {
            ++n_odt;
            used = 0;
        }
        used += size[k];
        odt_of[k] = (uint8_t)(n_odt - 1u);
        ++per_odt[n_odt - 1u];
    }
    if (expect_ok(connect, sizeof connect) < 0 || unlock(0x04) < 0 || unlock(0x01) < 0 ||
        expect_ok(free_daq, sizeof free_daq) < 0 || expect_ok(alloc_daq, sizeof alloc_daq) < 0) {
        return -1;
    }
    c[0] = 0xD4; c[1] = 0; c[2] = 0; c[3] = 0; c[4] = (uint8_t)n_odt;
    if (expect_ok(c, 5) < 0) return -1;
    for (k = 0; k < n_odt; ++k) {
        c[0] = 0xD3; c[1] = 0; c[2] = 0; c[3] = 0; c[4] = (uint8_t)k; c[5] = per_odt[k];
        if (expect_ok(c, 6) < 0) return -1;
    }
    for (k = 0; k < n; ++k) {
        if (k == 0u || odt_of[k] != odt_of[k - 1u]) {
            c[0] = 0xE2; c[1] = 0; c[2] = 0; c[3] = 0; c[4] = odt_of[k]; c[5] = 0;
            if (expect_ok(c, 6) < 0) return -1;
        }
        c[0] = 0xE1; c[1] = 0xFF; c[2] = size[k]; c[3] = 0;
        put32(c + 4, addr[k]);
        if (expect_ok(c, 8) < 0) return -1;
    }
    return expect_ok(mode, sizeof mode) < 0 ? -1 : expect_ok(start, sizeof start);
}

int main(int argc, char **argv)
{
    const fw_app_config cfg = {&LIM_IDENTIFIER, FRAMES_DEADLINE_NS, 0u};
    fw_hal hal;
    fw_xcp_config xc;
    fw_frame out;
    const char *mode = argc > 1 ? argv[1] : "daq";
    unsigned long n = argc > 2 ? strtoul(argv[2], NULL, 10) : 100ul;
    unsigned long k;

    if (fw_mem_hal_init(&mem, &hal) != FW_OK || fw_app_init(&app, &cfg, &hal) != FW_OK) {
        printf("error init\n");
        return 1;
    }
    xc.transport.ctx = NULL;
    xc.transport.send = count_packet;
    xc.signals = &signals;
    xc.calibration = &calibration;
    xc.address_base = 0u; /* absolute addresses, as on a microcontroller */
    if (strcmp(mode, "plain") != 0) {
        static const uint8_t connect[] = {0xFF, 0x00};
        if (fw_xcp_init(&xcp, &xc) != FW_OK || fw_xcp_attach(&xcp, &app) != FW_OK ||
            (strcmp(mode, "connected") == 0 ? expect_ok(connect, sizeof connect) : program_daq()) < 0 ||
            fw_xcp_set_deferred(&xcp, strcmp(mode, "deferred") == 0) != FW_OK) {
            printf("error xcp\n");
            return 1;
        }
    }
    printf("sizeof(fw_xcp) %lu\n", (unsigned long)sizeof(fw_xcp));
    printf("sizeof(fw_xcp_signals) %lu\n", (unsigned long)sizeof(fw_xcp_signals));
    printf("sizeof(fw_xcp_calibration) %lu\n", (unsigned long)sizeof(fw_xcp_calibration));
    printf("sizeof(fw_app) %lu\n", (unsigned long)sizeof(fw_app));
    packets = 0;
    if (strcmp(mode, "commands") == 0) {
        uint8_t c[8] = {0xF4, 4, 0, 0};
        static const uint8_t status[] = {0xFD};
        uint8_t dl[3] = {0xF0, 1, 0};
        uint8_t mta[8] = {0xF6, 0, 0, 0};
        put32(mta + 4, (uint32_t)(uintptr_t)&calibration);
        for (k = 0; k < n; ++k) {
            fw_status st;
            switch (k % 5u) {
            case 0: c[1] = 4; put32(c + 4, (uint32_t)(uintptr_t)&signals + FW_XCP_OFF_MEASUREMENTS);
                st = command(c, 8); break;
            case 1: c[1] = 56; put32(c + 4, (uint32_t)(uintptr_t)&signals + FW_XCP_OFF_WEIGHTS);
                st = command(c, 8); break;
            case 2: st = command(mta, 8); break;
            case 3: dl[2] = (uint8_t)((k / 5u) & 1u); st = command(dl, 3); break;
            default: st = command(status, 1); break;
            }
            if (st != FW_OK) {
                printf("error command %lu: %s\n", k, fw_status_name(st));
                return 1;
            }
        }
    } else {
        for (k = 0; k < n && k < FRAMES_N; ++k) {
            if (frame_id[k] != RHONN_ID_MEASUREMENT_FRAME_ID) {
                continue; /* the stream's commands and foreign frames: not this figure */
            }
            (void)feed((uint32_t)k);
            (void)fw_xcp_poll(&xcp, &app); /* the main loop's turn (no-op unless deferred) */
            while (fw_mem_hal_pop(&mem, &out) == FW_OK) {
            }
        }
    }
    printf("mode %s n %lu packets %lu dto_sent %lu\n", mode, n, (unsigned long)packets,
           (unsigned long)signals.daq_dto_sent);
    return 0;
}
