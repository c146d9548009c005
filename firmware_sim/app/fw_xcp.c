/*
 * fw_xcp.c - the XCP 1.4 slave of the identifier application. See fw_xcp.h.
 */
#include "fw_xcp.h"

#include <string.h>

#include "fw_secoc_key.h"

#define FW_XCP_MAGIC 0x58435031u /* "XCP1" */

#define FW_XCP_STATIC_ASSERT(name, cond) typedef char fw_xcp_static_assert_##name[(cond) ? 1 : -1]
/* The measurement layout the A2L describes (make_a2l.py): the LIM's six states. A build for another
 * identifier's protocol (generate_protocol.py --dbc) has its own FW_N_STATES and so its own layout. */
#if FW_N_STATES == 6u
FW_XCP_STATIC_ASSERT(off_weights, offsetof(fw_xcp_signals, weights) == FW_XCP_OFF_WEIGHTS);
FW_XCP_STATIC_ASSERT(off_xhat, offsetof(fw_xcp_signals, xhat) == FW_XCP_OFF_XHAT);
FW_XCP_STATIC_ASSERT(off_innovation, offsetof(fw_xcp_signals, innovation) == FW_XCP_OFF_INNOVATION);
FW_XCP_STATIC_ASSERT(off_nis, offsetof(fw_xcp_signals, nis) == FW_XCP_OFF_NIS);
FW_XCP_STATIC_ASSERT(off_trace_p, offsetof(fw_xcp_signals, trace_p) == FW_XCP_OFF_TRACE_P);
FW_XCP_STATIC_ASSERT(off_updates, offsetof(fw_xcp_signals, updates) == FW_XCP_OFF_UPDATES);
FW_XCP_STATIC_ASSERT(off_refused, offsetof(fw_xcp_signals, refused) == FW_XCP_OFF_REFUSED);
FW_XCP_STATIC_ASSERT(off_bounded, offsetof(fw_xcp_signals, bounded) == FW_XCP_OFF_BOUNDED);
FW_XCP_STATIC_ASSERT(off_gated, offsetof(fw_xcp_signals, gated) == FW_XCP_OFF_GATED);
FW_XCP_STATIC_ASSERT(off_resets, offsetof(fw_xcp_signals, resets) == FW_XCP_OFF_RESETS);
FW_XCP_STATIC_ASSERT(off_measurements, offsetof(fw_xcp_signals, measurements) == FW_XCP_OFF_MEASUREMENTS);
FW_XCP_STATIC_ASSERT(off_step_errors, offsetof(fw_xcp_signals, step_errors) == FW_XCP_OFF_STEP_ERRORS);
FW_XCP_STATIC_ASSERT(off_lost_frames, offsetof(fw_xcp_signals, lost_frames) == FW_XCP_OFF_LOST_FRAMES);
FW_XCP_STATIC_ASSERT(off_rejected, offsetof(fw_xcp_signals, rejected) == FW_XCP_OFF_REJECTED);
FW_XCP_STATIC_ASSERT(off_restarts, offsetof(fw_xcp_signals, restarts) == FW_XCP_OFF_RESTARTS);
FW_XCP_STATIC_ASSERT(off_learning, offsetof(fw_xcp_signals, learning) == FW_XCP_OFF_LEARNING);
FW_XCP_STATIC_ASSERT(off_step_status, offsetof(fw_xcp_signals, step_status) == FW_XCP_OFF_STEP_STATUS);
FW_XCP_STATIC_ASSERT(off_events, offsetof(fw_xcp_signals, events) == FW_XCP_OFF_EVENTS);
FW_XCP_STATIC_ASSERT(off_dto_sent, offsetof(fw_xcp_signals, daq_dto_sent) == FW_XCP_OFF_DAQ_DTO_SENT);
FW_XCP_STATIC_ASSERT(off_dto_lost, offsetof(fw_xcp_signals, daq_dto_lost) == FW_XCP_OFF_DAQ_DTO_LOST);
FW_XCP_STATIC_ASSERT(signals_size, sizeof(fw_xcp_signals) == FW_XCP_SIGNALS_SIZE);
FW_XCP_STATIC_ASSERT(cal_ceiling, offsetof(fw_xcp_calibration, trace_ceiling) == FW_XCP_CAL_OFF_TRACE_CEILING);
FW_XCP_STATIC_ASSERT(cal_gate, offsetof(fw_xcp_calibration, gate) == FW_XCP_CAL_OFF_GATE);
FW_XCP_STATIC_ASSERT(cal_size, sizeof(fw_xcp_calibration) == FW_XCP_CALIBRATION_SIZE);
#endif
FW_XCP_STATIC_ASSERT(cal_learning, offsetof(fw_xcp_calibration, learning) == FW_XCP_CAL_OFF_LEARNING);
FW_XCP_STATIC_ASSERT(float32, sizeof(float) == 4u);
FW_XCP_STATIC_ASSERT(max_odt_pid, FW_XCP_MAX_ODT <= 0xFCu);       /* PIDs 0x00..0xFB are DTOs */
FW_XCP_STATIC_ASSERT(entry_fits, FW_XCP_MAX_ENTRY_SIZE + 5u <= FW_XCP_MAX_DTO);
FW_XCP_STATIC_ASSERT(seed_fits, FW_XCP_SEED_LEN + 2u <= FW_XCP_MAX_CTO);
FW_XCP_STATIC_ASSERT(id_fits, sizeof(FW_XCP_A2L_NAME) - 1u <= FW_XCP_MAX_CTO - 1u);

/* Command codes (XCP 1.4 part 2). */
enum {
    CC_CONNECT = 0xFF, CC_DISCONNECT = 0xFE, CC_GET_STATUS = 0xFD, CC_SYNCH = 0xFC,
    CC_GET_COMM_MODE_INFO = 0xFB, CC_GET_ID = 0xFA, CC_GET_SEED = 0xF8, CC_UNLOCK = 0xF7,
    CC_SET_MTA = 0xF6, CC_UPLOAD = 0xF5, CC_SHORT_UPLOAD = 0xF4, CC_DOWNLOAD = 0xF0,
    CC_SET_DAQ_PTR = 0xE2, CC_WRITE_DAQ = 0xE1, CC_SET_DAQ_LIST_MODE = 0xE0,
    CC_START_STOP_DAQ_LIST = 0xDE, CC_START_STOP_SYNCH = 0xDD, CC_GET_DAQ_CLOCK = 0xDC,
    CC_GET_DAQ_PROCESSOR_INFO = 0xDA, CC_GET_DAQ_RESOLUTION_INFO = 0xD9,
    CC_FREE_DAQ = 0xD6, CC_ALLOC_DAQ = 0xD5, CC_ALLOC_ODT = 0xD4, CC_ALLOC_ODT_ENTRY = 0xD3
};

/* Error codes. */
enum {
    ERR_CMD_SYNCH = 0x00, ERR_DAQ_ACTIVE = 0x11, ERR_CMD_UNKNOWN = 0x20, ERR_CMD_SYNTAX = 0x21,
    ERR_OUT_OF_RANGE = 0x22, ERR_WRITE_PROTECTED = 0x23, ERR_ACCESS_DENIED = 0x24,
    ERR_ACCESS_LOCKED = 0x25, ERR_MODE_NOT_VALID = 0x27, ERR_SEQUENCE = 0x29, ERR_DAQ_CONFIG = 0x2A,
    ERR_MEMORY_OVERFLOW = 0x30
};

#define PID_RES 0xFFu
#define PID_ERR 0xFEu
#define RES_CAL_PAG 0x01u
#define RES_DAQ 0x04u
#define RES_ALL (RES_CAL_PAG | RES_DAQ)
#define DAQ_MODE_ALTERNATING 0x01u
#define DAQ_MODE_DIRECTION_STIM 0x02u
#define DAQ_MODE_TIMESTAMP 0x10u
#define DAQ_MODE_PID_OFF 0x20u
#define REGION_SIGNALS 0u
#define REGION_CAL 1u
#define TS_BYTES 4u

static uint16_t rd16(const uint8_t *p)
{
    return (uint16_t)(p[0] | (p[1] << 8));
}

static uint32_t rd32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static void wr16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

static void wr32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)((v >> 8) & 0xFFu);
    p[2] = (uint8_t)((v >> 16) & 0xFFu);
    p[3] = (uint8_t)(v >> 24);
}

static fw_status send_packet(fw_xcp *x, size_t len)
{
    return x->transport.send(x->transport.ctx, x->pkt, len) == FW_OK ? FW_OK : FW_E_HAL;
}

/* A positive response of len bytes (PID included); the caller filled pkt[1..]. */
static fw_status respond(fw_xcp *x, size_t len)
{
    x->pkt[0] = PID_RES;
    return send_packet(x, len);
}

static fw_status error(fw_xcp *x, uint8_t code)
{
    x->pkt[0] = PID_ERR;
    x->pkt[1] = code;
    x->last_error = code;
    return send_packet(x, 2u) == FW_OK ? FW_E_RANGE : FW_E_HAL;
}

/* Where n bytes at XCP address (ext, addr) live: region and offset. 0 when
 * they lie wholly inside one region, else -1. Integer arithmetic only: no
 * pointer is formed before the range is known to be inside. */
static int resolve(const fw_xcp *x, uint8_t ext, uint32_t addr, size_t n, uint8_t *region, uint16_t *offset)
{
    uint32_t off;
    if (ext != 0u || n == 0u) {
        return -1;
    }
    if (addr >= x->sig_address && addr - x->sig_address < FW_XCP_SIGNALS_SIZE) {
        off = addr - x->sig_address;
        if (n > FW_XCP_SIGNALS_SIZE - off) {
            return -1;
        }
        *region = REGION_SIGNALS;
    } else if (addr >= x->cal_address && addr - x->cal_address < sizeof(fw_xcp_calibration)) {
        off = addr - x->cal_address;
        if (n > sizeof(fw_xcp_calibration) - off) {
            return -1;
        }
        *region = REGION_CAL;
    } else {
        return -1;
    }
    *offset = (uint16_t)off;
    return 0;
}

static const uint8_t *region_bytes(const fw_xcp *x, uint8_t region)
{
    return region == REGION_CAL ? (const uint8_t *)x->calibration : (const uint8_t *)x->signals;
}

/* Copy n bytes from the MTA (region memory or the GET_ID text) to out,
 * advancing the MTA; an ERR_ code, or 0. */
static uint8_t read_mta(fw_xcp *x, uint8_t *out, size_t n)
{
    static const char id[] = FW_XCP_A2L_NAME;
    uint8_t region;
    uint16_t off;
    if (x->mta_ext == FW_XCP_EXT_ID) {
        if (x->mta > sizeof id - 1u || n > sizeof id - 1u - x->mta) {
            return ERR_ACCESS_DENIED;
        }
        memcpy(out, id + x->mta, n);
    } else {
        if (resolve(x, x->mta_ext, x->mta, n, &region, &off) != 0) {
            return ERR_ACCESS_DENIED;
        }
        memcpy(out, region_bytes(x, region) + off, n);
    }
    x->mta += (uint32_t)n;
    return 0;
}

#define ALL_NEURONS ((uint32_t)((1ull << FW_N_STATES) - 1u))

/* The calibration page's ceilings and gates from the values in force (only
 * a DOWNLOAD, taken before a step, changes those: a step event need not). */
static void show_in_force(fw_xcp *x, const fw_app *app)
{
    rhonn_real v;
    uint8_t i;
    for (i = 0; i < FW_N_STATES; ++i) {
        if (rhonn_get_trace_ceiling(&app->net, i, &v) == RHONN_OK) {
            x->calibration->trace_ceiling[i] = (float)v;
        }
        if (rhonn_get_gate(&app->net, i, &v) == RHONN_OK) {
            x->calibration->gate[i] = (float)v;
        }
    }
}
FW_XCP_STATIC_ASSERT(need_bits, FW_N_STATES <= 32u);

/* The signals from the identifier and the application's counters: the
 * weights of the neurons in need_weights (bit i: neuron i), the health of
 * those in need_health, the prediction when need_xhat, the counters always.
 * The slave is a protocol layer of the application, as fw_app.c's CAN
 * protocol is: it reads the application's fields in place (no copy of the
 * counters per step event) and changes nothing but through
 * fw_app_set_learning. */
static void refresh_some(fw_xcp *x, const fw_app *app, uint32_t need_weights, uint32_t need_health, int need_xhat)
{
    fw_xcp_signals *s = x->signals;
    rhonn_real v[RHONN_MAX_TERMS > FW_N_STATES ? RHONN_MAX_TERMS : FW_N_STATES];
    rhonn_health h;
    uint8_t i, t;

    for (i = 0; i < FW_N_STATES; ++i) {
        const uint32_t bit = (uint32_t)1u << i;
        if ((need_weights & bit) != 0u && app->n_terms[i] <= FW_XCP_TERMS) {
#ifdef RHONN_SINGLE
            /* float core: the weights land in the signals as they are */
            (void)v;
            (void)t;
            (void)rhonn_get_weights(&app->net, i, s->weights[i], app->n_terms[i]);
#else
            if (rhonn_get_weights(&app->net, i, v, app->n_terms[i]) == RHONN_OK) {
                for (t = 0; t < app->n_terms[i]; ++t) {
                    s->weights[i][t] = (float)v[t];
                }
            }
#endif
        }
        if ((need_health & bit) != 0u && rhonn_get_health(&app->net, i, &h) == RHONN_OK) {
            s->innovation[i] = (float)h.innovation;
            s->nis[i] = (float)h.nis;
            s->trace_p[i] = (float)h.trace_p;
            s->updates[i] = h.updates;
            s->refused[i] = h.rejected;
            s->bounded[i] = h.bounded;
            s->gated[i] = h.gated;
            s->resets[i] = h.resets;
        }
    }
    if (need_xhat && rhonn_get_prediction(&app->net, v, FW_N_STATES) == RHONN_OK) {
        for (i = 0; i < FW_N_STATES; ++i) {
            s->xhat[i] = (float)v[i];
        }
    }
    s->measurements = app->counters.measurements;
    s->step_errors = app->counters.step_errors;
    s->lost_frames = app->counters.lost_frames;
    s->rejected = app->counters.rejected;
    s->restarts = app->counters.restarts;
    s->learning = app->learning;
    s->step_status = app->counters.last_step_status;
    if (!x->cal_dirty) {
        x->calibration->learning = app->learning; /* the page shows the state until written */
    }
}

/* Every signal (a read between steps: UPLOAD, CONNECT, attach). */
static void refresh(fw_xcp *x, const fw_app *app)
{
    refresh_some(x, app, ALL_NEURONS, ALL_NEURONS, 1);
    if (!x->cal_dirty) {
        show_in_force(x, app);
    }
}

/* Which signals the bytes [off, off + n) of the signals region show. */
static void note_needs(fw_xcp *x, uint16_t off, uint8_t n)
{
    uint32_t o;
    for (o = off & ~3u; o < (uint32_t)off + n; o += 4u) {
        if (o < offsetof(fw_xcp_signals, xhat)) {
            x->need_weights |= (uint32_t)1u << (o / (4u * FW_XCP_TERMS));
        } else if (o < offsetof(fw_xcp_signals, innovation)) {
            x->need_xhat = 1;
        } else if (o < offsetof(fw_xcp_signals, measurements)) {
            x->need_health |= (uint32_t)1u << (((o - offsetof(fw_xcp_signals, innovation)) / 4u) % FW_N_STATES);
        }
    }
}

/* The running lists' ODTs as runs of contiguous bytes (entries that follow
 * each other in one region merged), and the signals they need: once, when
 * a list starts, not at every event. At most FW_XCP_MAX_ENTRIES runs and
 * FW_XCP_MAX_ENTRIES * FW_XCP_MAX_ENTRY_SIZE / 4 words looked at. */
static void compile_daq(fw_xcp *x)
{
    uint16_t runs = 0;
    uint8_t d, o, e;
    x->need_weights = 0;
    x->need_health = 0;
    x->need_xhat = 0;
    for (d = 0; d < x->n_daq; ++d) {
        const fw_xcp_daq *q = &x->daq[d];
        if (!q->running) {
            continue;
        }
        for (o = 0; o < q->n_odt; ++o) {
            fw_xcp_odt *t = &x->odt[q->first_odt + o];
            t->first_run = runs;
            t->n_runs = 0;
            for (e = 0; e < t->n_entries; ++e) {
                const fw_xcp_entry *en = &x->entry[t->first_entry + e];
                const uint16_t off = (uint16_t)(en->offset | (en->region == REGION_CAL ? 0x8000u : 0u));
                if (en->region == REGION_SIGNALS) {
                    note_needs(x, en->offset, en->size);
                }
                if (t->n_runs != 0u && (uint32_t)x->run_off[runs - 1u] + x->run_len[runs - 1u] == off) {
                    x->run_len[runs - 1u] = (uint8_t)(x->run_len[runs - 1u] + en->size); /* one ODT: <= MAX_DTO */
                } else {
                    x->run_off[runs] = off;
                    x->run_len[runs] = en->size;
                    ++runs;
                    ++t->n_runs;
                }
            }
        }
    }
}

static void stop_all_daq(fw_xcp *x)
{
    uint8_t d;
    for (d = 0; d < FW_XCP_MAX_DAQ; ++d) {
        x->daq[d].running = 0;
        x->daq[d].selected = 0;
    }
}

static void free_daq(fw_xcp *x)
{
    memset(x->daq, 0, sizeof x->daq);
    memset(x->odt, 0, sizeof x->odt);
    memset(x->entry, 0, sizeof x->entry);
    x->n_daq = 0;
    x->n_odt = 0;
    x->n_entries = 0;
    x->alloc_stage = 0;
    x->ptr_valid = 0;
}

static int daq_running(const fw_xcp *x)
{
    uint8_t d;
    for (d = 0; d < x->n_daq; ++d) {
        if (x->daq[d].running) {
            return 1;
        }
    }
    return 0;
}

static void disconnect(fw_xcp *x)
{
    stop_all_daq(x);
    x->connected = 0;
    x->protection = RES_ALL;
    x->seed_resource = 0;
}

/* The identifier takes the calibration page: between two steps. */
static void before_step(void *ctx, fw_app *app)
{
    fw_xcp *x = (fw_xcp *)ctx;
    uint8_t i;
    if (x->cal_dirty) {
        (void)fw_app_set_learning(app, x->calibration->learning);
        for (i = 0; i < FW_N_STATES; ++i) { /* checked by DOWNLOAD: accepted */
            (void)rhonn_set_trace_ceiling(&app->net, i, (rhonn_real)x->calibration->trace_ceiling[i]);
            (void)rhonn_set_gate(&app->net, i, (rhonn_real)x->calibration->gate[i]);
        }
        x->cal_dirty = 0;
    }
}

/* One DAQ sample of the step at now_ns: refresh the signals the running
 * lists read, send each due list's ODTs. */
static void sample(fw_xcp *x, const fw_app *app, uint64_t now_ns)
{
    const uint8_t *sig = (const uint8_t *)x->signals;
    const uint8_t *cal = (const uint8_t *)x->calibration;
    uint32_t stamp;
    uint8_t d, o, r;

    refresh_some(x, app, x->need_weights, x->need_health, x->need_xhat);
    stamp = (uint32_t)(now_ns / 1000u); /* one 64-bit division an event */
    for (d = 0; d < x->n_daq; ++d) {
        fw_xcp_daq *q = &x->daq[d];
        if (!q->running) {
            continue;
        }
        if (q->countdown > 1u) {
            --q->countdown;
            continue;
        }
        q->countdown = q->prescaler;
        for (o = 0; o < q->n_odt; ++o) {
            const fw_xcp_odt *t = &x->odt[q->first_odt + o];
            uint8_t *out = x->pkt + 1;
            x->pkt[0] = (uint8_t)(q->first_odt + o);
            if (o == 0u && (q->mode & DAQ_MODE_TIMESTAMP)) {
                wr32(out, stamp);
                out += TS_BYTES;
            }
            for (r = 0; r < t->n_runs; ++r) {
                /* a run's bytes at once: 4 at a time by fixed-size copies the
                 * compiler turns into word moves, the rest by bytes */
                const uint16_t off = x->run_off[t->first_run + r];
                const uint8_t *src = ((off & 0x8000u) != 0u ? cal : sig) + (off & 0x7FFFu);
                const uint8_t *end = src + x->run_len[t->first_run + r];
                for (; src + 4 <= end; src += 4, out += 4) {
                    memcpy(out, src, 4u);
                }
                while (src < end) {
                    *out++ = *src++;
                }
            }
            if (send_packet(x, (size_t)(out - x->pkt)) == FW_OK) {
                ++x->signals->daq_dto_sent;
            } else {
                ++x->signals->daq_dto_lost;
            }
        }
    }
}

/* The noted sample (deferred mode), while a list still runs. */
static void flush(fw_xcp *x, const fw_app *app)
{
    if (x->pending) {
        x->pending = 0;
        if (x->connected && daq_running(x)) {
            sample(x, app, x->pending_ns);
        }
    }
}

/* The step event: count it; sample the running lists now or note it. */
static void after_step(void *ctx, fw_app *app, uint64_t now_ns)
{
    fw_xcp *x = (fw_xcp *)ctx;
    ++x->signals->events;
    if (!x->connected || !daq_running(x)) {
        return; /* a read refreshes the signals itself (fw_xcp_on_command) */
    }
    if (x->deferred) {
        flush(x, app); /* not left by before_frame: kept in order */
        x->pending = 1;
        x->pending_ns = now_ns;
    } else {
        sample(x, app, now_ns);
    }
}

/* Before any frame can change the identifier: a noted sample goes out. */
static void before_frame(void *ctx, fw_app *app)
{
    flush((fw_xcp *)ctx, app);
}

fw_status fw_xcp_set_deferred(fw_xcp *x, int on)
{
    if (x == NULL) {
        return FW_E_NULL;
    }
    if (x->magic != FW_XCP_MAGIC) {
        return FW_E_NOT_INIT;
    }
    x->deferred = on ? 1u : 0u;
    return FW_OK;
}

fw_status fw_xcp_poll(fw_xcp *x, fw_app *app)
{
    if (x == NULL || app == NULL) {
        return FW_E_NULL;
    }
    if (x->magic != FW_XCP_MAGIC) {
        return FW_E_NOT_INIT;
    }
    flush(x, app);
    return FW_OK;
}

fw_status fw_xcp_init(fw_xcp *x, const fw_xcp_config *cfg)
{
    static const uint8_t key[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
    uintptr_t sig, cal;

    if (x == NULL || cfg == NULL || cfg->signals == NULL || cfg->calibration == NULL) {
        return FW_E_NULL;
    }
    if (cfg->transport.send == NULL) {
        return FW_E_CONFIG;
    }
    sig = (uintptr_t)cfg->signals;
    cal = (uintptr_t)cfg->calibration;
    if (sig < cfg->address_base || sig - cfg->address_base > 0xFFFFFFFFu - FW_XCP_SIGNALS_SIZE ||
        cal < cfg->address_base || cal - cfg->address_base > 0xFFFFFFFFu - sizeof(fw_xcp_calibration)) {
        return FW_E_CONFIG;
    }
    memset(x, 0, sizeof *x);
    x->transport = cfg->transport;
    x->signals = cfg->signals;
    x->calibration = cfg->calibration;
    x->address_base = cfg->address_base;
    x->sig_address = (uint32_t)(sig - cfg->address_base);
    x->cal_address = (uint32_t)(cal - cfg->address_base);
    (void)fw_cmac_init(&x->key, key);
    memset(x->signals, 0, sizeof *x->signals);
    memset(x->calibration, 0, sizeof *x->calibration);
    x->protection = RES_ALL;
    x->magic = FW_XCP_MAGIC;
    return FW_OK;
}

fw_status fw_xcp_attach(fw_xcp *x, fw_app *app)
{
    fw_step_hooks hooks;
    const rhonn_t *net;
    uint8_t i;

    if (x == NULL || app == NULL) {
        return FW_E_NULL;
    }
    if (x->magic != FW_XCP_MAGIC || fw_app_get_identifier(app, &net) != FW_OK) {
        return FW_E_NOT_INIT;
    }
    for (i = 0; i < FW_N_STATES; ++i) {
        if (app->n_terms[i] > FW_XCP_TERMS) {
            return FW_E_CONFIG;
        }
    }
    hooks.ctx = x;
    hooks.before_step = before_step;
    hooks.after_step = after_step;
    hooks.before_frame = before_frame;
    if (fw_app_set_step_hooks(app, &hooks) != FW_OK) {
        return FW_E_NOT_INIT;
    }
    refresh(x, app);
    return FW_OK;
}

uint8_t fw_xcp_last_error(const fw_xcp *x)
{
    return x != NULL ? x->last_error : 0u;
}

/* A fresh seed for one resource: AES-CMAC(K, "seed" | counter | time), so
 * it never repeats within a run and cannot be predicted without K. */
static void make_seed(fw_xcp *x, uint8_t resource, uint64_t now_ns)
{
    uint8_t msg[17];
    memcpy(msg, "seed", 4u);
    msg[4] = resource;
    wr32(msg + 5, ++x->seed_counter);
    wr32(msg + 9, (uint32_t)(now_ns & 0xFFFFFFFFu));
    wr32(msg + 13, (uint32_t)(now_ns >> 32));
    (void)fw_cmac(&x->key, msg, sizeof msg, x->seed);
    x->seed_resource = resource;
}

static fw_status cmd_connect(fw_xcp *x, fw_app *app, const uint8_t *c, size_t len)
{
    if (len < 2u) {
        return error(x, ERR_CMD_SYNTAX);
    }
    if (c[1] > 1u) {
        return error(x, ERR_OUT_OF_RANGE);
    }
    disconnect(x);
    x->connected = 1;
    refresh(x, app);
    x->pkt[1] = RES_ALL;            /* CAL/PAG and DAQ */
    x->pkt[2] = 0x80u;              /* Intel byte order, byte granularity, GET_COMM_MODE_INFO available */
    x->pkt[3] = (uint8_t)FW_XCP_MAX_CTO;
    wr16(x->pkt + 4, (uint16_t)FW_XCP_MAX_DTO);
    x->pkt[6] = 0x01u;              /* protocol layer version */
    x->pkt[7] = 0x01u;              /* transport layer version */
    return respond(x, 8u);
}

static fw_status cmd_get_seed(fw_xcp *x, const uint8_t *c, size_t len, uint64_t now_ns)
{
    uint8_t resource;
    if (len < 3u) {
        return error(x, ERR_CMD_SYNTAX);
    }
    resource = c[2];
    if (c[1] != 0u || (resource != RES_CAL_PAG && resource != RES_DAQ)) {
        return error(x, ERR_OUT_OF_RANGE); /* one resource a seed; the seed fits one response */
    }
    if ((x->protection & resource) == 0u) {
        x->pkt[1] = 0u; /* unlocked already: no seed */
        x->seed_resource = 0;
        return respond(x, 2u);
    }
    make_seed(x, resource, now_ns);
    x->pkt[1] = (uint8_t)FW_XCP_SEED_LEN;
    memcpy(x->pkt + 2, x->seed, FW_XCP_SEED_LEN);
    return respond(x, 2u + FW_XCP_SEED_LEN);
}

static fw_status cmd_unlock(fw_xcp *x, const uint8_t *c, size_t len)
{
    uint8_t expect[FW_AES_BLOCK];
    uint8_t resource = x->seed_resource;
    int good;
    if (len < 2u || len < 2u + (size_t)c[1]) {
        return error(x, ERR_CMD_SYNTAX);
    }
    if (resource == 0u) {
        return error(x, ERR_SEQUENCE);
    }
    x->seed_resource = 0; /* one try per seed */
    (void)fw_cmac(&x->key, x->seed, FW_XCP_SEED_LEN, expect);
    good = c[1] == FW_XCP_KEY_LEN && fw_mac_equal(expect, c + 2, FW_XCP_KEY_LEN);
    if (!good) {
        fw_status st = error(x, ERR_ACCESS_LOCKED);
        disconnect(x);
        return st;
    }
    x->protection = (uint8_t)(x->protection & ~resource);
    x->pkt[1] = x->protection;
    return respond(x, 2u);
}

static fw_status cmd_upload(fw_xcp *x, const uint8_t *c, size_t len)
{
    uint8_t n, err;
    if (len < 2u) {
        return error(x, ERR_CMD_SYNTAX);
    }
    n = c[1];
    if (n == 0u || n > FW_XCP_MAX_CTO - 1u) {
        return error(x, ERR_OUT_OF_RANGE);
    }
    err = read_mta(x, x->pkt + 1, n);
    return err != 0u ? error(x, err) : respond(x, 1u + n);
}

static fw_status cmd_short_upload(fw_xcp *x, const uint8_t *c, size_t len)
{
    if (len < 8u) {
        return error(x, ERR_CMD_SYNTAX);
    }
    if (c[1] == 0u || c[1] > FW_XCP_MAX_CTO - 1u) {
        return error(x, ERR_OUT_OF_RANGE);
    }
    x->mta_ext = c[3];
    x->mta = rd32(c + 4);
    return cmd_upload(x, c, 2u);
}

/* Whether the core takes every trace ceiling and gate of the page that this
 * write changes: the setters' own checks (rhonn_check_trace_ceiling,
 * rhonn_check_gate), which change nothing. */
static int core_accepts(const fw_app *app, const fw_xcp_calibration *page, const fw_xcp_calibration *old)
{
    uint8_t i;
    for (i = 0; i < FW_N_STATES; ++i) {
        if (memcmp(&page->trace_ceiling[i], &old->trace_ceiling[i], sizeof(float)) != 0 &&
            rhonn_check_trace_ceiling(&app->net, i, (rhonn_real)page->trace_ceiling[i]) != RHONN_OK) {
            return 0;
        }
        if (memcmp(&page->gate[i], &old->gate[i], sizeof(float)) != 0 &&
            rhonn_check_gate(&app->net, i, (rhonn_real)page->gate[i]) != RHONN_OK) {
            return 0;
        }
    }
    return 1;
}

static fw_status cmd_download(fw_xcp *x, fw_app *app, const uint8_t *c, size_t len)
{
    fw_xcp_calibration page;
    uint8_t n, region;
    uint16_t off;
    if (len < 2u) {
        return error(x, ERR_CMD_SYNTAX);
    }
    n = c[1];
    if (n == 0u || n > FW_XCP_MAX_CTO - 2u) {
        return error(x, ERR_OUT_OF_RANGE);
    }
    if (len < 2u + (size_t)n) {
        return error(x, ERR_CMD_SYNTAX);
    }
    if (x->protection & RES_CAL_PAG) {
        return error(x, ERR_ACCESS_LOCKED);
    }
    if (resolve(x, x->mta_ext, x->mta, n, &region, &off) != 0) {
        return error(x, ERR_ACCESS_DENIED);
    }
    if (region != REGION_CAL) {
        return error(x, ERR_WRITE_PROTECTED);
    }
    /* every value checked on a copy: all or nothing */
    page = *x->calibration;
    memcpy((uint8_t *)&page + off, c + 2, n);
    if (page.learning > 1u || page.reserved[0] != 0u || page.reserved[1] != 0u || page.reserved[2] != 0u ||
        !core_accepts(app, &page, x->calibration)) {
        return error(x, ERR_OUT_OF_RANGE);
    }
    *x->calibration = page;
    x->cal_dirty = 1;
    x->mta += n;
    return respond(x, 1u);
}

static fw_status cmd_daq(fw_xcp *x, const uint8_t *c, size_t len, uint64_t now_ns)
{
    uint16_t d;
    switch (c[0]) {
    case CC_GET_DAQ_PROCESSOR_INFO:
        x->pkt[1] = 0x13u; /* dynamic configuration, prescaler, timestamps */
        wr16(x->pkt + 2, 0u);                        /* MAX_DAQ: all dynamic */
        wr16(x->pkt + 4, 1u);                        /* one event channel */
        x->pkt[6] = 0u;                              /* MIN_DAQ */
        x->pkt[7] = 0u;                              /* absolute ODT number, 1-byte PID */
        return respond(x, 8u);
    case CC_GET_DAQ_RESOLUTION_INFO:
        x->pkt[1] = 1u;
        x->pkt[2] = (uint8_t)FW_XCP_MAX_ENTRY_SIZE;
        x->pkt[3] = 1u;
        x->pkt[4] = 0u;                              /* no STIM */
        x->pkt[5] = 0x34u | 0x08u;                   /* 4-byte timestamp, 1 us, always sent */
        wr16(x->pkt + 6, 1u);
        return respond(x, 8u);
    case CC_GET_DAQ_CLOCK:
        x->pkt[1] = 0u;
        x->pkt[2] = 0u;
        x->pkt[3] = 0u;
        wr32(x->pkt + 4, (uint32_t)(now_ns / 1000u));
        return respond(x, 8u);
    case CC_FREE_DAQ: case CC_ALLOC_DAQ: case CC_ALLOC_ODT: case CC_ALLOC_ODT_ENTRY: case CC_SET_DAQ_PTR:
    case CC_WRITE_DAQ: case CC_SET_DAQ_LIST_MODE: case CC_START_STOP_DAQ_LIST: case CC_START_STOP_SYNCH:
        break;
    default:
        return error(x, ERR_CMD_UNKNOWN);
    }
    if (x->protection & RES_DAQ) {
        return error(x, ERR_ACCESS_LOCKED);
    }
    switch (c[0]) {
    case CC_FREE_DAQ:
        free_daq(x);
        return respond(x, 1u);
    case CC_ALLOC_DAQ:
        if (len < 4u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        if (daq_running(x)) {
            return error(x, ERR_DAQ_ACTIVE);
        }
        if (x->alloc_stage != 0u) {
            return error(x, ERR_SEQUENCE);
        }
        d = rd16(c + 2);
        if (d > FW_XCP_MAX_DAQ) {
            return error(x, ERR_MEMORY_OVERFLOW);
        }
        x->n_daq = (uint8_t)d;
        x->alloc_stage = 1;
        return respond(x, 1u);
    case CC_ALLOC_ODT:
        if (len < 5u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        if (x->alloc_stage != 1u && x->alloc_stage != 2u) {
            return error(x, ERR_SEQUENCE);
        }
        d = rd16(c + 2);
        if (d >= x->n_daq || x->daq[d].n_odt != 0u) {
            return error(x, ERR_OUT_OF_RANGE);
        }
        if (c[4] > FW_XCP_MAX_ODT - x->n_odt) {
            return error(x, ERR_MEMORY_OVERFLOW);
        }
        x->daq[d].first_odt = x->n_odt;
        x->daq[d].n_odt = c[4];
        x->n_odt = (uint8_t)(x->n_odt + c[4]);
        x->alloc_stage = 2;
        return respond(x, 1u);
    case CC_ALLOC_ODT_ENTRY: {
        fw_xcp_odt *t;
        if (len < 6u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        if (x->alloc_stage != 2u && x->alloc_stage != 3u) {
            return error(x, ERR_SEQUENCE);
        }
        d = rd16(c + 2);
        if (d >= x->n_daq || c[4] >= x->daq[d].n_odt) {
            return error(x, ERR_OUT_OF_RANGE);
        }
        t = &x->odt[x->daq[d].first_odt + c[4]];
        if (t->n_entries != 0u) {
            return error(x, ERR_OUT_OF_RANGE);
        }
        if (c[5] > FW_XCP_MAX_ENTRIES - x->n_entries) {
            return error(x, ERR_MEMORY_OVERFLOW);
        }
        t->first_entry = x->n_entries;
        t->n_entries = c[5];
        x->n_entries = (uint16_t)(x->n_entries + c[5]);
        x->alloc_stage = 3;
        return respond(x, 1u);
    }
    case CC_SET_DAQ_PTR:
        if (len < 6u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        d = rd16(c + 2);
        if (d >= x->n_daq || c[4] >= x->daq[d].n_odt || c[5] >= x->odt[x->daq[d].first_odt + c[4]].n_entries) {
            return error(x, ERR_OUT_OF_RANGE);
        }
        if (x->daq[d].running) {
            return error(x, ERR_DAQ_ACTIVE);
        }
        x->ptr_daq = (uint8_t)d;
        x->ptr_odt = c[4];
        x->ptr_entry = c[5];
        x->ptr_valid = 1;
        return respond(x, 1u);
    case CC_WRITE_DAQ: {
        fw_xcp_odt *t;
        fw_xcp_entry en;
        size_t room, used;
        if (len < 8u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        if (!x->ptr_valid) {
            return error(x, ERR_SEQUENCE);
        }
        if (x->daq[x->ptr_daq].running) {
            return error(x, ERR_DAQ_ACTIVE);
        }
        if (c[1] != 0xFFu || c[2] == 0u || c[2] > FW_XCP_MAX_ENTRY_SIZE) {
            return error(x, ERR_OUT_OF_RANGE); /* no bit entries */
        }
        if (resolve(x, c[3], rd32(c + 4), c[2], &en.region, &en.offset) != 0) {
            return error(x, ERR_ACCESS_DENIED);
        }
        en.size = c[2];
        t = &x->odt[x->daq[x->ptr_daq].first_odt + x->ptr_odt];
        /* the ODT must fit one DTO: PID, a timestamp in the first, the entries
         * (an entry written again gives back its old bytes first) */
        room = FW_XCP_MAX_DTO - 1u - (x->ptr_odt == 0u ? TS_BYTES : 0u);
        used = (size_t)t->bytes - x->entry[t->first_entry + x->ptr_entry].size;
        if (used + en.size > room) {
            return error(x, ERR_DAQ_CONFIG);
        }
        x->entry[t->first_entry + x->ptr_entry] = en;
        t->bytes = (uint8_t)(used + en.size);
        if (x->ptr_entry + 1u < t->n_entries) {
            ++x->ptr_entry;
        } else {
            x->ptr_valid = 0; /* past the last entry: SET_DAQ_PTR again */
        }
        return respond(x, 1u);
    }
    case CC_SET_DAQ_LIST_MODE:
        if (len < 8u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        d = rd16(c + 2);
        if (d >= x->n_daq) {
            return error(x, ERR_OUT_OF_RANGE);
        }
        if (x->daq[d].running) {
            return error(x, ERR_DAQ_ACTIVE);
        }
        if ((c[1] & (DAQ_MODE_ALTERNATING | DAQ_MODE_DIRECTION_STIM | DAQ_MODE_PID_OFF)) != 0u) {
            return error(x, ERR_MODE_NOT_VALID);
        }
        if (rd16(c + 4) != FW_XCP_EVENT_STEP || c[6] == 0u) {
            return error(x, ERR_OUT_OF_RANGE);
        }
        x->daq[d].mode = (uint8_t)(c[1] | DAQ_MODE_TIMESTAMP); /* the timestamp is fixed */
        x->daq[d].prescaler = c[6];
        x->daq[d].configured = 1;
        return respond(x, 1u);
    case CC_START_STOP_DAQ_LIST: {
        fw_xcp_daq *q;
        uint8_t o;
        if (len < 4u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        d = rd16(c + 2);
        if (c[1] > 2u || d >= x->n_daq) {
            return error(x, ERR_OUT_OF_RANGE);
        }
        q = &x->daq[d];
        if (c[1] != 0u) {
            if (!q->configured || q->n_odt == 0u) {
                return error(x, ERR_DAQ_CONFIG);
            }
            for (o = 0; o < q->n_odt; ++o) { /* every entry written */
                const fw_xcp_odt *t = &x->odt[q->first_odt + o];
                uint8_t e;
                for (e = 0; e < t->n_entries; ++e) {
                    if (x->entry[t->first_entry + e].size == 0u) {
                        return error(x, ERR_DAQ_CONFIG);
                    }
                }
            }
        }
        if (c[1] == 0u) {
            q->running = 0;
            q->selected = 0;
        } else if (c[1] == 1u) {
            q->running = 1;
            q->countdown = 1;
        } else {
            q->selected = 1;
        }
        compile_daq(x);
        x->pkt[1] = q->first_odt;
        return respond(x, 2u);
    }
    case CC_START_STOP_SYNCH: {
        uint8_t k;
        if (len < 2u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        if (c[1] > 2u) {
            return error(x, ERR_OUT_OF_RANGE);
        }
        for (k = 0; k < x->n_daq; ++k) {
            fw_xcp_daq *q = &x->daq[k];
            if (c[1] == 0u) {
                q->running = 0;
            } else if (q->selected) {
                q->running = c[1] == 1u;
                q->countdown = 1;
            }
            q->selected = 0;
        }
        compile_daq(x);
        return respond(x, 1u);
    }
    default:
        return error(x, ERR_CMD_UNKNOWN);
    }
}

fw_status fw_xcp_on_command(fw_xcp *x, fw_app *app, const uint8_t *c, size_t len, uint64_t now_ns)
{
    if (x == NULL || app == NULL || (c == NULL && len != 0u)) {
        return FW_E_NULL;
    }
    if (x->magic != FW_XCP_MAGIC) {
        return FW_E_NOT_INIT;
    }
    if (len == 0u || len > FW_XCP_MAX_CTO) {
        return x->connected ? error(x, ERR_CMD_SYNTAX) : FW_E_STATE;
    }
    if (c[0] == CC_CONNECT) {
        return cmd_connect(x, app, c, len);
    }
    if (!x->connected) {
        return FW_E_STATE; /* the standard: a slave not connected stays silent */
    }
    switch (c[0]) {
    case CC_DISCONNECT:
        disconnect(x);
        return respond(x, 1u);
    case CC_GET_STATUS:
        x->pkt[1] = daq_running(x) ? 0x40u : 0x00u;
        x->pkt[2] = x->protection;
        x->pkt[3] = 0u;
        wr16(x->pkt + 4, 0u);
        return respond(x, 6u);
    case CC_SYNCH:
        return error(x, ERR_CMD_SYNCH);
    case CC_GET_COMM_MODE_INFO:
        x->pkt[1] = 0u;
        x->pkt[2] = 0u; /* no master block mode, no interleaving */
        x->pkt[3] = 0u;
        x->pkt[4] = 0u;
        x->pkt[5] = 0u;
        x->pkt[6] = 0u;
        x->pkt[7] = 0x10u; /* driver version 1.0 */
        return respond(x, 8u);
    case CC_GET_ID:
        if (len < 2u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        x->pkt[1] = 0u; /* upload from the MTA */
        x->pkt[2] = 0u;
        x->pkt[3] = 0u;
        if (c[1] == 0u || c[1] == 1u) {
            x->mta_ext = FW_XCP_EXT_ID;
            x->mta = 0;
            wr32(x->pkt + 4, (uint32_t)(sizeof(FW_XCP_A2L_NAME) - 1u));
        } else {
            wr32(x->pkt + 4, 0u); /* not available */
        }
        return respond(x, 8u);
    case CC_GET_SEED:
        return cmd_get_seed(x, c, len, now_ns);
    case CC_UNLOCK:
        return cmd_unlock(x, c, len);
    case CC_SET_MTA:
        if (len < 8u) {
            return error(x, ERR_CMD_SYNTAX);
        }
        x->mta_ext = c[3];
        x->mta = rd32(c + 4);
        return respond(x, 1u);
    case CC_UPLOAD:
    case CC_SHORT_UPLOAD:
        /* Without DAQ the step event leaves the signals alone: they are
         * refreshed here, between steps, from the same identifier state. */
        if (!daq_running(x)) {
            refresh(x, app);
        }
        return c[0] == CC_UPLOAD ? cmd_upload(x, c, len) : cmd_short_upload(x, c, len);
    case CC_DOWNLOAD:
        return cmd_download(x, app, c, len);
    default:
        return cmd_daq(x, c, len, now_ns);
    }
}
