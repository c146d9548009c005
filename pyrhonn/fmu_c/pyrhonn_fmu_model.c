/*
 * pyrhonn_fmu_model.c - the identifier as a co-simulation model: its
 * variables, its fixed communication step and its reset, shared by the
 * FMI 3.0 (pyrhonn_fmi3.c) and FMI 2.0 (pyrhonn_fmi2.c) interfaces.
 *
 * Compiled as one translation unit with the core (the FMU's <id>_fmu.c
 * includes rhonn.c, the exported configuration, the generated model header,
 * this file and one interface). The model header defines:
 *   FMU_CONFIG      the exported static const rhonn_config
 *   FMU_WARM        (optional) its exported running state: the model starts,
 *                   and a reset returns, there (rhonn_warm_start)
 *   FMU_N, FMU_M    states and inputs
 *   FMU_PERIOD      the sample period: the only communication step size
 *   FMU_LEARNING0, FMU_MODE0   the parameters' start values
 *   FMU_TOKEN       the instantiation token (FMI 3) or GUID (FMI 2)
 *   fmu_state_names, fmu_input_names   for log messages
 * and the interface defines fmu_emit (a message to the importer's logger).
 *
 * One communication step is one identifier step (rhonn_step): doStep at
 * time t with the inputs set for t (the measured states x(k), their valid
 * flags and the plant inputs u(k)) learns x(k) and predicts xhat(k+1), which
 * the outputs hold at t + period. In simulator mode every state is stepped
 * as not measured, so the network runs on its own predictions (a free run,
 * learning nothing); the measured inputs are then ignored.
 */
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Value references: one block per kind of variable, entry j of a block is
 * state (or input) j. */
#define FMU_VR_TIME 0u
#define FMU_VR_LEARNING 1u
#define FMU_VR_MODE 2u
#define FMU_VR_X 1000u
#define FMU_VR_VALID 2000u
#define FMU_VR_U 3000u
#define FMU_VR_XHAT 4000u
#define FMU_VR_NIS 5000u
#define FMU_VR_TRACE_P 6000u
#define FMU_VR_REFUSED 7000u

#define FMU_OBSERVER 0
#define FMU_SIMULATOR 1

#define FMU_M1 (FMU_M > 0 ? FMU_M : 1)

typedef enum { FMU_INSTANTIATED, FMU_INITIALIZING, FMU_STEPPING, FMU_TERMINATED } fmu_phase;
typedef enum { FMU_RESULT_OK, FMU_RESULT_WARNING, FMU_RESULT_ERROR } fmu_result;

typedef struct fmu_model {
    rhonn_t net;
    double x[FMU_N];        /* measured states, as set */
    int valid[FMU_N];       /* their valid flags */
    double u[FMU_M1];       /* plant inputs (unused when FMU_M is 0) */
    double xhat[FMU_N];     /* outputs */
    double nis[FMU_N];
    double trace_p[FMU_N];
    int refused[FMU_N];
    int learning;           /* parameters */
    int mode;
    double start_time;
    double time;
    unsigned long long steps;  /* communication steps since initialisation */
    fmu_phase phase;
    /* the interface's logger */
    void *log_env;
    void *log_fn;
    int log_on;
    char name[128];
} fmu_model;

static void fmu_emit(const fmu_model *m, fmu_result result, const char *message);

static void fmu_logf(const fmu_model *m, fmu_result result, const char *format, ...)
{
    char text[512];
    va_list args;
    va_start(args, format);
    (void)vsnprintf(text, sizeof text, format, args);
    va_end(args);
    fmu_emit(m, result, text);
}

/* The outputs from the identifier: xhat(k), and each neuron's health. */
static fmu_result fmu_read_outputs(fmu_model *m)
{
    rhonn_real xhat[FMU_N];
    size_t i;
    if (rhonn_get_prediction(&m->net, xhat, FMU_N) != RHONN_OK) {
        fmu_logf(m, FMU_RESULT_ERROR, "the prediction could not be read");
        return FMU_RESULT_ERROR;
    }
    for (i = 0; i < FMU_N; ++i) {
        rhonn_health h;
        if (rhonn_get_health(&m->net, i, &h) != RHONN_OK) {
            fmu_logf(m, FMU_RESULT_ERROR, "%s: the health could not be read", fmu_state_names[i]);
            return FMU_RESULT_ERROR;
        }
        m->xhat[i] = (double)xhat[i];
        m->nis[i] = (double)h.nis;
        m->trace_p[i] = (double)h.trace_p;
        m->refused[i] = h.rejected > (uint32_t)INT_MAX ? INT_MAX : (int)h.rejected;
    }
    return FMU_RESULT_OK;
}

/* As instantiated: the configuration's starting point (or the exported
 * running state), health counters at zero, every variable at its start
 * value. */
static fmu_result fmu_start(fmu_model *m)
{
    size_t j;
    rhonn_config_error where = {0, 0, 0, 0};
#ifdef FMU_WARM
    rhonn_status st = rhonn_warm_start(&m->net, &FMU_CONFIG, &FMU_WARM, &where);
#else
    rhonn_status st = rhonn_init(&m->net, &FMU_CONFIG, &where);
#endif
    if (st != RHONN_OK) {
        fmu_logf(m, FMU_RESULT_ERROR, "the exported configuration or running state was refused by the core (%s, "
                 "field %u of neuron %u)", rhonn_status_name(st), (unsigned)where.field, (unsigned)where.neuron);
        return FMU_RESULT_ERROR;
    }
    for (j = 0; j < FMU_N; ++j) {
        m->x[j] = (double)FMU_CONFIG.x0[j];
        m->valid[j] = 1;
    }
    for (j = 0; j < FMU_M1; ++j) {
        m->u[j] = 0.0;
    }
    m->learning = FMU_LEARNING0;
    m->mode = FMU_MODE0;
    m->start_time = 0.0;
    m->time = 0.0;
    m->steps = 0;
    m->phase = FMU_INSTANTIATED;
    return fmu_read_outputs(m);
}

static fmu_model *fmu_new(const char *name, void *log_env, void *log_fn, int log_on)
{
    fmu_model *m = (fmu_model *)calloc(1, sizeof *m);
    if (m == NULL) {
        return NULL;
    }
    m->log_env = log_env;
    m->log_fn = log_fn;
    m->log_on = log_on;
    (void)snprintf(m->name, sizeof m->name, "%s", name != NULL ? name : "");
    if (fmu_start(m) != FMU_RESULT_OK) {
        free(m);
        return NULL;
    }
    return m;
}

static int fmu_index(unsigned vr, unsigned base, unsigned count, size_t *j)
{
    if (vr >= base && vr < base + count) {
        *j = (size_t)(vr - base);
        return 1;
    }
    return 0;
}

static fmu_result fmu_unknown(const fmu_model *m, unsigned vr, const char *what)
{
    fmu_logf(m, FMU_RESULT_ERROR, "value reference %u is not a %s variable of this FMU", vr, what);
    return FMU_RESULT_ERROR;
}

static fmu_result fmu_get_real(const fmu_model *m, unsigned vr, double *value, int with_time)
{
    size_t j;
    if (with_time && vr == FMU_VR_TIME) {
        *value = m->time;
    } else if (fmu_index(vr, FMU_VR_X, FMU_N, &j)) {
        *value = m->x[j];
    } else if (fmu_index(vr, FMU_VR_U, FMU_M, &j)) {
        *value = m->u[j];
    } else if (fmu_index(vr, FMU_VR_XHAT, FMU_N, &j)) {
        *value = m->xhat[j];
    } else if (fmu_index(vr, FMU_VR_NIS, FMU_N, &j)) {
        *value = m->nis[j];
    } else if (fmu_index(vr, FMU_VR_TRACE_P, FMU_N, &j)) {
        *value = m->trace_p[j];
    } else {
        return fmu_unknown(m, vr, "Float64 (Real)");
    }
    return FMU_RESULT_OK;
}

static fmu_result fmu_get_int(const fmu_model *m, unsigned vr, int *value)
{
    size_t j;
    if (vr == FMU_VR_MODE) {
        *value = m->mode;
    } else if (fmu_index(vr, FMU_VR_REFUSED, FMU_N, &j)) {
        *value = m->refused[j];
    } else {
        return fmu_unknown(m, vr, "Int32 (Integer)");
    }
    return FMU_RESULT_OK;
}

static fmu_result fmu_get_bool(const fmu_model *m, unsigned vr, int *value)
{
    size_t j;
    if (vr == FMU_VR_LEARNING) {
        *value = m->learning;
    } else if (fmu_index(vr, FMU_VR_VALID, FMU_N, &j)) {
        *value = m->valid[j];
    } else {
        return fmu_unknown(m, vr, "Boolean");
    }
    return FMU_RESULT_OK;
}

static fmu_result fmu_set_real(fmu_model *m, unsigned vr, double value)
{
    size_t j;
    if (fmu_index(vr, FMU_VR_X, FMU_N, &j)) {
        m->x[j] = value;  /* checked when stepped: a state set not valid may be anything */
    } else if (fmu_index(vr, FMU_VR_U, FMU_M, &j)) {
        m->u[j] = value;
    } else {
        return fmu_unknown(m, vr, "settable Float64 (Real)");
    }
    return FMU_RESULT_OK;
}

static fmu_result fmu_set_int(fmu_model *m, unsigned vr, int value)
{
    if (vr != FMU_VR_MODE) {
        return fmu_unknown(m, vr, "settable Int32 (Integer)");
    }
    if (value != FMU_OBSERVER && value != FMU_SIMULATOR) {
        fmu_logf(m, FMU_RESULT_ERROR, "mode: %d is not a mode (0 = observer, 1 = simulator)", value);
        return FMU_RESULT_ERROR;
    }
    m->mode = value;
    return FMU_RESULT_OK;
}

static fmu_result fmu_set_bool(fmu_model *m, unsigned vr, int value)
{
    size_t j;
    if (vr == FMU_VR_LEARNING) {
        m->learning = value != 0;
    } else if (fmu_index(vr, FMU_VR_VALID, FMU_N, &j)) {
        m->valid[j] = value != 0;
    } else {
        return fmu_unknown(m, vr, "settable Boolean");
    }
    return FMU_RESULT_OK;
}

static fmu_result fmu_enter_initialization(fmu_model *m, double start_time)
{
    if (m->phase != FMU_INSTANTIATED) {
        fmu_logf(m, FMU_RESULT_ERROR, "enter initialization mode: only once after instantiation or reset");
        return FMU_RESULT_ERROR;
    }
    if (!isfinite(start_time)) {
        fmu_logf(m, FMU_RESULT_ERROR, "startTime: not a finite number");
        return FMU_RESULT_ERROR;
    }
    m->start_time = start_time;
    m->time = start_time;
    m->phase = FMU_INITIALIZING;
    return FMU_RESULT_OK;
}

static fmu_result fmu_exit_initialization(fmu_model *m)
{
    if (m->phase != FMU_INITIALIZING) {
        fmu_logf(m, FMU_RESULT_ERROR, "exit initialization mode: not in initialization mode");
        return FMU_RESULT_ERROR;
    }
    m->phase = FMU_STEPPING;
    return FMU_RESULT_OK;
}

/* One communication step of exactly the period, from the instance's own
 * time: one identifier step. */
static fmu_result fmu_do_step(fmu_model *m, double t, double h)
{
    rhonn_real x[FMU_N], u[FMU_M1], xhat[FMU_N];
    uint8_t valid[FMU_N];
    rhonn_status st;
    fmu_result result = FMU_RESULT_OK;
    size_t j;
    const double tol = 1e-6 * FMU_PERIOD;
    if (m->phase != FMU_STEPPING) {
        fmu_logf(m, FMU_RESULT_ERROR, "doStep: not in step mode (initialise first)");
        return FMU_RESULT_ERROR;
    }
    if (!(fabs(h - FMU_PERIOD) <= tol)) {
        fmu_logf(m, FMU_RESULT_ERROR, "communicationStepSize %.17g: this FMU steps only at the identifier's sample "
                 "period %.17g (one communication step is one identifier step)", h, FMU_PERIOD);
        return FMU_RESULT_ERROR;
    }
    if (!(fabs(t - m->time) <= tol + 1e-12 * fabs(m->time))) {
        fmu_logf(m, FMU_RESULT_ERROR, "currentCommunicationPoint %.17g: the instance is at time %.17g (steps are "
                 "taken one period after the other)", t, m->time);
        return FMU_RESULT_ERROR;
    }
    for (j = 0; j < FMU_N; ++j) {
        valid[j] = (uint8_t)(m->mode == FMU_OBSERVER && m->valid[j]);
        x[j] = (rhonn_real)m->x[j];
        if (valid[j] && !isfinite(x[j])) {
            fmu_logf(m, FMU_RESULT_ERROR, "%s = %g at time %.17g: a measured state must be finite%s (set %s_valid "
                     "false for a missing sample)", fmu_state_names[j], m->x[j], t,
                     isfinite(m->x[j]) ? " in the FMU's precision" : "", fmu_state_names[j]);
            return FMU_RESULT_ERROR;
        }
    }
#if FMU_M > 0
    for (j = 0; j < FMU_M; ++j) {
        u[j] = (rhonn_real)m->u[j];
        if (!isfinite(u[j])) {
            fmu_logf(m, FMU_RESULT_ERROR, "%s = %g at time %.17g: an input must be finite%s", fmu_input_names[j],
                     m->u[j], t, isfinite(m->u[j]) ? " in the FMU's precision" : "");
            return FMU_RESULT_ERROR;
        }
    }
#endif
    (void)rhonn_set_learning(&m->net, m->learning);
    st = rhonn_step(&m->net, x, FMU_M > 0 ? u : NULL, valid, xhat);
    if (st != RHONN_OK && m->learning) {
        /* A refused learning update (counted in <state>_refused): the sample
         * is predicted from the weights as they are, learning nothing. */
        fmu_logf(m, FMU_RESULT_WARNING, "time %.17g: the learning update was refused (%s); this sample is stepped "
                 "with learning frozen", t, rhonn_status_name(st));
        result = FMU_RESULT_WARNING;
        (void)rhonn_set_learning(&m->net, 0);
        st = rhonn_step(&m->net, x, FMU_M > 0 ? u : NULL, valid, xhat);
        (void)rhonn_set_learning(&m->net, 1);
    }
    if (st != RHONN_OK) {
        fmu_logf(m, FMU_RESULT_ERROR, "time %.17g: the identifier refused the step (%s)", t, rhonn_status_name(st));
        return FMU_RESULT_ERROR;
    }
    m->steps += 1;
    m->time = m->start_time + (double)m->steps * FMU_PERIOD;
    if (fmu_read_outputs(m) != FMU_RESULT_OK) {
        return FMU_RESULT_ERROR;
    }
    return result;
}
