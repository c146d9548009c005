/*
 * rhonn.h - recurrent high-order neural network identifier trained by a
 * per-neuron extended Kalman filter (Alanis et al., "Neural identifier for
 * unknown discrete-time nonlinear delayed systems", eq. 3-12).
 *
 * The plant x(k+1) = F(x(k-l), u(k)) (eq. 1) is approximated, one neuron per
 * state, in series-parallel form (eq. 12):
 *
 *     xhat_i(k+1) = w_i^T z_i(x(k), x(k-1), ..., u(k))            (eq. 3)
 *     z_ij       = prod_{f in I_j} xi_f ^ d_f                       (eq. 4)
 *     xi         = [S(x_1) .. S(x_n), u_1 .. u_m]                   (eq. 5)
 *
 * and each w_i is trained by the EKF of eq. 7-9. The network is linear in its
 * weights, so H_i = dxhat_i/dw_i = z_i and every neuron's update is a
 * scalar-measurement Kalman update of its own L_i x L_i covariance:
 *
 *     e_i   = x_i(k) - xhat_i(k)                                   (eq. 9)
 *     M_i   = 1 / (R_i + z_i^T P_i z_i)                              (eq. 8)
 *     K_i   = P_i z_i M_i                                            (eq. 7)
 *     w_i  <- w_i + eta_i K_i e_i                                    (eq. 7)
 *     P_i  <- P_i - K_i z_i^T P_i + Q_i                              (eq. 7)
 *
 * COVARIANCE FORM (per neuron, rhonn_neuron_config.covariance). RHONN_COV_FULL
 * stores P_i itself and runs eq. 7 as written. RHONN_COV_UD stores the factors
 * of P_i = U D U^T (U unit upper triangular, D diagonal > 0) and runs the same
 * filter as Bierman's scalar measurement update (the eq. 7-8 correction, with
 * K_i = P_i z_i M_i from the factors) followed by + Q_i as L_i rank-one
 * updates (Agee and Turner): the same filter in exact arithmetic, but every
 * d_j stays a positive number in floating point, so P_i cannot lose
 * definiteness through rounding (the conventional update can in float32 when
 * R_i is small against z^T P z and the regressors are nearly collinear). It
 * costs about L^3 / 3 multiply-adds and L (L + 3) / 2 divisions per neuron and
 * step against 2 L^2 and 1 for the full form (no + Q work when Q_i = 0).
 * RHONN_WITH_UD=0 compiles it out (configs asking for it are then refused).
 * Whatever the form, a learning update whose P_i(k+1) is not positive
 * definite at working precision (a pivot of its U D U^T factorisation is not
 * a positive finite number) or whose innovation variance s_i = R_i + z^T P_i z
 * is below R_i is not committed: the step returns RHONN_E_NOT_PD or
 * RHONN_E_INNOVATION. After every RHONN_OK, each P_i is positive definite.
 * The full form usually proves it without the O(L^3) factorisation: when the
 * old P_i was proven definite in exact arithmetic (initially by a shifted
 * factorisation), rounding-error bounds of the update, O(L) to evaluate,
 * show the new one is too whenever Q_i's smallest entry dominates them (no
 * forgetting, no trace bound that step). Only when they do not is the new
 * P_i factorised. The verdict is the factorisation's in every case.

 * WINDUP PROTECTION (per neuron, all off when zero, so eq. 7 stays exact):
 *   forgetting   lambda in (0, 1]: exponential forgetting of old information,
 *                bounded by the trace ceiling c_i (p_trace_max when set, else
 *                trace P_i(0)). With P+ = P_i - K_i z^T P_i (eq. 7's
 *                correction):
 *                    P_i <- P+ / lambda + Q_i   when trace(P+) / lambda <= c_i
 *                    P_i <- P+ + Q_i            otherwise (eq. 7 as written)
 *                so forgetting alone never lifts trace P_i above c_i: in a
 *                quiet stretch, where z visits few directions, the others
 *                grow by 1 / lambda a step only until P_i is as uncertain as
 *                it started, not without bound (which overflowed P or, in
 *                the full form, made it indefinite after ~10^4 steps at
 *                lambda = 0.999 in float). Where the filter is excited and
 *                trace P+ / lambda stays below c_i (the usual regime),
 *                every step forgets, as plain exponential forgetting does.
 *                trace(P+) is the sum of P+'s diagonal as formed (U D U^T:
 *                sum_j d_j (1 + sum_{i<j} U(i,j)^2)), in working precision;
 *                0 or 1 means off
 *   p_trace_max  a ceiling on trace P_i: a P_i(k+1) above it is scaled by
 *                p_trace_max / trace P_i(k+1) (counted in rhonn_health.bounded),
 *                so a long unexcited stretch, where Q_i piles up in every
 *                direction z does not visit, cannot build an unbounded gain
 *   reset_after  recovery: when a neuron's learning update is refused this many
 *                times in a row, the next refusal resets its P_i to P_i(0)
 *                instead (weights kept, the update skipped, counted in
 *                rhonn_health.resets) and the step goes on
 *
 * INNOVATION GATE (per neuron, gate; 0 = off, so eq. 7 stays exact): an
 * update whose normalised innovation squared nis_i = e_i^2 / s_i (eq. 8-9,
 * s_i = R_i + z^T P_i z) exceeds gate is skipped: w_i and P_i stay as they
 * were, the step goes on and returns RHONN_OK, and the skip is counted in
 * rhonn_health.gated (innovation and nis record it; fail_run is unchanged:
 * neither a refusal nor an update). For a consistent filter nis_i is
 * chi-square with 1 degree of freedom, so gate = 9 skips 0.27 % of good
 * samples, 10.83 0.1 %: an outlier (a spike, a stuck sensor's jump) is not
 * learned. s_i is checked first (RHONN_E_INNOVATION), the gate before the
 * weights are formed, so an outlier that would overflow them is skipped, not
 * refused.
 *
 * REFUSALS, NEURON BY NEURON (per neuron, skip_refused; 0 = off): a neuron
 * whose learning update is refused (RHONN_E_INNOVATION, RHONN_E_COVARIANCE,
 * RHONN_E_DIVERGED for its weights, RHONN_E_NOT_PD) does not stop the step:
 * its w_i and P_i stay as they were (the update is skipped), the refusal is
 * counted (rhonn_health.rejected, fail_run), the other neurons learn and the
 * step returns RHONN_OK. With reset_after, the refusal that completes the
 * run recovers the neuron as without skip_refused, so recovery happens
 * inside rhonn_run too. A neuron that keeps refusing is frozen (its
 * prediction goes on from its weights) until then, or until the caller
 * replaces its weights or covariance; the others keep learning. Errors that
 * are not a neuron's update (bad arguments, non-finite inputs, a prediction
 * that would not be finite) still stop the step.
 *
 * ORDER OF ONE STEP (rhonn_step), for the sample k carrying x(k), u(k):
 *   1. Learn: for every neuron i whose measurement is valid, form
 *      e_i(k) = x_i(k) - xhat_i(k) and update w_i, P_i using the regressor
 *      z_i(k-1) that produced xhat_i(k). No learning happens on the first
 *      step after init/reset (there is no xhat(0) to compare with), nor while
 *      learning is switched off, nor for a neuron whose z_i(k-1) read its own
 *      state's prediction in place of a missing x_i (at any of its own taps,
 *      counted down to its deepest one): then xhat_i(k) is the end of a free
 *      run of x_i, and e_i(k) is that run's accumulated drift, not a one-step
 *      error; learning it would kick w_i at the end of every dropout.
 *      With wait_for_history, a neuron also skips learning while z_i(k-1)
 *      read the constant history before the first sample at any of its
 *      taps (any factor's delay, states and inputs): it learns from the
 *      sample D_i + 1 after init, reset or restart on, D_i the deepest
 *      delay it reads, and after a dropout of its own state once it has
 *      been measured D_i + 1 samples in a row (its own-state rule then
 *      counts down to D_i). A model fitted offline on measured histories is
 *      not taught the padded start of every record.
 *      A neuron whose e_i^2 / s_i exceeds its gate skips its update.
 *   2. Form the regressor z(k) from x(k), the delayed samples x(k-d), u(k)
 *      and the delayed inputs u(k-d). A state whose measurement is invalid
 *      is replaced by its own prediction xhat_j(k) (on the very first step:
 *      config x0), so a dropout neither trains the neuron nor poisons the
 *      other regressors.
 *   3. Predict xhat(k+1) = w(k+1)^T z(k) with the freshly updated weights and
 *      return it.
 * Before the first step, every delayed tap reads the first sample: the
 * history is taken as constant, as for a delay equation's initial function.

 * ERRORS. Every function returns rhonn_status. A step that fails leaves the
 * identifier exactly as it was before the call (weights, covariances,
 * history, prediction): the new values are computed into the inactive half of
 * double-buffered storage and committed only when every neuron succeeded.
 * Only the failing neuron's health counters (rhonn_health: rejected,
 * fail_run) record the refusal.
 * Because nothing is committed, a failure caused by the stored state rather
 * than by the new sample (a learning update that overflows for the stored
 * z(k-1) and P, e.g. after huge inputs or with P0, Q or eta near the range
 * of rhonn_real) repeats on every later step. The caller recovers with
 * rhonn_reset, with rhonn_set_learning(net, 0) (predictions go on from the
 * frozen weights) or by replacing the weights and covariance with the
 * setters; the firmware app counts such steps as step errors.
 * Nothing in this library allocates, prints, recurses or aborts.
 *
 * PRECISION. rhonn_real is double, or float when RHONN_SINGLE is defined.
 * The same source builds both; the two builds are separate libraries.
 */
#ifndef RHONN_H
#define RHONN_H

#include <stddef.h>
#include <stdint.h>

#include "rhonn_capacity.h"

#ifdef __cplusplus
extern "C" {
#endif

#ifdef RHONN_SINGLE
typedef float rhonn_real;
#else
typedef double rhonn_real;
#endif

/* Version of this header's API and of rhonn_t's layout. */
#define RHONN_VERSION_MAJOR 1
#define RHONN_VERSION_MINOR 4

typedef enum {
    RHONN_OK = 0,
    RHONN_E_NULL = 1,           /* a required pointer argument is NULL */
    RHONN_E_NOT_INIT = 2,       /* rhonn_t was not set up by rhonn_init */
    RHONN_E_CONFIG = 3,         /* configuration invalid; see rhonn_config_error */
    RHONN_E_ARGUMENT = 4,       /* index or length argument out of range */
    RHONN_E_INPUT_NONFINITE = 5,/* a valid x_j(k) or some u_j(k) is NaN/Inf */
    RHONN_E_INNOVATION = 6,     /* R_i + z^T P_i z is not a positive finite number */
    RHONN_E_COVARIANCE = 7,     /* the updated P_i would not be finite */
    RHONN_E_DIVERGED = 8,       /* updated weights or the prediction would not be finite */
    RHONN_E_VALUE = 9,          /* a value given to a setter is invalid (non-finite, P_jj <= 0) */
    RHONN_E_NOT_PD = 10         /* the updated P_i would not be positive definite (not committed) */
} rhonn_status;

/* Factor kinds of a high-order term (eq. 4-5). */
typedef enum {
    RHONN_FACTOR_S = 0,   /* S(x_index(k - delay)): activation of a (delayed) state */
    RHONN_FACTOR_X = 1,   /* x_index(k - delay): the raw (delayed) state */
    RHONN_FACTOR_U = 2,   /* u_index(k - delay): a (delayed) input, input dead time */
    RHONN_FACTOR_ONE = 3  /* the constant 1 (bias); index and delay must be 0 */
} rhonn_factor_kind;

/* How a neuron stores and updates P_i (see COVARIANCE FORM above). */
typedef enum {
    RHONN_COV_FULL = 0,   /* P_i itself, eq. 7 as written, positive definiteness checked */
    RHONN_COV_UD = 1      /* P_i = U D U^T, Bierman + Agee-Turner: definite by construction */
} rhonn_covariance_form;

/* Activation S(.) of one neuron. */
typedef enum {
    RHONN_LOGISTIC = 0,   /* S(s) = 1 / (1 + exp(-beta s))                 (eq. 6)  */
    RHONN_BIPOLAR = 1     /* S(s) = (1 - exp(-beta s)) / (1 + exp(-beta s)) (eq. 19) */
} rhonn_activation;

typedef struct {
    uint8_t kind;   /* rhonn_factor_kind */
    uint8_t index;  /* state index (S, X) or input index (U); 0 for ONE */
    uint8_t delay;  /* d in x(k - d) or u(k - d), 0..RHONN_MAX_DELAY; 0 for ONE */
    uint8_t power;  /* exponent d_ij, 1..RHONN_MAX_POWER */
} rhonn_factor;

typedef struct {
    uint8_t n_factors;                          /* 1..RHONN_MAX_FACTORS */
    rhonn_factor factors[RHONN_MAX_FACTORS];
} rhonn_term;

typedef struct {
    uint8_t n_terms;            /* L_i, 1..RHONN_MAX_TERMS */
    uint8_t activation;         /* rhonn_activation */
    rhonn_real beta;            /* slope of S, > 0 */
    rhonn_real eta;             /* learning rate eta_i of eq. 7, > 0 */
    rhonn_real r;               /* R_i of eq. 8, > 0 */
    rhonn_real q[RHONN_MAX_TERMS];   /* diag(Q_i), >= 0 */
    rhonn_real w0[RHONN_MAX_TERMS];  /* w_i(0) */
    /* P_i(0), packed upper triangle row by row: P00 P01 .. P0L P11 P12 ..
     * The paper's diagonal P_i(0) has zeros off the diagonal; a full one
     * (e.g. exported after training) is accepted. Diagonal entries > 0.
     * It must also be positive definite (a covariance, eq. 10): the core
     * factorises it (U D U^T) and refuses it unless every pivot is a positive
     * finite number at working precision. So does rhonn_set_covariance. */
    rhonn_real p0[RHONN_MAX_PACKED];
    rhonn_term terms[RHONN_MAX_TERMS];
    /* Covariance form and windup protection (see above). Zero, as in a
     * zero- or designated-initialised config, is the full form, no
     * forgetting, no bound and no automatic reset: eq. 7 exactly. */
    uint8_t covariance;         /* rhonn_covariance_form */
    uint16_t reset_after;       /* 0 = off; else reset P_i after this many refusals in a row */
    rhonn_real forgetting;      /* lambda in (0, 1]; 0 = 1 = off */
    rhonn_real p_trace_max;     /* 0 = off; else >= trace P_i(0) */
    /* Innovation gate (see above): 0 = off; else >= 0, finite: the largest
     * e_i^2 / s_i learned (e.g. 9, chi-square 1 dof at 99.7 %). */
    rhonn_real gate;
    /* What a refused learning update stops (see REFUSALS above): 0 (as in a
     * zero-initialised config) the whole step, which returns the refusal and
     * commits nothing; 1 only this neuron's update, skipped while the others
     * learn and the step goes on. Last, so that positional initialisers
     * written before it existed leave it 0. */
    uint8_t skip_refused;
    /* When this neuron starts learning after init, reset or restart (see
     * STEP 1 below): 0 (as in a zero-initialised config) at the second
     * sample, the history before the first sample taken as constant (the
     * paper's initial function); 1 once every delayed tap of its regressor
     * reads a measured sample, its state measured in each of them. */
    uint8_t wait_for_history;
} rhonn_neuron_config;

typedef struct {
    uint8_t n_states;           /* n, 1..RHONN_MAX_STATES */
    uint8_t n_inputs;           /* m, 0..RHONN_MAX_INPUTS */
    rhonn_real x0[RHONN_MAX_STATES];  /* xhat(0): stands in for states invalid at k = 0 */
    rhonn_neuron_config neurons[RHONN_MAX_STATES];
} rhonn_config;

/* Which field of a configuration was rejected (rhonn_validate_config). */
typedef enum {
    RHONN_FIELD_NONE = 0,
    RHONN_FIELD_N_STATES, RHONN_FIELD_N_INPUTS, RHONN_FIELD_X0,
    RHONN_FIELD_N_TERMS, RHONN_FIELD_ACTIVATION, RHONN_FIELD_BETA,
    RHONN_FIELD_ETA, RHONN_FIELD_R, RHONN_FIELD_Q, RHONN_FIELD_W0, RHONN_FIELD_P0,
    RHONN_FIELD_N_FACTORS, RHONN_FIELD_FACTOR_KIND, RHONN_FIELD_FACTOR_INDEX,
    RHONN_FIELD_FACTOR_DELAY, RHONN_FIELD_FACTOR_POWER,
    RHONN_FIELD_COVARIANCE, RHONN_FIELD_FORGETTING, RHONN_FIELD_P_TRACE_MAX,
    RHONN_FIELD_RESET_AFTER, RHONN_FIELD_GATE, RHONN_FIELD_SKIP_REFUSED,
    RHONN_FIELD_WAIT_FOR_HISTORY
} rhonn_field;

typedef struct {
    uint8_t field;      /* rhonn_field */
    uint8_t neuron;     /* neuron index, when the field belongs to one */
    uint8_t term;       /* term index, when the field belongs to one */
    uint8_t factor;     /* factor index (or P0/Q entry index), likewise */
} rhonn_config_error;

/* Filter health of one neuron (rhonn_get_health). The counters wrap. */
typedef struct {
    rhonn_real innovation;  /* e_i of the last learning update, committed or gated (eq. 9);
                             * 0 before the first */
    rhonn_real nis;         /* normalised innovation squared e_i^2 / s_i of that update,
                             * s_i = R_i + z^T P_i z (eq. 8); about 1 on average for a
                             * consistent filter, persistently large when P_i is too small */
    rhonn_real trace_p;     /* trace of the committed P_i, computed by rhonn_get_health */
    uint32_t updates;       /* learning updates committed */
    uint32_t rejected;      /* learning updates refused (the step returned the refusal, or
                             * with skip_refused went on without this neuron's update) */
    uint32_t resets;        /* automatic covariance resets (reset_after) */
    uint32_t bounded;       /* updates whose P_i was scaled down to p_trace_max */
    uint32_t gated;         /* updates skipped by the innovation gate (e^2 / s > gate) */
    uint16_t fail_run;      /* refused updates in a row, up to now */
} rhonn_health;

/* RHONN_CONST_CONFIG=1 (a build option, the same for every translation unit
 * that sees rhonn_t): rhonn_t refers to the caller's configuration instead of
 * holding a copy of it, so firmware whose configuration is a static const in
 * flash does not duplicate it in RAM (sizeof(rhonn_config) bytes saved). The
 * configuration given to rhonn_init must then outlive the identifier and stay
 * unchanged: rhonn_init validates it once and the core never re-checks it. */
#ifndef RHONN_CONST_CONFIG
#define RHONN_CONST_CONFIG 0
#endif

/* RHONN_FIXED_CONFIG=<name>, with RHONN_FIXED_CONFIG_HEADER="<file.h>" that
 * defines the configuration <name> (a static const rhonn_config, as
 * pyrhonn.export.export_header writes it): the core compiled for that one
 * configuration. Options of the core's own source file only (rhonn_t is the
 * same with or without them). Every size, covariance form and constant of
 * the configuration is then known where the step is compiled: the loops
 * over the neurons unroll into straight code, one kernel per neuron with
 * nothing to dispatch (the firmware's LIM step on the Cortex-M4 costs about
 * a sixth less, its code about a third less: docs/firmware.md). The
 * same floating-point operations run in the same order, so every result is
 * bit for bit the general core's. rhonn_init then accepts only a
 * configuration equal to <name> in every field; RHONN_E_CONFIG names the
 * first that differs. */

/* The identifier. Caller-owned; treat the fields as private and use the
 * functions below. Its size is sizeof(rhonn_t), fixed by the capacities. */
typedef struct {
    uint32_t magic;                 /* set by rhonn_init */
#if RHONN_CONST_CONFIG
    const rhonn_config *cfg;        /* the validated configuration (caller's, constant) */
#else
    rhonn_config cfg;               /* validated copy of the configuration */
#endif

    /* Neurons that share an activation and beta share their S(x) values. */
    uint8_t n_groups;
    uint8_t group_of[RHONN_MAX_STATES];
    uint8_t group_activation[RHONN_MAX_STATES];
    rhonn_real group_beta[RHONN_MAX_STATES];

    /* Double-buffered learning state: bank[i] selects the committed half. */
    uint8_t bank[RHONN_MAX_STATES];
    rhonn_real w[RHONN_MAX_STATES][2][RHONN_MAX_TERMS];
    rhonn_real p[RHONN_MAX_STATES][2][RHONN_MAX_PACKED];
    /* cert[i][b]: bank b's full-form P_i is proven positive definite in
     * exact arithmetic (not only at working precision), which lets the next
     * update certify its result in O(L_i) instead of factorising it. 0
     * whenever P_i is written from outside the update (reset, set). */
    uint8_t cert[RHONN_MAX_STATES][2];

    /* Regressor z(k-1) that produced xhat(k), double-buffered by zbank. */
    uint8_t zbank;
    rhonn_real z[2][RHONN_MAX_STATES][RHONN_MAX_TERMS];
    rhonn_real xhat[RHONN_MAX_STATES];        /* xhat(k) */

    /* The terms compiled by rhonn_init (eq. 4). A step's values are this
     * sample (RHONN_SAMPLE_LEN: x_j(k), S(x_j(k)), u_j(k), 1) followed by
     * the entries: every distinct other factor value x_j(k-d)^p,
     * S(x_j(k-d))^p or u_j(k-d)^p (d > 0 or p > 1), read from offset
     * entry_off of the sample d back and raised to entry_power once per
     * step. Term t of neuron i is the product of the values
     * term_entry[i][t][0..n_factors), its other slots the sample's 1. */
    uint16_t n_entries;
    uint8_t max_delay;              /* deepest tap the configuration reads */
    /* Step 1's own-state rule: neuron i reads its own state x_i down to
     * x_i(k - own_need[i] + 1) (0: not at all); valid_run[j] counts the
     * samples in a row, up to the newest, in which x_j was measured. */
    uint8_t own_need[RHONN_MAX_STATES];
    /* What the first sample ORs into valid_run[j]: 0xFF (the run starts
     * full: nothing older) or, with neuron j's wait_for_history, 0 (the
     * run starts at 1). */
    uint8_t first_run[RHONN_MAX_STATES];
    rhonn_real q_min[RHONN_MAX_STATES];  /* min_t Q_i[t], for the definiteness proof */
    rhonn_real inv_lambda[RHONN_MAX_STATES];  /* 1 / forgetting, 0 when off */
    rhonn_real forget_ceiling[RHONN_MAX_STATES]; /* c_i: p_trace_max, else trace P_i(0) */
    uint8_t q_zero[RHONN_MAX_STATES];         /* Q_i all zero: nothing to add */
    uint8_t gates;                            /* some neuron has an innovation gate */
    uint8_t valid_run[RHONN_MAX_STATES];
    uint8_t entry_delay[RHONN_MAX_ENTRIES];
    uint8_t entry_power[RHONN_MAX_ENTRIES];
    uint16_t entry_off[RHONN_MAX_ENTRIES];
    uint16_t term_entry[RHONN_MAX_STATES][RHONN_MAX_TERMS][RHONN_MAX_FACTORS];

    /* Ring buffer of past samples (RHONN_SAMPLE_LEN values each: the
     * effective x, S(x) per group, u, 1), kept when a tap reads it. */
    uint8_t head;                   /* slot of the newest sample */
    rhonn_real hist[RHONN_HISTORY_LEN][RHONN_SAMPLE_LEN];

    uint8_t started;                /* a step has run since init/reset */
    uint8_t learning;               /* learning on (1) or frozen (0) */
    uint32_t steps;                 /* steps since init/reset (wraps) */
    uint8_t fault_neuron;           /* diagnostics: neuron of the last E_INNOVATION/COVARIANCE/DIVERGED/NOT_PD */
    rhonn_health health[RHONN_MAX_STATES];  /* per neuron; trace_p is filled on reading */
    /* The trace ceilings and innovation gates in force: the configuration's
     * p_trace_max and gate from rhonn_init, then rhonn_set_trace_ceiling and
     * rhonn_set_gate (kept by rhonn_reset and rhonn_restart). */
    rhonn_real trace_max[RHONN_MAX_STATES];
    rhonn_real gate[RHONN_MAX_STATES];
    uint8_t ceilings;                         /* some neuron has a trace ceiling in force */
} rhonn_t;

/* Check a configuration against the capacities and the paper's constraints.
 * On RHONN_E_CONFIG, *where (if not NULL) names the offending field. */
rhonn_status rhonn_validate_config(const rhonn_config *cfg, rhonn_config_error *where);

/* Validate cfg, copy it into net (RHONN_CONST_CONFIG: refer to it) and
 * reset. On error net is left unchanged. */
rhonn_status rhonn_init(rhonn_t *net, const rhonn_config *cfg, rhonn_config_error *where);

/* Back to w(0), P(0), xhat(0), empty history; learning on. */
rhonn_status rhonn_reset(rhonn_t *net);

/* One sample; see ORDER OF ONE STEP above. x has n_states entries, u has
 * n_inputs (may be NULL when n_inputs == 0), valid has n_states flags
 * (nonzero = measured) or is NULL for all valid. An invalid x_j is ignored
 * and may be NaN. xhat_next (n_states) receives xhat(k+1); may be NULL. */
rhonn_status rhonn_step(rhonn_t *net, const rhonn_real *x, const rhonn_real *u,
                        const uint8_t *valid, rhonn_real *xhat_next);

/* A whole trajectory: X is T x n_states, U is T x n_inputs, valid is
 * T x n_states or NULL, Xhat is T x n_states, all row-major. Row t of Xhat is
 * the prediction made at sample t (i.e. of x(t+1)). Stops at the first
 * failing step; *done (may be NULL) receives the number of steps that ran,
 * and the identifier holds the state after those steps. */
rhonn_status rhonn_run(rhonn_t *net, size_t T, const rhonn_real *X, const rhonn_real *U,
                       const uint8_t *valid, rhonn_real *Xhat, size_t *done);

/* Forget the history and the pending comparison, keep what was learnt: the
 * weights, the covariances, the learning switch and xhat(k) (which stands in
 * for states invalid on the next step). The next step learns nothing and
 * fills every delayed tap with its own sample, as the first step after
 * rhonn_init does. For a break in the sample stream (lost frames, a restarted
 * sender): learning the next sample against xhat(k), a prediction made for
 * another sample, would train on a wrong error. */
rhonn_status rhonn_restart(rhonn_t *net);

/* Health of one neuron: the last innovation, e^2/s, trace P_i and the
 * counters. Read-only; counters run since rhonn_init (rhonn_reset keeps
 * them). */
rhonn_status rhonn_get_health(const rhonn_t *net, size_t neuron, rhonn_health *out);

/* Freeze (0) or resume (nonzero) learning; predictions continue either way. */
rhonn_status rhonn_set_learning(rhonn_t *net, int on);

/* Calibrate neuron's trace ceiling (WINDUP PROTECTION's p_trace_max: 0 off,
 * else >= trace P_i(0)) or innovation gate (INNOVATION GATE: 0 off, else the
 * largest e_i^2 / s_i learned), between steps: the next step's learning
 * update uses the new value (a ceiling also bounds forgetting, as c_i).
 * They start as the configuration's p_trace_max and gate (rhonn_init) and
 * are kept by rhonn_reset and rhonn_restart; the configuration itself is
 * not changed. RHONN_E_ARGUMENT for a neuron >= n_states; RHONN_E_VALUE for
 * a value that is NaN, infinite or negative, or a ceiling above 0 but below
 * trace P_i(0) (the limits rhonn_validate_config puts on the configuration);
 * on any refusal nothing changes. With RHONN_FIXED_CONFIG too. The getters
 * read the values in force.
 * RHONN_CALIBRATE (an option of the core's source file, like
 * RHONN_FIXED_CONFIG; default 1): 0 compiles the step with the
 * configuration's ceilings and gates, as before these setters existed (with
 * RHONN_FIXED_CONFIG, no code for a neuron that has neither: the firmware's
 * LIM step on the Cortex-M4 is about 150 cycles shorter); the setters then
 * refuse any other value than the configuration's with RHONN_E_CONFIG.
 * rhonn_check_trace_ceiling and rhonn_check_gate return the status the
 * setter would return for the value and change nothing (a calibration tool
 * checks a whole page of values before it sets any). */
rhonn_status rhonn_set_trace_ceiling(rhonn_t *net, size_t neuron, rhonn_real value);
rhonn_status rhonn_set_gate(rhonn_t *net, size_t neuron, rhonn_real value);
rhonn_status rhonn_check_trace_ceiling(const rhonn_t *net, size_t neuron, rhonn_real value);
rhonn_status rhonn_check_gate(const rhonn_t *net, size_t neuron, rhonn_real value);
rhonn_status rhonn_get_trace_ceiling(const rhonn_t *net, size_t neuron, rhonn_real *value);
rhonn_status rhonn_get_gate(const rhonn_t *net, size_t neuron, rhonn_real *value);

/* Read or replace one neuron's weights (len must equal L_i) and covariance
 * (packed upper triangle, len must equal L_i (L_i + 1) / 2). The setters
 * reject non-finite values, and a covariance that is not positive definite
 * at working precision, with RHONN_E_VALUE.
 *
 * ROUND TRIP. What rhonn_get_covariance reads, rhonn_set_covariance accepts,
 * and writing it back changes nothing (bit for bit: the next steps are those
 * without the round trip), for both covariance forms, after init, reset and
 * every RHONN_OK step. A RHONN_COV_FULL neuron's P_i is stored as read, and
 * every committed one passed the setter's own check. For a RHONN_COV_UD
 * neuron the covariance read is U D U^T formed from the stored factors,
 * P^_rc = sum_{k >= c} U(r,k) d_k U(c,k) in working precision, whose
 * rounding (|P^ - U D U^T|_rc <= g sqrt(P_rr P_cc), g = gamma_{L+1} =
 * 1.01 (L+1) u, u = eps / 2) can leave a nearly singular P^ indefinite. So
 * the getter returns P^ when Rump's shifted factorisation proves it positive
 * definite in exact arithmetic with room to spare (the core's own proof, see
 * rhonn.c shifted_check: then every Cholesky at this precision or a wider
 * one accepts it), which is nearly always, and otherwise P^ with its
 * diagonal raised by delta P^_rr, delta = 32 L g (a relative 5.2e-4 in float
 * and 9.8e-13 in double at L = 16; doubled should the proof still fail):
 * definite with that margin whatever P^'s rounding (proof in rhonn.c
 * ud_covariance). Either way the result is positive definite in exact
 * arithmetic (when the factors' product is finite and its diagonal normal).
 * Given what the getter reads for the stored factors (equal as numbers:
 * -0 and +0 alike), the setter keeps those factors; any other P is
 * factorised (U D U^T), equal to rounding. rhonn_get_factors and
 * rhonn_set_factors move the factors bit for bit. */
rhonn_status rhonn_get_weights(const rhonn_t *net, size_t neuron, rhonn_real *w, size_t len);
rhonn_status rhonn_set_weights(rhonn_t *net, size_t neuron, const rhonn_real *w, size_t len);
rhonn_status rhonn_get_covariance(const rhonn_t *net, size_t neuron, rhonn_real *p, size_t len);
rhonn_status rhonn_set_covariance(rhonn_t *net, size_t neuron, const rhonn_real *p, size_t len);

/* The stored covariance exactly as kept (packed upper triangle, len as for
 * the covariance): P_i for RHONN_COV_FULL; for RHONN_COV_UD, D on the
 * diagonal and U's strict upper triangle beside it. For saving and restoring
 * a filter bit for bit. The setter checks every entry is finite and, for the
 * factors, that D > 0, or for P that it is positive definite (RHONN_E_VALUE). */
rhonn_status rhonn_get_factors(const rhonn_t *net, size_t neuron, rhonn_real *f, size_t len);
rhonn_status rhonn_set_factors(rhonn_t *net, size_t neuron, const rhonn_real *f, size_t len);

/* xhat(k): the last prediction (config x0 before the first step). */
rhonn_status rhonn_get_prediction(const rhonn_t *net, rhonn_real *xhat, size_t len);

/* Activation S(s) exactly as the core computes it (for tests and tools). */
rhonn_real rhonn_activate(uint8_t activation, rhonn_real beta, rhonn_real s);

/* exp(-a) for a >= 0, the core's own portable exponential: the same bits on
 * every IEEE-754 target built with -ffp-contract=off (libm's exp differs
 * between glibc and newlib). Returns 0 for a beyond the normal range and
 * 1 for a <= 0 or NaN-free negative input. */
rhonn_real rhonn_exp_neg(rhonn_real a);

/* Human-readable name of a status code (a static string). */
const char *rhonn_status_name(rhonn_status status);

#ifdef __cplusplus
}
#endif

#endif /* RHONN_H */
