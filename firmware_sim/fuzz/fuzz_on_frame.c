/*
 * Coverage-guided fuzz target (libFuzzer) for fw_app_on_frame, the
 * application's frame-receive entry.
 *
 * An input is a sequence of frames, each [selector][length][payload...]:
 * the selector picks one of the protocol's identifiers (or, for the top
 * values, an arbitrary 11-bit or a 29-bit one from the next bytes), the
 * length is taken mod 73 (so lengths above 64 are tried too), and the
 * payload is whatever bytes follow. Every input starts from a freshly
 * initialised application.
 *
 * Besides crashes and sanitizer reports (build with
 * -fsanitize=fuzzer,address,undefined), the target aborts when a frame the
 * application REJECTS changes the identifier in any byte (rejection must
 * leave the filter untouched), and when the first Measurement accepted
 * after a Seq jump moves a weight (no learning across a gap).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fw_app.h"
#include "fw_hal_mem.h"
#include "lim_identifier.h"
#include "rhonn_id.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static const uint32_t known_ids[] = {
    RHONN_ID_MEASUREMENT_FRAME_ID, RHONN_ID_MEASUREMENT_FRAME_ID, RHONN_ID_MEASUREMENT_FRAME_ID,
    RHONN_ID_CONTROL_FRAME_ID,     RHONN_ID_WEIGHT_LOAD_FRAME_ID, RHONN_ID_ESTIMATE_FRAME_ID,
    RHONN_ID_CONTROL_ACK_FRAME_ID, RHONN_ID_DIAGNOSTICS_FRAME_ID, RHONN_ID_HEALTH_FRAME_ID,
};

static fw_app app;
static fw_mem_hal mem;
static rhonn_t before;

/* Every weight of the identifier, in order; n of them. */
static size_t all_weights(const rhonn_t *net, rhonn_real *w, size_t cap)
{
    size_t i, n = 0;
    for (i = 0; i < LIM_IDENTIFIER.n_states; ++i) {
        size_t L = LIM_IDENTIFIER.neurons[i].n_terms;
        if (n + L > cap || rhonn_get_weights(net, i, w + n, L) != RHONN_OK) {
            abort();
        }
        n += L;
    }
    return n;
}

static int is_rejection(fw_status st)
{
    return st == FW_E_UNKNOWN_ID || st == FW_E_LENGTH || st == FW_E_RANGE || st == FW_E_SEQ_REPEAT ||
           st == FW_E_SEQ_JUMP || st == FW_E_STATE || st == FW_E_WEIGHTS;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fw_hal hal;
    fw_app_config cfg;
    size_t pos = 0;
    uint64_t t = 0;

    if (fw_mem_hal_init(&mem, &hal) != FW_OK) {
        abort();
    }
    mem.tick_ns = 1000u;
    cfg.identifier = &LIM_IDENTIFIER;
    cfg.deadline_ns = 300000u;
    cfg.diag_period = 7u;
    if (fw_app_init(&app, &cfg, &hal) != FW_OK) {
        abort();
    }
    while (pos + 2u <= size) {
        const uint8_t sel = data[pos];
        size_t len = (size_t)(data[pos + 1u] % 73u);
        uint32_t id;
        const rhonn_t *net;
        fw_frame out;
        fw_status st;
        fw_counters c0, c1;
        rhonn_real w0[RHONN_MAX_STATES * RHONN_MAX_TERMS], w1[RHONN_MAX_STATES * RHONN_MAX_TERMS];
        size_t nw;

        pos += 2u;
        if (sel < 0xF0u) {
            id = known_ids[sel % (sizeof known_ids / sizeof known_ids[0])];
        } else if (pos + 2u <= size) {
            id = ((uint32_t)data[pos] << 8 | data[pos + 1u]) & 0x7FFu;
            if (sel >= 0xF8u) {
                id |= FW_CAN_EFF_FLAG | ((uint32_t)sel << 16);
            }
            pos += 2u;
        } else {
            break;
        }
        if (len > size - pos) {
            len = size - pos;
        }
        if (fw_app_get_identifier(&app, &net) != FW_OK) {
            abort();
        }
        memcpy(&before, net, sizeof before);
        nw = all_weights(net, w0, sizeof w0 / sizeof w0[0]);
        (void)fw_app_get_counters(&app, &c0);
        t += 300000u;
        st = fw_app_on_frame(&app, id, len ? &data[pos] : NULL, len, t);
        if (is_rejection(st) && memcmp(&before, net, sizeof before) != 0) {
            abort(); /* a rejected frame touched the filter */
        }
        (void)fw_app_get_counters(&app, &c1);
        if (c1.restarts != c0.restarts &&
            (all_weights(net, w1, sizeof w1 / sizeof w1[0]) != nw || memcmp(w0, w1, nw * sizeof w0[0]) != 0)) {
            abort(); /* learnt across a gap */
        }
        pos += len;
        while (fw_mem_hal_pop(&mem, &out) == FW_OK) {
            /* keep the outbox from filling up */
        }
    }
    return 0;
}
