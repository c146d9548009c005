/*
 * test_xcp.c - host unit tests of the XCP slave (fw_xcp.h) on the firmware
 * application over the in-memory HAL (CTest):
 *
 *   - CONNECT, GET_STATUS, GET_COMM_MODE_INFO, GET_ID (the A2L name through
 *     UPLOAD), silence before CONNECT, ERR_CMD_UNKNOWN / ERR_CMD_SYNTAX;
 *   - seed & key: the right AES-CMAC key unlocks, a wrong one is refused
 *     and disconnects, UNLOCK without a seed is a sequence error;
 *   - memory: only the signals (read) and the calibration page (read,
 *     write) are reachable; a byte next to them, a straddling read and any
 *     write to the signals are refused, and a refused write changes nothing;
 *   - calibration: learning off written between steps freezes the weights
 *     from the next step on, never inside one;
 *   - DAQ: one sample per step, with the timestamp and the signals' bytes,
 *     the prescaler, and DTOs the transport refuses counted as lost;
 *   - the DAQ commands' sequence and capacity errors.
 */
#include <math.h>
#include <string.h>

#include "fw_check.h"
#include "fw_app.h"
#include "fw_hal_mem.h"
#include "fw_secoc_key.h"
#include "fw_xcp.h"
#include "lim_identifier.h"
#include "rhonn_id.h"

/* The image: a byte range the slave must never expose, then the regions. */
static struct {
    uint8_t before[64];
    fw_xcp_signals signals;
    fw_xcp_calibration calibration;
    uint8_t after[64];
} img;

static uint32_t sig_addr, cal_addr;

static fw_app app;
static fw_mem_hal mem;
static fw_xcp xcp;

/* The transport: every packet the slave sends. */
#define MAX_PKTS 64
static uint8_t pkts[MAX_PKTS][FW_XCP_MAX_DTO];
static size_t pkt_len[MAX_PKTS];
static unsigned n_pkts;
static int refuse_sends;

static fw_status capture(void *ctx, const uint8_t *p, size_t len)
{
    (void)ctx;
    if (refuse_sends || n_pkts >= MAX_PKTS || len > FW_XCP_MAX_DTO) {
        return FW_E_HAL;
    }
    memcpy(pkts[n_pkts], p, len);
    pkt_len[n_pkts++] = len;
    return FW_OK;
}

static uint64_t now = 1000000u;
static uint16_t seq;

static void setup(void)
{
    fw_hal hal;
    fw_app_config cfg;
    fw_xcp_config xc;
    cfg.identifier = &LIM_IDENTIFIER;
    cfg.deadline_ns = 0;
    cfg.diag_period = 0;
    memset(&app, 0, sizeof app);
    CHECK_FW(fw_mem_hal_init(&mem, &hal), FW_OK);
    CHECK_FW(fw_app_init(&app, &cfg, &hal), FW_OK);
    xc.transport.ctx = NULL;
    xc.transport.send = capture;
    xc.signals = &img.signals;
    xc.calibration = &img.calibration;
    xc.address_base = (uintptr_t)&img;
    CHECK_FW(fw_xcp_init(&xcp, &xc), FW_OK);
    CHECK_FW(fw_xcp_attach(&xcp, &app), FW_OK);
    sig_addr = (uint32_t)((uintptr_t)&img.signals - (uintptr_t)&img);
    cal_addr = (uint32_t)((uintptr_t)&img.calibration - (uintptr_t)&img);
    n_pkts = 0;
    refuse_sends = 0;
    seq = 0;
}

/* One Measurement: a slow trajectory inside the DBC ranges. */
static fw_status step(void)
{
    struct rhonn_id_measurement_t f;
    uint8_t data[RHONN_ID_MEASUREMENT_LENGTH];
    fw_frame out;
    fw_status st;
    int32_t k = (int32_t)seq;
    (void)rhonn_id_measurement_init(&f);
    f.seq = seq++;
    f.valid_qm = f.valid_v = f.valid_lambda_a = f.valid_lambda_b = f.valid_ia = f.valid_ib = 1;
    f.qm = 1000 * (k % 37);
    f.v = (int16_t)(200 * (k % 11) - 1000);
    f.lambda_a = (int16_t)(300 * (k % 7) - 900);
    f.lambda_b = (int16_t)(250 * (k % 9) - 1000);
    f.ia = (int16_t)(500 * (k % 13) - 3000);
    f.ib = (int16_t)(450 * (k % 5) - 900);
    f.ua = (int16_t)(2000 * (k % 17) - 16000);
    f.ub = (int16_t)(1500 * (k % 19) - 13500);
    CHECK(rhonn_id_measurement_pack(data, &f, sizeof data) == (int)RHONN_ID_MEASUREMENT_LENGTH);
    now += 300000u;
    st = fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, data, sizeof data, now);
    while (fw_mem_hal_pop(&mem, &out) == FW_OK) {
    }
    return st;
}

/* Send a command; the last packet sent is its answer. */
static fw_status cmd(const uint8_t *c, size_t len)
{
    n_pkts = 0;
    return fw_xcp_on_command(&xcp, &app, c, len, now);
}

static int answered_error(uint8_t code)
{
    return n_pkts == 1u && pkt_len[0] == 2u && pkts[0][0] == 0xFEu && pkts[0][1] == code;
}

static int answered_ok(void)
{
    return n_pkts == 1u && pkts[0][0] == 0xFFu;
}

static void put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static void connect(void)
{
    static const uint8_t c[] = {0xFF, 0x00};
    CHECK_FW(cmd(c, sizeof c), FW_OK);
    CHECK(answered_ok() && pkt_len[0] == 8u);
}

/* GET_SEED for a resource, then UNLOCK with AES-CMAC(K, seed), or a key
 * with one bit flipped when good is 0. */
static fw_status unlock(uint8_t resource, int good)
{
    static const uint8_t key_bytes[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
    fw_cmac_key k;
    uint8_t seed_cmd[3] = {0xF8, 0x00, 0};
    uint8_t un[2 + FW_XCP_KEY_LEN] = {0xF7, FW_XCP_KEY_LEN};
    uint8_t seed[FW_XCP_SEED_LEN];
    seed_cmd[2] = resource;
    CHECK_FW(cmd(seed_cmd, sizeof seed_cmd), FW_OK);
    CHECK(answered_ok() && pkts[0][1] == FW_XCP_SEED_LEN && pkt_len[0] == 2u + FW_XCP_SEED_LEN);
    memcpy(seed, pkts[0] + 2, FW_XCP_SEED_LEN);
    CHECK_FW(fw_cmac_init(&k, key_bytes), FW_OK);
    CHECK_FW(fw_cmac(&k, seed, sizeof seed, un + 2), FW_OK);
    if (!good) {
        un[2 + 5] ^= 0x10u;
    }
    return cmd(un, sizeof un);
}

static fw_status short_upload(uint8_t n, uint8_t ext, uint32_t addr)
{
    uint8_t c[8] = {0xF4, 0, 0, 0};
    c[1] = n;
    c[3] = ext;
    put32(c + 4, addr);
    return cmd(c, sizeof c);
}

static fw_status set_mta(uint32_t addr)
{
    uint8_t c[8] = {0xF6, 0, 0, 0};
    put32(c + 4, addr);
    return cmd(c, sizeof c);
}

static fw_status download1(uint8_t v)
{
    uint8_t c[3] = {0xF0, 1, 0};
    c[2] = v;
    return cmd(c, sizeof c);
}

static fw_status download_float(uint32_t addr, float v)
{
    uint8_t c[6] = {0xF0, 4};
    fw_status st = set_mta(addr);
    if (st != FW_OK) {
        return st;
    }
    memcpy(c + 2, &v, 4);
    return cmd(c, sizeof c);
}

/* ---- tests ----------------------------------------------------------------- */

static void test_connect_status_and_get_id_name_the_a2l(void)
{
    static const uint8_t status[] = {0xFD};
    static const uint8_t get_id[] = {0xFA, 0x01};
    static const uint8_t comm[] = {0xFB};
    static const uint8_t unknown[] = {0xC0, 0x01};
    static const uint8_t upload_bad[] = {0xF5};
    uint8_t up[2] = {0xF5, 0};
    uint32_t n;
    setup();
    CHECK_FW(cmd(status, sizeof status), FW_E_STATE); /* not connected: silence */
    CHECK(n_pkts == 0u);
    connect();
    CHECK(pkts[0][1] == 0x05u && pkts[0][3] == FW_XCP_MAX_CTO && pkts[0][4] == FW_XCP_MAX_DTO);
    CHECK_FW(cmd(status, sizeof status), FW_OK);
    CHECK(answered_ok() && pkts[0][2] == 0x05u); /* CAL/PAG and DAQ locked */
    CHECK_FW(cmd(comm, sizeof comm), FW_OK);
    CHECK(answered_ok() && pkt_len[0] == 8u);
    CHECK_FW(cmd(get_id, sizeof get_id), FW_OK);
    n = (uint32_t)pkts[0][4] | ((uint32_t)pkts[0][5] << 8);
    CHECK(answered_ok() && n == sizeof(FW_XCP_A2L_NAME) - 1u);
    up[1] = (uint8_t)n;
    CHECK_FW(cmd(up, sizeof up), FW_OK);
    CHECK(answered_ok() && pkt_len[0] == 1u + n && memcmp(pkts[0] + 1, FW_XCP_A2L_NAME, n) == 0);
    CHECK_FW(cmd(up, sizeof up), FW_E_RANGE); /* past the text */
    CHECK(answered_error(0x24));
    CHECK_FW(cmd(unknown, sizeof unknown), FW_E_RANGE);
    CHECK(answered_error(0x20));
    CHECK_FW(cmd(upload_bad, sizeof upload_bad), FW_E_RANGE);
    CHECK(answered_error(0x21));
    CHECK(fw_xcp_last_error(&xcp) == 0x21u);
}

static void test_seed_and_key_unlock_and_a_wrong_key_disconnects(void)
{
    static const uint8_t status[] = {0xFD};
    static const uint8_t bare_unlock[2 + FW_XCP_KEY_LEN] = {0xF7, FW_XCP_KEY_LEN};
    setup();
    connect();
    CHECK_FW(cmd(bare_unlock, sizeof bare_unlock), FW_E_RANGE);
    CHECK(answered_error(0x29)); /* no seed asked for */
    CHECK_FW(unlock(0x01, 1), FW_OK);
    CHECK(answered_ok() && pkts[0][1] == 0x04u); /* CAL/PAG open, DAQ still locked */
    CHECK_FW(unlock(0x04, 0), FW_E_RANGE);
    CHECK(answered_error(0x25));
    CHECK_FW(cmd(status, sizeof status), FW_E_STATE); /* disconnected */
    connect();
    CHECK_FW(cmd(status, sizeof status), FW_OK);
    CHECK(pkts[0][2] == 0x05u); /* everything locked again after CONNECT */
    CHECK_FW(download1(0), FW_E_RANGE);
    CHECK(answered_error(0x25));
}

static void test_only_the_signals_and_the_calibration_page_are_reachable(void)
{
    rhonn_real w[RHONN_MAX_TERMS];
    const rhonn_t *net;
    float got;
    setup();
    CHECK(step() == FW_OK && step() == FW_OK && step() == FW_OK);
    connect();
    CHECK_FW(fw_app_get_identifier(&app, &net), FW_OK);
    CHECK_STATUS(rhonn_get_weights(net, 1, w, LIM_IDENTIFIER.neurons[1].n_terms), RHONN_OK);
    CHECK_FW(short_upload(4, 0, sig_addr + FW_XCP_OFF_WEIGHTS + 4u * (FW_XCP_TERMS + 2u)), FW_OK);
    memcpy(&got, pkts[0] + 1, 4);
    CHECK(answered_ok() && got == (float)w[2]);
    CHECK_FW(short_upload(4, 0, sig_addr + FW_XCP_OFF_MEASUREMENTS), FW_OK);
    CHECK(pkts[0][1] == 3u && pkts[0][2] == 0u);
    /* the byte before, the byte after, a straddling read, another extension, far away */
    CHECK_FW(short_upload(1, 0, sig_addr - 1u), FW_E_RANGE);
    CHECK(answered_error(0x24));
    CHECK_FW(short_upload(1, 0, cal_addr + FW_XCP_CALIBRATION_SIZE), FW_E_RANGE);
    CHECK(answered_error(0x24));
    CHECK_FW(short_upload(8, 0, sig_addr + FW_XCP_SIGNALS_SIZE - 4u), FW_E_RANGE);
    CHECK(answered_error(0x24));
    CHECK_FW(short_upload(4, 1, sig_addr), FW_E_RANGE);
    CHECK(answered_error(0x24));
    CHECK_FW(short_upload(4, 0, 0xFFFFFFFEu), FW_E_RANGE);
    CHECK(answered_error(0x24));
    CHECK_FW(short_upload(64, 0, sig_addr), FW_E_RANGE); /* more than a response holds */
    CHECK(answered_error(0x22));
    /* writes: the signals are read only, the page checks its values */
    CHECK_FW(unlock(0x01, 1), FW_OK);
    CHECK_FW(set_mta(sig_addr + FW_XCP_OFF_LEARNING), FW_OK);
    CHECK_FW(download1(0), FW_E_RANGE);
    CHECK(answered_error(0x23) && img.signals.learning == 1u);
    CHECK_FW(set_mta(sig_addr - 1u), FW_OK);
    CHECK_FW(download1(0), FW_E_RANGE);
    CHECK(answered_error(0x24) && img.before[63] == 0u);
    CHECK_FW(set_mta(cal_addr + FW_XCP_CAL_OFF_LEARNING), FW_OK);
    CHECK_FW(download1(2), FW_E_RANGE);
    CHECK(answered_error(0x22) && img.calibration.learning == 1u);
    CHECK_FW(set_mta(cal_addr + 1u), FW_OK);
    CHECK_FW(download1(7), FW_E_RANGE); /* a reserved byte */
    CHECK(answered_error(0x22) && img.calibration.reserved[0] == 0u);
}

/* A fresh application after five steps, a master connected, CAL/PAG unlocked. */
static void calibrating_after_five_steps(void)
{
    int k;
    setup();
    for (k = 0; k < 5; ++k) {
        CHECK(step() == FW_OK);
    }
    connect();
    CHECK_FW(unlock(0x01, 1), FW_OK);
}

static void test_learning_off_takes_effect_at_the_next_step(void)
{
    rhonn_real w0[RHONN_MAX_TERMS], w1[RHONN_MAX_TERMS];
    const rhonn_t *net;
    int k;
    calibrating_after_five_steps();
    CHECK_FW(set_mta(cal_addr + FW_XCP_CAL_OFF_LEARNING), FW_OK);
    CHECK_FW(download1(0), FW_OK);
    CHECK(answered_ok() && img.calibration.learning == 0u);
    CHECK(fw_app_learning(&app) == 1); /* written, not yet taken: no step ran */
    CHECK_FW(fw_app_get_identifier(&app, &net), FW_OK);
    CHECK(step() == FW_OK);
    CHECK(fw_app_learning(&app) == 0);
    CHECK_FW(short_upload(4, 0, sig_addr + FW_XCP_OFF_LEARNING), FW_OK); /* a read refreshes the signals */
    CHECK(pkts[0][1] == 0u && img.signals.learning == 0u);
    CHECK_STATUS(rhonn_get_weights(net, 4, w0, LIM_IDENTIFIER.neurons[4].n_terms), RHONN_OK);
    for (k = 0; k < 5; ++k) {
        CHECK(step() == FW_OK);
    }
    CHECK_STATUS(rhonn_get_weights(net, 4, w1, LIM_IDENTIFIER.neurons[4].n_terms), RHONN_OK);
    CHECK(memcmp(w0, w1, sizeof(rhonn_real) * LIM_IDENTIFIER.neurons[4].n_terms) == 0);
    CHECK_FW(set_mta(cal_addr + 1u), FW_OK);
    CHECK_FW(download1(1), FW_E_RANGE); /* a reserved byte */
    CHECK(answered_error(0x22));
    CHECK_FW(set_mta(cal_addr), FW_OK);
    CHECK_FW(download1(1), FW_OK);
    CHECK(step() == FW_OK && fw_app_learning(&app) == 1);
    CHECK(step() == FW_OK);
    CHECK_STATUS(rhonn_get_weights(net, 4, w1, LIM_IDENTIFIER.neurons[4].n_terms), RHONN_OK);
    CHECK(memcmp(w0, w1, sizeof(rhonn_real) * LIM_IDENTIFIER.neurons[4].n_terms) != 0);
}

/* DOWNLOAD of a gate or a trace ceiling: checked by the core's rules, taken
 * before the next step (not before), and acting from that step on. */
static void test_a_downloaded_gate_and_trace_ceiling_act_from_the_next_step(void)
{
    rhonn_real w0[RHONN_MAX_TERMS], w1[RHONN_MAX_TERMS], v;
    rhonn_health h0, h1;
    const rhonn_t *net;
    fw_xcp_calibration page;
    calibrating_after_five_steps();
    CHECK_FW(fw_app_get_identifier(&app, &net), FW_OK);
    CHECK(img.calibration.gate[4] == 0.0f && img.calibration.trace_ceiling[4] == 0.0f); /* in force: off */
    /* refused, nothing written: NaN, negative, a ceiling below trace P(0) */
    page = img.calibration;
    CHECK_FW(download_float(cal_addr + FW_XCP_CAL_OFF_GATE + 16u, (float)NAN), FW_E_RANGE);
    CHECK(answered_error(0x22));
    CHECK_FW(download_float(cal_addr + FW_XCP_CAL_OFF_GATE + 16u, -1.0f), FW_E_RANGE);
    CHECK_FW(download_float(cal_addr + FW_XCP_CAL_OFF_TRACE_CEILING + 16u, 1e-30f), FW_E_RANGE);
    CHECK(memcmp(&page, &img.calibration, sizeof page) == 0);
    CHECK_STATUS(rhonn_get_weights(net, 4, w0, LIM_IDENTIFIER.neurons[4].n_terms), RHONN_OK);
    CHECK_STATUS(rhonn_get_health(net, 4, &h0), RHONN_OK);
    /* a gate that skips every update of neuron 4, and a ceiling on neuron 5 */
    CHECK_FW(download_float(cal_addr + FW_XCP_CAL_OFF_GATE + 16u, 1e-30f), FW_OK);
    CHECK_FW(download_float(cal_addr + FW_XCP_CAL_OFF_TRACE_CEILING + 20u, 1e30f), FW_OK);
    CHECK_STATUS(rhonn_get_gate(net, 4, &v), RHONN_OK);
    CHECK(v == (rhonn_real)0.0); /* written, not yet taken: no step ran */
    CHECK(step() == FW_OK);
    CHECK_STATUS(rhonn_get_gate(net, 4, &v), RHONN_OK);
    CHECK(v == (rhonn_real)1e-30f);
    CHECK_STATUS(rhonn_get_trace_ceiling(net, 5, &v), RHONN_OK);
    CHECK(v == (rhonn_real)1e30f);
    CHECK_STATUS(rhonn_get_health(net, 4, &h1), RHONN_OK);
    CHECK_STATUS(rhonn_get_weights(net, 4, w1, LIM_IDENTIFIER.neurons[4].n_terms), RHONN_OK);
    CHECK(h1.gated == h0.gated + 1u && h1.updates == h0.updates);
    CHECK(memcmp(w0, w1, sizeof(rhonn_real) * LIM_IDENTIFIER.neurons[4].n_terms) == 0);
    CHECK_FW(download_float(cal_addr + FW_XCP_CAL_OFF_GATE + 16u, 0.0f), FW_OK); /* off again */
    CHECK(step() == FW_OK);
    CHECK_STATUS(rhonn_get_weights(net, 4, w1, LIM_IDENTIFIER.neurons[4].n_terms), RHONN_OK);
    CHECK(memcmp(w0, w1, sizeof(rhonn_real) * LIM_IDENTIFIER.neurons[4].n_terms) != 0);
    CHECK_FW(short_upload(4, 0, cal_addr + FW_XCP_CAL_OFF_TRACE_CEILING + 20u), FW_OK); /* the page reads back */
    memcpy(&page.gate[0], pkts[0] + 1, 4);
    CHECK(page.gate[0] == 1e30f);
}

/* Program one DAQ list: ODT 0 the measurement counter, ODT 1 neuron 0's
 * 12 weights and the six x_hat (72 bytes: too many, so split), ... */
static void program_daq(uint8_t prescaler)
{
    static const uint8_t free_daq[] = {0xD6};
    static const uint8_t alloc_daq[] = {0xD5, 0, 1, 0};
    static const uint8_t alloc_odt[] = {0xD4, 0, 0, 0, 2};
    static const uint8_t alloc_e0[] = {0xD3, 0, 0, 0, 0, 1};
    static const uint8_t alloc_e1[] = {0xD3, 0, 0, 0, 1, 2};
    static const uint8_t ptr0[] = {0xE2, 0, 0, 0, 0, 0};
    static const uint8_t ptr1[] = {0xE2, 0, 0, 0, 1, 0};
    uint8_t wr[8] = {0xE1, 0xFF, 4, 0};
    uint8_t mode[8] = {0xE0, 0x10, 0, 0, FW_XCP_EVENT_STEP, 0, 1, 0};
    static const uint8_t start[] = {0xDE, 0x02, 0, 0};
    static const uint8_t synch[] = {0xDD, 0x01};
    CHECK_FW(cmd(free_daq, sizeof free_daq), FW_OK);
    CHECK_FW(cmd(alloc_daq, sizeof alloc_daq), FW_OK);
    CHECK_FW(cmd(alloc_odt, sizeof alloc_odt), FW_OK);
    CHECK_FW(cmd(alloc_e0, sizeof alloc_e0), FW_OK);
    CHECK_FW(cmd(alloc_e1, sizeof alloc_e1), FW_OK);
    CHECK_FW(cmd(ptr0, sizeof ptr0), FW_OK);
    put32(wr + 4, sig_addr + FW_XCP_OFF_MEASUREMENTS);
    CHECK_FW(cmd(wr, sizeof wr), FW_OK);
    CHECK_FW(cmd(ptr1, sizeof ptr1), FW_OK);
    wr[2] = 48; /* neuron 0's 12 weights */
    put32(wr + 4, sig_addr + FW_XCP_OFF_WEIGHTS);
    CHECK_FW(cmd(wr, sizeof wr), FW_OK);
    wr[2] = 12; /* x_hat 0..2 */
    put32(wr + 4, sig_addr + FW_XCP_OFF_XHAT);
    CHECK_FW(cmd(wr, sizeof wr), FW_OK);
    mode[6] = prescaler;
    CHECK_FW(cmd(mode, sizeof mode), FW_OK);
    CHECK_FW(cmd(start, sizeof start), FW_OK);
    CHECK(answered_ok() && pkts[0][1] == 0u); /* first PID */
    CHECK_FW(cmd(synch, sizeof synch), FW_OK);
}

static void test_daq_sends_one_sample_per_step_with_timestamp(void)
{
    const rhonn_t *net;
    rhonn_real w[RHONN_MAX_TERMS];
    static const uint8_t stop[] = {0xDD, 0x00};
    uint32_t ts, meas, lost0;
    int k;
    setup();
    connect();
    CHECK_FW(unlock(0x04, 1), FW_OK);
    program_daq(1);
    CHECK_FW(fw_app_get_identifier(&app, &net), FW_OK);
    for (k = 0; k < 20; ++k) {
        n_pkts = 0;
        CHECK(step() == FW_OK);
        CHECK(n_pkts == 2u && pkt_len[0] == 1u + 4u + 4u && pkt_len[1] == 1u + 48u + 12u);
        CHECK(pkts[0][0] == 0u && pkts[1][0] == 1u);
        memcpy(&ts, pkts[0] + 1, 4);
        memcpy(&meas, pkts[0] + 5, 4);
        CHECK(ts == (uint32_t)(now / 1000u) && meas == (uint32_t)k + 1u);
        CHECK_STATUS(rhonn_get_weights(net, 0, w, LIM_IDENTIFIER.neurons[0].n_terms), RHONN_OK);
        {
            float f0, x0;
            rhonn_real xhat[FW_N_STATES];
            memcpy(&f0, pkts[1] + 1, 4);
            memcpy(&x0, pkts[1] + 1 + 48, 4);
            CHECK_STATUS(rhonn_get_prediction(net, xhat, FW_N_STATES), RHONN_OK);
            CHECK(f0 == (float)w[0] && x0 == (float)xhat[0]); /* the entries' signals refreshed */
        }
    }
    CHECK(img.signals.daq_dto_sent == 40u && img.signals.daq_dto_lost == 0u && img.signals.events == 20u);
    /* a transport that refuses: counted lost, the step unharmed */
    refuse_sends = 1;
    lost0 = img.signals.daq_dto_lost;
    CHECK(step() == FW_OK);
    refuse_sends = 0;
    CHECK(img.signals.daq_dto_lost == lost0 + 2u);
    CHECK_FW(cmd(stop, sizeof stop), FW_OK);
    n_pkts = 0;
    CHECK(step() == FW_OK && n_pkts == 0u);
    /* prescaler 3: every third step */
    program_daq(3);
    n_pkts = 0;
    for (k = 0; k < 9; ++k) {
        CHECK(step() == FW_OK);
    }
    CHECK(n_pkts == 6u);
}

/* Deferred: the step event sends nothing; fw_xcp_poll, or else the next
 * frame, sends the same bytes the event would have sent. */
static void test_a_deferred_sample_equals_the_one_sent_inside_the_step(void)
{
    uint8_t eager[3][2][FW_XCP_MAX_DTO];
    size_t eager_len[3][2];
    int k;
    now = 1000000u;
    setup();
    connect();
    CHECK_FW(unlock(0x04, 1), FW_OK);
    program_daq(1);
    for (k = 0; k < 3; ++k) {
        n_pkts = 0;
        CHECK(step() == FW_OK && n_pkts == 2u);
        memcpy(eager[k], pkts, sizeof eager[k]);
        eager_len[k][0] = pkt_len[0];
        eager_len[k][1] = pkt_len[1];
    }
    now = 1000000u;
    setup();
    connect();
    CHECK_FW(unlock(0x04, 1), FW_OK);
    program_daq(1);
    CHECK_FW(fw_xcp_set_deferred(&xcp, 1), FW_OK);
    n_pkts = 0;
    CHECK(step() == FW_OK && n_pkts == 0u); /* noted, not sent */
    CHECK_FW(fw_xcp_poll(&xcp, &app), FW_OK);
    CHECK(n_pkts == 2u && pkt_len[0] == eager_len[0][0] && pkt_len[1] == eager_len[0][1]);
    CHECK(memcmp(pkts[0], eager[0][0], pkt_len[0]) == 0 && memcmp(pkts[1], eager[0][1], pkt_len[1]) == 0);
    n_pkts = 0;
    CHECK_FW(fw_xcp_poll(&xcp, &app), FW_OK); /* nothing left */
    CHECK(n_pkts == 0u);
    CHECK(step() == FW_OK && n_pkts == 0u);
    CHECK(step() == FW_OK && n_pkts == 2u); /* no poll between: the frame sent the first before stepping */
    CHECK(memcmp(pkts[0], eager[1][0], pkt_len[0]) == 0 && memcmp(pkts[1], eager[1][1], pkt_len[1]) == 0);
    n_pkts = 0;
    CHECK_FW(fw_xcp_poll(&xcp, &app), FW_OK);
    CHECK(n_pkts == 2u && memcmp(pkts[0], eager[2][0], pkt_len[0]) == 0 &&
          memcmp(pkts[1], eager[2][1], pkt_len[1]) == 0);
    CHECK_FW(fw_xcp_set_deferred(NULL, 1), FW_E_NULL);
    CHECK_FW(fw_xcp_poll(NULL, &app), FW_E_NULL);
    CHECK_FW(fw_xcp_poll(&xcp, NULL), FW_E_NULL);
}

static void test_daq_commands_refuse_bad_sequences_and_sizes(void)
{
    static const uint8_t free_daq[] = {0xD6};
    static const uint8_t alloc_odt[] = {0xD4, 0, 0, 0, 1};
    static const uint8_t alloc_many[] = {0xD5, 0, 200, 0};
    static const uint8_t alloc_daq[] = {0xD5, 0, 1, 0};
    static const uint8_t alloc_odt_big[] = {0xD4, 0, 0, 0, 250};
    static const uint8_t alloc_e[] = {0xD3, 0, 0, 0, 0, 3};
    static const uint8_t ptr[] = {0xE2, 0, 0, 0, 0, 0};
    static const uint8_t start[] = {0xDE, 0x01, 0, 0};
    static const uint8_t stim_mode[] = {0xE0, 0x02, 0, 0, 0, 0, 1, 0};
    static const uint8_t other_event[] = {0xE0, 0x10, 0, 0, 5, 0, 1, 0};
    uint8_t wr[8] = {0xE1, 0xFF, 40, 0};
    setup();
    connect();
    CHECK_FW(cmd(free_daq, sizeof free_daq), FW_E_RANGE);
    CHECK(answered_error(0x25)); /* locked */
    CHECK_FW(unlock(0x04, 1), FW_OK);
    CHECK_FW(cmd(free_daq, sizeof free_daq), FW_OK);
    CHECK_FW(cmd(alloc_odt, sizeof alloc_odt), FW_E_RANGE);
    CHECK(answered_error(0x29));
    CHECK_FW(cmd(alloc_many, sizeof alloc_many), FW_E_RANGE);
    CHECK(answered_error(0x30));
    CHECK_FW(cmd(alloc_daq, sizeof alloc_daq), FW_OK);
    CHECK_FW(cmd(alloc_odt_big, sizeof alloc_odt_big), FW_E_RANGE);
    CHECK(answered_error(0x30));
    CHECK_FW(cmd(alloc_odt, sizeof alloc_odt), FW_OK);
    CHECK_FW(cmd(alloc_e, sizeof alloc_e), FW_OK);
    CHECK_FW(cmd(ptr, sizeof ptr), FW_OK);
    put32(wr + 4, sig_addr - 8u); /* next to the signals */
    CHECK_FW(cmd(wr, sizeof wr), FW_E_RANGE);
    CHECK(answered_error(0x24));
    put32(wr + 4, sig_addr);
    CHECK_FW(cmd(wr, sizeof wr), FW_OK);
    CHECK_FW(cmd(wr, sizeof wr), FW_E_RANGE); /* 80 bytes do not fit one DTO */
    CHECK(answered_error(0x2A));
    CHECK_FW(cmd(start, sizeof start), FW_E_RANGE); /* no mode set, entries missing */
    CHECK(answered_error(0x2A));
    CHECK_FW(cmd(stim_mode, sizeof stim_mode), FW_E_RANGE);
    CHECK(answered_error(0x27));
    CHECK_FW(cmd(other_event, sizeof other_event), FW_E_RANGE);
    CHECK(answered_error(0x22));
    wr[1] = 3; /* a bit entry */
    CHECK_FW(cmd(ptr, sizeof ptr), FW_OK);
    CHECK_FW(cmd(wr, sizeof wr), FW_E_RANGE);
    CHECK(answered_error(0x22));
}

static void test_init_refuses_bad_arguments(void)
{
    fw_xcp_config xc;
    fw_xcp other;
    memset(&xc, 0, sizeof xc);
    CHECK_FW(fw_xcp_init(NULL, &xc), FW_E_NULL);
    CHECK_FW(fw_xcp_init(&other, &xc), FW_E_NULL);
    xc.signals = &img.signals;
    xc.calibration = &img.calibration;
    CHECK_FW(fw_xcp_init(&other, &xc), FW_E_CONFIG); /* no transport */
    xc.transport.send = capture;
    xc.address_base = (uintptr_t)&img.calibration; /* the signals lie below it */
    CHECK_FW(fw_xcp_init(&other, &xc), FW_E_CONFIG);
    memset(&other, 0, sizeof other);
    CHECK_FW(fw_xcp_on_command(&other, &app, (const uint8_t *)"\xFF\x00", 2, 0), FW_E_NOT_INIT);
    CHECK_FW(fw_xcp_attach(&other, &app), FW_E_NOT_INIT);
    CHECK_FW(fw_xcp_on_command(NULL, &app, NULL, 0, 0), FW_E_NULL);
    CHECK_FW(fw_xcp_attach(&xcp, NULL), FW_E_NULL);
    /* the application's side of the hooks */
    {
        fw_app blank;
        memset(&blank, 0, sizeof blank);
        CHECK_FW(fw_app_set_step_hooks(NULL, NULL), FW_E_NULL);
        CHECK_FW(fw_app_set_step_hooks(&blank, NULL), FW_E_NOT_INIT);
        CHECK_FW(fw_app_set_learning(&blank, 0), FW_E_NOT_INIT);
        CHECK(fw_app_learning(&blank) == 0 && fw_app_learning(NULL) == 0);
        CHECK_FW(fw_xcp_attach(&xcp, &blank), FW_E_NOT_INIT);
    }
    /* hooks removed: the slave sees no more steps */
    setup();
    CHECK(step() == FW_OK && img.signals.events == 1u);
    CHECK_FW(fw_app_set_step_hooks(&app, NULL), FW_OK);
    CHECK(step() == FW_OK && img.signals.events == 1u);
}

int main(void)
{
    printf("sizeof(fw_xcp) = %u bytes\n", (unsigned)sizeof(fw_xcp));
    RUN(test_connect_status_and_get_id_name_the_a2l);
    RUN(test_seed_and_key_unlock_and_a_wrong_key_disconnects);
    RUN(test_only_the_signals_and_the_calibration_page_are_reachable);
    RUN(test_learning_off_takes_effect_at_the_next_step);
    RUN(test_a_downloaded_gate_and_trace_ceiling_act_from_the_next_step);
    RUN(test_daq_sends_one_sample_per_step_with_timestamp);
    RUN(test_a_deferred_sample_equals_the_one_sent_inside_the_step);
    RUN(test_daq_commands_refuse_bad_sequences_and_sizes);
    RUN(test_init_refuses_bad_arguments);
    return CHECK_SUMMARY();
}
