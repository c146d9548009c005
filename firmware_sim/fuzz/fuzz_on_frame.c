/*
 * Coverage-guided fuzz target (libFuzzer) for fw_app_on_frame, the
 * application's frame-receive entry.
 *
 * An input is a sequence of frames, each [selector][length][payload...]:
 * the selector picks one of the protocol's identifiers (or, for the top
 * values, an arbitrary 11-bit or a 29-bit one from the next bytes), the
 * length is taken mod 73 (so lengths above 64 are tried too), and the
 * payload is whatever bytes follow. Selectors 0xE0-0xEF ask the harness to
 * SECURE the frame as the rig would (Control for even, WeightLoad for odd
 * selectors; the DBC length, the payload zero-padded; the compiled-in key and
 * the next freshness value), so that the command paths behind the
 * authentication stay reachable. Every input starts from a freshly
 * initialised application.
 *
 * Besides crashes and sanitizer reports (build with
 * -fsanitize=fuzzer,address,undefined), the target aborts when a frame the
 * application REJECTS changes the identifier in any byte: rejection must
 * leave the filter untouched. It aborts when the first Measurement accepted
 * after a Seq jump moves a weight (no learning across a gap). With
 * authentication on (FW_SECOC), it also aborts when a Control or WeightLoad
 * frame the harness did not secure gets past the authentication (any status
 * but FW_E_LENGTH, FW_E_AUTH, FW_E_FRESHNESS) or moves the freshness value:
 * only the key holder commands.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fw_app.h"
#include "fw_hal_mem.h"
#include "fw_secoc_key.h"
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
static fw_cmac_key rig_key;
static uint8_t secured[FW_MAX_FRAME_LEN];

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
           st == FW_E_SEQ_JUMP || st == FW_E_STATE || st == FW_E_WEIGHTS || st == FW_E_AUTH ||
           st == FW_E_FRESHNESS;
}

static int is_command(uint32_t id)
{
    return id == RHONN_ID_CONTROL_FRAME_ID || id == RHONN_ID_WEIGHT_LOAD_FRAME_ID;
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
    {
        static const uint8_t key[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
        if (fw_cmac_init(&rig_key, key) != FW_OK) {
            abort();
        }
    }
    while (pos + 2u <= size) {
        const uint8_t sel = data[pos];
        size_t len = (size_t)(data[pos + 1u] % 73u);
        uint32_t id;
        const rhonn_t *net;
        fw_frame out;
        fw_status st;
        const uint8_t *payload;
        int signed_here = 0;
        uint64_t fv_before = 0, fv_after = 0;
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
        payload = len ? &data[pos] : NULL;
        if (fw_app_get_identifier(&app, &net) != FW_OK || fw_app_get_freshness(&app, &fv_before) != FW_OK) {
            abort();
        }
        if (sel >= 0xE0u && sel < 0xF0u) {
            /* the rig's side: a secured command built from the fuzzer's bytes */
            size_t full = (sel & 1u) ? RHONN_ID_WEIGHT_LOAD_LENGTH : RHONN_ID_CONTROL_LENGTH;
            id = (sel & 1u) ? RHONN_ID_WEIGHT_LOAD_FRAME_ID : RHONN_ID_CONTROL_FRAME_ID;
            memset(secured, 0, sizeof secured);
            memcpy(secured, &data[pos], len < full ? len : full);
            if (fw_secoc_protect(&rig_key, (uint16_t)id, secured, full, fv_before + 1u) != FW_OK) {
                abort();
            }
            payload = secured;
            pos += len;
            len = full;
            signed_here = 1;
        } else {
            pos += len;
        }
        memcpy(&before, net, sizeof before);
        nw = all_weights(net, w0, sizeof w0 / sizeof w0[0]);
        (void)fw_app_get_counters(&app, &c0);
        t += 300000u;
        st = fw_app_on_frame(&app, id, payload, len, t);
        if (is_rejection(st) && memcmp(&before, net, sizeof before) != 0) {
            abort(); /* a rejected frame touched the filter */
        }
        if (fw_app_get_freshness(&app, &fv_after) != FW_OK) {
            abort();
        }
#if FW_SECOC
        if (is_command(id) && !signed_here &&
            ((st != FW_E_LENGTH && st != FW_E_AUTH && st != FW_E_FRESHNESS) || fv_after != fv_before)) {
            abort(); /* a command without a valid MAC got through */
        }
#endif
        if (signed_here && st == FW_E_AUTH) {
            abort(); /* the rig's own frames must verify */
        }
        (void)fw_app_get_counters(&app, &c1);
        if (c1.restarts != c0.restarts &&
            (all_weights(net, w1, sizeof w1 / sizeof w1[0]) != nw || memcmp(w0, w1, nw * sizeof w0[0]) != 0)) {
            abort(); /* learnt across a gap */
        }
        while (fw_mem_hal_pop(&mem, &out) == FW_OK) {
            /* keep the outbox from filling up */
        }
    }
    return 0;
}
