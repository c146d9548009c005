/*
 * fw_app.c - the RHONN identifier as a CAN FD application. See fw_app.h.
 */
#include "fw_app.h"

#include <string.h>

#include "fw_secoc_key.h"
#include "rhonn_id.h"
#include "rhonn_id_limits.h"

#define FW_APP_MAGIC 0x46574150u /* "FWAP" */

/* The status numbers travel in ControlAck.Result and Diagnostics.LastReject:
 * they must be the DBC's. A mismatch does not compile. */
#define FW_STATIC_ASSERT(name, cond) typedef char fw_static_assert_##name[(cond) ? 1 : -1]
FW_STATIC_ASSERT(ok, FW_OK == RHONN_ID_CONTROL_ACK_RESULT_OK_CHOICE);
FW_STATIC_ASSERT(null, FW_E_NULL == RHONN_ID_CONTROL_ACK_RESULT_NULL_CHOICE);
FW_STATIC_ASSERT(not_init, FW_E_NOT_INIT == RHONN_ID_CONTROL_ACK_RESULT_NOT_INIT_CHOICE);
FW_STATIC_ASSERT(config, FW_E_CONFIG == RHONN_ID_CONTROL_ACK_RESULT_CONFIG_CHOICE);
FW_STATIC_ASSERT(unknown_id, FW_E_UNKNOWN_ID == RHONN_ID_CONTROL_ACK_RESULT_UNKNOWN_ID_CHOICE);
FW_STATIC_ASSERT(length, FW_E_LENGTH == RHONN_ID_CONTROL_ACK_RESULT_LENGTH_CHOICE);
FW_STATIC_ASSERT(range, FW_E_RANGE == RHONN_ID_CONTROL_ACK_RESULT_RANGE_CHOICE);
FW_STATIC_ASSERT(seq_repeat, FW_E_SEQ_REPEAT == RHONN_ID_CONTROL_ACK_RESULT_SEQ_REPEAT_CHOICE);
FW_STATIC_ASSERT(seq_jump, FW_E_SEQ_JUMP == RHONN_ID_CONTROL_ACK_RESULT_SEQ_JUMP_CHOICE);
FW_STATIC_ASSERT(state, FW_E_STATE == RHONN_ID_CONTROL_ACK_RESULT_STATE_CHOICE);
FW_STATIC_ASSERT(weights, FW_E_WEIGHTS == RHONN_ID_CONTROL_ACK_RESULT_WEIGHTS_CHOICE);
FW_STATIC_ASSERT(step, FW_E_STEP == RHONN_ID_CONTROL_ACK_RESULT_STEP_CHOICE);
FW_STATIC_ASSERT(hal, FW_E_HAL == RHONN_ID_CONTROL_ACK_RESULT_HAL_CHOICE);
FW_STATIC_ASSERT(empty, FW_E_EMPTY == RHONN_ID_CONTROL_ACK_RESULT_EMPTY_CHOICE);
FW_STATIC_ASSERT(auth, FW_E_AUTH == RHONN_ID_CONTROL_ACK_RESULT_AUTH_CHOICE);
FW_STATIC_ASSERT(freshness, FW_E_FRESHNESS == RHONN_ID_CONTROL_ACK_RESULT_FRESHNESS_CHOICE);
/* The SecOC trailer closes Control and WeightLoad (fw_secoc.h), and
 * WeightLoad's Count range is the number of weights a frame has room for. */
FW_STATIC_ASSERT(control_trailer, RHONN_ID_CONTROL_LENGTH == 4u + FW_SECOC_TRAILER_BYTES);
FW_STATIC_ASSERT(weights_trailer,
                 RHONN_ID_WEIGHT_LOAD_LENGTH == 4u + 4u * FW_WEIGHTS_PER_FRAME + FW_SECOC_TRAILER_BYTES);
FW_STATIC_ASSERT(diag_table_auth,
                 RHONN_ID_DIAGNOSTICS_LAST_REJECT_FRESHNESS_CHOICE == RHONN_ID_CONTROL_ACK_RESULT_FRESHNESS_CHOICE);
FW_STATIC_ASSERT(diag_table,
                 RHONN_ID_DIAGNOSTICS_LAST_REJECT_EMPTY_CHOICE == RHONN_ID_CONTROL_ACK_RESULT_EMPTY_CHOICE);
/* Estimate.StepStatus carries rhonn_status in 4 bits. */
FW_STATIC_ASSERT(step_status, RHONN_E_VALUE == RHONN_ID_ESTIMATE_STEP_STATUS_VALUE_CHOICE && RHONN_E_VALUE <= 15);
FW_STATIC_ASSERT(step_status_not_pd, RHONN_E_NOT_PD == RHONN_ID_ESTIMATE_STEP_STATUS_NOT_PD_CHOICE &&
                                         RHONN_E_NOT_PD == RHONN_ID_DIAGNOSTICS_STEP_STATUS_NOT_PD_CHOICE &&
                                         RHONN_E_NOT_PD <= 15);
/* One Health frame per neuron, indexed by Health.Neuron. */
FW_STATIC_ASSERT(health_neurons, FW_N_STATES - 1u == RHONN_ID_HEALTH_NEURON_RAW_MAX);
FW_STATIC_ASSERT(frame_sizes,
                 RHONN_ID_WEIGHT_LOAD_LENGTH <= FW_MAX_FRAME_LEN && RHONN_ID_MEASUREMENT_LENGTH <= FW_MAX_FRAME_LEN);
FW_STATIC_ASSERT(missing_fits, RHONN_MAX_STATES * RHONN_MAX_TERMS <= 65535);

static int app_ready(const fw_app *app)
{
    return app->magic == FW_APP_MAGIC;
}

static uint32_t clamp_u32(uint64_t v)
{
    return v > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)v;
}

/* ns -> the Diagnostics' 10 ns unit, saturating at 655.35 us. */
static uint16_t to_10ns(uint32_t ns)
{
    uint32_t v = ns / 10u;
    return v > 0xFFFFu ? (uint16_t)0xFFFFu : (uint16_t)v;
}

/* StepTimeMax: 10 ns per LSB, saturated at the top of its 24-bit range (the DBC's
 * 167772.15 us), which the rig reads as "at least", not as a measurement. */
static uint32_t step_time_max_raw(uint32_t ns)
{
    uint32_t v = ns / 10u;
    return v > RHONN_ID_DIAGNOSTICS_STEP_TIME_MAX_RAW_MAX ? RHONN_ID_DIAGNOSTICS_STEP_TIME_MAX_RAW_MAX : v;
}

static fw_status reject(fw_app *app, fw_status why)
{
    fw_counters *c = &app->counters;

    ++c->rejected;
    c->last_reject = (uint8_t)why;
    switch (why) {
    case FW_E_UNKNOWN_ID: ++c->rejected_unknown_id; break;
    case FW_E_LENGTH: ++c->rejected_length; break;
    case FW_E_RANGE: ++c->rejected_range; break;
    case FW_E_SEQ_REPEAT: ++c->rejected_seq_repeat; break;
    case FW_E_SEQ_JUMP: ++c->rejected_seq_jump; break;
    case FW_E_STATE: ++c->rejected_state; break;
    case FW_E_WEIGHTS: ++c->rejected_weights; break;
    case FW_E_AUTH: ++c->rejected_auth; break;
    case FW_E_FRESHNESS: ++c->rejected_freshness; break;
    default: break;
    }
    return why;
}

/* A frame to send with len payload bytes (len <= FW_MAX_FRAME_LEN), the
 * payload past them zero; the caller writes the first len. */
static void frame_start(fw_frame *f, uint32_t id, uint8_t len)
{
    f->id = id;
    f->len = len;
    f->flags = (uint8_t)(FW_FRAME_FD | FW_FRAME_BRS);
    memset(f->data + len, 0, sizeof f->data - len);
}

static fw_status transmit(fw_app *app, const fw_frame *f)
{
    if (app->hal.send(app->hal.ctx, f) != FW_OK) {
        ++app->counters.hal_errors;
        return FW_E_HAL;
    }
    ++app->counters.frames_out;
    return FW_OK;
}

static fw_status send_frame(fw_app *app, uint32_t id, const uint8_t *data, uint8_t len)
{
    fw_frame f;

    frame_start(&f, id, len);
    memcpy(f.data, data, len);
    return transmit(app, &f);
}

static void close_weights(fw_app *app)
{
    app->weights_open = 0;
    app->weights_missing = 0;
    memset(app->w_stage, 0, sizeof app->w_stage);
    memset(app->w_have, 0, sizeof app->w_have);
}

static void open_weights(fw_app *app)
{
    uint16_t missing = 0;
    uint8_t i;

    close_weights(app);
    for (i = 0; i < app->n_states; ++i) {
        missing = (uint16_t)(missing + app->n_terms[i]);
    }
    app->weights_open = 1;
    app->weights_missing = missing;
}

/* Back to the configuration: w(0), P(0), x0, empty history, learning on,
 * sequence counter unanchored, open weight transfer dropped. */
static fw_status reset_identifier(fw_app *app)
{
    if (rhonn_reset(&app->net) != RHONN_OK) {
        return FW_E_STATE;
    }
    app->learning = 1;
    app->started = 0;
    app->anchored = 0;
    app->resync = 1;
    app->have_last_time = 0;
    close_weights(app);
    return FW_OK;
}

fw_status fw_app_init(fw_app *app, const fw_app_config *cfg, const fw_hal *hal)
{
    const rhonn_config *id;
    uint8_t i;

    if (app == NULL || cfg == NULL || hal == NULL || cfg->identifier == NULL) {
        return FW_E_NULL;
    }
    id = cfg->identifier;
    if (hal->send == NULL || hal->now == NULL) {
        return FW_E_CONFIG;
    }
    if (id->n_states != FW_N_STATES || id->n_inputs != FW_N_INPUTS) {
        return FW_E_CONFIG;
    }
    /* rhonn_init validates and leaves net untouched when it refuses. */
    if (rhonn_init(&app->net, id, NULL) != RHONN_OK) {
        return FW_E_CONFIG;
    }
    app->hal = *hal;
    app->deadline_ns = cfg->deadline_ns;
    app->diag_period = cfg->diag_period;
    app->since_diag = 0;
    app->n_states = id->n_states;
    memset(app->n_terms, 0, sizeof app->n_terms);
    for (i = 0; i < id->n_states; ++i) {
        app->n_terms[i] = id->neurons[i].n_terms;
    }
    memset(&app->counters, 0, sizeof app->counters);
    memset(&app->tx_estimate, 0, sizeof app->tx_estimate);
    frame_start(&app->tx_estimate, RHONN_ID_ESTIMATE_FRAME_ID, (uint8_t)RHONN_ID_ESTIMATE_LENGTH);
    app->last_seq = 0;
    app->diag_counter = 0;
    app->last_time_ns = 0;
    {
        static const uint8_t key[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
        (void)fw_cmac_init(&app->secoc_key, key);
    }
    app->secoc_freshness = 0;
    memset(&app->hooks, 0, sizeof app->hooks);
    app->magic = FW_APP_MAGIC;
    return reset_identifier(app);
}

static fw_status on_measurement(fw_app *app, const uint8_t *data, size_t len, uint64_t now_ns)
{
    fw_measurement m;
    fw_estimate e;
    rhonn_status rs;
    fw_status st;
    uint64_t t_end;
    fw_counters *c = &app->counters;

    st = fw_measurement_decode(data, len, &m);
    if (st != FW_OK) {
        return reject(app, st);
    }
    if (app->anchored) {
        /* d = Seq - last mod 65536: 1 continues, 0 repeats, 2..32768 skipped
         * d - 1 frames, above that the counter went back (see fw_app.h). */
        uint16_t d = (uint16_t)(m.seq - app->last_seq);
        if (d == 0u) {
            return reject(app, FW_E_SEQ_REPEAT);
        }
        if (d != 1u) {
            if (d <= 0x8000u) {
                c->lost_frames += (uint32_t)d - 1u;
                ++c->seq_gaps;
            }
            app->last_seq = m.seq; /* re-anchor: the next consecutive frame is accepted */
            app->resync = 1;
            return reject(app, FW_E_SEQ_JUMP);
        }
    }
    /* After a break, x_hat(k) was predicted for a sample that never came:
     * learning this one against it (eq. 9) would train on a wrong error.
     * Restart: this step learns nothing and refills the delayed taps. A
     * filter that never stepped since init/Reset is in that state already. */
    if (app->resync && app->started) {
        if (rhonn_restart(&app->net) != RHONN_OK) {
            return reject(app, FW_E_STATE); /* not reached: the app holds an initialised identifier */
        }
        ++c->restarts;
    }
    if (app->hooks.before_step != NULL) {
        app->hooks.before_step(app->hooks.ctx, app);
    }

    /* Accepted: exactly one step. */
    rs = rhonn_step(&app->net, m.x, m.u, m.valid, e.xhat);
    app->anchored = 1;
    app->last_seq = m.seq;
    ++c->measurements;
    c->last_step_status = (uint8_t)rs;
    if (rs == RHONN_OK) {
        app->started = 1;
    } else {
        /* The filter is unchanged; send the last good prediction x_hat(k). */
        ++c->step_errors;
        (void)rhonn_get_prediction(&app->net, e.xhat, FW_N_STATES);
    }
    e.seq = m.seq;
    e.step_status = (uint8_t)rs;
    e.learning = app->learning;
    e.resync = app->resync;
    app->resync = 0;
    /* encoded into the frame kept for it: no payload copy, and its header
     * and zero padding were set once, at init */
    st = fw_estimate_encode(&e, app->tx_estimate.data, RHONN_ID_ESTIMATE_LENGTH, NULL);
    if (st == FW_OK) {
        st = transmit(app, &app->tx_estimate);
    }

    if (app->have_last_time) {
        c->cycle_time_ns = now_ns >= app->last_time_ns ? clamp_u32(now_ns - app->last_time_ns) : 0u;
    }
    app->last_time_ns = now_ns;
    app->have_last_time = 1;
    if (app->hal.now(app->hal.ctx, &t_end) == FW_OK) {
        uint32_t step = t_end >= now_ns ? clamp_u32(t_end - now_ns) : 0u;
        c->step_time_ns = step;
        if (step > c->step_time_max_ns) {
            c->step_time_max_ns = step;
        }
        if (step > c->step_time_worst_ns) {
            c->step_time_worst_ns = step;
        }
        if (app->deadline_ns != 0u && step > app->deadline_ns) {
            ++c->overruns;
        }
    } else {
        ++c->hal_errors;
        st = FW_E_HAL;
    }
    if (app->hooks.after_step != NULL) {
        app->hooks.after_step(app->hooks.ctx, app, now_ns);
    }

    if (app->diag_period != 0u) {
        ++app->since_diag;
        if (app->since_diag >= app->diag_period && fw_app_send_diagnostics(app) != FW_OK) {
            st = FW_E_HAL;
        }
    }
    return rs != RHONN_OK ? FW_E_STEP : st;
}

static fw_status commit_weights(fw_app *app)
{
    rhonn_real saved[RHONN_MAX_STATES][RHONN_MAX_TERMS];
    uint8_t i, j;

    if (!app->weights_open) {
        return FW_E_STATE;
    }
    if (app->weights_missing != 0u) {
        return FW_E_WEIGHTS; /* stays open: the missing chunks may still come */
    }
    for (i = 0; i < app->n_states; ++i) {
        if (rhonn_get_weights(&app->net, i, saved[i], app->n_terms[i]) != RHONN_OK) {
            return FW_E_WEIGHTS;
        }
    }
    /* All or nothing: should the core refuse one neuron, put back the ones
     * already replaced. (Every staged value is finite, so it does not.) */
    for (i = 0; i < app->n_states; ++i) {
        if (rhonn_set_weights(&app->net, i, app->w_stage[i], app->n_terms[i]) != RHONN_OK) {
            for (j = 0; j < i; ++j) {
                (void)rhonn_set_weights(&app->net, j, saved[j], app->n_terms[j]);
            }
            return FW_E_WEIGHTS;
        }
    }
    close_weights(app);
    return FW_OK;
}

/* A secured command frame of the DBC length: verify its trailer against
 * the last accepted freshness value (fw_secoc.h), which moves only when the
 * MAC verifies. Nothing of the frame is interpreted before that. */
static fw_status authenticate(fw_app *app, uint16_t data_id, const uint8_t *data, size_t len)
{
#if FW_SECOC
    return fw_secoc_verify(&app->secoc_key, data_id, data, len, &app->secoc_freshness);
#else
    (void)app;
    (void)data_id;
    (void)data;
    (void)len;
    return FW_OK;
#endif
}

static fw_status on_control(fw_app *app, const uint8_t *data, size_t len)
{
    struct rhonn_id_control_t f;
    struct rhonn_id_control_ack_t a;
    uint8_t frame[RHONN_ID_CONTROL_ACK_LENGTH];
    fw_status result = FW_OK, sent;
    int diag = 0;

    if (len != RHONN_ID_CONTROL_LENGTH) {
        return reject(app, FW_E_LENGTH);
    }
    result = authenticate(app, (uint16_t)RHONN_ID_CONTROL_FRAME_ID, data, len);
    if (result != FW_OK) {
        return reject(app, result); /* not answered: a forger learns nothing */
    }
    if (rhonn_id_control_unpack(&f, data, len) != 0) {
        return reject(app, FW_E_LENGTH);
    }
    if (!rhonn_id_control_command_is_in_range(f.command)) {
        return reject(app, FW_E_RANGE);
    }
    switch (f.command) {
    case RHONN_ID_CONTROL_COMMAND_RESET_CHOICE:
        result = reset_identifier(app);
        break;
    case RHONN_ID_CONTROL_COMMAND_LEARNING_OFF_CHOICE:
    case RHONN_ID_CONTROL_COMMAND_LEARNING_ON_CHOICE:
        result = fw_app_set_learning(app, f.command == RHONN_ID_CONTROL_COMMAND_LEARNING_ON_CHOICE);
        break;
    case RHONN_ID_CONTROL_COMMAND_WEIGHTS_BEGIN_CHOICE:
        open_weights(app);
        break;
    case RHONN_ID_CONTROL_COMMAND_WEIGHTS_COMMIT_CHOICE:
        result = commit_weights(app);
        break;
    case RHONN_ID_CONTROL_COMMAND_WEIGHTS_ABORT_CHOICE:
        if (app->weights_open) {
            close_weights(app);
        } else {
            result = FW_E_STATE;
        }
        break;
    case RHONN_ID_CONTROL_COMMAND_DIAG_REQUEST_CHOICE:
        diag = 1;
        break;
    default:
        return reject(app, FW_E_RANGE); /* not reached: the range check above */
    }

    (void)rhonn_id_control_ack_init(&a);
    a.command = f.command;
    a.token = f.token;
    a.result = (uint8_t)result;
    a.missing = app->weights_open ? app->weights_missing : 0u;
    if (rhonn_id_control_ack_pack(frame, &a, sizeof frame) == (int)RHONN_ID_CONTROL_ACK_LENGTH) {
        sent = send_frame(app, RHONN_ID_CONTROL_ACK_FRAME_ID, frame, (uint8_t)RHONN_ID_CONTROL_ACK_LENGTH);
    } else {
        sent = FW_E_LENGTH; /* not reached: the buffer is the DBC length */
    }
    if (result != FW_OK) {
        return reject(app, result);
    }
    ++app->counters.commands;
    if (diag && fw_app_send_diagnostics(app) != FW_OK) {
        sent = FW_E_HAL;
    }
    return sent;
}

static fw_status on_weight_load(fw_app *app, const uint8_t *data, size_t len)
{
    fw_weight_chunk c;
    fw_status st;
    uint8_t k;

    if (len != RHONN_ID_WEIGHT_LOAD_LENGTH) {
        return reject(app, FW_E_LENGTH);
    }
    st = authenticate(app, (uint16_t)RHONN_ID_WEIGHT_LOAD_FRAME_ID, data, len);
    if (st != FW_OK) {
        return reject(app, st);
    }
    st = fw_weight_chunk_decode(data, len, &c);
    if (st != FW_OK) {
        return reject(app, st);
    }
    if (!app->weights_open) {
        return reject(app, FW_E_STATE);
    }
    if (c.neuron >= app->n_states || (unsigned)c.first + c.count > app->n_terms[c.neuron]) {
        return reject(app, FW_E_RANGE);
    }
    for (k = 0; k < c.count; ++k) {
        uint8_t t = (uint8_t)(c.first + k);
        app->w_stage[c.neuron][t] = (rhonn_real)c.w[k];
        if (!app->w_have[c.neuron][t]) {
            app->w_have[c.neuron][t] = 1;
            --app->weights_missing;
        }
    }
    ++app->counters.weight_chunks;
    return FW_OK;
}

fw_status fw_app_on_frame(fw_app *app, uint32_t id, const uint8_t *data, size_t len, uint64_t now_ns)
{
    if (app == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    if (data == NULL && len != 0u) {
        return FW_E_NULL;
    }
    if (app->hooks.before_frame != NULL) {
        app->hooks.before_frame(app->hooks.ctx, app);
    }
    ++app->counters.frames_in;
    switch (id) {
    case RHONN_ID_MEASUREMENT_FRAME_ID:
        return on_measurement(app, data, len, now_ns);
    case RHONN_ID_CONTROL_FRAME_ID:
        return on_control(app, data, len);
    case RHONN_ID_WEIGHT_LOAD_FRAME_ID:
        return on_weight_load(app, data, len);
    default:
        return reject(app, FW_E_UNKNOWN_ID);
    }
}

fw_status fw_app_poll(fw_app *app, uint32_t max_frames, uint32_t *handled)
{
    uint32_t n = 0;
    fw_status st = FW_OK;

    if (app == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    if (app->hal.receive == NULL) {
        return FW_E_CONFIG;
    }
    while (n < max_frames) {
        fw_frame f;
        uint64_t t = 0;
        fw_status got = app->hal.receive(app->hal.ctx, &f);
        if (got == FW_E_EMPTY) {
            break;
        }
        if (got != FW_OK || app->hal.now(app->hal.ctx, &t) != FW_OK) {
            ++app->counters.hal_errors;
            st = FW_E_HAL;
            break;
        }
        (void)fw_app_on_frame(app, f.id, f.data, f.len, t);
        ++n;
    }
    if (handled != NULL) {
        *handled = n;
    }
    return st;
}

/* The range of Health's float32 signals in the DBC. */
#define FW_HEALTH_LIMIT 3.4e38f

/* A health value as Health's float32 signal: one outside the signal's
 * range (+-3.4e38, infinities included) or NaN goes out as the nearest
 * limit (0 for NaN) with its Sat flag set, never as a measurement. */
static float health_value(rhonn_real v, uint8_t *sat)
{
    if (v != v) {
        *sat = 1;
        return 0.0f;
    }
    if (v > (rhonn_real)FW_HEALTH_LIMIT || v < -(rhonn_real)FW_HEALTH_LIMIT) {
        *sat = 1;
        return v > 0 ? FW_HEALTH_LIMIT : -FW_HEALTH_LIMIT;
    }
    *sat = 0;
    return (float)v;
}

/* One Health frame per neuron. */
static fw_status send_health(fw_app *app)
{
    struct rhonn_id_health_t h;
    uint8_t frame[RHONN_ID_HEALTH_LENGTH];
    rhonn_health nh;
    fw_status st = FW_OK;
    uint8_t i;

    for (i = 0; i < app->n_states; ++i) {
        if (rhonn_get_health(&app->net, i, &nh) != RHONN_OK) {
            return FW_E_STATE; /* not reached: i < n_states of an initialised identifier */
        }
        (void)rhonn_id_health_init(&h);
        h.neuron = i;
        h.innovation = health_value(nh.innovation, &h.innovation_sat);
        h.nis = health_value(nh.nis, &h.nis_sat);
        h.trace_p = health_value(nh.trace_p, &h.trace_p_sat);
        h.fail_run = nh.fail_run;
        h.updates = nh.updates;
        h.rejected = nh.rejected;
        h.resets = nh.resets;
        h.bounded = nh.bounded;
        h.gated = nh.gated;
        if (rhonn_id_health_pack(frame, &h, sizeof frame) != (int)RHONN_ID_HEALTH_LENGTH) {
            return FW_E_LENGTH; /* not reached */
        }
        if (send_frame(app, RHONN_ID_HEALTH_FRAME_ID, frame, (uint8_t)RHONN_ID_HEALTH_LENGTH) != FW_OK) {
            st = FW_E_HAL;
        }
    }
    return st;
}

fw_status fw_app_send_diagnostics(fw_app *app)
{
    struct rhonn_id_diagnostics_t d;
    uint8_t frame[RHONN_ID_DIAGNOSTICS_LENGTH];
    const fw_counters *c;
    fw_status st;

    if (app == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    c = &app->counters;
    (void)rhonn_id_diagnostics_init(&d);
    d.counter = app->diag_counter;
    d.last_seq = app->last_seq;
    d.cycle_time = to_10ns(c->cycle_time_ns);
    d.step_time = to_10ns(c->step_time_ns);
    d.step_time_max = step_time_max_raw(c->step_time_max_ns);
    d.overruns = (uint16_t)(c->overruns & 0xFFFFu);
    d.rejected = (uint16_t)(c->rejected & 0xFFFFu);
    d.last_reject = c->last_reject;
    d.step_errors = (uint16_t)(c->step_errors & 0xFFFFu);
    d.step_status = (uint8_t)(c->last_step_status & 0x0Fu);
    d.learning = app->learning;
    d.started = app->started;
    d.weights_open = app->weights_open;
    d.synced = app->anchored;
    d.measurements = c->measurements;
    d.seq_errors = (uint16_t)((c->rejected_seq_repeat + c->rejected_seq_jump) & 0xFFFFu);
    d.lost_frames = c->lost_frames;
    d.rx_drops = c->rx_drops;
    if (rhonn_id_diagnostics_pack(frame, &d, sizeof frame) != (int)RHONN_ID_DIAGNOSTICS_LENGTH) {
        return FW_E_LENGTH; /* not reached */
    }
    st = send_frame(app, RHONN_ID_DIAGNOSTICS_FRAME_ID, frame, (uint8_t)RHONN_ID_DIAGNOSTICS_LENGTH);
    if (send_health(app) != FW_OK) {
        st = FW_E_HAL;
    }
    app->diag_counter = (uint8_t)(app->diag_counter + 1u);
    app->since_diag = 0;
    app->counters.step_time_max_ns = 0;
    return st;
}

fw_status fw_app_note_overrun(fw_app *app)
{
    if (app == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    ++app->counters.overruns;
    return FW_OK;
}

fw_status fw_app_note_rx_drops(fw_app *app, uint32_t dropped)
{
    if (app == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    app->counters.rx_drops += dropped; /* wraps, as the other totals */
    return FW_OK;
}

fw_status fw_app_get_counters(const fw_app *app, fw_counters *out)
{
    if (app == NULL || out == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    *out = app->counters;
    return FW_OK;
}

fw_status fw_app_get_identifier(const fw_app *app, const rhonn_t **net)
{
    if (app == NULL || net == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    *net = &app->net;
    return FW_OK;
}

fw_status fw_app_get_freshness(const fw_app *app, uint64_t *freshness)
{
    if (app == NULL || freshness == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    *freshness = app->secoc_freshness;
    return FW_OK;
}

fw_status fw_app_set_freshness(fw_app *app, uint64_t freshness)
{
    if (app == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    if (freshness < app->secoc_freshness) {
        return FW_E_FRESHNESS; /* going back would reopen accepted frames to replay */
    }
    app->secoc_freshness = freshness;
    return FW_OK;
}

fw_status fw_app_set_step_hooks(fw_app *app, const fw_step_hooks *hooks)
{
    if (app == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    if (hooks == NULL) {
        memset(&app->hooks, 0, sizeof app->hooks);
    } else {
        app->hooks = *hooks;
    }
    return FW_OK;
}

fw_status fw_app_set_learning(fw_app *app, int on)
{
    if (app == NULL) {
        return FW_E_NULL;
    }
    if (!app_ready(app)) {
        return FW_E_NOT_INIT;
    }
    if (rhonn_set_learning(&app->net, on != 0) != RHONN_OK) {
        return FW_E_STATE; /* not reached: the app holds an initialised identifier */
    }
    app->learning = (uint8_t)(on != 0);
    return FW_OK;
}

int fw_app_learning(const fw_app *app)
{
    return app != NULL && app_ready(app) && app->learning;
}

const char *fw_status_name(fw_status status)
{
    switch (status) {
    case FW_OK: return "FW_OK";
    case FW_E_NULL: return "FW_E_NULL";
    case FW_E_NOT_INIT: return "FW_E_NOT_INIT";
    case FW_E_CONFIG: return "FW_E_CONFIG";
    case FW_E_UNKNOWN_ID: return "FW_E_UNKNOWN_ID";
    case FW_E_LENGTH: return "FW_E_LENGTH";
    case FW_E_RANGE: return "FW_E_RANGE";
    case FW_E_SEQ_REPEAT: return "FW_E_SEQ_REPEAT";
    case FW_E_SEQ_JUMP: return "FW_E_SEQ_JUMP";
    case FW_E_STATE: return "FW_E_STATE";
    case FW_E_WEIGHTS: return "FW_E_WEIGHTS";
    case FW_E_STEP: return "FW_E_STEP";
    case FW_E_HAL: return "FW_E_HAL";
    case FW_E_EMPTY: return "FW_E_EMPTY";
    case FW_E_AUTH: return "FW_E_AUTH";
    case FW_E_FRESHNESS: return "FW_E_FRESHNESS";
    default: return "FW_E_UNKNOWN_STATUS";
    }
}
