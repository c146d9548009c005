/*
 * Coverage-guided fuzz target (libFuzzer) for fw_xcp_on_command, the XCP
 * slave's command entry, with the step event in between.
 *
 * An input is a sequence of items, each [selector][length][bytes...]:
 *   selector 0x00-0xEF  a command packet of length mod 66 (0..65) from the
 *                       bytes that follow (an address field is left as
 *                       given, so it points anywhere; selector bit 0 set
 *                       moves a 32-bit address at bytes 4..7 next to the
 *                       regions, where the interesting edges are);
 *   selector 0xF0-0xF7  one Measurement step (the DAQ event);
 *   selector 0xF8-0xFF  GET_SEED + the right UNLOCK for the resource in the
 *                       low bits (CAL/PAG or DAQ), as a key holder would.
 * Every input starts from a freshly initialised application and slave.
 *
 * Besides crashes and sanitizer reports, the target aborts when:
 *   - a command changes the identifier (only steps may);
 *   - the calibration page changes while CAL/PAG was never unlocked by the
 *     harness, or takes a value the page does not allow (learning not 0 or
 *     1, a trace ceiling or gate NaN, infinite or negative);
 *   - a packet longer than MAX_DTO is sent, or a response that is neither
 *     positive, an error, nor a DTO;
 *   - any byte outside the two regions changes (the guards around them).
 */
#include <float.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fw_app.h"
#include "fw_hal_mem.h"
#include "fw_secoc_key.h"
#include "fw_xcp.h"
#include "lim_identifier.h"
#include "rhonn_id.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static struct {
    uint8_t guard0[64];
    fw_xcp_signals signals;
    fw_xcp_calibration calibration;
    uint8_t guard1[64];
} img;

static fw_app app;
static fw_mem_hal mem;
static fw_xcp xcp;
static rhonn_t before;
static uint8_t last[FW_XCP_MAX_DTO];
static size_t last_len;

static fw_status sink(void *ctx, const uint8_t *p, size_t len)
{
    (void)ctx;
    if (len == 0u || len > FW_XCP_MAX_DTO) {
        abort();
    }
    memcpy(last, p, len);
    last_len = len;
    return FW_OK;
}

static void step(uint16_t seq, const uint8_t *b, size_t n)
{
    struct rhonn_id_measurement_t f;
    uint8_t frame[RHONN_ID_MEASUREMENT_LENGTH];
    fw_frame out;
    (void)rhonn_id_measurement_init(&f);
    f.seq = seq;
    f.valid_qm = f.valid_v = f.valid_lambda_a = f.valid_lambda_b = f.valid_ia = f.valid_ib = 1;
    f.qm = n > 0 ? (int32_t)b[0] * 100 : 0;
    f.v = (int16_t)(n > 1 ? b[1] * 10 : 0);
    f.ia = (int16_t)(n > 2 ? b[2] * 20 : 0);
    f.ua = (int16_t)(n > 3 ? b[3] * 50 : 0);
    (void)rhonn_id_measurement_pack(frame, &f, sizeof frame);
    (void)fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, frame, sizeof frame, 1000u * seq);
    while (fw_mem_hal_pop(&mem, &out) == FW_OK) {
    }
}

static void unlock(uint8_t resource)
{
    static const uint8_t key_bytes[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
    fw_cmac_key k;
    uint8_t seed_cmd[3] = {0xF8, 0x00, 0};
    uint8_t un[2 + FW_XCP_KEY_LEN] = {0xF7, FW_XCP_KEY_LEN};
    seed_cmd[2] = resource;
    last_len = 0;
    if (fw_xcp_on_command(&xcp, &app, seed_cmd, sizeof seed_cmd, 0) != FW_OK || last_len != 2u + FW_XCP_SEED_LEN) {
        return; /* not connected, or unlocked already */
    }
    (void)fw_cmac_init(&k, key_bytes);
    (void)fw_cmac(&k, last + 2, FW_XCP_SEED_LEN, un + 2);
    if (fw_xcp_on_command(&xcp, &app, un, sizeof un, 0) != FW_OK) {
        abort(); /* the right key is refused */
    }
}

static int zero(const uint8_t *p, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        if (p[i] != 0u) {
            return 0;
        }
    }
    return 1;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fw_hal hal;
    fw_app_config cfg;
    fw_xcp_config xc;
    size_t pos = 0;
    uint16_t seq = 0;
    int cal_unlocked = 0;
    fw_xcp_calibration page;
    uint8_t i;

    memset(&img, 0, sizeof img);
    cfg.identifier = &LIM_IDENTIFIER;
    cfg.deadline_ns = 0;
    cfg.diag_period = 0;
    if (fw_mem_hal_init(&mem, &hal) != FW_OK || fw_app_init(&app, &cfg, &hal) != FW_OK) {
        abort();
    }
    xc.transport.ctx = NULL;
    xc.transport.send = sink;
    xc.signals = &img.signals;
    xc.calibration = &img.calibration;
    xc.address_base = (uintptr_t)&img;
    if (fw_xcp_init(&xcp, &xc) != FW_OK || fw_xcp_attach(&xcp, &app) != FW_OK) {
        abort();
    }
    while (pos + 2u <= size) {
        uint8_t sel = data[pos];
        size_t len = data[pos + 1] % 66u;
        const uint8_t *b = data + pos + 2;
        size_t avail = size - pos - 2u;
        uint8_t pkt[66];
        fw_status st;
        if (len > avail) {
            len = avail;
        }
        pos += 2u + len;
        if (sel >= 0xF8u) {
            unlock((sel & 1u) ? 0x04u : 0x01u);
            if (!(sel & 1u)) {
                cal_unlocked = 1;
            }
            continue;
        }
        if (sel >= 0xF0u) {
            step(seq++, b, len);
            continue;
        }
        memcpy(pkt, b, len);
        if ((sel & 1u) && len >= 8u) {
            uint32_t base = (sel & 2u) ? 64u : 64u + FW_XCP_SIGNALS_SIZE;
            uint32_t a = base + (uint32_t)(int8_t)pkt[4];
            pkt[3] = 0;
            pkt[4] = (uint8_t)a;
            pkt[5] = (uint8_t)(a >> 8);
            pkt[6] = 0;
            pkt[7] = 0;
        }
        memcpy(&before, &app.net, sizeof before);
        page = img.calibration;
        last_len = 0;
        st = fw_xcp_on_command(&xcp, &app, pkt, len, 0);
        if (memcmp(&before, &app.net, sizeof before) != 0) {
            abort(); /* a command moved the identifier */
        }
        if (st == FW_OK && (last_len == 0u || last[0] != 0xFFu)) {
            abort();
        }
        if (st == FW_E_RANGE && (last_len != 2u || last[0] != 0xFEu)) {
            abort();
        }
        if (!cal_unlocked && memcmp(&page, &img.calibration, sizeof page) != 0) {
            abort(); /* written without the key */
        }
        if (img.calibration.learning > 1u || !zero(img.calibration.reserved, sizeof img.calibration.reserved)) {
            abort();
        }
        for (i = 0; i < FW_N_STATES; ++i) { /* only what the core takes: finite, >= 0 */
            const float c = img.calibration.trace_ceiling[i], g = img.calibration.gate[i];
            if (!(c >= 0.0f && c <= FLT_MAX) || !(g >= 0.0f && g <= FLT_MAX)) {
                abort();
            }
        }
        if (!zero(img.guard0, sizeof img.guard0) || !zero(img.guard1, sizeof img.guard1)) {
            abort();
        }
    }
    return 0;
}
