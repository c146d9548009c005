/*
 * rhonn.c - the RHONN identifier and its per-neuron EKF (see rhonn.h).
 *
 * Built twice from this one source: double (default) and float
 * (-DRHONN_SINGLE). Build with -std=c99 -ffp-contract=off so that every
 * IEEE-754 target rounds the same operations in the same order.
 */
#include "rhonn.h"
#include "rhonn_internal.h"

/* Beyond this, exp(-a) is below the smallest normal float (double): return 0. */
#ifdef RHONN_SINGLE
#define RHONN_EXP_CUTOFF 87.0f
#else
#define RHONN_EXP_CUTOFF 708.0
#endif

#if defined(__GNUC__) || defined(__clang__)
#define RHONN_RESTRICT __restrict__
#else
#define RHONN_RESTRICT restrict
#endif

/* RHONN_UNROLL=1 compiles one fully unrolled EKF kernel per neuron size
 * L = 1..RHONN_MAX_TERMS (eq. 7-8 with L a constant: no loop overhead, z and
 * P z in registers). The unrolled and the generic kernel perform the same
 * floating-point operations in the same order, so their results are
 * bit-identical; only speed and code size differ (x86-64, -O2: about 9 kB of
 * .text for the generic core, 85 kB unrolled with RHONN_MAX_TERMS = 16).
 * Sizes above 16 (research capacities) run the generic kernel either way.
 * 0, the default, keeps the core small for firmware; the Python extension
 * unrolls. */
#ifndef RHONN_UNROLL
#define RHONN_UNROLL 0
#endif
#if RHONN_UNROLL && (defined(__GNUC__) || defined(__clang__))
#define RHONN_INLINE static __inline__ __attribute__((always_inline))
#define RHONN_UNROLL_LOOP _Pragma("GCC unroll 16")
#else
#define RHONN_INLINE static
#define RHONN_UNROLL_LOOP
#endif

/* Kept out of line (GCC, clang): the accessors' one copy of a factorisation
 * that the unrolled build would otherwise inline, unrolled, at each call. */
#if defined(__GNUC__) || defined(__clang__)
#define RHONN_NOINLINE __attribute__((noinline))
#else
#define RHONN_NOINLINE
#endif

/* RHONN_CERTIFY=0 (tests) always factorises a full-form P: CTest holds it
 * to the default build, which proves most covariances without factorising,
 * and requires the same verdict and the same bits. */
#ifndef RHONN_CERTIFY
#define RHONN_CERTIFY 1
#endif

/* RHONN_CALIBRATE=1 (the default): the trace ceilings and gates in force
 * are rhonn_t's, which the setters change; 0: the configuration's (rhonn.h). */
#ifndef RHONN_CALIBRATE
#define RHONN_CALIBRATE 1
#endif

/* RHONN_WITH_UD=1 (the default) builds the factored covariance update
 * (RHONN_COV_UD); 0 leaves it out for the smallest code, and a config that
 * asks for it is refused as RHONN_FIELD_COVARIANCE. */
#ifndef RHONN_WITH_UD
#define RHONN_WITH_UD 1
#endif

/* Finite: the exponent field is not all ones (NaN and +-Inf have it). An
 * integer test on the bits: no floating-point operation, so no exception
 * flags and no FPU round trip; portable without isfinite() (which needs C99
 * libm macros some freestanding targets lack). */
#ifdef RHONN_SINGLE
typedef uint32_t rhonn_bits;
#define RHONN_EXP_MASK 0x7F800000UL
#else
typedef uint64_t rhonn_bits;
#define RHONN_EXP_MASK 0x7FF0000000000000ULL
#endif

static rhonn_bits bits_of(rhonn_real v)
{
    union { rhonn_real f; rhonn_bits u; } b;
    b.f = v;
    return b.u;
}

static int is_finite(rhonn_real v)
{
    return (bits_of(v) & (rhonn_bits)RHONN_EXP_MASK) != (rhonn_bits)RHONN_EXP_MASK;
}

/* ------------------------------------------------------------------------ */
/* The core's own exp: exp(-a) = 2^-k * exp(-r), a = k ln2 + r, |r| <= ln2/2.
 * Same bits on glibc and newlib targets, which a libm exp cannot promise. */

/* The bodies of rhonn_exp_neg and rhonn_activate, inlined into the step's
 * S(x) loop (a call per state was a tenth of its cost on the Cortex-M4). */
RHONN_INLINE rhonn_real exp_neg(rhonn_real a)
{
    /* ln2 split in a high part with trailing zero bits, so k * LN2_HI is
     * exact for the k this range reduction produces (Cody-Waite). */
#ifdef RHONN_SINGLE
    const float LN2_HI = 6.9314575195e-1f;
    const float LN2_LO = 1.4286067653e-6f;
    const float INV_LN2 = 1.4426950409e+0f;
    union { float f; uint32_t u; } scale;
#else
    const double LN2_HI = 6.93147180369123816490e-01;
    const double LN2_LO = 1.90821492927058770002e-10;
    const double INV_LN2 = 1.44269504088896338700e+00;
    union { double f; uint64_t u; } scale;
#endif
    rhonn_real r, r2, r4, p;
    int k;

    if (a != a) {
        return a;
    }
    if (a <= R(0.0)) {
        return R(1.0);
    }
    if (a > RHONN_EXP_CUTOFF) {
        return R(0.0);
    }
    k = (int)(a * INV_LN2 + R(0.5));
    /* exp(-a) = 2^-k exp(r), r = k ln2 - a in [-ln2/2, ln2/2] */
    r = ((rhonn_real)k * LN2_HI - a) + (rhonn_real)k * LN2_LO;
    r2 = r * r;
    r4 = r2 * r2;
    /* Taylor polynomial of exp(r), degree chosen so the truncation error is
     * below half an ulp, evaluated in Estrin form: short dependency chains
     * instead of one long Horner chain. */
#ifdef RHONN_SINGLE
    p = ((R(1.0) + r) + r2 * (R(0.5) + r * R(1.6666667163e-1)))
        + r4 * ((R(4.1666667908e-2) + r * R(8.3333337680e-3))
                + r2 * (R(1.3888889225e-3) + r * R(1.9841270114e-4)));
    /* 2^-k built from its bits: exact, and k <= 126 keeps it normal */
    scale.u = (uint32_t)(127 - k) << 23;
#else
    {
        const rhonn_real r8 = r4 * r4;
        p = (((R(1.0) + r) + r2 * (R(0.5) + r * 1.66666666666666657415e-01))
             + r4 * ((4.16666666666666643537e-02 + r * 8.33333333333333321769e-03)
                     + r2 * (1.38888888888888894189e-03 + r * 1.98412698412698412526e-04)))
            + r8 * (((2.48015873015873015658e-05 + r * 2.75573192239858925110e-06)
                     + r2 * (2.75573192239858882740e-07 + r * 2.50521083854417202239e-08))
                    + r4 * (2.08767569878680989792e-09 + r * 1.60590438368216145994e-10));
    }
    /* 2^-k built from its bits: exact, and k <= 1022 keeps it normal */
    scale.u = (uint64_t)(1023 - k) << 52;
#endif
    return p * scale.f;
}

rhonn_real rhonn_exp_neg(rhonn_real a)
{
    return exp_neg(a);
}

RHONN_INLINE rhonn_real activate(uint8_t activation, rhonn_real beta, rhonn_real s)
{
    /* t = exp(-beta |s|) lies in (0, 1], so neither form can overflow. */
    rhonn_real bs = beta * s;
    rhonn_real t = exp_neg(bs < R(0.0) ? -bs : bs);
    if (activation == (uint8_t)RHONN_BIPOLAR) {
        /* eq. 19: (1 - e^-bs) / (1 + e^-bs) is odd in s */
        rhonn_real v = (R(1.0) - t) / (R(1.0) + t);
        return bs < R(0.0) ? -v : v;
    }
    /* eq. 6: 1 / (1 + e^-bs), and e^bs / (1 + e^bs) for bs < 0 */
    return bs < R(0.0) ? t / (R(1.0) + t) : R(1.0) / (R(1.0) + t);
}

rhonn_real rhonn_activate(uint8_t activation, rhonn_real beta, rhonn_real s)
{
    return activate(activation, beta, s);
}

/* ------------------------------------------------------------------------ */
/* Configuration */

static rhonn_status config_error(rhonn_config_error *where, rhonn_field field, size_t neuron,
                                 size_t term, size_t factor)
{
    if (where != NULL) {
        where->field = (uint8_t)field;
        where->neuron = (uint8_t)neuron;
        where->term = (uint8_t)term;
        where->factor = (uint8_t)factor;
    }
    return RHONN_E_CONFIG;
}

static size_t packed_size(size_t L)
{
    return L * (L + 1u) / 2u;
}

RHONN_INLINE int pd_check(const rhonn_real *RHONN_RESTRICT P, const size_t L);
RHONN_NOINLINE static int accessor_check(const rhonn_real *P, size_t L, rhonn_real shift);
static rhonn_real full_trace(const rhonn_real *P, size_t L);

/* 1 when some neuron's entry of a table in force (trace_max, gate) is set. */
static uint8_t any_positive(const rhonn_real *table, size_t n)
{
    uint8_t any = 0u;
    size_t i;
    for (i = 0; i < n; ++i) {
        any = (uint8_t)(any | (table[i] > R(0.0)));
    }
    return any;
}

/* A neuron's trace ceiling p_trace_max is 0 (none) or at least trace P_i(0)
 * (rhonn.h WINDUP PROTECTION): rhonn_validate_config and
 * rhonn_set_trace_ceiling apply this one rule. */
static int trace_ceiling_ok(const rhonn_neuron_config *nc, rhonn_real value)
{
    return is_finite(value) && value >= R(0.0) && !(value > R(0.0) && value < full_trace(nc->p0, nc->n_terms));
}
static void load_p0(const rhonn_t *net, size_t i, rhonn_real *dst);
static uint8_t p0_proven(const rhonn_neuron_config *nc);
#if RHONN_WITH_UD
static int udu_of(const rhonn_real *P, rhonn_real *F, size_t L);
#endif

/* Where a factor's value sits in a sample (RHONN_SAMPLE_LEN layout: x, then
 * S(x) per activation group, then u, then the constant 1). */
#define OFF_S(g) ((size_t)RHONN_MAX_STATES * (1u + (size_t)(g)))
#define OFF_U ((size_t)RHONN_MAX_STATES * ((size_t)RHONN_MAX_STATES + 1u))
#define OFF_ONE (OFF_U + (size_t)RHONN_MAX_INPUTS)

#if RHONN_MAX_ENTRIES < RHONN_MAX_STATES * RHONN_MAX_TERMS * RHONN_MAX_FACTORS
/* Do factors (i, t, f) and (i2, t2, f2) read the same value, raised to the
 * same power? S factors of neurons whose activation or beta differ do not. */
static int same_value(const rhonn_config *cfg, size_t i, const rhonn_factor *a, size_t i2, const rhonn_factor *b)
{
    const uint8_t da = a->kind == (uint8_t)RHONN_FACTOR_ONE ? 0u : a->delay;
    const uint8_t db = b->kind == (uint8_t)RHONN_FACTOR_ONE ? 0u : b->delay;
    if (a->kind != b->kind || a->index != b->index || da != db || a->power != b->power) {
        return 0;
    }
    return a->kind != (uint8_t)RHONN_FACTOR_S ||
           (cfg->neurons[i].activation == cfg->neurons[i2].activation &&
            cfg->neurons[i].beta == cfg->neurons[i2].beta);
}

/* Does a factor before (i, t, f), in neuron-term-factor order, read the same
 * value? (Counts distinct values without storage, for validation.) */
static int seen_before(const rhonn_config *cfg, size_t i, size_t t, size_t f)
{
    const rhonn_factor *a = &cfg->neurons[i].terms[t].factors[f];
    size_t i2, t2, f2;
    for (i2 = 0; i2 <= i; ++i2) {
        for (t2 = 0; t2 < cfg->neurons[i2].n_terms && (i2 < i || t2 <= t); ++t2) {
            for (f2 = 0; f2 < cfg->neurons[i2].terms[t2].n_factors; ++f2) {
                if (i2 == i && t2 == t && f2 == f) {
                    return 0;
                }
                if (same_value(cfg, i, a, i2, &cfg->neurons[i2].terms[t2].factors[f2])) {
                    return 1;
                }
            }
        }
    }
    return 0;
}
#endif

rhonn_status rhonn_validate_config(const rhonn_config *cfg, rhonn_config_error *where)
{
    size_t n, m, i, t, f, e;

    if (cfg == NULL) {
        return RHONN_E_NULL;
    }
    n = cfg->n_states;
    m = cfg->n_inputs;
    if (n < 1u || n > (size_t)RHONN_MAX_STATES) {
        return config_error(where, RHONN_FIELD_N_STATES, 0, 0, 0);
    }
    if (m > (size_t)RHONN_MAX_INPUTS) {
        return config_error(where, RHONN_FIELD_N_INPUTS, 0, 0, 0);
    }
    for (i = 0; i < n; ++i) {
        if (!is_finite(cfg->x0[i])) {
            return config_error(where, RHONN_FIELD_X0, i, 0, i);
        }
    }
    for (i = 0; i < n; ++i) {
        const rhonn_neuron_config *nc = &cfg->neurons[i];
        size_t L = nc->n_terms;
        size_t pi = 0;

        if (L < 1u || L > (size_t)RHONN_MAX_TERMS) {
            return config_error(where, RHONN_FIELD_N_TERMS, i, 0, 0);
        }
        if (nc->activation != (uint8_t)RHONN_LOGISTIC && nc->activation != (uint8_t)RHONN_BIPOLAR) {
            return config_error(where, RHONN_FIELD_ACTIVATION, i, 0, 0);
        }
        if (!is_finite(nc->beta) || !(nc->beta > R(0.0))) {
            return config_error(where, RHONN_FIELD_BETA, i, 0, 0);
        }
        if (!is_finite(nc->eta) || !(nc->eta > R(0.0))) {
            return config_error(where, RHONN_FIELD_ETA, i, 0, 0);
        }
        if (!is_finite(nc->r) || !(nc->r > R(0.0))) {
            return config_error(where, RHONN_FIELD_R, i, 0, 0);
        }
        for (t = 0; t < L; ++t) {
            if (!is_finite(nc->q[t]) || !(nc->q[t] >= R(0.0))) {
                return config_error(where, RHONN_FIELD_Q, i, t, t);
            }
            if (!is_finite(nc->w0[t])) {
                return config_error(where, RHONN_FIELD_W0, i, t, t);
            }
        }
        for (t = 0; t < L; ++t) {
            for (e = t; e < L; ++e, ++pi) {
                rhonn_real v = nc->p0[pi];
                if (!is_finite(v) || (e == t && !(v > R(0.0)))) {
                    return config_error(where, RHONN_FIELD_P0, i, t, e);
                }
            }
        }
        /* P0 is a covariance (eq. 10): positive definite at this precision
         * (and, kept as U D U^T, its factors are normal numbers) */
        if (!accessor_check(nc->p0, L, R(0.0))) { /* pd_check */
            return config_error(where, RHONN_FIELD_P0, i, 0, 0);
        }
#if RHONN_WITH_UD
        if (nc->covariance == (uint8_t)RHONN_COV_UD) {
            rhonn_real F[RHONN_MAX_PACKED];
            if (!udu_of(nc->p0, F, L)) {
                return config_error(where, RHONN_FIELD_P0, i, 0, 0);
            }
        }
#endif
        if (nc->covariance != (uint8_t)RHONN_COV_FULL &&
            (nc->covariance != (uint8_t)RHONN_COV_UD || !RHONN_WITH_UD)) {
            return config_error(where, RHONN_FIELD_COVARIANCE, i, 0, 0);
        }
        if (!is_finite(nc->forgetting) || nc->forgetting < R(0.0) || nc->forgetting > R(1.0)) {
            return config_error(where, RHONN_FIELD_FORGETTING, i, 0, 0);
        }
        if (!trace_ceiling_ok(nc, nc->p_trace_max)) {
            return config_error(where, RHONN_FIELD_P_TRACE_MAX, i, 0, 0);
        }
        if (!is_finite(nc->gate) || nc->gate < R(0.0)) {
            return config_error(where, RHONN_FIELD_GATE, i, 0, 0);
        }
        if (nc->skip_refused > 1u) {
            return config_error(where, RHONN_FIELD_SKIP_REFUSED, i, 0, 0);
        }
        if (nc->wait_for_history > 1u) {
            return config_error(where, RHONN_FIELD_WAIT_FOR_HISTORY, i, 0, 0);
        }
        for (t = 0; t < L; ++t) {
            const rhonn_term *term = &nc->terms[t];
            if (term->n_factors < 1u || term->n_factors > (size_t)RHONN_MAX_FACTORS) {
                return config_error(where, RHONN_FIELD_N_FACTORS, i, t, 0);
            }
            for (f = 0; f < term->n_factors; ++f) {
                const rhonn_factor *fa = &term->factors[f];
                if (fa->power < 1u || fa->power > (size_t)RHONN_MAX_POWER) {
                    return config_error(where, RHONN_FIELD_FACTOR_POWER, i, t, f);
                }
                switch (fa->kind) {
                case RHONN_FACTOR_S:
                case RHONN_FACTOR_X:
                    if (fa->index >= n) {
                        return config_error(where, RHONN_FIELD_FACTOR_INDEX, i, t, f);
                    }
                    if (fa->delay > (size_t)RHONN_MAX_DELAY) {
                        return config_error(where, RHONN_FIELD_FACTOR_DELAY, i, t, f);
                    }
                    break;
                case RHONN_FACTOR_U:
                    if (fa->index >= m) {
                        return config_error(where, RHONN_FIELD_FACTOR_INDEX, i, t, f);
                    }
                    if (fa->delay > (size_t)RHONN_MAX_DELAY) {
                        return config_error(where, RHONN_FIELD_FACTOR_DELAY, i, t, f);
                    }
                    break;
                case RHONN_FACTOR_ONE:
                    if (fa->index != 0u) {
                        return config_error(where, RHONN_FIELD_FACTOR_INDEX, i, t, f);
                    }
                    if (fa->delay != 0u) {
                        return config_error(where, RHONN_FIELD_FACTOR_DELAY, i, t, f);
                    }
                    break;
                default:
                    return config_error(where, RHONN_FIELD_FACTOR_KIND, i, t, f);
                }
            }
        }
    }
#if RHONN_MAX_ENTRIES < RHONN_MAX_STATES * RHONN_MAX_TERMS * RHONN_MAX_FACTORS
    /* A lowered RHONN_MAX_ENTRIES: the distinct factor values must fit. */
    {
        size_t count = 0;
        for (i = 0; i < n; ++i) {
            for (t = 0; t < cfg->neurons[i].n_terms; ++t) {
                for (f = 0; f < cfg->neurons[i].terms[t].n_factors; ++f) {
                    if (!seen_before(cfg, i, t, f) && ++count > (size_t)RHONN_MAX_ENTRIES) {
                        return config_error(where, RHONN_FIELD_N_FACTORS, i, t, f);
                    }
                }
            }
        }
    }
#endif
    if (where != NULL) {
        where->field = (uint8_t)RHONN_FIELD_NONE;
        where->neuron = 0;
        where->term = 0;
        where->factor = 0;
    }
    return RHONN_OK;
}

/* A neuron's constants derived from its configuration: 1 / forgetting (0
 * when off), the smallest Q entry (for the definiteness proof), whether Q
 * is all zero (nothing to add). rhonn_init keeps them in rhonn_t; with
 * RHONN_FIXED_CONFIG the kernels take them from here, where the compiler
 * folds them into constants. */
RHONN_INLINE rhonn_real inverse_forgetting(const rhonn_neuron_config *nc)
{
    return (nc->forgetting > R(0.0) && nc->forgetting < R(1.0)) ? R(1.0) / nc->forgetting : R(0.0);
}

RHONN_INLINE rhonn_real q_min_of(const rhonn_neuron_config *nc)
{
    rhonn_real qm = nc->q[0];
    size_t t;
    RHONN_NEURON_LOOP
    for (t = 1; t < nc->n_terms; ++t) {
        qm = nc->q[t] < qm ? nc->q[t] : qm;
    }
    return qm;
}

/* c_i, the ceiling of bounded forgetting (rhonn.h WINDUP PROTECTION):
 * p_trace_max when set, else trace P_i(0) as full_trace sums it. rhonn_init
 * keeps it in rhonn_t (also with RHONN_FIXED_CONFIG: a load where a
 * neuron forgets, nothing where it does not). */
RHONN_NOINLINE static rhonn_real forget_ceiling_of(const rhonn_neuron_config *nc, rhonn_real p_trace_max)
{
    return p_trace_max > R(0.0) ? p_trace_max : full_trace(nc->p0, nc->n_terms);
}

RHONN_INLINE uint8_t q_zero_of(const rhonn_neuron_config *nc)
{
    uint8_t zero = 1u;
    size_t t;
    RHONN_NEURON_LOOP
    for (t = 0; t < nc->n_terms; ++t) {
        zero = (uint8_t)(zero && nc->q[t] == R(0.0));
    }
    return zero;
}

#ifdef RHONN_FIXED_CONFIG
#define INV_LAMBDA(net, i) inverse_forgetting(&CFG(net)->neurons[i])
#define Q_MIN(net, i) q_min_of(&CFG(net)->neurons[i])
#define Q_ZERO(net, i) q_zero_of(&CFG(net)->neurons[i])
#else
#define INV_LAMBDA(net, i) ((net)->inv_lambda[i])
#define Q_MIN(net, i) ((net)->q_min[i])
#define Q_ZERO(net, i) ((net)->q_zero[i])
#endif

#define FORGET_CEILING(net, i) ((net)->forget_ceiling[i])

/* The gate and the trace ceiling in force. RHONN_CALIBRATE=1 (rhonn.h):
 * rhonn_t's (rhonn_set_gate, rhonn_set_trace_ceiling can set one where the
 * configuration had none, also with RHONN_FIXED_CONFIG), each behind one
 * test of a flag (rhonn_t.gates, .ceilings: some neuron has one in force),
 * so that an identifier without them pays little. RHONN_CALIBRATE=0: the
 * configuration's, which RHONN_FIXED_CONFIG folds into constants (a neuron
 * without a gate or a ceiling then has no code for it), as before the
 * setters existed. */
#if RHONN_CALIBRATE
#define GATE_ON(net, i) ((net)->gates != 0u)
#define GATE(net, i) ((net)->gate[i])
#define CEILING_ON(net, i) ((net)->ceilings != 0u)
#define TRACE_MAX(net, i) ((net)->trace_max[i])
#else
#ifdef RHONN_FIXED_CONFIG
#define GATE_ON(net, i) (CFG(net)->neurons[i].gate > R(0.0))
#else
#define GATE_ON(net, i) ((net)->gates != 0u)
#endif
#define GATE(net, i) (CFG(net)->neurons[i].gate)
#define CEILING_ON(net, i) 1
#define TRACE_MAX(net, i) (CFG(net)->neurons[i].p_trace_max)
#endif

/* Where a factor's value sits in a sample (its delay and power aside), for
 * a neuron whose activation group is group. */
RHONN_INLINE size_t sample_offset(const rhonn_factor *fa, size_t group)
{
    if (fa->kind == (uint8_t)RHONN_FACTOR_S) {
        return OFF_S(group) + fa->index;
    }
    if (fa->kind == (uint8_t)RHONN_FACTOR_X) {
        return fa->index;
    }
    if (fa->kind == (uint8_t)RHONN_FACTOR_U) {
        return OFF_U + fa->index;
    }
    return OFF_ONE;
}

/* A factor's delay (the constant 1 has none, whatever the field says). */
RHONN_INLINE uint8_t factor_delay(const rhonn_factor *fa)
{
    return fa->kind == (uint8_t)RHONN_FACTOR_ONE ? 0u : fa->delay;
}

/* Is a factor's value this sample's own (no delay, power 1), read in place? */
RHONN_INLINE int in_sample(const rhonn_factor *fa)
{
    return factor_delay(fa) == 0u && fa->power == 1u;
}

/* Compile the terms (eq. 4) into indices of the step's values (see
 * features): a factor of this sample at power 1 is read in place, at its
 * offset in the sample; every other distinct factor value (a delayed tap, a
 * power) is an entry, computed once per step after the sample. So the step
 * reads values by index instead of interpreting factor kinds, and copies
 * nothing for the common factor. The configuration was validated: the
 * entries fit RHONN_MAX_ENTRIES (which counts every distinct factor). */
static void compile_terms(rhonn_t *net)
{
    const rhonn_config *cfg = CFG(net);
    size_t i, t, f, e;
    net->n_entries = 0;
    net->max_delay = 0;
    for (i = 0; i < (size_t)RHONN_MAX_STATES; ++i) {
        net->own_need[i] = 0;
        net->first_run[i] = 0xFFu;
        net->q_min[i] = R(0.0);
        net->inv_lambda[i] = R(0.0);
        net->forget_ceiling[i] = R(0.0);
        net->q_zero[i] = 1u;
        net->trace_max[i] = R(0.0);
        net->gate[i] = R(0.0);
    }
    for (i = 0; i < cfg->n_states; ++i) {
        net->inv_lambda[i] = inverse_forgetting(&cfg->neurons[i]);
        net->forget_ceiling[i] = forget_ceiling_of(&cfg->neurons[i], cfg->neurons[i].p_trace_max);
        net->trace_max[i] = cfg->neurons[i].p_trace_max;
        net->gate[i] = cfg->neurons[i].gate;
        net->q_zero[i] = q_zero_of(&cfg->neurons[i]);
        net->first_run[i] = (uint8_t)(cfg->neurons[i].wait_for_history != 0u ? 0u : 0xFFu);
        net->q_min[i] = q_min_of(&cfg->neurons[i]);
        for (t = 0; t < cfg->neurons[i].n_terms; ++t) {
            for (f = 0; f < cfg->neurons[i].terms[t].n_factors; ++f) {
                const rhonn_factor *fa = &cfg->neurons[i].terms[t].factors[f];
                const uint8_t delay = factor_delay(fa);
                const size_t off = sample_offset(fa, net->group_of[i]);
                if (in_sample(fa)) {
                    net->term_entry[i][t][f] = (uint16_t)off;
                } else {
                    for (e = 0; e < net->n_entries; ++e) {
                        if (net->entry_off[e] == off && net->entry_delay[e] == delay &&
                            net->entry_power[e] == fa->power) {
                            break;
                        }
                    }
                    if (e == net->n_entries && e < (size_t)RHONN_MAX_ENTRIES) {
                        net->entry_off[e] = (uint16_t)off;
                        net->entry_delay[e] = delay;
                        net->entry_power[e] = fa->power;
                        net->n_entries = (uint16_t)(e + 1u);
                    }
                    net->term_entry[i][t][f] = (uint16_t)((size_t)RHONN_SAMPLE_LEN + (e < (size_t)RHONN_MAX_ENTRIES ? e : 0u));
                }
                if (delay > net->max_delay) {
                    net->max_delay = delay;
                }
                if (f + 1u == cfg->neurons[i].terms[t].n_factors) {
                    /* the unused factor slots read the sample's constant 1:
                     * x * 1 is x exactly, and the product needs no per-term
                     * factor count */
                    size_t pad;
                    for (pad = f + 1u; pad < (size_t)RHONN_MAX_FACTORS; ++pad) {
                        net->term_entry[i][t][pad] = (uint16_t)OFF_ONE;
                    }
                }
                if (((fa->kind == (uint8_t)RHONN_FACTOR_S || fa->kind == (uint8_t)RHONN_FACTOR_X) &&
                     fa->index == i) || cfg->neurons[i].wait_for_history != 0u) {
                    if (delay >= net->own_need[i]) { /* wait_for_history: every tap counts */
                        net->own_need[i] = (uint8_t)(delay + 1u);
                    }
                }
            }
        }
    }
    net->gates = any_positive(net->gate, cfg->n_states);
    net->ceilings = any_positive(net->trace_max, cfg->n_states);
}

#ifdef RHONN_FIXED_CONFIG
/* Is cfg the configuration the core was compiled for (RHONN_FIXED_CONFIG)?
 * Field by field, in the order rhonn_validate_config reports them; the first
 * that differs is named. cfg was validated: its counts are within range. */
static rhonn_status fixed_config_matches(const rhonn_config *cfg, rhonn_config_error *where)
{
    const rhonn_config *fx = &RHONN_FIXED_CONFIG;
    size_t i, t, f, k;
    if (cfg->n_states != fx->n_states) {
        return config_error(where, RHONN_FIELD_N_STATES, 0, 0, 0);
    }
    if (cfg->n_inputs != fx->n_inputs) {
        return config_error(where, RHONN_FIELD_N_INPUTS, 0, 0, 0);
    }
    for (i = 0; i < cfg->n_states; ++i) {
        if (bits_of(cfg->x0[i]) != bits_of(fx->x0[i])) {
            return config_error(where, RHONN_FIELD_X0, i, 0, i);
        }
    }
    for (i = 0; i < cfg->n_states; ++i) {
        const rhonn_neuron_config *a = &cfg->neurons[i], *b = &fx->neurons[i];
        if (a->n_terms != b->n_terms) {
            return config_error(where, RHONN_FIELD_N_TERMS, i, 0, 0);
        }
        if (a->activation != b->activation) {
            return config_error(where, RHONN_FIELD_ACTIVATION, i, 0, 0);
        }
        if (bits_of(a->beta) != bits_of(b->beta)) {
            return config_error(where, RHONN_FIELD_BETA, i, 0, 0);
        }
        if (bits_of(a->eta) != bits_of(b->eta)) {
            return config_error(where, RHONN_FIELD_ETA, i, 0, 0);
        }
        if (bits_of(a->r) != bits_of(b->r)) {
            return config_error(where, RHONN_FIELD_R, i, 0, 0);
        }
        for (t = 0; t < a->n_terms; ++t) {
            if (bits_of(a->q[t]) != bits_of(b->q[t])) {
                return config_error(where, RHONN_FIELD_Q, i, t, t);
            }
            if (bits_of(a->w0[t]) != bits_of(b->w0[t])) {
                return config_error(where, RHONN_FIELD_W0, i, t, t);
            }
        }
        for (t = 0, k = 0; t < a->n_terms; ++t) { /* row t of the packed triangle */
            for (f = t; f < a->n_terms; ++f, ++k) {
                if (bits_of(a->p0[k]) != bits_of(b->p0[k])) {
                    return config_error(where, RHONN_FIELD_P0, i, t, k);
                }
            }
        }
        for (t = 0; t < a->n_terms; ++t) {
            if (a->terms[t].n_factors != b->terms[t].n_factors) {
                return config_error(where, RHONN_FIELD_N_FACTORS, i, t, 0);
            }
            for (f = 0; f < a->terms[t].n_factors; ++f) {
                const rhonn_factor *fa = &a->terms[t].factors[f], *fb = &b->terms[t].factors[f];
                if (fa->kind != fb->kind) {
                    return config_error(where, RHONN_FIELD_FACTOR_KIND, i, t, f);
                }
                if (fa->index != fb->index) {
                    return config_error(where, RHONN_FIELD_FACTOR_INDEX, i, t, f);
                }
                if (fa->delay != fb->delay) {
                    return config_error(where, RHONN_FIELD_FACTOR_DELAY, i, t, f);
                }
                if (fa->power != fb->power) {
                    return config_error(where, RHONN_FIELD_FACTOR_POWER, i, t, f);
                }
            }
        }
        if (a->covariance != b->covariance) {
            return config_error(where, RHONN_FIELD_COVARIANCE, i, 0, 0);
        }
        if (bits_of(a->forgetting) != bits_of(b->forgetting)) {
            return config_error(where, RHONN_FIELD_FORGETTING, i, 0, 0);
        }
        if (bits_of(a->p_trace_max) != bits_of(b->p_trace_max)) {
            return config_error(where, RHONN_FIELD_P_TRACE_MAX, i, 0, 0);
        }
        if (a->reset_after != b->reset_after) {
            return config_error(where, RHONN_FIELD_RESET_AFTER, i, 0, 0);
        }
        if (bits_of(a->gate) != bits_of(b->gate)) {
            return config_error(where, RHONN_FIELD_GATE, i, 0, 0);
        }
        if (a->skip_refused != b->skip_refused) {
            return config_error(where, RHONN_FIELD_SKIP_REFUSED, i, 0, 0);
        }
        if (a->wait_for_history != b->wait_for_history) {
            return config_error(where, RHONN_FIELD_WAIT_FOR_HISTORY, i, 0, 0);
        }
    }
    return RHONN_OK;
}
#endif

rhonn_status rhonn_init(rhonn_t *net, const rhonn_config *cfg, rhonn_config_error *where)
{
    rhonn_status st;
    size_t i, g;

    if (net == NULL || cfg == NULL) {
        return RHONN_E_NULL;
    }
    st = rhonn_validate_config(cfg, where);
#ifdef RHONN_FIXED_CONFIG
    if (st == RHONN_OK) {
        st = fixed_config_matches(cfg, where);
    }
#endif
    if (st != RHONN_OK) {
        return st;
    }
#if RHONN_CONST_CONFIG
    net->cfg = cfg; /* the caller's constant: it must outlive net, unchanged */
#else
    net->cfg = *cfg;
#endif
    /* Neurons with the same (activation, beta) see the same S(x_j), so the
     * exps of eq. 6/19 are paid once per group, not once per neuron. */
    net->n_groups = 0;
    for (i = 0; i < cfg->n_states; ++i) {
        const rhonn_neuron_config *nc = &cfg->neurons[i];
        for (g = 0; g < net->n_groups; ++g) {
            if (net->group_activation[g] == nc->activation && net->group_beta[g] == nc->beta) {
                break;
            }
        }
        if (g == net->n_groups) {
            net->group_activation[g] = nc->activation;
            net->group_beta[g] = nc->beta;
            net->n_groups = (uint8_t)(g + 1u);
        }
        net->group_of[i] = (uint8_t)g;
    }
    compile_terms(net);
    for (i = 0; i < (size_t)RHONN_MAX_STATES; ++i) {
        rhonn_health *h = &net->health[i];
        h->innovation = R(0.0);
        h->nis = R(0.0);
        h->trace_p = R(0.0);
        h->updates = 0;
        h->rejected = 0;
        h->resets = 0;
        h->bounded = 0;
        h->gated = 0;
        h->fail_run = 0;
    }
    net->magic = (uint32_t)RHONN_MAGIC;
    return rhonn_reset(net);
}

static rhonn_status check_net(const rhonn_t *net)
{
    if (net == NULL) {
        return RHONN_E_NULL;
    }
    /* The bounds re-check guards against a struct overwritten after init
     * (and lets the compiler see every index below capacity). */
    if (net->magic != (uint32_t)RHONN_MAGIC || CFG(net)->n_states > (uint8_t)RHONN_MAX_STATES ||
        CFG(net)->n_inputs > (uint8_t)RHONN_MAX_INPUTS) {
        return RHONN_E_NOT_INIT;
    }
    return RHONN_OK;
}

rhonn_status rhonn_reset(rhonn_t *net)
{
    rhonn_status st = check_net(net);
    size_t n, i, t, h;

    if (st != RHONN_OK) {
        return st;
    }
    n = CFG(net)->n_states;
    for (i = 0; i < (size_t)RHONN_MAX_STATES; ++i) {
        const rhonn_neuron_config *nc = &CFG(net)->neurons[i];
        net->bank[i] = 0;
        for (t = 0; t < (size_t)RHONN_MAX_TERMS; ++t) {
            net->w[i][0][t] = (i < n && t < nc->n_terms) ? nc->w0[t] : R(0.0);
            net->w[i][1][t] = R(0.0);
            net->z[0][i][t] = R(0.0);
            net->z[1][i][t] = R(0.0);
        }
        for (t = 0; t < (size_t)RHONN_MAX_PACKED; ++t) {
            net->p[i][0][t] = R(0.0);
            net->p[i][1][t] = R(0.0);
        }
        net->cert[i][0] = 0;
        net->cert[i][1] = 0;
        if (i < n) {
            load_p0(net, i, net->p[i][0]);
            net->cert[i][0] = p0_proven(nc);
        }
        net->xhat[i] = i < n ? CFG(net)->x0[i] : R(0.0);
    }
    for (h = 0; h < (size_t)RHONN_HISTORY_LEN; ++h) {
        for (i = 0; i < (size_t)RHONN_SAMPLE_LEN; ++i) {
            net->hist[h][i] = R(0.0);
        }
    }
    for (i = 0; i < (size_t)RHONN_MAX_STATES; ++i) {
        net->valid_run[i] = 0;
    }
    net->zbank = 0;
    net->head = 0;
    net->started = 0;
    net->learning = 1;
    net->steps = 0;
    net->fault_neuron = 0;
    return RHONN_OK;
}

rhonn_status rhonn_restart(rhonn_t *net)
{
    rhonn_status st = check_net(net);
    size_t i;
    if (st != RHONN_OK) {
        return st;
    }
    /* The step after this one sees started == 0: it does not learn (there is
     * no prediction made for its sample) and refills the history with its
     * own sample, exactly as the first step after rhonn_init; the runs of
     * measured samples start again with it (wait_for_history). */
    net->started = 0;
    for (i = 0; i < (size_t)RHONN_MAX_STATES; ++i) {
        net->valid_run[i] = 0;
    }
    return RHONN_OK;
}

rhonn_status rhonn_set_learning(rhonn_t *net, int on)
{
    rhonn_status st = check_net(net);
    if (st != RHONN_OK) {
        return st;
    }
    net->learning = on ? 1u : 0u;
    return RHONN_OK;
}

/* Calibration between steps (rhonn.h): the value is checked as
 * rhonn_validate_config checks p_trace_max and gate (rhonn_check_trace_ceiling,
 * rhonn_check_gate: the setters' own checks), and only then stored,
 * so a refusal changes nothing. A new ceiling is also the bounded
 * forgetting's c_i (rhonn.h WINDUP PROTECTION: p_trace_max when set, else
 * trace P_i(0)), as forget_ceiling_of derives it at rhonn_init. */
static rhonn_status check_neuron(const rhonn_t *net, size_t neuron)
{
    rhonn_status st = check_net(net);
    if (st == RHONN_OK && neuron >= CFG(net)->n_states) {
        st = RHONN_E_ARGUMENT;
    }
    return st;
}

rhonn_status rhonn_check_trace_ceiling(const rhonn_t *net, size_t neuron, rhonn_real value)
{
    rhonn_status st = check_neuron(net, neuron);
    const rhonn_neuron_config *nc;
    if (st != RHONN_OK) {
        return st;
    }
    nc = &CFG(net)->neurons[neuron];
    if (!trace_ceiling_ok(nc, value)) {
        return RHONN_E_VALUE;
    }
    if (!RHONN_CALIBRATE && value != nc->p_trace_max) {
        return RHONN_E_CONFIG; /* compiled without calibration: the configuration's only */
    }
    return RHONN_OK;
}

rhonn_status rhonn_check_gate(const rhonn_t *net, size_t neuron, rhonn_real value)
{
    rhonn_status st = check_neuron(net, neuron);
    if (st != RHONN_OK) {
        return st;
    }
    if (!is_finite(value) || value < R(0.0)) {
        return RHONN_E_VALUE;
    }
    if (!RHONN_CALIBRATE && value != CFG(net)->neurons[neuron].gate) {
        return RHONN_E_CONFIG; /* compiled without calibration: the configuration's only */
    }
    return RHONN_OK;
}

rhonn_status rhonn_set_trace_ceiling(rhonn_t *net, size_t neuron, rhonn_real value)
{
    rhonn_status st = rhonn_check_trace_ceiling(net, neuron, value);
    if (st != RHONN_OK) {
        return st;
    }
    net->trace_max[neuron] = value;
    net->forget_ceiling[neuron] = forget_ceiling_of(&CFG(net)->neurons[neuron], value);
    net->ceilings = any_positive(net->trace_max, CFG(net)->n_states);
    return RHONN_OK;
}

rhonn_status rhonn_set_gate(rhonn_t *net, size_t neuron, rhonn_real value)
{
    rhonn_status st = rhonn_check_gate(net, neuron, value);
    if (st != RHONN_OK) {
        return st;
    }
    net->gate[neuron] = value;
    net->gates = any_positive(net->gate, CFG(net)->n_states);
    return RHONN_OK;
}

/* One neuron's entry of a table of values in force (trace_max, gate). */
static rhonn_status get_in_force(const rhonn_t *net, size_t neuron, const rhonn_real *table, rhonn_real *value)
{
    rhonn_status st = check_neuron(net, neuron);
    if (st == RHONN_OK && value == NULL) {
        st = RHONN_E_NULL;
    }
    if (st == RHONN_OK) {
        *value = table[neuron];
    }
    return st;
}

rhonn_status rhonn_get_trace_ceiling(const rhonn_t *net, size_t neuron, rhonn_real *value)
{
    return get_in_force(net, neuron, net != NULL ? net->trace_max : NULL, value);
}

rhonn_status rhonn_get_gate(const rhonn_t *net, size_t neuron, rhonn_real *value)
{
    return get_in_force(net, neuron, net != NULL ? net->gate : NULL, value);
}

/* ------------------------------------------------------------------------ */
/* One step */

/* r^p by repeated multiplication: exact order, no pow() from libm. */
static rhonn_real ipow(rhonn_real v, uint8_t p)
{
    rhonn_real acc = v;
    uint8_t k;
    for (k = 1; k < p; ++k) {
        acc *= v;
    }
    return acc;
}

/* Dot product with two accumulators: half the floating-point dependency
 * chain of a single running sum, same operations on every target. */
RHONN_INLINE rhonn_real dot(const rhonn_real *RHONN_RESTRICT a, const rhonn_real *RHONN_RESTRICT b, size_t len)
{
    rhonn_real s0 = R(0.0), s1 = R(0.0);
    size_t c;
    RHONN_UNROLL_LOOP
    for (c = 0; c + 1u < len; c += 2u) {
        s0 += a[c] * b[c];
        s1 += a[c + 1u] * b[c + 1u];
    }
    if (c < len) {
        s0 += a[c] * b[c];
    }
    return s0 + s1;
}

/* 1 if any of v[0..len) is NaN or +-Inf: integer tests of the exponent
 * bits ORed together, so no floating-point chain and no branch per entry.
 * With RHONN_FINITE_BY_SUM (the default on a Cortex-M FPU, where moving a
 * value to an integer register and testing it costs four cycles and an
 * FPU add one), a finite sum of the entries first proves them all finite
 * (a NaN or an infinity makes any sum NaN or infinite); only a sum that is
 * not finite, because of a bad entry or an overflow of finite ones, goes
 * on to the exact test. The same answer either way. */
#ifndef RHONN_FINITE_BY_SUM
#if defined(__ARM_ARCH_PROFILE) && defined(__ARM_FP)
#if __ARM_ARCH_PROFILE == 'M'
#define RHONN_FINITE_BY_SUM 1
#endif
#endif
#endif
#ifndef RHONN_FINITE_BY_SUM
#define RHONN_FINITE_BY_SUM 0
#endif
RHONN_INLINE int any_nonfinite(const rhonn_real *v, size_t len)
{
    int bad = 0;
    size_t c;
#if RHONN_FINITE_BY_SUM
    rhonn_real sum = R(0.0);
    RHONN_UNROLL_LOOP
    for (c = 0; c < len; ++c) {
        sum += v[c];
    }
    if (RHONN_LIKELY(is_finite(sum))) {
        return 0;
    }
#endif
    RHONN_UNROLL_LOOP
    for (c = 0; c < len; ++c) {
        bad |= (bits_of(v[c]) & (rhonn_bits)RHONN_EXP_MASK) == (rhonn_bits)RHONN_EXP_MASK;
    }
    return bad;
}

/* Packed upper triangle: row r holds (r, r..L-1) and starts after the
 * L + (L-1) + ... + (L-r+1) entries of the rows above it. */
static size_t row_start(size_t r, size_t L)
{
    return r * (2u * L + 1u - r) / 2u;
}

/* U D U^T factorisation of the packed symmetric C = S P S, S = diag(sc),
 * into F (D on the diagonal, U's strict upper triangle beside it), from the
 * last column back; each entry of C is formed as (P_ij sc_i) sc_j where it
 * is read, so C is never stored. Returns 1 when every pivot d_j is a
 * positive finite number, else 0 with F partly written. About L^3/6
 * multiply-adds and L divisions; the row offsets are tabulated once so the
 * inner loops are plain strided dot products. shift is subtracted from each
 * diagonal entry of C (Rump's shifted factorisation; 0 for the plain one). */
RHONN_INLINE int udu_factor(const rhonn_real *RHONN_RESTRICT P, const rhonn_real *RHONN_RESTRICT sc,
                            rhonn_real *RHONN_RESTRICT F, const size_t L, const rhonn_real shift)
{
    rhonn_real t[RHONN_MAX_TERMS], d[RHONN_MAX_TERMS];
    size_t rs[RHONN_MAX_TERMS];
    size_t j, r;
    rs[0] = 0;
    RHONN_UNROLL_LOOP
    for (r = 0; r + 1u < L; ++r) {
        rs[r + 1u] = rs[r] + (L - r);
    }
    RHONN_UNROLL_LOOP
    for (j = L; j-- > 0u;) {
        const rhonn_real *RHONN_RESTRICT uj = F + rs[j] + 1u; /* U(j, j+1..L-1) */
        const size_t tail = L - 1u - j;
        rhonn_real dj = (P[rs[j]] * sc[j]) * sc[j] - shift, inv; /* x - 0 is x, bit for bit */
        size_t i, k;
        /* t_k = d_k U(j,k) for the columns k > j already factorised */
        RHONN_UNROLL_LOOP
        for (k = 0; k < tail; ++k) {
            t[k] = d[j + 1u + k] * uj[k];
            dj -= uj[k] * t[k];
        }
        /* false for NaN too, and -Inf: a non-finite entry anywhere in P
         * reaches some pivot as NaN or -Inf (U(i,k)^2 d_k >= 0) */
        if (!(dj > R(0.0)) || !is_finite(dj)) {
            return 0;
        }
        d[j] = dj;
        F[rs[j]] = dj;
        inv = R(1.0) / dj;
        RHONN_UNROLL_LOOP
        for (i = 0; i < j; ++i) {
            rhonn_real *RHONN_RESTRICT fi = F + rs[i] + (j - i); /* U(i, j..L-1) */
            rhonn_real a = (P[rs[i] + (j - i)] * sc[i]) * sc[j];
            RHONN_UNROLL_LOOP
            for (k = 0; k < tail; ++k) {
                a -= fi[1u + k] * t[k];
            }
            fi[0] = a * inv;
        }
    }
    return 1;
}

/* 2^-h with h = floor(e / 2) for v = m 2^e, m in [1, 2): v times its
 * square is in [1, 4). Built from the bits, so scaling by it is exact. */
static rhonn_real half_exponent_scale(rhonn_real v)
{
#ifdef RHONN_SINGLE
    union { float f; uint32_t u; } b;
    int e, h;
    b.f = v;
    e = (int)((b.u >> 23) & 0xFFu) - 127;
    h = e >= 0 ? e / 2 : -((1 - e) / 2);
    b.u = (uint32_t)(127 - h) << 23;
#else
    union { double f; uint64_t u; } b;
    int e, h;
    b.f = v;
    e = (int)((b.u >> 52) & 0x7FFu) - 1023;
    h = e >= 0 ? e / 2 : -((1 - e) / 2);
    b.u = (uint64_t)(1023 - h) << 52;
#endif
    return b.f;
}

/* Is the packed symmetric P positive definite at working precision: does
 * its U D U^T factorisation succeed? P is first scaled symmetrically by
 * powers of two (exactly) to a diagonal in [1, 4): the factorisation then
 * works on unit-order numbers whatever the units of the terms, so it can
 * neither overflow nor underflow on a P near the ends of the range.
 *
 * This is a working-precision verdict, as any floating-point Cholesky test:
 * a nearly singular P passes or fails by a few ulps, and one indefinite by
 * less than its own rounding can pass. Refusing those too (Rump's shifted
 * factorisation as the verdict) would refuse the covariances an ordinary
 * float32 filter reaches with a small R: at rest, 15 updates of
 * firmware-lim's velocity neuron leave eigenvalues near eps of the diagonal.
 * Where that matters, the U D U^T form keeps P definite by construction.
 * The shifted factorisation serves instead to prove a P definite in exact
 * arithmetic (shifted_check), which the next update builds on.
 * A diagonal below the normal range is refused: such a P is singular at
 * this precision. */
RHONN_INLINE int scaled_udu(const rhonn_real *RHONN_RESTRICT P, rhonn_real *RHONN_RESTRICT F,
                            rhonn_real *RHONN_RESTRICT sc, const size_t L, const rhonn_real shift)
{
    size_t i, idx;
    for (i = 0, idx = 0; i < L; idx += L - i, ++i) {
        const rhonn_real v = P[idx];
        if (!(v >= RHONN_MIN_NORMAL) || !is_finite(v)) {
            return 0;
        }
        sc[i] = half_exponent_scale(v);
    }
    return udu_factor(P, sc, F, L, shift);
}

RHONN_INLINE int pd_check(const rhonn_real *RHONN_RESTRICT P, const size_t L)
{
    rhonn_real F[RHONN_MAX_PACKED], sc[RHONN_MAX_TERMS];
    return scaled_udu(P, F, sc, L, R(0.0));
}

/* pd_check (shift 0: x - 0 is x, bit for bit) or shifted_check
 * (rhonn_proof_shift(L)) for the configuration check and the accessors:
 * the same verdicts, from one out-of-line copy of the factorisation (the
 * step's own checks stay inlined into its kernels). */
RHONN_NOINLINE static int accessor_check(const rhonn_real *P, size_t L, rhonn_real shift)
{
    rhonn_real F[RHONN_MAX_PACKED], sc[RHONN_MAX_TERMS];
    return scaled_udu(P, F, sc, L, shift);
}

#if RHONN_CERTIFY
/* Is P positive definite in exact arithmetic, with room to spare? The
 * factorisation of C - alpha I, C = S P S scaled to a diagonal in [1, 4),
 * alpha = 17 L gamma_{L+1} (rhonn_proof_shift; u the unit roundoff,
 * gamma_k = k u / (1 - k u) <= 1.01 k u). Its computed factors are those of
 * C - alpha I + dC, |dC| <= gamma_{L+1} |U| D |U|^T (Higham, Accuracy and
 * Stability, Thm 10.3), whose 2-norm is at most 4.04 L gamma_{L+1} here; the
 * shift rounds by at most 4u. Success therefore proves
 * lambda_min(C) > 12.9 L gamma_{L+1}: P is definite, and above Demmel's
 * bound (Higham Thm 10.7: lambda_min of the unit-diagonal scaling above
 * L gamma_{L+1} / (1 - L gamma_{L+1}), at most 4.04 L gamma_{L+1} for C)
 * under which the plain factorisation of pd_check always succeeds. So a P
 * this accepts, pd_check accepts too: the verdict does not change. */
RHONN_INLINE int shifted_check(const rhonn_real *RHONN_RESTRICT P, const size_t L)
{
    rhonn_real F[RHONN_MAX_PACKED], sc[RHONN_MAX_TERMS];
    return scaled_udu(P, F, sc, L, rhonn_proof_shift(L));
}

/* |v| by clearing the sign bit: no compare and branch (GCC and clang emit
 * the FPU's own absolute value, VABS on the Cortex-M4, for the builtin). */
static rhonn_real abs_of(rhonn_real v)
{
#if defined(__GNUC__) || defined(__clang__)
#ifdef RHONN_SINGLE
    return __builtin_fabsf(v);
#else
    return __builtin_fabs(v);
#endif
#elif defined(RHONN_SINGLE)
    union { float f; uint32_t u; } b;
    b.f = v;
    b.u &= 0x7FFFFFFFUL;
    return b.f;
#else
    union { double f; uint64_t u; } b;
    b.f = v;
    b.u &= 0x7FFFFFFFFFFFFFFFULL;
    return b.f;
#endif
}

/* The certificate of a full-form update (eq. 7 without forgetting or trace
 * bound) whose old P is definite in exact arithmetic (cert): O(L) work that
 * proves the new P definite and accepted by pd_check, so the O(L^3)
 * factorisation is skipped. Returns 0 (not proven: factorise) whenever a
 * bound is out of reach, never a wrong 1.
 *
 * P' = P - v v^T / s + Q as computed, v = fl(P z), s = fl(R + z^T v). With
 * M = P - v v^T / s_e, s_e = R + z^T v exactly, P' = M + Q + E:
 *  - lambda_min(M) >= -2 |delta|^2 / (R + z^T delta) for v = P z + delta,
 *    P definite (Cauchy-Schwarz in P's inner product, then the best split
 *    of (y^T P z + y^T delta)^2); |delta| <= gamma_L |P| |z| and, P being
 *    definite, |P_rc| <= sqrt(P_rr P_cc), so with
 *    w = sum_c sqrt(P_cc) |z_c|: |delta|^2 <= gamma_L^2 tr(P) w^2 and
 *    z^T delta >= -gamma_L w^2; and w^2 <= L sum_c P_cc z_c^2 (Cauchy-
 *    Schwarz over the L terms), which takes no square root;
 *  - |E| (2-norm) <= (3 rho + 8u) |v|^2 / s + 2u (tr(P) + max_r P'_rr),
 *    rho = gamma_{L+1} (R + |z|^T |v|) / s the relative error of s: the
 *    roundings of 1 / s, k_r = v_r / s, k_r v_c, the subtraction and + q,
 *    with |P|_F <= tr(P);
 * so lambda_min(P') >= q_min - eta - |E|. Accepted when 9/8 of
 * (eta + |E| + Demmel's bound 1.01 L gamma_{L+1} max P'_rr) is at most
 * q_min: P' is definite with lambda_min >= q_min / 9 + Demmel's bound, and
 * pd_check (every diagonal above q_min / 9 >= the normal range) would
 * accept it. The 1/8 also covers the rounding of these bounds themselves
 * (a few dozen roundings, below 1e-5 relative; 1 / s is the rounded
 * inv_s). Overflow or NaN
 * anywhere fails a comparison, and every entry of P' is finite, at most
 * (tr(P) + |v|^2 / s)(1 + u) off the diagonal, which is bounded here; the
 * diagonal's largest is pmax. The sums are taken here; rhonn_internal.h's
 * rhonn_proof_holds (shared with the population kernels) does the rest. */
RHONN_INLINE int certified_update(const rhonn_real *RHONN_RESTRICT P, const rhonn_real *RHONN_RESTRICT z,
                                  const rhonn_real *RHONN_RESTRICT v, const rhonn_real inv_s,
                                  const rhonn_real *RHONN_RESTRICT Pn, const rhonn_neuron_config *nc,
                                  const rhonn_real qmin, const size_t L)
{
    rhonn_real tr = R(0.0), pzz = R(0.0), vv = R(0.0), zv = R(0.0), pmax = R(0.0);
    size_t r, idx;
    RHONN_UNROLL_LOOP
    for (r = 0, idx = 0; r < L; idx += L - r, ++r) {
        tr += P[idx];
        pzz += (P[idx] * z[r]) * z[r];
        vv += v[r] * v[r];
        zv += abs_of(z[r] * v[r]); /* = |z_r| |v_r|, bit for bit: one VABS */
        pmax = Pn[idx] > pmax ? Pn[idx] : pmax;
    }
    return rhonn_proof_holds(tr, pzz, vv, zv, pmax, qmin, nc->r, inv_s, L);
}
#endif

#if RHONN_WITH_UD
/* The U D U^T factors of P itself, from those of the scaled C = S P S that
 * pd_check judges (S = diag(sc), powers of two): U = S^-1 U_C S and
 * D = S^-2 D_C, exact unless a d_j leaves the normal range. Returns 1 when P
 * passes pd_check and every factor is finite with D > 0, so a covariance is
 * accepted or refused the same way whatever its form. */
static int udu_of(const rhonn_real *P, rhonn_real *F, size_t L)
{
    rhonn_real sc[RHONN_MAX_TERMS];
    size_t i, j;
    if (!scaled_udu(P, F, sc, L, R(0.0))) {
        return 0;
    }
    for (j = 0; j < L; ++j) {
        const rhonn_real inv = R(1.0) / sc[j];
        rhonn_real *d = &F[row_start(j, L)];
        *d = (*d * inv) * inv;
        if (!(*d >= RHONN_MIN_NORMAL) || !is_finite(*d)) {
            return 0;
        }
        for (i = 0; i < j; ++i) {
            rhonn_real *u = &F[row_start(i, L) + (j - i)];
            *u = (*u * sc[j]) / sc[i];
            if (!is_finite(*u)) {
                return 0;
            }
        }
    }
    return 1;
}
#endif

/* trace(U D U^T) = sum_j d_j (1 + sum_{i<j} U(i,j)^2) */
static rhonn_real ud_trace(const rhonn_real *F, size_t L)
{
    rhonn_real tr = R(0.0);
    size_t i, j;
    for (j = 0; j < L; ++j) {
        rhonn_real col = R(1.0);
        for (i = 0; i < j; ++i) {
            const rhonn_real u = F[row_start(i, L) + (j - i)];
            col += u * u;
        }
        tr += F[row_start(j, L)] * col;
    }
    return tr;
}

static rhonn_real full_trace(const rhonn_real *P, size_t L)
{
    rhonn_real tr = R(0.0);
    size_t r;
    for (r = 0; r < L; ++r) {
        tr += P[row_start(r, L)];
    }
    return tr;
}

/* The fault of neuron i: only on a refused update (cold: the paths that
 * reach it are compiled as rare). */
RHONN_COLD static rhonn_status neuron_fault(rhonn_t *net, size_t i, rhonn_status st)
{
    net->fault_neuron = (uint8_t)i;
    return st;
}

/* The trace ceiling: P scaled down to p_trace_max when its trace is above. */
static void bound_trace(rhonn_real *P, size_t L, rhonn_real p_trace_max, uint8_t *bounded)
{
    const rhonn_real tr = full_trace(P, L);
    size_t c;
    if (tr > p_trace_max) {
        const rhonn_real scale = p_trace_max / tr;
        for (c = 0; c < packed_size(L); ++c) {
            P[c] *= scale;
        }
        *bounded = 1;
    }
}

/* eq. 7-8 for a RHONN_COV_FULL neuron, written into the inactive bank, then
 * the check that makes the committed P a covariance: positive definite at
 * working precision (its U D U^T pivots; a non-finite entry fails it too).
 * H = z (eq. 11: the network is linear in w). P is the packed upper
 * triangle: row r holds P(r, r..L-1) contiguously. */
RHONN_INLINE rhonn_status ekf_kernel(rhonn_t *net, size_t i, rhonn_real e, const rhonn_real *z, rhonn_real *nis,
                                      uint8_t *bounded, uint8_t *gated, const size_t L)
{
    const rhonn_neuron_config *nc = &CFG(net)->neurons[i];
    const uint8_t b = net->bank[i];
    const rhonn_real *RHONN_RESTRICT P = net->p[i][b];
    rhonn_real *RHONN_RESTRICT Pn = net->p[i][b ^ 1u];
    const rhonn_real *RHONN_RESTRICT w = net->w[i][b];
    rhonn_real *RHONN_RESTRICT wn = net->w[i][b ^ 1u];
    rhonn_real pz[RHONN_MAX_TERMS];
    rhonn_real s, inv_s, gain;
    rhonn_real inv_lambda = INV_LAMBDA(net, i);
    size_t r, c, len;
    const rhonn_real *row;

    /* pz = P z: row r of the triangle gives pz[r] its (r, c >= r) part as a
     * dot product and scatters zr * P(r, c > r) into pz[c], the (c, r) part. */
    RHONN_UNROLL_LOOP
    for (r = 0; r < L; ++r) {
        pz[r] = R(0.0);
    }
    row = P;
    RHONN_UNROLL_LOOP
    for (r = 0; r < L; ++r) {
        const rhonn_real zr = z[r];
        len = L - r;
        RHONN_UNROLL_LOOP
        for (c = 1; c < len; ++c) {
            pz[r + c] += row[c] * zr;
        }
        pz[r] += dot(row, &z[r], len);
        row += len;
    }
    /* eq. 8: M = 1 / (R + z^T P z), a scalar: no matrix inversion. With P
     * positive definite z^T P z >= 0; a rounded value below 0 (s < R) means P
     * is too close to singular for this z at working precision. */
    s = nc->r + dot(z, pz, L);
    if (!is_finite(s) || !(s >= nc->r)) {
        return neuron_fault(net, i, RHONN_E_INNOVATION);
    }
    inv_s = R(1.0) / s;
    *nis = e * (e * inv_s);
    /* The innovation gate: an update with e^2 / s (eq. 8-9) above it is
     * skipped, nothing written (rhonn.h INNOVATION GATE). */
    if (RHONN_UNLIKELY(GATE_ON(net, i) && GATE(net, i) > R(0.0) && *nis > GATE(net, i))) {
        *gated = 1;
        return RHONN_OK;
    }
    /* eq. 7: K = P z M and w(k+1) = w + eta K e, i.e. w + (eta e M) P z. */
    gain = nc->eta * e * inv_s;
    RHONN_UNROLL_LOOP
    for (r = 0; r < L; ++r) {
        wn[r] = w[r] + gain * pz[r];
    }
    if (any_nonfinite(wn, L)) {
        return neuron_fault(net, i, RHONN_E_DIVERGED);
    }
    /* Bounded forgetting (rhonn.h WINDUP PROTECTION): / lambda only when the
     * trace of P+ = P - K z^T P, its diagonal formed as below, stays within
     * the ceiling after it; else eq. 7 as written. */
    if (inv_lambda > R(0.0)) {
        rhonn_real trp = R(0.0);
        row = P;
        RHONN_UNROLL_LOOP
        for (r = 0; r < L; ++r) {
            trp += row[0] - (pz[r] * inv_s) * pz[r];
            row += L - r;
        }
        if (!(trp * inv_lambda <= FORGET_CEILING(net, i))) {
            inv_lambda = R(0.0);
        }
    }
    /* eq. 7: P(k+1) = P - K z^T P + Q = P - (P z)(P z)^T M + Q: symmetric,
     * so only the upper triangle is formed, row by row. With forgetting,
     * (P - K z^T P) / lambda + Q. */
    row = P;
    RHONN_UNROLL_LOOP
    for (r = 0; r < L; ++r) {
        const rhonn_real kr = pz[r] * inv_s;
        rhonn_real *RHONN_RESTRICT out = Pn + (row - P);
        len = L - r;
        if (inv_lambda > R(0.0)) {
            RHONN_UNROLL_LOOP
            for (c = 0; c < len; ++c) {
                out[c] = (row[c] - kr * pz[r + c]) * inv_lambda;
            }
            out[0] += nc->q[r];
        } else {
            out[0] = (row[0] - kr * pz[r]) + nc->q[r];
            RHONN_UNROLL_LOOP
            for (c = 1; c < len; ++c) {
                out[c] = row[c] - kr * pz[r + c];
            }
        }
        row += len;
    }
    if (RHONN_UNLIKELY(CEILING_ON(net, i) && TRACE_MAX(net, i) > R(0.0))) {
        bound_trace(Pn, L, TRACE_MAX(net, i), bounded);
    }
    /* The committed P must be definite. Proven in O(L) from the old P's
     * proof when it has one; else by the shifted factorisation, which also
     * gives the new P its proof; else only at working precision (pd_check).
     * Every path accepts exactly the P that pd_check accepts. */
#if RHONN_CERTIFY
    if (RHONN_LIKELY(net->cert[i][b] && inv_lambda == R(0.0) && !*bounded &&
                     certified_update(P, z, pz, inv_s, Pn, nc, Q_MIN(net, i), L))) {
        net->cert[i][b ^ 1u] = 1u;
        return RHONN_OK;
    }
    if (shifted_check(Pn, L)) {
        net->cert[i][b ^ 1u] = 1u;
        return RHONN_OK;
    }
#endif
    net->cert[i][b ^ 1u] = 0u;
    if (!pd_check(Pn, L)) {
        /* which way it failed, off the hot path */
        return neuron_fault(net, i, any_nonfinite(Pn, packed_size(L)) ? RHONN_E_COVARIANCE : RHONN_E_NOT_PD);
    }
    return RHONN_OK;
}

#if RHONN_WITH_UD
/* The U D U^T kernel's loops are unrolled where every size it runs at is a
 * compile-time constant (RHONN_UNROLL with RHONN_MAX_TERMS <= 8, e.g. the
 * firmware's build): a runtime-L copy unrolled 16 times is all guards. */
#if RHONN_UNROLL && RHONN_MAX_TERMS <= 8
#define RHONN_UD_UNROLL_LOOP RHONN_UNROLL_LOOP
#else
#define RHONN_UD_UNROLL_LOOP
#endif

/* eq. 7-8 for a RHONN_COV_UD neuron: P = U D U^T is stored as its factors
 * (D on the packed diagonal, U beside it).
 *
 * Measurement (Bierman): with f = U^T z and v = D f, the innovation variance
 * builds up as a_0 = R, a_j = a_{j-1} + f_j v_j, so s = a_L >= R; the new
 * d_j = d_j a_{j-1} / a_j stays in (0, d_j]; U(k,j) += -f_j / a_{j-1} b_k
 * with b accumulating P z, so the gain K = b / s is that of eq. 7.
 *
 * Then / lambda (D / lambda) and + Q as L rank-one updates
 * P + q_J e_J e_J^T (Agee and Turner; Bierman, Factorization Methods for
 * Discrete Sequential Estimation, 1977), each from column J back to column
 * 0, the columns right of J being untouched: with a = e_J and c = q_J,
 * column j takes p = a_j, d~_j = d_j + c p^2, b = c p / d~_j,
 * c <- c d_j / d~_j, then for i < j U(i,j) <- U(i,j) d_j / d~_j + b a_i and
 * a_i -= p U(i,j) (the old U(i,j)). That is Agee and Turner's
 * U + b (a_i - p U) regrouped: when q_J dwarfs d_j, b p is 1 to rounding
 * and U - b p U would cancel to rounding noise of U's size; the product
 * with d_j / d~_j keeps U(i,j)'s relative accuracy.
 * c >= 0 makes every d~_j >= d_j > 0: definite by construction, in about
 * L^3 / 3 multiply-adds and L (L + 1) / 2 divisions, half the work of a
 * Gram-Schmidt re-factorisation of [U | I] (Thornton's). A neuron whose Q is
 * all zero skips it. */
RHONN_INLINE rhonn_status ekf_ud(rhonn_t *net, size_t i, rhonn_real e, const rhonn_real *z, rhonn_real *nis,
                                  uint8_t *bounded, uint8_t *gated, const size_t L)
{
    const rhonn_neuron_config *nc = &CFG(net)->neurons[i];
    const uint8_t bk = net->bank[i];
    const rhonn_real *RHONN_RESTRICT F = net->p[i][bk];
    rhonn_real *RHONN_RESTRICT Fn = net->p[i][bk ^ 1u];
    const rhonn_real *RHONN_RESTRICT w = net->w[i][bk];
    rhonn_real *RHONN_RESTRICT wn = net->w[i][bk ^ 1u];
    rhonn_real wu[RHONN_MAX_PACKED];
    rhonn_real f[RHONN_MAX_TERMS], v[RHONN_MAX_TERMS], b[RHONN_MAX_TERMS], dt[RHONN_MAX_TERMS];
    rhonn_real a[RHONN_MAX_TERMS];
    size_t rs[RHONN_MAX_TERMS];
    rhonn_real alpha, alpha_new, inv, inv_prev, s, gain;
    const rhonn_real inv_lambda = INV_LAMBDA(net, i);
    size_t j, k, at;

    rs[0] = 0;
    RHONN_UD_UNROLL_LOOP
    for (j = 0; j + 1u < L; ++j) {
        rs[j + 1u] = rs[j] + (L - j);
    }
    /* f = U^T z (U unit upper triangular), v = D f */
    RHONN_UD_UNROLL_LOOP
    for (j = 0; j < L; ++j) {
        f[j] = z[j];
    }
    RHONN_UD_UNROLL_LOOP
    for (k = 0; k < L; ++k) {
        RHONN_UD_UNROLL_LOOP
        for (j = k + 1u; j < L; ++j) {
            f[j] += F[rs[k] + (j - k)] * z[k];
        }
    }
    RHONN_UD_UNROLL_LOOP
    for (j = 0; j < L; ++j) {
        v[j] = F[rs[j]] * f[j];
    }
    /* Bierman's update, column by column; wu receives U~ with a unit diagonal */
    alpha = nc->r;
    inv_prev = R(0.0);
    RHONN_UD_UNROLL_LOOP
    for (j = 0; j < L; ++j) {
        const rhonn_real lam = -f[j] * inv_prev;
        alpha_new = alpha + f[j] * v[j];
        inv = R(1.0) / alpha_new;
        dt[j] = F[rs[j]] * (alpha * inv);
        /* column j of U walks the packed rows: U(k,j) then U(k+1,j) sits
         * L - 1 - k entries further (row k + 1 is one shorter) */
        RHONN_UD_UNROLL_LOOP
        for (k = 0, at = j; k < j; at += L - 1u - k, ++k) {
            const rhonn_real ukj = F[at];
            wu[at] = ukj + lam * b[k];
            b[k] += ukj * v[j];
        }
        wu[rs[j]] = R(1.0);
        b[j] = v[j];
        alpha = alpha_new;
        inv_prev = inv;
    }
    s = alpha;
    if (!is_finite(s)) {
        return neuron_fault(net, i, RHONN_E_INNOVATION);
    }
    *nis = e * (e * inv_prev);
    /* the innovation gate (rhonn.h INNOVATION GATE): skipped, nothing written */
    if (RHONN_UNLIKELY(GATE_ON(net, i) && GATE(net, i) > R(0.0) && *nis > GATE(net, i))) {
        *gated = 1;
        return RHONN_OK;
    }
    gain = nc->eta * e * inv_prev;
    RHONN_UD_UNROLL_LOOP
    for (j = 0; j < L; ++j) {
        wn[j] = w[j] + gain * b[j];
    }
    if (any_nonfinite(wn, L)) {
        return neuron_fault(net, i, RHONN_E_DIVERGED);
    }
    if (inv_lambda > R(0.0)) {
        /* bounded forgetting (rhonn.h WINDUP PROTECTION): D / lambda only
         * when trace(U~ D~ U~^T) / lambda, the measurement's P+ as
         * ud_trace sums it, stays within the ceiling */
        rhonn_real trp = R(0.0);
        RHONN_UD_UNROLL_LOOP
        for (j = 0; j < L; ++j) {
            rhonn_real col = R(1.0);
            RHONN_UD_UNROLL_LOOP
            for (k = 0; k < j; ++k) {
                const rhonn_real u = wu[rs[k] + (j - k)];
                col += u * u;
            }
            trp += dt[j] * col;
        }
        if (trp * inv_lambda <= FORGET_CEILING(net, i)) {
            RHONN_UD_UNROLL_LOOP
            for (j = 0; j < L; ++j) {
                dt[j] *= inv_lambda;
            }
        }
    }
    /* The measurement's factors into the new bank, then + Q in place. */
    RHONN_UD_UNROLL_LOOP
    for (j = 0; j < L; ++j) {
        Fn[rs[j]] = dt[j];
        RHONN_UD_UNROLL_LOOP
        for (k = 0; k < j; ++k) {
            Fn[rs[k] + (j - k)] = wu[rs[k] + (j - k)];
        }
    }
    if (!Q_ZERO(net, i)) {
        size_t J, jp;
        RHONN_UD_UNROLL_LOOP
        for (J = 0; J < L; ++J) {
            /* column J: p = a_J = 1, and a_i = -U(i,J) */
            rhonn_real c = nc->q[J];
            rhonn_real dj = Fn[rs[J]], dn = dj + c, inv_dn = R(1.0) / dn, bj, ratio = dj * inv_dn;
            c = c * ratio;
            Fn[rs[J]] = dn;
            RHONN_UD_UNROLL_LOOP
            for (k = 0, at = J; k < J; at += L - 1u - k, ++k) {
                a[k] = -Fn[at];
                Fn[at] *= ratio;
            }
            /* the columns left of it */
            RHONN_UD_UNROLL_LOOP
            for (jp = J; jp > 0u; --jp) {
                const rhonn_real p = a[jp - 1u];
                dj = Fn[rs[jp - 1u]];
                dn = dj + c * (p * p);
                inv_dn = R(1.0) / dn;
                bj = (c * p) * inv_dn;
                ratio = dj * inv_dn;
                c = c * ratio;
                Fn[rs[jp - 1u]] = dn;
                RHONN_UD_UNROLL_LOOP
                for (k = 0, at = jp - 1u; k + 1u < jp; at += L - 1u - k, ++k) {
                    const rhonn_real u = Fn[at];
                    Fn[at] = u * ratio + bj * a[k];
                    a[k] -= p * u;
                }
            }
        }
    }
    RHONN_UD_UNROLL_LOOP
    for (j = 0; j < L; ++j) {
        if (!(Fn[rs[j]] > R(0.0))) { /* a d~_j that underflowed */
            return neuron_fault(net, i, RHONN_E_NOT_PD);
        }
    }
    if (RHONN_UNLIKELY(CEILING_ON(net, i) && TRACE_MAX(net, i) > R(0.0))) {
        const rhonn_real tr = ud_trace(Fn, L);
        if (tr > TRACE_MAX(net, i)) {
            const rhonn_real scale = TRACE_MAX(net, i) / tr;
            RHONN_UD_UNROLL_LOOP
            for (j = 0; j < L; ++j) {
                Fn[rs[j]] *= scale;
                if (!(Fn[rs[j]] > R(0.0))) { /* scaled into underflow */
                    return neuron_fault(net, i, RHONN_E_NOT_PD);
                }
            }
            *bounded = 1;
        }
    }
    if (any_nonfinite(Fn, packed_size(L))) {
        return neuron_fault(net, i, RHONN_E_COVARIANCE);
    }
    return RHONN_OK;
}

#if !RHONN_UNROLL || RHONN_MAX_TERMS > 8
/* The kernel for a runtime L: the generic build's, and the unrolled one's
 * above its specialised sizes (up to L = 8: where loop overhead dominates,
 * at a bounded code size). */
static rhonn_status ekf_ud_generic(rhonn_t *net, size_t i, rhonn_real e, const rhonn_real *z, rhonn_real *nis,
                                   uint8_t *bounded, uint8_t *gated, size_t L)
{
    return ekf_ud(net, i, e, z, nis, bounded, gated, L);
}
#endif
#endif

#define RHONN_KERNEL(n) ekf_kernel(net, i, e, z, nis, bounded, gated, n)

#if RHONN_UNROLL && RHONN_MAX_TERMS > 16
/* The kernel for L above the unrolled sizes: one loop-based copy. */
static rhonn_status ekf_kernel_generic(rhonn_t *net, size_t i, rhonn_real e, const rhonn_real *z, rhonn_real *nis,
                                       uint8_t *bounded, uint8_t *gated, size_t L)
{
    return ekf_kernel(net, i, e, z, nis, bounded, gated, L);
}
#endif

/* One neuron's learning update into its inactive bank (eq. 7-9). Inlined
 * into learn's loop in the unrolled build: the kernels keep many values in
 * registers, and saving and restoring them once per step instead of once
 * per neuron is a few hundred cycles on the Cortex-M4. */
RHONN_INLINE rhonn_status ekf_dispatch(rhonn_t *net, size_t i, rhonn_real e, const rhonn_real *z, rhonn_real *nis,
                                       uint8_t *bounded, uint8_t *gated)
{
    const size_t L = CFG(net)->neurons[i].n_terms;
#if RHONN_WITH_UD
    /* As the full form: one specialised kernel per size up to 8 in the
     * unrolled build (see RHONN_UNROLL), the loop-based one otherwise. */
    if (CFG(net)->neurons[i].covariance == (uint8_t)RHONN_COV_UD) {
#if RHONN_UNROLL
        switch (L) {
#define RHONN_UD_CASE(n) case n: return ekf_ud(net, i, e, z, nis, bounded, gated, n);
        RHONN_UD_CASE(1)
#if RHONN_MAX_TERMS >= 2
        RHONN_UD_CASE(2)
#endif
#if RHONN_MAX_TERMS >= 3
        RHONN_UD_CASE(3)
#endif
#if RHONN_MAX_TERMS >= 4
        RHONN_UD_CASE(4)
#endif
#if RHONN_MAX_TERMS >= 5
        RHONN_UD_CASE(5)
#endif
#if RHONN_MAX_TERMS >= 6
        RHONN_UD_CASE(6)
#endif
#if RHONN_MAX_TERMS >= 7
        RHONN_UD_CASE(7)
#endif
#if RHONN_MAX_TERMS >= 8
        RHONN_UD_CASE(8)
#endif
#undef RHONN_UD_CASE
        default:
#if RHONN_MAX_TERMS > 8
            return ekf_ud_generic(net, i, e, z, nis, bounded, gated, L);
#else
            return RHONN_E_NOT_INIT; /* L outside 1..RHONN_MAX_TERMS: rhonn_init never allows it */
#endif
        }
#else
        return ekf_ud_generic(net, i, e, z, nis, bounded, gated, L);
#endif
    }
#endif
#if RHONN_UNROLL
    /* L as a constant: one specialised kernel per size (see RHONN_UNROLL) */
    switch (L) {
#define RHONN_CASE(n) case n: return RHONN_KERNEL(n);
    RHONN_CASE(1)
#if RHONN_MAX_TERMS >= 2
    RHONN_CASE(2)
#endif
#if RHONN_MAX_TERMS >= 3
    RHONN_CASE(3)
#endif
#if RHONN_MAX_TERMS >= 4
    RHONN_CASE(4)
#endif
#if RHONN_MAX_TERMS >= 5
    RHONN_CASE(5)
#endif
#if RHONN_MAX_TERMS >= 6
    RHONN_CASE(6)
#endif
#if RHONN_MAX_TERMS >= 7
    RHONN_CASE(7)
#endif
#if RHONN_MAX_TERMS >= 8
    RHONN_CASE(8)
#endif
#if RHONN_MAX_TERMS >= 9
    RHONN_CASE(9)
#endif
#if RHONN_MAX_TERMS >= 10
    RHONN_CASE(10)
#endif
#if RHONN_MAX_TERMS >= 11
    RHONN_CASE(11)
#endif
#if RHONN_MAX_TERMS >= 12
    RHONN_CASE(12)
#endif
#if RHONN_MAX_TERMS >= 13
    RHONN_CASE(13)
#endif
#if RHONN_MAX_TERMS >= 14
    RHONN_CASE(14)
#endif
#if RHONN_MAX_TERMS >= 15
    RHONN_CASE(15)
#endif
#if RHONN_MAX_TERMS >= 16
    RHONN_CASE(16)
#endif
#undef RHONN_CASE
    default:
#if RHONN_MAX_TERMS > 16
        return ekf_kernel_generic(net, i, e, z, nis, bounded, gated, L);
#else
        return RHONN_E_NOT_INIT; /* L outside 1..RHONN_MAX_TERMS: rhonn_init never allows it */
#endif
    }
#else
    return RHONN_KERNEL(L);
#endif
}
#undef RHONN_KERNEL

/* The updates of the neurons that learns marks, from *from on, each from
 * its innovation e[i] and regressor z[i] (eq. 7-9), into their inactive
 * banks. Stops at the first refused one: returns its status, *from its
 * index. The one function with the kernels inlined: step 1 runs it over all
 * neurons, the population's per-member fallback over one, so the kernels'
 * code is in the core once. Its loop runs over every neuron (a constant
 * count under RHONN_FIXED_CONFIG, whose kernels are then specialised per
 * neuron) and skips the others. A neuron the innovation gate skips is
 * marked in gated[] and cleared in learns[] (nothing to commit). */
static rhonn_status update_neurons(rhonn_t *net, uint8_t *learns, const rhonn_real *e,
                                   rhonn_real (*z)[RHONN_MAX_TERMS], rhonn_real *nis, uint8_t *bounded, uint8_t *gated,
                                   size_t *from)
{
    const size_t n = CFG(net)->n_states, start = *from;
    size_t i;
    RHONN_ASSUME(n <= (size_t)RHONN_MAX_STATES);
    RHONN_NEURON_LOOP
    for (i = 0; i < n; ++i) {
        if (i >= start && learns[i]) {
            const rhonn_status st = ekf_dispatch(net, i, e[i], z[i], &nis[i], &bounded[i], &gated[i]);
            if (RHONN_UNLIKELY(st != RHONN_OK)) {
                *from = i;
                return st;
            }
            if (GATE_ON(net, i) && RHONN_UNLIKELY(gated[i])) {
                learns[i] = 0; /* skipped by the gate: its bank is not committed */
            }
        }
    }
    return RHONN_OK;
}

/* P_i(0) in neuron i's storage form: a copy, or its U D U^T factors (the
 * config was validated, so the factorisation succeeds). */
/* A full-form P_i(0) that is diagonal (the paper's, and the default) is
 * definite in exact arithmetic with nothing to prove (its entries were
 * validated positive): its proof starts at once, so the first update after
 * init, reset or a recovery costs no factorisation either. */
static uint8_t p0_proven(const rhonn_neuron_config *nc)
{
    size_t r, c, idx;
    if (nc->covariance != (uint8_t)RHONN_COV_FULL) {
        return 0u;
    }
    for (r = 0, idx = 0; r < nc->n_terms; ++r) {
        for (c = r; c < nc->n_terms; ++c, ++idx) {
            if (c != r && nc->p0[idx] != R(0.0)) {
                return 0u;
            }
        }
    }
    return 1u;
}

static void load_p0(const rhonn_t *net, size_t i, rhonn_real *dst)
{
    const rhonn_neuron_config *nc = &CFG(net)->neurons[i];
    size_t t;
    for (t = 0; t < packed_size(nc->n_terms); ++t) {
        dst[t] = nc->p0[t];
    }
#if RHONN_WITH_UD
    if (nc->covariance == (uint8_t)RHONN_COV_UD) {
        (void)udu_of(nc->p0, dst, nc->n_terms); /* succeeds: the config was validated */
    }
#endif
}

/* The part of a sample the regressor reads: x, S(x) of each group, u, 1.
 * The copies run to the capacities with the count as a condition: a plain
 * copy loop is turned into a memmove call by the compiler, which costs more
 * than the few values a sample holds (a tenth of commit_sample on the M4). */
static void store_sample(rhonn_real *RHONN_RESTRICT dst, const rhonn_real *RHONN_RESTRICT src, size_t n,
                         size_t groups, size_t m)
{
    size_t g, j;
    for (g = 0; g <= groups; ++g) { /* x at offset 0, then the groups' S(x) */
        RHONN_UNROLL_LOOP
        for (j = 0; j < (size_t)RHONN_MAX_STATES; ++j) {
            if (j < n) {
                dst[(size_t)RHONN_MAX_STATES * g + j] = src[(size_t)RHONN_MAX_STATES * g + j];
            }
        }
    }
    RHONN_UNROLL_LOOP
    for (j = 0; j < (size_t)RHONN_MAX_INPUTS; ++j) {
        if (j < m) {
            dst[OFF_U + j] = src[OFF_U + j];
        }
    }
    /* The constant 1 sits after the last possible input, not after the
     * m-th: copying index m would store a slot the step never wrote. */
    dst[OFF_ONE] = src[OFF_ONE];
}

/* A valid x_j or any u_j that is not finite refuses the step before
 * anything is touched. */
static rhonn_status check_inputs(const rhonn_t *net, const rhonn_real *x, const rhonn_real *u, const uint8_t *valid)
{
    const size_t n = CFG(net)->n_states, m = CFG(net)->n_inputs;
    size_t j;
    RHONN_ASSUME(n <= (size_t)RHONN_MAX_STATES);
    RHONN_NEURON_LOOP
    for (j = 0; j < n; ++j) {
        if ((valid == NULL || valid[j] != 0u) && !is_finite(x[j])) {
            return RHONN_E_INPUT_NONFINITE;
        }
    }
    for (j = 0; j < m; ++j) {
        if (!is_finite(u[j])) {
            return RHONN_E_INPUT_NONFINITE;
        }
    }
    return RHONN_OK;
}

/* Steps 2-3 of a step: the values the regressor reads (RHONN_VALUES_LEN):
 * this sample as the regressor reads it (RHONN_SAMPLE_LEN values, which
 * commit_sample stores), then the compiled entries' values. */
static void features(const rhonn_t *net, const rhonn_real *x, const rhonn_real *u, const uint8_t *valid,
                     rhonn_real *RHONN_RESTRICT val)
{
    const rhonn_real *vb[RHONN_HISTORY_LEN];               /* sample d back */
    const size_t n = CFG(net)->n_states, m = CFG(net)->n_inputs, groups = net->n_groups;
    const size_t maxd = net->max_delay;
    rhonn_real *RHONN_RESTRICT ent = val + RHONN_SAMPLE_LEN;
    size_t j, g, e, d;
    RHONN_ASSUME(n <= (size_t)RHONN_MAX_STATES);

    /* 2. This sample as the regressor reads it: a missing measurement is
     *    replaced by its own prediction, then S(x_j(k)) once per activation
     *    group, u(k) and 1. */
    RHONN_NEURON_LOOP
    for (j = 0; j < n; ++j) {
        val[j] = (valid == NULL || valid[j] != 0u) ? x[j] : net->xhat[j];
    }
    for (g = 0; g < groups; ++g) {
        rhonn_real *sg = val + OFF_S(g);
        RHONN_NEURON_LOOP
        for (j = 0; j < n; ++j) {
            sg[j] = activate(net->group_activation[g], net->group_beta[g], val[j]);
        }
    }
    RHONN_UNROLL_LOOP
    for (j = 0; j < (size_t)RHONN_MAX_INPUTS; ++j) {
        if (j < m) { /* not a plain copy loop: see store_sample */
            val[OFF_U + j] = u[j];
        }
    }
    val[OFF_ONE] = R(1.0);

    /* 3. The entries (eq. 4's factors that are not this sample's values at
     *    power 1), each once. Delay d reads the ring slot d back (the newest
     *    stored slot is k-1); before the first sample the history is the
     *    first sample itself. */
    vb[0] = val;
    for (d = 1; d <= maxd; ++d) {
        const size_t slot = ((size_t)net->head + (size_t)RHONN_HISTORY_LEN + 1u - d) % (size_t)RHONN_HISTORY_LEN;
        vb[d] = net->started ? net->hist[slot] : val;
    }
    for (e = 0; e < net->n_entries; ++e) {
        const rhonn_real v = vb[net->entry_delay[e]][net->entry_off[e]];
        ent[e] = net->entry_power[e] == 1u ? v : ipow(v, net->entry_power[e]);
    }
}

/* How many factors of term t of neuron i the prediction multiplies: under
 * RHONN_FIXED_CONFIG the term's own count, known where the step is compiled
 * (a factor past them reads the constant 1, and x * 1 is x); else
 * RHONN_MAX_FACTORS, those past the term's own reading the 1 that
 * compile_terms pads them with, so the loop has no per-term count to load. */
RHONN_INLINE size_t factors_read(const rhonn_t *net, size_t i, size_t t)
{
#ifdef RHONN_FIXED_CONFIG
    return CFG(net)->neurons[i].terms[t].n_factors;
#else
    (void)net;
    (void)i;
    (void)t;
    return (size_t)RHONN_MAX_FACTORS;
#endif
}

/* Where factor f (below factors_read) of term t of neuron i is read among
 * the step's values (compile_terms). With RHONN_FIXED_CONFIG the
 * configuration's constants give it where it is this sample's own value, so
 * the step reads it at a constant offset instead of loading its index; else
 * (and for delayed or powered factors) the compiled index. */
RHONN_INLINE size_t value_index(const rhonn_t *net, size_t i, size_t t, size_t f)
{
#ifdef RHONN_FIXED_CONFIG
    const rhonn_term *tm = &CFG(net)->neurons[i].terms[t];
    if (in_sample(&tm->factors[f])) {
        return sample_offset(&tm->factors[f], net->group_of[i]);
    }
#endif
    return net->term_entry[i][t][f];
}

/* The ring part of the commit: cur into the history ring, which is only
 * kept when a tap reads it (cur NULL: a population member that is owed the
 * sample instead, see rhonn_population.c), then the head advanced. */
static void commit_ring(rhonn_t *net, const rhonn_real *cur)
{
    const size_t n = CFG(net)->n_states, m = CFG(net)->n_inputs, groups = net->n_groups;
    const uint8_t next_head = (uint8_t)((net->head + 1u) % (unsigned)RHONN_HISTORY_LEN);
    RHONN_ASSUME(n <= (size_t)RHONN_MAX_STATES);
    if (net->max_delay > 0u && cur != NULL) {
        size_t h;
        for (h = 0; h < (size_t)RHONN_HISTORY_LEN; ++h) {
            if (net->started && h != (size_t)next_head) {
                continue; /* after the first sample only the newest slot changes */
            }
            store_sample(net->hist[h], cur, n, groups, m);
        }
    }
    net->head = next_head;
}

/* The commit's count of the sample: valid_run[j], the samples in a row in
 * which x_j was measured (the population keeps its members' counts in its
 * lanes and writes them back). */
static void count_runs(rhonn_t *net, const uint8_t *valid)
{
    const size_t n = CFG(net)->n_states;
    /* the first sample starts every run full: there is nothing older
     * (with wait_for_history at 1: the history before it was not measured) */
    const uint8_t first = net->started ? 0u : 0xFFu;
    size_t j;
    RHONN_ASSUME(n <= (size_t)RHONN_MAX_STATES);
    RHONN_NEURON_LOOP
    for (j = 0; j < n; ++j) {
        net->valid_run[j] = rhonn_run_next(net->valid_run[j], (uint8_t)(first & net->first_run[j]),
                                           (uint8_t)(valid == NULL || valid[j] != 0u));
    }
}

/* The history part of the commit. */
static void commit_sample(rhonn_t *net, const rhonn_real *cur, const uint8_t *valid)
{
    commit_ring(net, cur);
    count_runs(net, valid);
}

/* What step 1 did per neuron, for the commit. */
typedef struct {
    uint8_t updated[RHONN_MAX_STATES];   /* its inactive bank holds the update */
    uint8_t bounded[RHONN_MAX_STATES];
    uint8_t recovered[RHONN_MAX_STATES]; /* skipped, covariance back to P_i(0) */
    uint8_t gated[RHONN_MAX_STATES];     /* skipped by the innovation gate (not updated) */
    rhonn_real innov[RHONN_MAX_STATES];
    rhonn_real nis[RHONN_MAX_STATES];
} learned;

/* A refusal of neuron i's update counted (rejected, the run of refusals);
 * 1 when that run reaches reset_after: the neuron is recovered. */
RHONN_COLD static int count_refusal(rhonn_t *net, size_t i);

/* A neuron's update was refused (st): counted; with reset_after reached,
 * recovered instead (RHONN_OK): the update skipped, the weights kept and
 * the covariance restarted from P_i(0); else, with skip_refused, the update
 * skipped alone (RHONN_OK, nothing of this neuron committed). Off the hot
 * path. */
static int count_refusal(rhonn_t *net, size_t i)
{
    const rhonn_neuron_config *nc = &CFG(net)->neurons[i];
    rhonn_health *h = &net->health[i];
    h->rejected += 1u;
    if (h->fail_run < 0xFFFFu) {
        h->fail_run = (uint16_t)(h->fail_run + 1u);
    }
    return nc->reset_after != 0u && h->fail_run >= nc->reset_after;
}

static rhonn_status refused(rhonn_t *net, size_t i, rhonn_status st, learned *out)
{
    const rhonn_neuron_config *nc = &CFG(net)->neurons[i];
    const uint8_t nb = (uint8_t)(net->bank[i] ^ 1u);
    size_t t;
    if (!count_refusal(net, i)) {
        if (nc->skip_refused == 0u) {
            return st;
        }
        out->updated[i] = 0; /* skip_refused: this neuron's update is skipped, the step goes on */
        out->bounded[i] = 0;
        return RHONN_OK;
    }
    for (t = 0; t < nc->n_terms; ++t) {
        net->w[i][nb][t] = net->w[i][net->bank[i]][t];
    }
    load_p0(net, i, net->p[i][nb]);
    net->cert[i][nb] = p0_proven(nc);
    out->bounded[i] = 0;
    out->recovered[i] = 1;
    return RHONN_OK;
}

/* Step 1: learn from e(k) = x(k) - xhat(k) (eq. 9) with z(k-1), into the
 * inactive banks; nothing is committed until every neuron passed. A neuron
 * whose update is refused stops the step, or (reset_after) is recovered, or
 * (skip_refused) keeps its weights and covariance, and the others go on. */
static rhonn_status learn(rhonn_t *net, const rhonn_real *x, const uint8_t *valid, learned *out)
{
    const size_t n = CFG(net)->n_states;
    const int on = net->started && net->learning;
    size_t i, from = 0;
    rhonn_status st;
    RHONN_ASSUME(n <= (size_t)RHONN_MAX_STATES);
    RHONN_NEURON_LOOP
    for (i = 0; i < n; ++i) {
        out->updated[i] = (uint8_t)(on && (valid == NULL || valid[i] != 0u) && net->valid_run[i] >= net->own_need[i]);
        out->bounded[i] = 0;
        out->recovered[i] = 0;
        out->gated[i] = 0;
        out->innov[i] = out->updated[i] ? x[i] - net->xhat[i] : R(0.0);
    }
    while ((st = update_neurons(net, out->updated, out->innov, net->z[net->zbank], out->nis, out->bounded, out->gated,
                                &from)) != RHONN_OK) {
        if (refused(net, from, st, out) != RHONN_OK) {
            return st;
        }
        ++from; /* recovered: the others go on */
    }
    return RHONN_OK;
}

/* rhonn_step after the argument checks (rhonn_run makes them once). */
static rhonn_status step_checked(rhonn_t *net, const rhonn_real *x, const rhonn_real *u,
                                 const uint8_t *valid, rhonn_real *xhat_next)
{
    rhonn_real val[RHONN_VALUES_LEN];                      /* this sample, then the entries */
    rhonn_real xnew[RHONN_MAX_STATES];
    learned out;
    const size_t n = CFG(net)->n_states;
    rhonn_status st;
    size_t i, t;
    uint8_t zb_new;
    RHONN_ASSUME(n <= (size_t)RHONN_MAX_STATES);

    st = check_inputs(net, x, u, valid);
    if (st != RHONN_OK) {
        return st;
    }

    st = learn(net, x, valid, &out);
    if (st != RHONN_OK) {
        return st;
    }

    /* 2-3. This sample and the entries' values. */
    features(net, x, u, valid, val);

    /* 4. z(k) (eq. 4) and xhat(k+1) = w(k+1)^T z(k) (eq. 3). */
    zb_new = (uint8_t)(net->zbank ^ 1u);
    RHONN_NEURON_LOOP
    for (i = 0; i < n; ++i) {
        const rhonn_neuron_config *nc = &CFG(net)->neurons[i];
        const size_t L = nc->n_terms;
        const rhonn_real *w = net->w[i][net->bank[i] ^ out.updated[i]];
        rhonn_real *z = net->z[zb_new][i];
        rhonn_real acc = R(0.0);

        RHONN_NEURON_LOOP
        for (t = 0; t < L; ++t) {
            rhonn_real prod = val[value_index(net, i, t, 0)];
            size_t f;
            RHONN_UNROLL_LOOP
            for (f = 1; f < factors_read(net, i, t); ++f) {
                prod *= val[value_index(net, i, t, f)];
            }
            z[t] = prod;
            acc += w[t] * prod;
        }
        if (!is_finite(acc)) {
            net->fault_neuron = (uint8_t)i;
            return RHONN_E_DIVERGED;
        }
        xnew[i] = acc;
    }

    /* Commit. */
    commit_sample(net, val, valid);
    RHONN_NEURON_LOOP
    for (i = 0; i < n; ++i) {
        if (out.updated[i]) {
            rhonn_health *h = &net->health[i];
            if (out.recovered[i]) {
                h->resets += 1u;
            } else {
                h->innovation = out.innov[i];
                h->nis = out.nis[i];
                h->updates += 1u;
                h->bounded += out.bounded[i];
            }
            h->fail_run = 0;
            net->bank[i] = (uint8_t)(net->bank[i] ^ 1u);
        } else if (GATE_ON(net, i) && RHONN_UNLIKELY(out.gated[i])) {
            rhonn_health *h = &net->health[i];
            h->innovation = out.innov[i];
            h->nis = out.nis[i];
            h->gated += 1u;
        }
        net->xhat[i] = xnew[i];
        if (xhat_next != NULL) { /* here, not in a loop of its own: that becomes a memcpy call */
            xhat_next[i] = xnew[i];
        }
    }
    net->zbank = zb_new;
    net->started = 1;
    net->steps += 1u;
    return RHONN_OK;
}

/* The entry points of rhonn_internal.h (for rhonn_population.c). */
rhonn_status rhonn_internal_check_net(const rhonn_t *net)
{
    return check_net(net);
}

rhonn_status rhonn_internal_check_inputs(const rhonn_t *net, const rhonn_real *x, const rhonn_real *u,
                                         const uint8_t *valid)
{
    return check_inputs(net, x, u, valid);
}

void rhonn_internal_features(const rhonn_t *net, const rhonn_real *x, const rhonn_real *u, const uint8_t *valid,
                             rhonn_real *val)
{
    features(net, x, u, valid, val);
}

void rhonn_internal_held_values(const rhonn_t *net, const rhonn_real *xhat, const uint8_t *valid, rhonn_real *val,
                                uint8_t *rewritten)
{
    const size_t n = CFG(net)->n_states, groups = net->n_groups;
    rhonn_real *ent = val + RHONN_SAMPLE_LEN;
    size_t j, g, e;
    if (rewritten != NULL) {
        for (j = 0; j < (size_t)RHONN_SAMPLE_LEN + net->n_entries; ++j) {
            rewritten[j] = 0;
        }
    }
    /* step 2 for the missing x_j: the member's own prediction and its S */
    for (j = 0; j < n; ++j) {
        if (valid[j] != 0u) {
            continue;
        }
        val[j] = xhat[j];
        for (g = 0; g < groups; ++g) {
            val[OFF_S(g) + j] = activate(net->group_activation[g], net->group_beta[g], val[j]);
        }
        if (rewritten != NULL) {
            for (g = 0; g <= groups; ++g) {
                rewritten[(size_t)RHONN_MAX_STATES * g + j] = 1;
            }
        }
    }
    /* step 3 for the entries of this sample that read them (powers) */
    for (e = 0; e < net->n_entries; ++e) {
        const size_t off = net->entry_off[e];
        if (net->entry_delay[e] != 0u || off >= OFF_U || valid[off % (size_t)RHONN_MAX_STATES] != 0u) {
            continue;
        }
        ent[e] = net->entry_power[e] == 1u ? val[off] : ipow(val[off], net->entry_power[e]);
        if (rewritten != NULL) {
            rewritten[RHONN_SAMPLE_LEN + e] = 1;
        }
    }
}

uint8_t rhonn_internal_delayed_reads(const rhonn_t *net, uint8_t *deepest)
{
    uint8_t inputs = 0;
    size_t j, e;
    for (j = 0; j < (size_t)RHONN_MAX_STATES; ++j) {
        deepest[j] = 0;
    }
    for (e = 0; e < net->n_entries; ++e) {
        const size_t off = net->entry_off[e];
        uint8_t *d = off < OFF_U ? &deepest[off % (size_t)RHONN_MAX_STATES] : &inputs;
        *d = net->entry_delay[e] > *d ? net->entry_delay[e] : *d;
    }
    return inputs;
}

void rhonn_internal_commit_sample(rhonn_t *net, const rhonn_real *cur, const uint8_t *valid)
{
    commit_sample(net, cur, valid);
}

void rhonn_internal_commit_ring(rhonn_t *net, const rhonn_real *cur)
{
    commit_ring(net, cur);
}

void rhonn_internal_store_sample(rhonn_t *net, size_t slot, const rhonn_real *cur)
{
    store_sample(net->hist[slot], cur, CFG(net)->n_states, net->n_groups, CFG(net)->n_inputs);
}

rhonn_status rhonn_internal_ekf_update(rhonn_t *net, size_t i, rhonn_real e, const rhonn_real *z, rhonn_real *nis,
                                       uint8_t *bounded)
{
    uint8_t learns[RHONN_MAX_STATES] = {0}, bnd[RHONN_MAX_STATES] = {0}, gated[RHONN_MAX_STATES] = {0};
    rhonn_real ev[RHONN_MAX_STATES], zv[RHONN_MAX_STATES][RHONN_MAX_TERMS], nv[RHONN_MAX_STATES];
    size_t t, from = i;
    rhonn_status st;
    learns[i] = 1;
    ev[i] = e;
    nv[i] = *nis; /* as the kernel leaves them when it refuses early */
    bnd[i] = *bounded;
    for (t = 0; t < CFG(net)->neurons[i].n_terms; ++t) {
        zv[i][t] = z[t];
    }
    /* no gate here: a gated lane discards this update's result (gate_lanes, rhonn_population.c) */
    st = update_neurons(net, learns, ev, zv, nv, bnd, gated, &from);
    *nis = nv[i];
    *bounded = bnd[i];
    return st;
}

void rhonn_internal_load_p0(const rhonn_t *net, size_t i, rhonn_real *dst)
{
    load_p0(net, i, dst);
}

int rhonn_internal_count_refusal(rhonn_t *net, size_t i)
{
    return count_refusal(net, i);
}

uint8_t rhonn_internal_p0_proven(const rhonn_t *net, size_t i)
{
    return p0_proven(&CFG(net)->neurons[i]);
}

rhonn_status rhonn_step(rhonn_t *net, const rhonn_real *x, const rhonn_real *u,
                        const uint8_t *valid, rhonn_real *xhat_next)
{
    const rhonn_status st = check_net(net);
    if (st != RHONN_OK) {
        return st;
    }
    if (x == NULL || (u == NULL && CFG(net)->n_inputs > 0u)) {
        return RHONN_E_NULL;
    }
    return step_checked(net, x, u, valid, xhat_next);
}

rhonn_status rhonn_run(rhonn_t *net, size_t T, const rhonn_real *X, const rhonn_real *U,
                       const uint8_t *valid, rhonn_real *Xhat, size_t *done)
{
    rhonn_status st = check_net(net);
    size_t n, m, k;

    if (done != NULL) {
        *done = 0;
    }
    if (st != RHONN_OK) {
        return st;
    }
    n = CFG(net)->n_states;
    m = CFG(net)->n_inputs;
    if (T == 0u) {
        return RHONN_OK;
    }
    if (X == NULL || Xhat == NULL || (U == NULL && m > 0u)) {
        return RHONN_E_NULL;
    }
    /* the net and the buffers were checked once, above */
    for (k = 0; k < T; ++k) {
        st = step_checked(net, X + k * n, m > 0u ? U + k * m : U, valid != NULL ? valid + k * n : NULL,
                          Xhat + k * n);
        if (st != RHONN_OK) {
            return st;
        }
        if (done != NULL) {
            *done = k + 1u;
        }
    }
    return RHONN_OK;
}

/* ------------------------------------------------------------------------ */
/* Accessors */

/* Checks shared by the per-neuron accessors: an initialised net, a buffer,
 * a neuron in range, and exactly the length that neuron's vector (L_i) or
 * packed covariance (L_i (L_i + 1) / 2) has. */
static rhonn_status neuron_access(const rhonn_t *net, const void *buf, size_t neuron, size_t len, int packed)
{
    rhonn_status st = check_net(net);
    size_t L;
    if (st != RHONN_OK) {
        return st;
    }
    if (buf == NULL) {
        return RHONN_E_NULL;
    }
    if (neuron >= CFG(net)->n_states) {
        return RHONN_E_ARGUMENT;
    }
    L = CFG(net)->neurons[neuron].n_terms;
    return len == (packed ? packed_size(L) : L) ? RHONN_OK : RHONN_E_ARGUMENT;
}

static void copy_reals(rhonn_real *dst, const rhonn_real *src, size_t len)
{
    size_t t;
    for (t = 0; t < len; ++t) {
        dst[t] = src[t];
    }
}

rhonn_status rhonn_get_weights(const rhonn_t *net, size_t neuron, rhonn_real *w, size_t len)
{
    rhonn_status st = neuron_access(net, w, neuron, len, 0);
    if (st == RHONN_OK) {
        copy_reals(w, net->w[neuron][net->bank[neuron]], len);
    }
    return st;
}

rhonn_status rhonn_set_weights(rhonn_t *net, size_t neuron, const rhonn_real *w, size_t len)
{
    rhonn_status st = neuron_access(net, w, neuron, len, 0);
    if (st != RHONN_OK) {
        return st;
    }
    if (any_nonfinite(w, len)) {
        return RHONN_E_VALUE;
    }
    copy_reals(net->w[neuron][net->bank[neuron]], w, len);
    return RHONN_OK;
}

static int is_ud(const rhonn_t *net, size_t neuron)
{
    return CFG(net)->neurons[neuron].covariance == (uint8_t)RHONN_COV_UD;
}

/* U D U^T from the factors F (D on the packed diagonal, U beside it):
 * P(r,c) = sum_{k >= c} U(r,k) d_k U(c,k), r <= c, U(k,k) = 1. */
static void ud_product(const rhonn_real *F, rhonn_real *p, size_t L)
{
    size_t r, c, k;
    for (r = 0; r < L; ++r) {
        const size_t rr = row_start(r, L);
        for (c = r; c < L; ++c) {
            const size_t rc = row_start(c, L);
            rhonn_real acc = F[rc] * (c == r ? R(1.0) : F[rr + (c - r)]);
            for (k = c + 1u; k < L; ++k) {
                acc += F[rr + (k - r)] * (F[row_start(k, L)] * F[rc + (k - c)]);
            }
            p[rr + (c - r)] = acc;
        }
    }
}

/* The covariance a RHONN_COV_UD neuron reads (rhonn.h ROUND TRIP): the
 * product P^ of ud_product when shifted_check proves it definite, else P^
 * with its diagonal raised by delta P^_rr.
 *
 * Why delta = 32 L g, g = gamma_{L+1} = 1.01 (L+1) u, suffices. Let P be
 * the exact U D U^T of the stored factors (positive definite: d_j > 0, U
 * unit triangular). Each P^_rc sums at most L products of three factors,
 * so |P^_rc - P_rc| <= g sum_k |U(r,k)| d_k |U(c,k)| <= g sqrt(P_rr P_cc)
 * (Cauchy-Schwarz; Higham, Accuracy and Stability, 3.1). With
 * T = diag(P_rr)^(-1/2): |T (P^ - P) T|_2 <= L g, and the raised diagonal
 * adds at least (delta - 2u)(1 - g) to T P^ T's, so the raised P~ has
 * lambda_min(T P~ T) >= (delta - 2u)(1 - g) - L g > 30.9 L g - 2u.
 * shifted_check scales P~ to C, diagonal in [1, 4), and passes when
 * lambda_min(C) > 17 L g + 4u + 4.04 L g (the shift, its rounding, Demmel's
 * bound at a diagonal below 4; see shifted_check); C = (S T^-1)(T P~ T)
 * (T^-1 S) with (S T^-1)_rr^2 >= P_rr / P~_rr >= 1 - delta - g - 3u, so
 * lambda_min(C) > (30.9 L g - 2u)(1 - 2 delta) > 21.1 L g + 4u whenever
 * delta <= 1/8 (L g <= 1/256: L up to 255 in float). Each further doubling
 * of delta, for the rounding of these bounds themselves, only adds margin;
 * a P^ that is not finite, or whose diagonal leaves the normal range, no
 * raise can help (the last one tried is returned). */
RHONN_NOINLINE static void ud_covariance(const rhonn_real *F, rhonn_real *p, size_t L)
{
    rhonn_real diag[RHONN_MAX_TERMS];
    rhonn_real delta = (R(32.0) / R(17.0)) * rhonn_proof_shift(L); /* 32 L gamma_{L+1} */
    size_t r, attempt;
    ud_product(F, p, L);
    for (r = 0; r < L; ++r) {
        diag[r] = p[row_start(r, L)];
    }
    /* attempt 0: P^ itself; then the raises (one factorisation in the code) */
    for (attempt = 0; !accessor_check(p, L, rhonn_proof_shift(L)) && attempt < 9u; ++attempt) { /* shifted_check */
        for (r = 0; r < L; ++r) {
            p[row_start(r, L)] = diag[r] + delta * diag[r];
        }
        delta *= R(2.0);
    }
}

rhonn_status rhonn_get_covariance(const rhonn_t *net, size_t neuron, rhonn_real *p, size_t len)
{
    rhonn_status st = neuron_access(net, p, neuron, len, 1);
    const rhonn_real *F;
    if (st != RHONN_OK) {
        return st;
    }
    F = net->p[neuron][net->bank[neuron]];
    if (!is_ud(net, neuron)) {
        copy_reals(p, F, len);
        return RHONN_OK;
    }
    ud_covariance(F, p, CFG(net)->neurons[neuron].n_terms);
    return RHONN_OK;
}

rhonn_status rhonn_set_covariance(rhonn_t *net, size_t neuron, const rhonn_real *p, size_t len)
{
    rhonn_status st = neuron_access(net, p, neuron, len, 1);
    size_t L;
    if (st != RHONN_OK) {
        return st;
    }
    L = CFG(net)->neurons[neuron].n_terms;
    if (any_nonfinite(p, len)) {
        return RHONN_E_VALUE;
    }
#if RHONN_WITH_UD
    if (is_ud(net, neuron)) {
        rhonn_real F[RHONN_MAX_PACKED];
        size_t t;
        int same = 1;
        /* what rhonn_get_covariance reads for the stored factors keeps them
         * (rhonn.h ROUND TRIP): the round trip changes nothing. Equal as
         * numbers (a copy may have turned a -0 into +0). */
        ud_covariance(net->p[neuron][net->bank[neuron]], F, L);
        for (t = 0; t < len; ++t) {
            same &= F[t] == p[t];
        }
        if (same) {
            return RHONN_OK;
        }
    }
#endif
    /* a covariance: positive definite at working precision (pd_check) */
    if (!accessor_check(p, L, R(0.0))) {
        return RHONN_E_VALUE;
    }
#if RHONN_WITH_UD
    if (is_ud(net, neuron)) {
        rhonn_real F[RHONN_MAX_PACKED];
        if (!udu_of(p, F, L)) {
            return RHONN_E_VALUE;
        }
        copy_reals(net->p[neuron][net->bank[neuron]], F, len);
        return RHONN_OK;
    }
#endif
    copy_reals(net->p[neuron][net->bank[neuron]], p, len);
    net->cert[neuron][net->bank[neuron]] = 0;
    return RHONN_OK;
}

rhonn_status rhonn_get_factors(const rhonn_t *net, size_t neuron, rhonn_real *f, size_t len)
{
    rhonn_status st = neuron_access(net, f, neuron, len, 1);
    if (st == RHONN_OK) {
        copy_reals(f, net->p[neuron][net->bank[neuron]], len);
    }
    return st;
}

rhonn_status rhonn_set_factors(rhonn_t *net, size_t neuron, const rhonn_real *f, size_t len)
{
    rhonn_status st = neuron_access(net, f, neuron, len, 1);
    size_t L, r;
    if (st != RHONN_OK) {
        return st;
    }
    if (!is_ud(net, neuron)) {
        return rhonn_set_covariance(net, neuron, f, len);
    }
    if (any_nonfinite(f, len)) {
        return RHONN_E_VALUE;
    }
    L = CFG(net)->neurons[neuron].n_terms;
    for (r = 0; r < L; ++r) {
        if (!(f[row_start(r, L)] > R(0.0))) {
            return RHONN_E_VALUE;
        }
    }
    copy_reals(net->p[neuron][net->bank[neuron]], f, len);
    return RHONN_OK;
}

rhonn_status rhonn_get_health(const rhonn_t *net, size_t neuron, rhonn_health *out)
{
    rhonn_status st = check_net(net);
    const rhonn_real *F;
    size_t L;
    if (st != RHONN_OK) {
        return st;
    }
    if (out == NULL) {
        return RHONN_E_NULL;
    }
    if (neuron >= CFG(net)->n_states) {
        return RHONN_E_ARGUMENT;
    }
    L = CFG(net)->neurons[neuron].n_terms;
    F = net->p[neuron][net->bank[neuron]];
    *out = net->health[neuron];
    out->trace_p = is_ud(net, neuron) ? ud_trace(F, L) : full_trace(F, L);
    return RHONN_OK;
}

rhonn_status rhonn_get_prediction(const rhonn_t *net, rhonn_real *xhat, size_t len)
{
    rhonn_status st = check_net(net);
    size_t j;
    if (st != RHONN_OK) {
        return st;
    }
    if (xhat == NULL) {
        return RHONN_E_NULL;
    }
    if (len != CFG(net)->n_states) {
        return RHONN_E_ARGUMENT;
    }
    for (j = 0; j < len; ++j) {
        xhat[j] = net->xhat[j];
    }
    return RHONN_OK;
}

const char *rhonn_status_name(rhonn_status status)
{
    switch (status) {
    case RHONN_OK: return "RHONN_OK";
    case RHONN_E_NULL: return "RHONN_E_NULL";
    case RHONN_E_NOT_INIT: return "RHONN_E_NOT_INIT";
    case RHONN_E_CONFIG: return "RHONN_E_CONFIG";
    case RHONN_E_ARGUMENT: return "RHONN_E_ARGUMENT";
    case RHONN_E_INPUT_NONFINITE: return "RHONN_E_INPUT_NONFINITE";
    case RHONN_E_INNOVATION: return "RHONN_E_INNOVATION";
    case RHONN_E_COVARIANCE: return "RHONN_E_COVARIANCE";
    case RHONN_E_DIVERGED: return "RHONN_E_DIVERGED";
    case RHONN_E_VALUE: return "RHONN_E_VALUE";
    case RHONN_E_NOT_PD: return "RHONN_E_NOT_PD";
    default: return "RHONN_E_UNKNOWN";
    }
}
