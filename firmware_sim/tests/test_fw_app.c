/*
 * test_fw_app.c - host unit tests of the firmware application (CTest), built
 * once per precision. The application runs on the in-memory HAL; the
 * identifier is the exported LIM configuration.
 *
 *   - a stream of valid frames gives exactly rhonn_run's predictions on the
 *     decoded measurements, and the Estimate frames carry them;
 *   - every rejection path leaves the identifier bit for bit unchanged and
 *     is counted, and the stream then goes on as if the bad frames had never
 *     been sent;
 *   - control commands, the weight transfer, diagnostics, HAL failures,
 *     the quantiser's rounding and saturation;
 *   - command authentication (FW_SECOC): forged, replayed, stale and short
 *     command frames are rejected, counted, not answered, and leave the
 *     identifier bit for bit unchanged; authenticated ones work.
 *
 * Command frames are secured by a sender of the test's own (the compiled-in
 * key, a freshness counter restarted with each setup), as a rig does; with
 * -DFW_SECOC=0 the firmware ignores the trailer and the same tests run.
 */
#include <math.h>
#include <string.h>

#include "fw_check.h"
#include "fw_app.h"
#include "fw_hal_mem.h"
#include "fw_secoc_key.h"
#include "lim_identifier.h"
#include "rhonn_id.h"
#include "rhonn_id_limits.h"

enum { N = FW_N_STATES, M = FW_N_INPUTS }; /* int constants */
#define T_MAX 400
#define MAX_L RHONN_MAX_TERMS
#define MAX_P RHONN_MAX_PACKED

static fw_app app;
static fw_mem_hal mem;
static fw_hal hal;
static fw_cmac_key tx_key;  /* the rig's side of the authentication */
static uint64_t tx_fv;      /* the rig's freshness counter: last value used */

/* ---- helpers -------------------------------------------------------------- */

static void setup(uint16_t diag_period, uint32_t deadline_ns)
{
    fw_app_config cfg;
    cfg.identifier = &LIM_IDENTIFIER;
    cfg.deadline_ns = deadline_ns;
    cfg.diag_period = diag_period;
    memset(&app, 0, sizeof app);
    CHECK_FW(fw_mem_hal_init(&mem, &hal), FW_OK);
    CHECK_FW(fw_app_init(&app, &cfg, &hal), FW_OK);
    {
        static const uint8_t key[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
        CHECK_FW(fw_cmac_init(&tx_key, key), FW_OK);
        tx_fv = 0;
    }
}

/* Secure a command frame with the rig's next freshness value. */
static void secure(uint32_t id, uint8_t *data, size_t len)
{
    CHECK_FW(fw_secoc_protect(&tx_key, (uint16_t)id, data, len, ++tx_fv), FW_OK);
}

static fw_counters counters(void)
{
    fw_counters c;
    memset(&c, 0, sizeof c);
    CHECK_FW(fw_app_get_counters(&app, &c), FW_OK);
    return c;
}

static const rhonn_t *net_of(const fw_app *a)
{
    const rhonn_t *net = NULL;
    CHECK_FW(fw_app_get_identifier(a, &net), FW_OK);
    return net;
}

static uint32_t outbox_count(void)
{
    return mem.outbox.count;
}

static fw_frame pop(void)
{
    fw_frame f;
    memset(&f, 0, sizeof f);
    CHECK_FW(fw_mem_hal_pop(&mem, &f), FW_OK);
    return f;
}

/* The Health frames that follow every Diagnostics frame: one per neuron,
 * in order, each the neuron's rhonn_get_health. */
static void pop_health(void)
{
    uint8_t i;
    for (i = 0; i < N; ++i) {
        struct rhonn_id_health_t h;
        rhonn_health want;
        fw_frame f = pop();
        CHECK(f.id == RHONN_ID_HEALTH_FRAME_ID && f.len == RHONN_ID_HEALTH_LENGTH);
        CHECK(rhonn_id_health_unpack(&h, f.data, f.len) == 0);
        CHECK_STATUS(rhonn_get_health(net_of(&app), i, &want), RHONN_OK);
        CHECK(h.neuron == i && h.updates == want.updates && h.rejected == want.rejected);
        CHECK(h.resets == want.resets && h.bounded == want.bounded && h.fail_run == want.fail_run);
        CHECK(h.gated == want.gated);
        CHECK(h.innovation_sat == 0 && h.nis_sat == 0 && h.trace_p_sat == 0);
        CHECK(h.innovation == (float)want.innovation && h.nis == (float)want.nis);
        CHECK(h.trace_p == (float)want.trace_p);
    }
}

static void drain(void)
{
    fw_frame f;
    while (fw_mem_hal_pop(&mem, &f) == FW_OK) {
    }
}

/* Deterministic pseudo-random numbers (a 32-bit LCG). */
static uint32_t lcg_state = 12345u;
static uint32_t lcg(void)
{
    lcg_state = lcg_state * 1664525u + 1013904223u;
    return lcg_state >> 8;
}

static int32_t clamp_i32(int32_t v, int32_t lo, int32_t hi)
{
    return v < lo ? lo : (v > hi ? hi : v);
}

/* A rig's trajectory in raw units: a random walk within the DBC ranges, with
 * dropouts (state 0 held for a stretch, random single dropouts). */
typedef struct {
    int32_t x[N];
    int32_t u[M];
} raw_sample;

static const int32_t raw_min[N + M] = {
    RHONN_ID_MEASUREMENT_QM_RAW_MIN, RHONN_ID_MEASUREMENT_V_RAW_MIN, RHONN_ID_MEASUREMENT_LAMBDA_A_RAW_MIN,
    RHONN_ID_MEASUREMENT_LAMBDA_B_RAW_MIN, RHONN_ID_MEASUREMENT_IA_RAW_MIN, RHONN_ID_MEASUREMENT_IB_RAW_MIN,
    RHONN_ID_MEASUREMENT_UA_RAW_MIN, RHONN_ID_MEASUREMENT_UB_RAW_MIN};
static const int32_t raw_max[N + M] = {
    RHONN_ID_MEASUREMENT_QM_RAW_MAX, RHONN_ID_MEASUREMENT_V_RAW_MAX, RHONN_ID_MEASUREMENT_LAMBDA_A_RAW_MAX,
    RHONN_ID_MEASUREMENT_LAMBDA_B_RAW_MAX, RHONN_ID_MEASUREMENT_IA_RAW_MAX, RHONN_ID_MEASUREMENT_IB_RAW_MAX,
    RHONN_ID_MEASUREMENT_UA_RAW_MAX, RHONN_ID_MEASUREMENT_UB_RAW_MAX};
/* random-walk step sizes (raw) and starting points */
static const int32_t walk[N + M] = {300, 50, 40, 40, 400, 400, 800, 800};

static raw_sample walk_state;

static void walk_reset(void)
{
    int j;
    lcg_state = 12345u;
    for (j = 0; j < N; ++j) {
        walk_state.x[j] = raw_max[j] / 10;
    }
    walk_state.u[0] = 0;
    walk_state.u[1] = 0;
}

static int32_t walk_step(int32_t v, int j)
{
    int32_t step = (int32_t)(lcg() % (uint32_t)(2 * walk[j] + 1)) - walk[j];
    return clamp_i32(v + step, raw_min[j] / 4, raw_max[j] / 4);
}

static raw_sample walk_next(void)
{
    int j;
    for (j = 0; j < N; ++j) {
        walk_state.x[j] = walk_step(walk_state.x[j], j);
    }
    for (j = 0; j < M; ++j) {
        walk_state.u[j] = walk_step(walk_state.u[j], N + j);
    }
    return walk_state;
}

typedef struct {
    uint8_t data[RHONN_ID_MEASUREMENT_LENGTH];
} meas_frame;

static meas_frame pack_measurement(uint16_t seq, const raw_sample *s, const uint8_t valid[N])
{
    struct rhonn_id_measurement_t f;
    meas_frame out;
    (void)rhonn_id_measurement_init(&f);
    f.seq = seq;
    f.valid_qm = valid[0];
    f.valid_v = valid[1];
    f.valid_lambda_a = valid[2];
    f.valid_lambda_b = valid[3];
    f.valid_ia = valid[4];
    f.valid_ib = valid[5];
    f.qm = s->x[0];
    f.v = (int16_t)s->x[1];
    f.lambda_a = (int16_t)s->x[2];
    f.lambda_b = (int16_t)s->x[3];
    f.ia = (int16_t)s->x[4];
    f.ib = (int16_t)s->x[5];
    f.ua = (int16_t)s->u[0];
    f.ub = (int16_t)s->u[1];
    CHECK(rhonn_id_measurement_pack(out.data, &f, sizeof out.data) == (int)RHONN_ID_MEASUREMENT_LENGTH);
    return out;
}

static void valid_pattern(uint32_t k, uint8_t valid[N])
{
    int j;
    for (j = 0; j < N; ++j) {
        valid[j] = (uint8_t)((lcg() % 50u) != 0u); /* 2 % dropouts */
    }
    if (k >= 40u && k < 70u) {
        valid[0] = 0; /* a held position */
    }
}

/* The whole observable state of an identifier, through the public getters. */
typedef struct {
    rhonn_real w[N][MAX_L];
    rhonn_real p[N][MAX_P];
    rhonn_real xhat[N];
} snapshot;

static void take(const rhonn_t *net, snapshot *s)
{
    size_t i;
    memset(s, 0, sizeof *s);
    for (i = 0; i < N; ++i) {
        size_t L = LIM_IDENTIFIER.neurons[i].n_terms;
        CHECK_STATUS(rhonn_get_weights(net, i, s->w[i], L), RHONN_OK);
        CHECK_STATUS(rhonn_get_covariance(net, i, s->p[i], L * (L + 1) / 2), RHONN_OK);
    }
    CHECK_STATUS(rhonn_get_prediction(net, s->xhat, N), RHONN_OK);
}

static int same_snapshot(const snapshot *a, const snapshot *b)
{
    return memcmp(a, b, sizeof *a) == 0;
}

static fw_status send_control(uint8_t command, uint8_t token)
{
    struct rhonn_id_control_t f;
    uint8_t data[RHONN_ID_CONTROL_LENGTH];
    (void)rhonn_id_control_init(&f);
    f.command = command;
    f.token = token;
    CHECK(rhonn_id_control_pack(data, &f, sizeof data) == (int)RHONN_ID_CONTROL_LENGTH);
    secure(RHONN_ID_CONTROL_FRAME_ID, data, sizeof data);
    return fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, data, sizeof data, 0);
}

static struct rhonn_id_control_ack_t pop_ack(void)
{
    struct rhonn_id_control_ack_t a;
    fw_frame f = pop();
    memset(&a, 0, sizeof a);
    CHECK(f.id == RHONN_ID_CONTROL_ACK_FRAME_ID && f.len == RHONN_ID_CONTROL_ACK_LENGTH);
    CHECK(rhonn_id_control_ack_unpack(&a, f.data, f.len) == 0);
    return a;
}

static void pack_weights(uint8_t *data, uint8_t neuron, uint8_t first, uint8_t count, const float *w)
{
    struct rhonn_id_weight_load_t f;
    float v[FW_WEIGHTS_PER_FRAME];
    uint8_t k;
    for (k = 0; k < FW_WEIGHTS_PER_FRAME; ++k) {
        v[k] = k < count ? w[k] : 0.0f;
    }
    (void)rhonn_id_weight_load_init(&f);
    f.neuron = neuron;
    f.first = first;
    f.count = count;
    f.w00 = v[0]; f.w01 = v[1]; f.w02 = v[2]; f.w03 = v[3]; f.w04 = v[4];
    f.w05 = v[5]; f.w06 = v[6]; f.w07 = v[7]; f.w08 = v[8]; f.w09 = v[9];
    f.w10 = v[10]; f.w11 = v[11];
    CHECK(rhonn_id_weight_load_pack(data, &f, RHONN_ID_WEIGHT_LOAD_LENGTH) == (int)RHONN_ID_WEIGHT_LOAD_LENGTH);
}

static fw_status send_weights(uint8_t neuron, uint8_t first, uint8_t count, const float *w)
{
    uint8_t data[RHONN_ID_WEIGHT_LOAD_LENGTH];
    pack_weights(data, neuron, first, count, w);
    secure(RHONN_ID_WEIGHT_LOAD_FRAME_ID, data, sizeof data);
    return fw_app_on_frame(&app, RHONN_ID_WEIGHT_LOAD_FRAME_ID, data, sizeof data, 0);
}

/* ---- the stream of valid frames equals rhonn_run -------------------------- */

static rhonn_real X[T_MAX][N], U[T_MAX][M], XHAT[T_MAX][N], PRED[T_MAX][N];
static uint8_t V[T_MAX][N];
static meas_frame FRAMES[T_MAX];
static fw_frame EST[T_MAX];
static rhonn_t ref;

static void test_valid_stream_gives_rhonn_run_predictions(void)
{
    const uint32_t T = 300;
    const uint16_t seq0 = 65400; /* wraps through 0 */
    uint32_t k;
    size_t done = 0;
    snapshot a, b;

    setup(0, 0);
    walk_reset();
    for (k = 0; k < T; ++k) {
        raw_sample s = walk_next();
        uint8_t valid[N];
        fw_measurement m;
        valid_pattern(k, valid);
        if (k == 50) {
            s.x[0] = raw_max[0] + 12345; /* out of range, but flagged invalid: accepted, ignored */
        }
        FRAMES[k] = pack_measurement((uint16_t)(seq0 + k), &s, valid);
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, FRAMES[k].data, RHONN_ID_MEASUREMENT_LENGTH,
                                 (uint64_t)k * 300000u), FW_OK);
        CHECK(outbox_count() == 1u);
        EST[k] = pop();
        CHECK_STATUS(rhonn_get_prediction(net_of(&app), PRED[k], N), RHONN_OK);
        /* the decoded measurement, as the reference sees it */
        CHECK_FW(fw_measurement_decode(FRAMES[k].data, RHONN_ID_MEASUREMENT_LENGTH, &m), FW_OK);
        memcpy(X[k], m.x, sizeof m.x);
        memcpy(U[k], m.u, sizeof m.u);
        memcpy(V[k], m.valid, sizeof m.valid);
        CHECK(memcmp(m.valid, valid, N) == 0);
    }
    CHECK_STATUS(rhonn_init(&ref, &LIM_IDENTIFIER, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_run(&ref, T, &X[0][0], &U[0][0], &V[0][0], &XHAT[0][0], &done), RHONN_OK);
    CHECK(done == T);
    CHECK(memcmp(PRED, XHAT, sizeof(rhonn_real) * N * T) == 0);
    take(net_of(&app), &a);
    take(&ref, &b);
    CHECK(same_snapshot(&a, &b));
    for (k = 0; k < T; ++k) {
        fw_estimate e;
        uint8_t want[RHONN_ID_ESTIMATE_LENGTH];
        struct rhonn_id_estimate_t got;
        e.seq = (uint16_t)(seq0 + k);
        e.step_status = 0;
        e.learning = 1;
        e.resync = k == 0;
        memcpy(e.xhat, XHAT[k], sizeof e.xhat);
        CHECK_FW(fw_estimate_encode(&e, want, sizeof want, NULL), FW_OK);
        CHECK(EST[k].id == RHONN_ID_ESTIMATE_FRAME_ID && EST[k].len == RHONN_ID_ESTIMATE_LENGTH);
        CHECK(EST[k].flags == (FW_FRAME_FD | FW_FRAME_BRS));
        CHECK(memcmp(EST[k].data, want, sizeof want) == 0);
        CHECK(rhonn_id_estimate_unpack(&got, EST[k].data, EST[k].len) == 0);
        CHECK(got.seq == e.seq && got.resync == (k == 0) && got.step_status == 0 && got.learning == 1);
    }
    {
        fw_counters c = counters();
        CHECK(c.frames_in == T && c.measurements == T && c.frames_out == T && c.rejected == 0);
        CHECK(c.cycle_time_ns == 300000u);
    }
}

/* ---- every rejection leaves the filter untouched -------------------------- */

static rhonn_t net_before;
static snapshot snap_before;

typedef struct {
    const char *what;
    uint32_t id;
    uint8_t data[80];
    size_t len;
    fw_status want;
    int secured;    /* secure with the next freshness value when sent */
} bad_frame;

static bad_frame BAD[128];

static void expect_untouched(const char *what, size_t rejected_before)
{
    snapshot now;
    fw_counters c = counters();
    take(net_of(&app), &now);
    CHECK(memcmp(net_of(&app), &net_before, sizeof net_before) == 0);
    CHECK(same_snapshot(&now, &snap_before));
    CHECK(c.rejected == rejected_before + 1u);
    if (memcmp(net_of(&app), &net_before, sizeof net_before) != 0 || c.rejected != rejected_before + 1u) {
        fprintf(stderr, "  ... after %s\n", what);
    }
}

static void test_rejections_leave_the_filter_bit_for_bit_unchanged(void)
{
    uint32_t k, n_bad = 0, i;
    uint16_t seq = 100;
    raw_sample s;
    uint8_t all_valid[N] = {1, 1, 1, 1, 1, 1};
    meas_frame good;
    int j;
    size_t T_ref = 0, T_gap;
    size_t done = 0;

    setup(0, 0);
    walk_reset();
    for (k = 0; k < 50; ++k, ++seq) {
        fw_measurement m;
        s = walk_next();
        good = pack_measurement(seq, &s, all_valid);
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, good.data, sizeof good.data, 0), FW_OK);
        drain();
        CHECK_FW(fw_measurement_decode(good.data, sizeof good.data, &m), FW_OK);
        memcpy(X[T_ref], m.x, sizeof m.x);
        memcpy(U[T_ref], m.u, sizeof m.u);
        memcpy(V[T_ref], m.valid, sizeof m.valid);
        ++T_ref;
    }
    drain();
    /* seq is now the next expected counter; s the last sample */
    s = walk_next();
    good = pack_measurement(seq, &s, all_valid);

#define ADD(what_, id_, len_, want_)                                                      \
    do {                                                                                  \
        BAD[n_bad].what = (what_);                                                        \
        BAD[n_bad].id = (id_);                                                            \
        BAD[n_bad].len = (len_);                                                          \
        BAD[n_bad].want = (want_);                                                        \
        BAD[n_bad].secured = 0;                                                           \
        memset(BAD[n_bad].data, 0, sizeof BAD[n_bad].data);                               \
        memcpy(BAD[n_bad].data, good.data, sizeof good.data);                             \
        ++n_bad;                                                                          \
    } while (0)

    /* unknown identifiers, with a perfectly good measurement payload */
    ADD("id 0x000", 0x000u, 20, FW_E_UNKNOWN_ID);
    ADD("estimate id", RHONN_ID_ESTIMATE_FRAME_ID, 20, FW_E_UNKNOWN_ID);
    ADD("ack id", RHONN_ID_CONTROL_ACK_FRAME_ID, 20, FW_E_UNKNOWN_ID);
    ADD("diagnostics id", RHONN_ID_DIAGNOSTICS_FRAME_ID, 20, FW_E_UNKNOWN_ID);
    ADD("id 0x7ff", 0x7FFu, 20, FW_E_UNKNOWN_ID);
    ADD("29-bit 0x100", RHONN_ID_MEASUREMENT_FRAME_ID | FW_CAN_EFF_FLAG, 20, FW_E_UNKNOWN_ID);
    ADD("rtr 0x100", RHONN_ID_MEASUREMENT_FRAME_ID | FW_CAN_RTR_FLAG, 20, FW_E_UNKNOWN_ID);
    ADD("error frame", RHONN_ID_MEASUREMENT_FRAME_ID | FW_CAN_ERR_FLAG, 20, FW_E_UNKNOWN_ID);
    /* wrong lengths */
    {
        static const size_t lens[] = {0, 1, 8, 12, 16, 19, 21, 24, 32, 48, 64, 65, 80};
        for (i = 0; i < sizeof lens / sizeof lens[0]; ++i) {
            ADD("measurement length", RHONN_ID_MEASUREMENT_FRAME_ID, lens[i], FW_E_LENGTH);
        }
        ADD("control length 8", RHONN_ID_CONTROL_FRAME_ID, 8, FW_E_LENGTH);
        ADD("control length 17", RHONN_ID_CONTROL_FRAME_ID, 17, FW_E_LENGTH);
        ADD("control length 0", RHONN_ID_CONTROL_FRAME_ID, 0, FW_E_LENGTH);
        ADD("weights length 63", RHONN_ID_WEIGHT_LOAD_FRAME_ID, 63, FW_E_LENGTH);
        ADD("weights length 20", RHONN_ID_WEIGHT_LOAD_FRAME_ID, 20, FW_E_LENGTH);
    }
    /* out of range: each valid state and each input, one raw step beyond
     * either end, and at the end of the field */
    for (j = 0; j < N + M; ++j) {
        static const int32_t field_max[N + M] = {0x7FFFFF, 32767, 32767, 32767, 32767, 32767, 32767, 32767};
        int32_t values[4];
        int v;
        values[0] = raw_max[j] + 1;
        values[1] = raw_min[j] - 1;
        values[2] = field_max[j];
        values[3] = -field_max[j] - 1;
        for (v = 0; v < 4; ++v) {
            raw_sample t = s;
            meas_frame f;
            if (j < N) {
                t.x[j] = values[v];
            } else {
                t.u[j - N] = values[v];
            }
            f = pack_measurement(seq, &t, all_valid);
            ADD("out of range", RHONN_ID_MEASUREMENT_FRAME_ID, 20, FW_E_RANGE);
            memcpy(BAD[n_bad - 1].data, f.data, sizeof f.data);
        }
    }
    /* sequence: a repeat of the last accepted counter */
    {
        meas_frame f = pack_measurement((uint16_t)(seq - 1u), &s, all_valid);
        ADD("repeat", RHONN_ID_MEASUREMENT_FRAME_ID, 20, FW_E_SEQ_REPEAT);
        memcpy(BAD[n_bad - 1].data, f.data, sizeof f.data);
    }
    /* control: commands outside 1..7, commands that do not fit the state */
    {
        static const uint8_t cmds[] = {0, 8, 9, 200, 255};
        for (i = 0; i < sizeof cmds / sizeof cmds[0]; ++i) {
            ADD("command out of range", RHONN_ID_CONTROL_FRAME_ID, 16, FW_E_RANGE);
            memset(BAD[n_bad - 1].data, 0, 16);
            BAD[n_bad - 1].data[0] = cmds[i];
            BAD[n_bad - 1].secured = 1;
        }
        ADD("commit without begin", RHONN_ID_CONTROL_FRAME_ID, 16, FW_E_STATE);
        memset(BAD[n_bad - 1].data, 0, 16);
        BAD[n_bad - 1].data[0] = RHONN_ID_CONTROL_COMMAND_WEIGHTS_COMMIT_CHOICE;
        BAD[n_bad - 1].secured = 1;
        ADD("abort without begin", RHONN_ID_CONTROL_FRAME_ID, 16, FW_E_STATE);
        memset(BAD[n_bad - 1].data, 0, 16);
        BAD[n_bad - 1].data[0] = RHONN_ID_CONTROL_COMMAND_WEIGHTS_ABORT_CHOICE;
        BAD[n_bad - 1].secured = 1;
    }
    /* a weight chunk with no transfer open */
    {
        float w[2] = {1.0f, 2.0f};
        ADD("weights without begin", RHONN_ID_WEIGHT_LOAD_FRAME_ID, 64, FW_E_STATE);
        pack_weights(BAD[n_bad - 1].data, 0, 0, 2, w);
        BAD[n_bad - 1].secured = 1;
    }

    memcpy(&net_before, net_of(&app), sizeof net_before);
    take(net_of(&app), &snap_before);
    for (i = 0; i < n_bad; ++i) {
        fw_counters before = counters();
        fw_status got;
        if (BAD[i].secured) {
            secure(BAD[i].id, BAD[i].data, BAD[i].len);
        }
        got = fw_app_on_frame(&app, BAD[i].id, BAD[i].len ? BAD[i].data : NULL, BAD[i].len, 0);
        CHECK(got == BAD[i].want);
        if (got != BAD[i].want) {
            fprintf(stderr, "  %s (#%u): got %s, expected %s\n", BAD[i].what, (unsigned)i, fw_status_name(got),
                    fw_status_name(BAD[i].want));
        }
        expect_untouched(BAD[i].what, before.rejected);
        CHECK(counters().last_reject == (uint8_t)BAD[i].want);
        if (BAD[i].id == RHONN_ID_CONTROL_FRAME_ID && BAD[i].want == FW_E_STATE) {
            struct rhonn_id_control_ack_t a = pop_ack(); /* a refused command is answered */
            CHECK(a.result == (uint8_t)FW_E_STATE && a.command == BAD[i].data[0]);
        }
        CHECK(outbox_count() == 0u);
    }
    {
        fw_counters c = counters();
        CHECK(c.rejected == n_bad);
        CHECK(c.rejected_unknown_id == 8u && c.rejected_length == 18u && c.rejected_range == 32u + 5u);
        CHECK(c.rejected_seq_repeat == 1u && c.rejected_state == 3u && c.measurements == 50u);
    }

    /* The weight transfer: staging does not touch the filter either. */
    {
        float w[15];
        fw_counters before;
        float nan_ = (float)NAN;
        float inf_ = (float)INFINITY;
        for (i = 0; i < 15; ++i) {
            w[i] = 0.5f + (float)i;
        }
        CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_WEIGHTS_BEGIN_CHOICE, 7), FW_OK);
        {
            struct rhonn_id_control_ack_t a = pop_ack();
            uint16_t total = 0;
            for (j = 0; j < N; ++j) {
                total = (uint16_t)(total + LIM_IDENTIFIER.neurons[j].n_terms);
            }
            CHECK(a.result == 0 && a.token == 7 && a.missing == total);
        }
        CHECK(memcmp(net_of(&app), &net_before, sizeof net_before) == 0);
        before = counters();
        CHECK_FW(send_weights(6, 0, 1, w), FW_E_RANGE);      /* neuron outside the DBC range */
        CHECK_FW(send_weights(255, 0, 1, w), FW_E_RANGE);
        CHECK_FW(send_weights(0, 0, 0, w), FW_E_RANGE);      /* count 0 */
        CHECK_FW(send_weights(0, 0, FW_WEIGHTS_PER_FRAME + 1u, w), FW_E_RANGE); /* count 13 */
        CHECK_FW(send_weights(0, 255, 1, w), FW_E_RANGE);    /* first outside the DBC range */
        CHECK_FW(send_weights(0, LIM_IDENTIFIER.neurons[0].n_terms, 1, w), FW_E_RANGE); /* past L_0 */
        CHECK_FW(send_weights(1, 0, (uint8_t)(LIM_IDENTIFIER.neurons[1].n_terms + 1u), w), FW_E_RANGE);
        w[1] = nan_;
        CHECK_FW(send_weights(0, 0, 2, w), FW_E_RANGE);
        w[1] = inf_;
        CHECK_FW(send_weights(0, 0, 2, w), FW_E_RANGE);
        w[1] = -inf_;
        CHECK_FW(send_weights(0, 0, 2, w), FW_E_RANGE);
        w[1] = 3.40282e38f;
        CHECK_FW(send_weights(0, 0, 2, w), FW_E_RANGE);      /* beyond the DBC's +-3.4e38 */
        w[1] = 1.5f;
        CHECK(counters().rejected == before.rejected + 11u);
        CHECK_FW(send_weights(0, 0, 2, w), FW_OK);           /* staged only */
        CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_WEIGHTS_COMMIT_CHOICE, 8), FW_E_WEIGHTS);
        {
            struct rhonn_id_control_ack_t a = pop_ack();
            CHECK(a.result == (uint8_t)FW_E_WEIGHTS && a.token == 8 && a.missing > 0);
        }
        CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_DIAG_REQUEST_CHOICE, 9), FW_OK);
        (void)pop_ack();
        CHECK(pop().id == RHONN_ID_DIAGNOSTICS_FRAME_ID);
        pop_health();
        CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_WEIGHTS_ABORT_CHOICE, 10), FW_OK);
        CHECK(pop_ack().result == 0);
        CHECK(memcmp(net_of(&app), &net_before, sizeof net_before) == 0);
        CHECK(outbox_count() == 0u);
    }

    /* A jump: rejected, the counter re-anchors at the jumped value. The
     * backward one loses nothing; the forward one, counted from the
     * re-anchored value, skipped 24 frames. */
    {
        meas_frame jump = pack_measurement((uint16_t)(seq + 5u), &s, all_valid);
        meas_frame back = pack_measurement((uint16_t)(seq - 20u), &s, all_valid);
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, back.data, 20, 0), FW_E_SEQ_JUMP);
        CHECK(memcmp(net_of(&app), &net_before, sizeof net_before) == 0);
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, jump.data, 20, 0), FW_E_SEQ_JUMP);
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, jump.data, 20, 0), FW_E_SEQ_REPEAT);
        CHECK(memcmp(net_of(&app), &net_before, sizeof net_before) == 0);
        CHECK(outbox_count() == 0u);
        CHECK(counters().rejected_seq_jump == 2u);
        CHECK(counters().lost_frames == 24u && counters().seq_gaps == 1u && counters().restarts == 0u);
        seq = (uint16_t)(seq + 6u);
    }

    /* The stream goes on (from the re-anchored counter) exactly as if the
     * bad frames had never been sent and the identifier had been restarted
     * at the break: the first frame after it learns nothing. */
    T_gap = T_ref;
    for (k = 0; k < 30; ++k, ++seq) {
        fw_measurement m;
        fw_frame est;
        struct rhonn_id_estimate_t e;
        meas_frame f = pack_measurement(seq, &s, all_valid);
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_OK);
        est = pop();
        CHECK(rhonn_id_estimate_unpack(&e, est.data, est.len) == 0);
        CHECK(e.seq == seq && e.resync == (k == 0));
        CHECK_FW(fw_measurement_decode(f.data, 20, &m), FW_OK);
        memcpy(X[T_ref], m.x, sizeof m.x);
        memcpy(U[T_ref], m.u, sizeof m.u);
        memcpy(V[T_ref], m.valid, sizeof m.valid);
        ++T_ref;
        s = walk_next();
    }
    CHECK(counters().restarts == 1u);
    CHECK_STATUS(rhonn_init(&ref, &LIM_IDENTIFIER, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_run(&ref, T_gap, &X[0][0], &U[0][0], &V[0][0], &XHAT[0][0], &done), RHONN_OK);
    CHECK_STATUS(rhonn_restart(&ref), RHONN_OK);
    CHECK_STATUS(rhonn_run(&ref, T_ref - T_gap, &X[T_gap][0], &U[T_gap][0], &V[T_gap][0], &XHAT[T_gap][0], &done),
                 RHONN_OK);
    {
        snapshot a, b;
        take(net_of(&app), &a);
        take(&ref, &b);
        CHECK(same_snapshot(&a, &b));
    }
#undef ADD
}

/* ---- weight transfer ----------------------------------------------------- */

static void test_weight_transfer_replaces_all_weights_at_commit(void)
{
    float w[N][MAX_L];
    uint8_t i, t;
    uint8_t all_valid[N] = {1, 1, 1, 1, 1, 1};
    raw_sample s;
    meas_frame f;
    rhonn_real got[MAX_L], x_app[N], x_ref[N];
    fw_measurement m;

    setup(0, 0);
    memcpy(&net_before, net_of(&app), sizeof net_before);
    for (i = 0; i < N; ++i) {
        for (t = 0; t < MAX_L; ++t) {
            w[i][t] = 0.01f * (float)(i + 1) - 0.003f * (float)t;
        }
    }
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_WEIGHTS_BEGIN_CHOICE, 1), FW_OK);
    (void)pop_ack();
    /* last neuron first, one weight per frame for neuron 2, duplicates */
    for (i = N; i-- > 0;) {
        uint8_t L = LIM_IDENTIFIER.neurons[i].n_terms;
        if (i == 2) {
            for (t = L; t-- > 0;) {
                CHECK_FW(send_weights(i, t, 1, &w[i][t]), FW_OK);
            }
        } else {
            CHECK_FW(send_weights(i, 0, L, w[i]), FW_OK);
            CHECK_FW(send_weights(i, 1, 1, &w[i][1]), FW_OK);
        }
        CHECK(memcmp(net_of(&app), &net_before, sizeof net_before) == 0); /* staged only */
    }
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_WEIGHTS_COMMIT_CHOICE, 2), FW_OK);
    {
        struct rhonn_id_control_ack_t a = pop_ack();
        CHECK(a.result == 0 && a.token == 2 && a.missing == 0);
    }
    for (i = 0; i < N; ++i) {
        uint8_t L = LIM_IDENTIFIER.neurons[i].n_terms;
        CHECK_STATUS(rhonn_get_weights(net_of(&app), i, got, L), RHONN_OK);
        for (t = 0; t < L; ++t) {
            CHECK(got[t] == (rhonn_real)w[i][t]);
        }
    }
    /* a second commit has nothing open */
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_WEIGHTS_COMMIT_CHOICE, 3), FW_E_STATE);
    (void)pop_ack();
    /* the next step is the reference's with the same weights */
    walk_reset();
    s = walk_next();
    f = pack_measurement(0, &s, all_valid);
    CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_OK);
    drain();
    CHECK_STATUS(rhonn_init(&ref, &LIM_IDENTIFIER, NULL), RHONN_OK);
    for (i = 0; i < N; ++i) {
        uint8_t L = LIM_IDENTIFIER.neurons[i].n_terms;
        for (t = 0; t < L; ++t) {
            got[t] = (rhonn_real)w[i][t];
        }
        CHECK_STATUS(rhonn_set_weights(&ref, i, got, L), RHONN_OK);
    }
    CHECK_FW(fw_measurement_decode(f.data, 20, &m), FW_OK);
    CHECK_STATUS(rhonn_step(&ref, m.x, m.u, m.valid, x_ref), RHONN_OK);
    CHECK_STATUS(rhonn_get_prediction(net_of(&app), x_app, N), RHONN_OK);
    CHECK(memcmp(x_app, x_ref, sizeof x_ref) == 0);
    /* Reset goes back to the configuration's w0 */
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_RESET_CHOICE, 4), FW_OK);
    (void)pop_ack();
    CHECK_STATUS(rhonn_get_weights(net_of(&app), 0, got, LIM_IDENTIFIER.neurons[0].n_terms), RHONN_OK);
    CHECK(got[0] == LIM_IDENTIFIER.neurons[0].w0[0]);
}

/* ---- learning, reset ------------------------------------------------------- */

static void test_learning_off_freezes_weights_and_reset_restarts(void)
{
    uint8_t all_valid[N] = {1, 1, 1, 1, 1, 1};
    uint32_t k;
    rhonn_real w_before[MAX_L], w_after[MAX_L];
    size_t L0 = LIM_IDENTIFIER.neurons[0].n_terms;
    snapshot a, b;

    setup(0, 0);
    walk_reset();
    for (k = 0; k < 10; ++k) {
        raw_sample s = walk_next();
        meas_frame f = pack_measurement((uint16_t)k, &s, all_valid);
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_OK);
    }
    drain();
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_LEARNING_OFF_CHOICE, 1), FW_OK);
    CHECK(pop_ack().result == 0);
    CHECK_STATUS(rhonn_get_weights(net_of(&app), 0, w_before, L0), RHONN_OK);
    for (k = 10; k < 20; ++k) {
        raw_sample s = walk_next();
        meas_frame f = pack_measurement((uint16_t)k, &s, all_valid);
        struct rhonn_id_estimate_t e;
        fw_frame est;
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_OK);
        est = pop();
        CHECK(rhonn_id_estimate_unpack(&e, est.data, est.len) == 0);
        CHECK(e.learning == 0);
    }
    CHECK_STATUS(rhonn_get_weights(net_of(&app), 0, w_after, L0), RHONN_OK);
    CHECK(memcmp(w_before, w_after, sizeof(rhonn_real) * L0) == 0);
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_LEARNING_ON_CHOICE, 2), FW_OK);
    CHECK(pop_ack().result == 0);

    /* Reset: the configuration's state, the counter unanchored. */
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_RESET_CHOICE, 3), FW_OK);
    CHECK(pop_ack().result == 0);
    CHECK_STATUS(rhonn_init(&ref, &LIM_IDENTIFIER, NULL), RHONN_OK);
    take(net_of(&app), &a);
    take(&ref, &b);
    CHECK(same_snapshot(&a, &b));
    {
        raw_sample s = walk_next();
        meas_frame f = pack_measurement(5, &s, all_valid); /* any counter is accepted now */
        fw_measurement m;
        rhonn_real x_ref[N];
        struct rhonn_id_estimate_t e;
        fw_frame est;
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_OK);
        est = pop();
        CHECK(rhonn_id_estimate_unpack(&e, est.data, est.len) == 0);
        CHECK(e.resync == 1 && e.seq == 5 && e.learning == 1);
        CHECK_FW(fw_measurement_decode(f.data, 20, &m), FW_OK);
        CHECK_STATUS(rhonn_step(&ref, m.x, m.u, m.valid, x_ref), RHONN_OK);
        take(net_of(&app), &a);
        take(&ref, &b);
        CHECK(same_snapshot(&a, &b));
    }
}

/* ---- a failing step ------------------------------------------------------------ */

static rhonn_config bad_cfg;

static void test_failed_step_sends_the_last_prediction_and_keeps_the_filter(void)
{
    uint8_t all_valid[N] = {1, 1, 1, 1, 1, 1};
    fw_app_config cfg;
    raw_sample s;
    meas_frame f;
    fw_frame est;
    struct rhonn_id_estimate_t e;
    rhonn_real xhat[N];
    fw_estimate want;
    uint8_t want_data[RHONN_ID_ESTIMATE_LENGTH];
    size_t i, p;
    const rhonn_real big = (rhonn_real)(sizeof(rhonn_real) == 4 ? 3e38 : 1.7e308);
    uint8_t status;

    /* P(0) and Q near the largest finite value: the second step (the first
     * that learns) overflows the innovation or the covariance update. */
    bad_cfg = LIM_IDENTIFIER;
    for (i = 0; i < N; ++i) {
        size_t L = bad_cfg.neurons[i].n_terms;
        for (p = 0; p < L * (L + 1) / 2; ++p) {
            bad_cfg.neurons[i].p0[p] = 0;
        }
        for (p = 0; p < L; ++p) {
            /* diagonal entry (p, p) of the packed upper triangle */
            bad_cfg.neurons[i].p0[p * L - p * (p - 1) / 2] = big;
            bad_cfg.neurons[i].q[p] = big;
        }
    }
    CHECK_FW(fw_mem_hal_init(&mem, &hal), FW_OK);
    cfg.identifier = &bad_cfg;
    cfg.deadline_ns = 0;
    cfg.diag_period = 0;
    CHECK_FW(fw_app_init(&app, &cfg, &hal), FW_OK);
    walk_reset();
    s = walk_next();
    f = pack_measurement(0, &s, all_valid);
    CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_OK);
    drain();
    CHECK_STATUS(rhonn_get_prediction(net_of(&app), xhat, N), RHONN_OK);
    take(net_of(&app), &snap_before);
    s = walk_next();
    f = pack_measurement(1, &s, all_valid);
    CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_E_STEP);
    {
        snapshot after; /* (rhonn_t's fault_neuron diagnostic does change) */
        take(net_of(&app), &after);
        CHECK(same_snapshot(&after, &snap_before));
    }
    est = pop();
    CHECK(rhonn_id_estimate_unpack(&e, est.data, est.len) == 0);
    status = e.step_status;
    CHECK((status == RHONN_E_INNOVATION || status == RHONN_E_COVARIANCE || status == RHONN_E_DIVERGED ||
           status == RHONN_E_NOT_PD) && e.seq == 1);
    want.seq = 1;
    want.step_status = status;
    want.learning = 1;
    want.resync = 0;
    memcpy(want.xhat, xhat, sizeof xhat);
    CHECK_FW(fw_estimate_encode(&want, want_data, sizeof want_data, NULL), FW_OK);
    CHECK(memcmp(est.data, want_data, sizeof want_data) == 0);
    {
        fw_counters c = counters();
        CHECK(c.step_errors == 1u && c.measurements == 2u && c.rejected == 0u);
        CHECK(c.last_step_status == status);
    }
    /* the counter advanced: the same Seq again is a repeat */
    CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_E_SEQ_REPEAT);
}

/* ---- diagnostics, timing, HAL -------------------------------------------------- */

static void test_diagnostics_report_counters_and_timing(void)
{
    uint8_t all_valid[N] = {1, 1, 1, 1, 1, 1};
    uint32_t k;
    struct rhonn_id_diagnostics_t d;
    fw_frame f;

    setup(10, 4000);
    walk_reset();
    mem.tick_ns = 5000; /* every step takes 5 us on the fake clock: an overrun at 4 us */
    for (k = 0; k < 25; ++k) {
        raw_sample s = walk_next();
        meas_frame m = pack_measurement((uint16_t)(1000u + k), &s, all_valid);
        mem.now_ns = (uint64_t)k * 300000u;
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, m.data, 20, (uint64_t)k * 300000u), FW_OK);
        if (k == 12) {
            CHECK_FW(fw_app_on_frame(&app, 0x42u, m.data, 20, 0), FW_E_UNKNOWN_ID);
            CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, m.data, 20, 0), FW_E_SEQ_REPEAT);
        }
        CHECK(pop().id == RHONN_ID_ESTIMATE_FRAME_ID);
        if (k == 9 || k == 19) {
            f = pop();
            CHECK(f.id == RHONN_ID_DIAGNOSTICS_FRAME_ID && f.len == RHONN_ID_DIAGNOSTICS_LENGTH);
            CHECK(rhonn_id_diagnostics_unpack(&d, f.data, f.len) == 0);
            CHECK(d.counter == (k == 9 ? 0 : 1));
            CHECK(d.last_seq == 1000u + k && d.measurements == k + 1u);
            CHECK(d.cycle_time == 30000u && d.step_time == 500u && d.step_time_max == 500u);
            CHECK(d.overruns == k + 1u);
            CHECK(d.rejected == (k == 9 ? 0u : 2u) && d.seq_errors == (k == 9 ? 0u : 1u));
            CHECK(d.last_reject == (k == 9 ? 0u : (uint8_t)FW_E_SEQ_REPEAT));
            CHECK(d.learning == 1 && d.started == 1 && d.synced == 1 && d.weights_open == 0);
            CHECK(d.step_errors == 0 && d.step_status == 0);
            CHECK(d.lost_frames == 0u && d.rx_drops == (k == 9 ? 0u : 7u));
            pop_health();
        }
        if (k == 15) {
            CHECK_FW(fw_app_note_rx_drops(&app, 7u), FW_OK);
        }
        CHECK(outbox_count() == 0u);
    }
    CHECK_FW(fw_app_note_overrun(&app), FW_OK);
    CHECK(counters().overruns == 26u);
    CHECK(counters().step_time_worst_ns == 5000u);
}

static void test_hal_failures_and_poll(void)
{
    uint8_t all_valid[N] = {1, 1, 1, 1, 1, 1};
    raw_sample s;
    meas_frame m;
    fw_frame f;
    uint32_t handled = 0, k;

    setup(0, 0);
    walk_reset();
    s = walk_next();
    m = pack_measurement(0, &s, all_valid);
    mem.fail_send = 1;
    CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, m.data, 20, 0), FW_E_HAL);
    mem.fail_send = 0;
    CHECK(counters().measurements == 1u && counters().hal_errors == 1u && counters().frames_out == 0u);
    mem.fail_clock = 1;
    m = pack_measurement(1, &s, all_valid);
    CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, m.data, 20, 0), FW_E_HAL);
    mem.fail_clock = 0;
    CHECK(counters().measurements == 2u && counters().hal_errors == 2u);
    drain();

    /* poll: frames from the HAL's inbox, good and bad */
    for (k = 2; k < 8; ++k) {
        m = pack_measurement((uint16_t)(k < 5 ? k : k - 1), &s, all_valid);
        memset(&f, 0, sizeof f);
        f.id = k == 5 ? 0x55u : RHONN_ID_MEASUREMENT_FRAME_ID; /* one foreign frame in between */
        f.len = 20;
        f.flags = FW_FRAME_FD | FW_FRAME_BRS;
        memcpy(f.data, m.data, 20);
        CHECK_FW(fw_mem_hal_push(&mem, &f), FW_OK);
    }
    CHECK_FW(fw_app_poll(&app, 4, &handled), FW_OK);
    CHECK(handled == 4u && outbox_count() == 3u);
    CHECK_FW(fw_app_poll(&app, 100, &handled), FW_OK);
    CHECK(handled == 2u && outbox_count() == 5u);
    CHECK_FW(fw_app_poll(&app, 100, &handled), FW_OK);
    CHECK(handled == 0u);
    CHECK(counters().rejected_unknown_id == 1u && counters().measurements == 7u);
}

/* ---- quantiser, init, API guards ------------------------------------------------ */

static void test_quantiser_rounds_half_to_even_and_saturates(void)
{
    int32_t r = 99;
    uint8_t sat = 9;
    static const double in[] = {2.5, 3.5, -2.5, -3.5, 0.5, -0.5, 1.5, 0.49999999999999994, -0.0, 2.4999999,
                                99.5, 100.4, 100.6};
    static const int32_t out[] = {2, 4, -2, -4, 0, 0, 2, 0, 0, 2, 100, 100, 100};
    static const uint8_t sats[] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
    size_t i;

    for (i = 0; i < sizeof in / sizeof in[0]; ++i) {
        CHECK_FW(fw_quantise(in[i], 1.0, -100, 100, &r, &sat), FW_OK);
        CHECK(r == out[i] && sat == sats[i]);
    }
    CHECK_FW(fw_quantise(-100.5, 1.0, -100, 100, &r, &sat), FW_OK);
    CHECK(r == -100 && sat == 0); /* ties to even: -100 */
    CHECK_FW(fw_quantise(-101.5, 1.0, -100, 100, &r, &sat), FW_OK);
    CHECK(r == -100 && sat == 1);
    CHECK_FW(fw_quantise((double)NAN, 1.0, -100, 100, &r, &sat), FW_OK);
    CHECK(r == 0 && sat == 1);
    CHECK_FW(fw_quantise((double)INFINITY, 1.0, -100, 100, &r, &sat), FW_OK);
    CHECK(r == 100 && sat == 1);
    CHECK_FW(fw_quantise(-(double)INFINITY, 1.0, -100, 100, &r, &sat), FW_OK);
    CHECK(r == -100 && sat == 1);
    CHECK_FW(fw_quantise(1e300, 1e-6, -8000000, 8000000, &r, &sat), FW_OK);
    CHECK(r == 8000000 && sat == 1);
    CHECK_FW(fw_quantise(-1e300, 1e-300, -8000000, 8000000, &r, &sat), FW_OK);
    CHECK(r == -8000000 && sat == 1);
    CHECK_FW(fw_quantise(1.0, 0.0, -1, 1, &r, &sat), FW_E_RANGE);
    CHECK_FW(fw_quantise(1.0, (double)NAN, -1, 1, &r, &sat), FW_E_RANGE);
    CHECK_FW(fw_quantise(1.0, 1.0, 1, -1, &r, &sat), FW_E_RANGE);
    CHECK_FW(fw_quantise(1.0, 1.0, -1, 1, NULL, &sat), FW_E_NULL);
    {
        fw_estimate e;
        uint8_t data[RHONN_ID_ESTIMATE_LENGTH];
        struct rhonn_id_estimate_t f;
        memset(&e, 0, sizeof e);
        e.xhat[4] = (rhonn_real)-75.0; /* beyond -60 A */
        CHECK_FW(fw_estimate_encode(&e, data, sizeof data, &sat), FW_OK);
        CHECK(sat == 1);
        CHECK(rhonn_id_estimate_unpack(&f, data, sizeof data) == 0);
        CHECK(f.saturated == 1 && f.ia_hat == RHONN_ID_ESTIMATE_IA_HAT_RAW_MIN && f.ib_hat == 0);
        e.step_status = 16;
        CHECK_FW(fw_estimate_encode(&e, data, sizeof data, &sat), FW_E_RANGE);
        e.step_status = 0;
        CHECK_FW(fw_estimate_encode(&e, data, 15, &sat), FW_E_LENGTH);
    }
}

/* ---- scaling without double arithmetic (fw_protocol.h) ---------------------------- */

/* Every FW_QUANTISE_STRIDE-th float32 bit pattern is compared; 1 compares all
 * 2^32 of them for each signal (minutes, not a CTest run). */
#ifndef FW_QUANTISE_STRIDE
#define FW_QUANTISE_STRIDE 4099u
#endif

static float float_of_bits(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* One comparison: the float32 build's quantiser and cantools' double formula
 * (fw_quantise with the DBC's double scale) give the same status, raw value
 * and flag. Returns 1 when they differ (the first few are printed); one
 * CHECK per signal counts the differences, so that an exhaustive run does not
 * overflow the check counter. */
static long quantisers_differ(float x, uint32_t n, double scale, int32_t lo, int32_t hi)
{
    static int printed = 0;
    int32_t r32 = 0, r64 = 1;
    uint8_t s32 = 2, s64 = 3;
    const fw_status st32 = fw_quantise_f32(x, n, lo, hi, &r32, &s32);
    const fw_status st64 = fw_quantise((double)x, scale, lo, hi, &r64, &s64);

    if (st32 == FW_OK && st64 == FW_OK && r32 == r64 && s32 == s64) {
        return 0;
    }
    if (printed++ < 10) {
        fprintf(stderr, "quantise %.9g / %g: float32 %ld (sat %u), double %ld (sat %u)\n", (double)x, scale,
                (long)r32, (unsigned)s32, (long)r64, (unsigned)s64);
    }
    return 1;
}

static void test_float_quantiser_equals_the_double_one_for_every_float(void)
{
    static const struct {
        uint32_t n;
        double scale;
        int32_t lo, hi;
    } sig[] = {
        {RHONN_ID_ESTIMATE_QM_HAT_INV_SCALE, RHONN_ID_ESTIMATE_QM_HAT_SCALE, RHONN_ID_ESTIMATE_QM_HAT_RAW_MIN,
         RHONN_ID_ESTIMATE_QM_HAT_RAW_MAX},
        {RHONN_ID_ESTIMATE_V_HAT_INV_SCALE, RHONN_ID_ESTIMATE_V_HAT_SCALE, RHONN_ID_ESTIMATE_V_HAT_RAW_MIN,
         RHONN_ID_ESTIMATE_V_HAT_RAW_MAX},
        {RHONN_ID_ESTIMATE_LAMBDA_A_HAT_INV_SCALE, RHONN_ID_ESTIMATE_LAMBDA_A_HAT_SCALE,
         RHONN_ID_ESTIMATE_LAMBDA_A_HAT_RAW_MIN, RHONN_ID_ESTIMATE_LAMBDA_A_HAT_RAW_MAX},
        {RHONN_ID_ESTIMATE_IA_HAT_INV_SCALE, RHONN_ID_ESTIMATE_IA_HAT_SCALE, RHONN_ID_ESTIMATE_IA_HAT_RAW_MIN,
         RHONN_ID_ESTIMATE_IA_HAT_RAW_MAX},
        /* the whole int32 range: products far past 2^23, where the float fast path
         * must hand over to the exact one */
        {RHONN_ID_ESTIMATE_QM_HAT_INV_SCALE, RHONN_ID_ESTIMATE_QM_HAT_SCALE, -2147483647 - 1, 2147483647},
    };
    size_t i;

    for (i = 0; i < sizeof sig / sizeof sig[0]; ++i) {
        const uint32_t n = sig[i].n;
        const double s = sig[i].scale;
        const int32_t lo = sig[i].lo, hi = sig[i].hi;
        uint64_t bits;
        uint32_t pow2 = 1u, j, ties = 0u;
        long differ = 0;
        /* a float32 step through the whole bit space: both signs, subnormals, inf, NaN */
        for (bits = 0; bits <= 0xFFFFFFFFu; bits += FW_QUANTISE_STRIDE) {
            differ += quantisers_differ(float_of_bits((uint32_t)bits), n, s, lo, hi);
        }
        /* every exact tie x * N = k + 1/2 within the range and a little past it, and the
         * floats next to it: N = 2^a * odd, so the ties are the odd multiples of 2^-(a+1) */
        while (n % (2u * pow2) == 0u) {
            pow2 *= 2u;
        }
        for (j = 1u; (double)j / (2.0 * pow2) <= (double)hi * s * 1.01; j += 2u) {
            const float x = (float)((double)j / (2.0 * pow2));
            differ += quantisers_differ(x, n, s, lo, hi) + quantisers_differ(-x, n, s, lo, hi)
                + quantisers_differ(nextafterf(x, 0.0f), n, s, lo, hi)
                + quantisers_differ(nextafterf(x, 1e30f), n, s, lo, hi)
                + quantisers_differ(-nextafterf(x, 0.0f), n, s, lo, hi);
            ++ties;
        }
        CHECK(ties >= 40u); /* 48 for 0.1 mm/s per LSB, the fewest */
        CHECK(differ == 0);
    }
}

static void test_float_quantiser_rounds_half_to_even_and_saturates(void)
{
    int32_t r = 99;
    uint8_t sat = 9;
    static const float in[] = {2.5f, 3.5f, -2.5f, -3.5f, 0.5f, -0.5f, 1.5f, 0.49999997f, -0.0f, 2.4999998f,
                               99.5f, 100.49999f, 100.5f, -100.5f, 1e-45f, 8388607.5f};
    static const int32_t out[] = {2, 4, -2, -4, 0, 0, 2, 0, 0, 2, 100, 100, 100, -100, 0, 100};
    static const uint8_t sats[] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
    size_t i;

    for (i = 0; i < sizeof in / sizeof in[0]; ++i) {
        CHECK_FW(fw_quantise_f32(in[i], 1u, -100, 100, &r, &sat), FW_OK);
        CHECK(r == out[i] && sat == sats[i]);
    }
    /* 1 um per LSB: 0.5 um ties to 0, 1.5 um to 2, 2^-7 m = 7812.5 um to 7812 */
    CHECK_FW(fw_quantise_f32(0x1p-7f, 1000000u, -8000000, 8000000, &r, &sat), FW_OK);
    CHECK(r == 7812 && sat == 0);
    CHECK_FW(fw_quantise_f32(3.0f * 0x1p-7f, 1000000u, -8000000, 8000000, &r, &sat), FW_OK);
    CHECK(r == 23438 && sat == 0); /* 23437.5: to even */
    CHECK_FW(fw_quantise_f32(3.00004f, 10000u, -30000, 30000, &r, &sat), FW_OK);
    CHECK(r == 30000 && sat == 0); /* 30000.4 LSB rounds onto the end, unflagged */
    CHECK_FW(fw_quantise_f32(3.00006f, 10000u, -30000, 30000, &r, &sat), FW_OK);
    CHECK(r == 30000 && sat == 1);
    CHECK_FW(fw_quantise_f32(8.000001f, 1000000u, -8000000, 8000000, &r, &sat), FW_OK);
    CHECK(r == 8000000 && sat == 1);
    CHECK_FW(fw_quantise_f32(-3.4028235e38f, 1000000u, -8000000, 8000000, &r, &sat), FW_OK);
    CHECK(r == -8000000 && sat == 1);
    CHECK_FW(fw_quantise_f32(NAN, 500u, -30000, 30000, &r, &sat), FW_OK);
    CHECK(r == 0 && sat == 1);
    CHECK_FW(fw_quantise_f32(INFINITY, 500u, -30000, 30000, &r, &sat), FW_OK);
    CHECK(r == 30000 && sat == 1);
    CHECK_FW(fw_quantise_f32(-INFINITY, 500u, -30000, 30000, &r, &sat), FW_OK);
    CHECK(r == -30000 && sat == 1);
    CHECK_FW(fw_quantise_f32(1.0f, 0u, -1, 1, &r, &sat), FW_E_RANGE);
    CHECK_FW(fw_quantise_f32(1.0f, FW_INV_SCALE_MAX + 1u, -1, 1, &r, &sat), FW_E_RANGE);
    CHECK_FW(fw_quantise_f32(1.0f, 1u, 1, -1, &r, &sat), FW_E_RANGE);
    CHECK_FW(fw_quantise_f32(1.0f, 1u, -1, 1, NULL, &sat), FW_E_NULL);
    CHECK_FW(fw_quantise_f32(2.5f, 1u, -100, 100, &r, NULL), FW_OK);
    CHECK(r == 2);
}

/* The float32 decode, (float)raw / (float)N, is the float nearest the double
 * raw * scale for every raw value of every scaled Measurement field; and
 * fw_measurement_decode returns it for states (flagged not valid, so not
 * range-checked) and inputs alike. */
static void test_float_decode_equals_the_double_one_for_every_raw_value(void)
{
    struct rhonn_id_measurement_t f;
    uint8_t data[RHONN_ID_MEASUREMENT_LENGTH];
    fw_measurement m;
    int32_t raw;
    long bad = 0;

    for (raw = -(1 << 23); raw < (1 << 23); ++raw) {
        if ((float)raw / (float)RHONN_ID_MEASUREMENT_QM_INV_SCALE != (float)((double)raw * RHONN_ID_MEASUREMENT_QM_SCALE)) {
            ++bad;
        }
        if (raw >= -32768 && raw < 32768) {
            bad += (float)raw / (float)RHONN_ID_MEASUREMENT_V_INV_SCALE != (float)((double)raw * RHONN_ID_MEASUREMENT_V_SCALE);
            bad += (float)raw / (float)RHONN_ID_MEASUREMENT_IA_INV_SCALE != (float)((double)raw * RHONN_ID_MEASUREMENT_IA_SCALE);
            bad += (float)raw / (float)RHONN_ID_MEASUREMENT_UA_INV_SCALE != (float)((double)raw * RHONN_ID_MEASUREMENT_UA_SCALE);
        }
    }
    CHECK(bad == 0);
    (void)rhonn_id_measurement_init(&f);
    for (raw = -(1 << 23); raw < (1 << 23); raw += 61) {
        const int16_t r16 = (int16_t)(raw % 32768);
        f.qm = raw;
        f.v = f.lambda_a = f.lambda_b = f.ia = f.ib = r16;
        f.ua = f.ub = (int16_t)(raw % 32001);
        CHECK(rhonn_id_measurement_pack(data, &f, sizeof data) == (int)sizeof data);
        CHECK_FW(fw_measurement_decode(data, sizeof data, &m), FW_OK);
        bad += m.x[0] != (rhonn_real)rhonn_id_measurement_qm_decode(f.qm);
        bad += m.x[1] != (rhonn_real)rhonn_id_measurement_v_decode(f.v);
        bad += m.x[2] != (rhonn_real)rhonn_id_measurement_lambda_a_decode(f.lambda_a);
        bad += m.x[3] != (rhonn_real)rhonn_id_measurement_lambda_b_decode(f.lambda_b);
        bad += m.x[4] != (rhonn_real)rhonn_id_measurement_ia_decode(f.ia);
        bad += m.x[5] != (rhonn_real)rhonn_id_measurement_ib_decode(f.ib);
        bad += m.u[0] != (rhonn_real)rhonn_id_measurement_ua_decode(f.ua);
        bad += m.u[1] != (rhonn_real)rhonn_id_measurement_ub_decode(f.ub);
    }
    CHECK(bad == 0);
}

static fw_app other;

static void test_init_and_api_guards(void)
{
    fw_app_config cfg;
    fw_hal h;
    fw_mem_hal mh;
    static rhonn_config small;
    const rhonn_t *net;
    fw_counters c;

    CHECK_FW(fw_mem_hal_init(&mh, &h), FW_OK);
    cfg.identifier = &LIM_IDENTIFIER;
    cfg.deadline_ns = 0;
    cfg.diag_period = 0;
    memset(&other, 0xA5, sizeof other);
    {
        static fw_app copy;
        memcpy(&copy, &other, sizeof other);
        CHECK_FW(fw_app_init(NULL, &cfg, &h), FW_E_NULL);
        CHECK_FW(fw_app_init(&other, NULL, &h), FW_E_NULL);
        CHECK_FW(fw_app_init(&other, &cfg, NULL), FW_E_NULL);
        small = LIM_IDENTIFIER;
        small.n_states = 4;
        cfg.identifier = &small;
        CHECK_FW(fw_app_init(&other, &cfg, &h), FW_E_CONFIG);
        small = LIM_IDENTIFIER;
        small.n_inputs = 1;
        CHECK_FW(fw_app_init(&other, &cfg, &h), FW_E_CONFIG);
        small = LIM_IDENTIFIER;
        small.neurons[3].beta = 0; /* the core refuses it */
        CHECK_FW(fw_app_init(&other, &cfg, &h), FW_E_CONFIG);
        cfg.identifier = &LIM_IDENTIFIER;
        h.send = NULL;
        CHECK_FW(fw_app_init(&other, &cfg, &h), FW_E_CONFIG);
        CHECK(memcmp(&copy, &other, sizeof other) == 0); /* untouched by every refusal */
    }
    memset(&other, 0, sizeof other);
    CHECK_FW(fw_app_on_frame(&other, RHONN_ID_MEASUREMENT_FRAME_ID, NULL, 0, 0), FW_E_NOT_INIT);
    CHECK_FW(fw_app_poll(&other, 1, NULL), FW_E_NOT_INIT);
    CHECK_FW(fw_app_send_diagnostics(&other), FW_E_NOT_INIT);
    CHECK_FW(fw_app_note_rx_drops(&other, 1u), FW_E_NOT_INIT);
    CHECK_FW(fw_app_note_rx_drops(NULL, 1u), FW_E_NULL);
    CHECK_FW(fw_app_note_overrun(&other), FW_E_NOT_INIT);
    CHECK_FW(fw_app_get_counters(&other, &c), FW_E_NOT_INIT);
    CHECK_FW(fw_app_get_identifier(&other, &net), FW_E_NOT_INIT);
    CHECK_FW(fw_app_on_frame(NULL, 0, NULL, 0, 0), FW_E_NULL);
    setup(0, 0);
    CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, NULL, 20, 0), FW_E_NULL);
    CHECK(counters().frames_in == 0u);
    CHECK_FW(fw_app_get_counters(&app, NULL), FW_E_NULL);
    CHECK_FW(fw_app_get_identifier(&app, NULL), FW_E_NULL);
    hal.receive = NULL;
    app.hal.receive = NULL;
    CHECK_FW(fw_app_poll(&app, 1, NULL), FW_E_CONFIG);
    CHECK(strcmp(fw_status_name(FW_E_SEQ_JUMP), "FW_E_SEQ_JUMP") == 0);
    CHECK(strcmp(fw_status_name((fw_status)99), "FW_E_UNKNOWN_STATUS") == 0);
}

/* ---- command authentication ------------------------------------------------- */

#if FW_SECOC
/* A Control frame secured with an explicit freshness value and DataId. */
static void control_frame(uint8_t *data, uint8_t command, uint8_t token, uint16_t data_id, uint64_t fv)
{
    struct rhonn_id_control_t f;
    (void)rhonn_id_control_init(&f);
    f.command = command;
    f.token = token;
    CHECK(rhonn_id_control_pack(data, &f, RHONN_ID_CONTROL_LENGTH) == (int)RHONN_ID_CONTROL_LENGTH);
    CHECK_FW(fw_secoc_protect(&tx_key, data_id, data, RHONN_ID_CONTROL_LENGTH, fv), FW_OK);
}

static void expect_refused(const char *what, fw_status got, fw_status want, const rhonn_t *net_ref,
                           uint64_t fv_ref)
{
    uint64_t fv = 0;
    CHECK_FW(got, want);
    CHECK(memcmp(net_of(&app), net_ref, sizeof *net_ref) == 0);
    CHECK_FW(fw_app_get_freshness(&app, &fv), FW_OK);
    CHECK(fv == fv_ref);
    CHECK(outbox_count() == 0u); /* not answered */
    CHECK(counters().last_reject == (uint8_t)want);
    if (got != want || memcmp(net_of(&app), net_ref, sizeof *net_ref) != 0) {
        fprintf(stderr, "  ... %s\n", what);
    }
}

static void test_forged_replayed_stale_and_short_commands_are_rejected_untouched(void)
{
    uint8_t c[RHONN_ID_CONTROL_LENGTH], replay[RHONN_ID_CONTROL_LENGTH], w[RHONN_ID_WEIGHT_LOAD_LENGTH];
    uint8_t all_valid[N] = {1, 1, 1, 1, 1, 1};
    float ones[FW_WEIGHTS_PER_FRAME];
    uint16_t seq;
    uint64_t fv;
    fw_counters cnt;
    unsigned k;

    setup(0, 0);
    walk_reset();
    for (seq = 0; seq < 20u; ++seq) {
        raw_sample smp = walk_next();
        meas_frame f = pack_measurement(seq, &smp, all_valid);
        CHECK_FW(fw_app_on_frame(&app, RHONN_ID_MEASUREMENT_FRAME_ID, f.data, 20, 0), FW_OK);
        drain();
    }
    memcpy(&net_before, net_of(&app), sizeof net_before);

    /* forged: one MAC bit flipped; a frame with no MAC at all; a Control
     * signed as a WeightLoad; a WeightLoad with a flipped payload bit */
    control_frame(c, RHONN_ID_CONTROL_COMMAND_RESET_CHOICE, 1, RHONN_ID_CONTROL_FRAME_ID, 1);
    c[RHONN_ID_CONTROL_LENGTH - 1u] ^= 0x80u;
    expect_refused("flipped MAC", fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, 0), FW_E_AUTH,
                   &net_before, 0);
    memset(c, 0, sizeof c);
    c[0] = RHONN_ID_CONTROL_COMMAND_LEARNING_OFF_CHOICE;
    c[4] = 1; /* freshness 1, MAC 0 */
    expect_refused("no MAC", fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, 0), FW_E_AUTH,
                   &net_before, 0);
    control_frame(c, RHONN_ID_CONTROL_COMMAND_RESET_CHOICE, 1, RHONN_ID_WEIGHT_LOAD_FRAME_ID, 1);
    expect_refused("other DataId", fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, 0), FW_E_AUTH,
                   &net_before, 0);
    for (k = 0; k < FW_WEIGHTS_PER_FRAME; ++k) {
        ones[k] = 1.0f;
    }
    pack_weights(w, 0, 0, 2, ones);
    CHECK_FW(fw_secoc_protect(&tx_key, RHONN_ID_WEIGHT_LOAD_FRAME_ID, w, sizeof w, 1), FW_OK);
    w[4] ^= 0x01u;
    expect_refused("weights forged", fw_app_on_frame(&app, RHONN_ID_WEIGHT_LOAD_FRAME_ID, w, sizeof w, 0),
                   FW_E_AUTH, &net_before, 0);
    /* wrong length: a secured 15-byte Control, a 63-byte WeightLoad */
    control_frame(c, RHONN_ID_CONTROL_COMMAND_RESET_CHOICE, 1, RHONN_ID_CONTROL_FRAME_ID, 1);
    CHECK_FW(fw_secoc_protect(&tx_key, RHONN_ID_CONTROL_FRAME_ID, c, 15, 1), FW_OK);
    expect_refused("short control", fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, c, 15, 0), FW_E_LENGTH,
                   &net_before, 0);
    expect_refused("short weights", fw_app_on_frame(&app, RHONN_ID_WEIGHT_LOAD_FRAME_ID, w, 63, 0), FW_E_LENGTH,
                   &net_before, 0);
    /* too far ahead: beyond the acceptance window, with a valid MAC */
    control_frame(c, RHONN_ID_CONTROL_COMMAND_RESET_CHOICE, 1, RHONN_ID_CONTROL_FRAME_ID,
                  (uint64_t)FW_SECOC_ACCEPTANCE_WINDOW + 1u);
    expect_refused("too far ahead", fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, 0),
                   FW_E_FRESHNESS, &net_before, 0);
    cnt = counters();
    CHECK(cnt.rejected_auth == 4u && cnt.rejected_freshness == 1u && cnt.rejected_length == 2u);
    CHECK(cnt.commands == 0u && cnt.weight_chunks == 0u);

    /* an authenticated command works: LearningOff, answered */
    tx_fv = 4;
    control_frame(c, RHONN_ID_CONTROL_COMMAND_LEARNING_OFF_CHOICE, 7, RHONN_ID_CONTROL_FRAME_ID, ++tx_fv);
    memcpy(replay, c, sizeof c);
    CHECK_FW(fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, 0), FW_OK);
    {
        struct rhonn_id_control_ack_t a = pop_ack();
        CHECK(a.result == 0 && a.token == 7 && a.command == RHONN_ID_CONTROL_COMMAND_LEARNING_OFF_CHOICE);
    }
    CHECK_FW(fw_app_get_freshness(&app, &fv), FW_OK);
    CHECK(fv == 5u && counters().commands == 1u);
    memcpy(&net_before, net_of(&app), sizeof net_before);

    /* replayed: the same frame again; stale: an older freshness value */
    expect_refused("replay", fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, replay, sizeof replay, 0),
                   FW_E_FRESHNESS, &net_before, 5);
    control_frame(c, RHONN_ID_CONTROL_COMMAND_RESET_CHOICE, 8, RHONN_ID_CONTROL_FRAME_ID, 3);
    expect_refused("stale", fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, 0), FW_E_FRESHNESS,
                   &net_before, 5);
    cnt = counters();
    CHECK(cnt.rejected_freshness == 3u && cnt.rejected_auth == 4u && cnt.commands == 1u);

    /* Reset, authenticated, works and keeps the freshness value: the
     * LearningOff frame stays a replay after it */
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_RESET_CHOICE, 9), FW_OK);
    CHECK(pop_ack().result == 0);
    CHECK_FW(fw_app_get_freshness(&app, &fv), FW_OK);
    CHECK(fv == 6u);
    memcpy(&net_before, net_of(&app), sizeof net_before);
    expect_refused("replay after reset", fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, replay, sizeof replay, 0),
                   FW_E_FRESHNESS, &net_before, 6);
    /* a persisted value can be restored, never lowered */
    CHECK_FW(fw_app_set_freshness(&app, 5), FW_E_FRESHNESS);
    CHECK_FW(fw_app_set_freshness(&app, 1000), FW_OK);
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_DIAG_REQUEST_CHOICE, 10), FW_E_FRESHNESS); /* tx at 7 */
    tx_fv = 1000;
    CHECK_FW(send_control(RHONN_ID_CONTROL_COMMAND_DIAG_REQUEST_CHOICE, 11), FW_OK);
    drain();
    CHECK_FW(fw_app_get_freshness(NULL, &fv), FW_E_NULL);
    CHECK_FW(fw_app_set_freshness(NULL, 1), FW_E_NULL);
    CHECK(strcmp(fw_status_name(FW_E_AUTH), "FW_E_AUTH") == 0);
    CHECK(strcmp(fw_status_name(FW_E_FRESHNESS), "FW_E_FRESHNESS") == 0);
}
#endif

int main(void)
{
    printf("rhonn_real is %s, sizeof(fw_app) = %u bytes\n", sizeof(rhonn_real) == 4 ? "float" : "double",
           (unsigned)sizeof(fw_app));
    RUN(test_valid_stream_gives_rhonn_run_predictions);
    RUN(test_rejections_leave_the_filter_bit_for_bit_unchanged);
    RUN(test_weight_transfer_replaces_all_weights_at_commit);
    RUN(test_learning_off_freezes_weights_and_reset_restarts);
    RUN(test_failed_step_sends_the_last_prediction_and_keeps_the_filter);
    RUN(test_diagnostics_report_counters_and_timing);
    RUN(test_hal_failures_and_poll);
    RUN(test_quantiser_rounds_half_to_even_and_saturates);
    RUN(test_float_quantiser_rounds_half_to_even_and_saturates);
    RUN(test_float_quantiser_equals_the_double_one_for_every_float);
    RUN(test_float_decode_equals_the_double_one_for_every_raw_value);
    RUN(test_init_and_api_guards);
#if FW_SECOC
    RUN(test_forged_replayed_stale_and_short_commands_are_rejected_untouched);
#endif
    return CHECK_SUMMARY();
}
