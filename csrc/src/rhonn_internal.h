/*
 * rhonn_internal.h - entry points of rhonn.c for the other core sources
 * (rhonn_population.c), not part of the installed API: they skip the
 * argument checks the public functions make and assume a net set up by
 * rhonn_init.
 */
#ifndef RHONN_INTERNAL_H
#define RHONN_INTERNAL_H

#include "rhonn.h"

/* The non-finite checks rely on IEEE semantics (v - v is NaN for +-Inf). */
#if defined(__FAST_MATH__) || defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__
#error "the rhonn core must not be built with -ffast-math or -ffinite-math-only"
#endif

/* rhonn_t.magic: set up by rhonn_init ("RHNN"), or lent to a population
 * workspace by rhonn_wide_begin ("RHNL"), which every public function then
 * refuses as not set up until rhonn_wide_end gives it back. */
#define RHONN_MAGIC 0x52484E4EUL
#define RHONN_LENT_MAGIC 0x52484E4CUL

/* The working precision's constants, one definition for every core source. */
#ifdef RHONN_SINGLE
#define R(c) c##f
#define RHONN_MAX_REAL 3.402823466e38f
#define RHONN_EPSILON 1.1920928955e-7f
#define RHONN_MIN_NORMAL 1.1754943508e-38f
#else
#define R(c) c
#define RHONN_MAX_REAL 1.7976931348623157e308
#define RHONN_EPSILON 2.220446049250313e-16
#define RHONN_MIN_NORMAL 2.2250738585072014e-308
#endif

/* Compiled inside each caller (and so inside each target clone of the
 * population kernels: a call to baseline-ISA code from an AVX-512 clone ran
 * 3x slower there). */
#if defined(__GNUC__) || defined(__clang__)
#define RHONN_INTERNAL_INLINE static inline __attribute__((always_inline))
#else
#define RHONN_INTERNAL_INLINE static inline
#endif

/* Branch hints for the rare paths (faults, refusals, the proof failing).
 * Without them GCC's guessed profile splits a block's frequency at every
 * test; in a core unrolled over the neurons the later neurons' kernels fell
 * below its hot threshold and were compiled for size (on the Cortex-M4, the
 * 3-cycle chained VMLA instead of a VMUL and a VADD: about 160 cycles a
 * step). */
#if defined(__GNUC__) || defined(__clang__)
#define RHONN_LIKELY(c) __builtin_expect(!!(c), 1)
#define RHONN_UNLIKELY(c) __builtin_expect(!!(c), 0)
#define RHONN_COLD __attribute__((cold))
#else
#define RHONN_LIKELY(c) (c)
#define RHONN_UNLIKELY(c) (c)
#define RHONN_COLD
#endif

/* A state's valid run after a commit (neuron j learns only when the run
 * covers the history its regressor reads, own_need[j]): one more sample in
 * a row, saturating at 0xFF; first = 0xFF on an identifier's first sample,
 * which starts every run full (there is nothing older); 0 when the sample
 * did not measure x_j. rhonn.c's commit and the population's lanes both
 * count with it. */
RHONN_INTERNAL_INLINE uint8_t rhonn_run_next(uint8_t run, uint8_t first, uint8_t measured)
{
    const uint8_t next = (uint8_t)((uint8_t)(run + (uint8_t)(run < 0xFFu)) | first);
    return measured ? next : 0u;
}

/* The shift alpha = 17 L gamma_{L+1} of the factorisation that proves a P
 * definite (rhonn.c shifted_check has the derivation). */
RHONN_INTERNAL_INLINE rhonn_real rhonn_proof_shift(size_t L)
{
    return R(17.0) * (rhonn_real)L * (R(1.01) * (rhonn_real)(L + 1u) * (RHONN_EPSILON * R(0.5)));
}

/* The proof that a full-form update kept P definite (rhonn.c
 * certified_update has the derivation), from its sums over the L terms of
 * the old P, z, v = fl(P z) and the new P': tr = trace P,
 * pzz = sum_r P_rr z_r^2, vv = |v|^2, zv = |z|^T |v|, pmax = the largest
 * diagonal of P'; and q_min, R and inv_s = fl(1 / s). With the unit
 * roundoff u, gamma_k <= 1.01 k u and ww = L pzz, which bounds
 * w^2 = (sum_r sqrt(P_rr) |z_r|)^2 (Cauchy-Schwarz over the L terms, each
 * P_rr paired with its own z_r, with no square root to take):
 *   r_low = R - gamma_L ww (a lower bound on R + z^T delta),
 *   rho   = gamma_{L+1} (R + zv) / s (the relative error of s),
 *   eta   = 2 gamma_L^2 tr ww / r_low (the rounding of P z),
 *   err   = (3 rho + 8u) vv / s + 2u (tr + pmax) (the update's roundings),
 *   and Demmel's bound 1.01 L gamma_{L+1} pmax;
 * 1 when 9/8 of their sum is within q_min (and the bounds are finite, r_low
 * > 0, rho <= 1/4, tr + vv / s far from overflow): P' is then definite with
 * lambda_min >= q_min / 9 + Demmel's bound, which the plain factorisation
 * accepts. 0 when it cannot tell: factorise. */
RHONN_INTERNAL_INLINE int rhonn_proof_holds(rhonn_real tr, rhonn_real pzz, rhonn_real vv, rhonn_real zv,
                                            rhonn_real pmax, rhonn_real qmin, rhonn_real r_i, rhonn_real inv_s,
                                            size_t L)
{
    const rhonn_real unit = RHONN_EPSILON * R(0.5);
    const rhonn_real gl = R(1.01) * (rhonn_real)L * unit, g1 = R(1.01) * (rhonn_real)(L + 1u) * unit;
    const rhonn_real ww = (rhonn_real)L * pzz;
    rhonn_real r_low, rho, vs, err, eta_r;
    if (!(qmin >= R(16.0) * RHONN_MIN_NORMAL)) {
        return 0;
    }
    r_low = r_i - gl * ww;
    rho = g1 * (r_i + zv) * inv_s;
    vs = vv * inv_s;
    if (!(r_low > R(0.0)) || !(rho <= R(0.25)) || !(tr + vs <= RHONN_MAX_REAL * R(0.25)) ||
        !(pmax <= RHONN_MAX_REAL)) {
        return 0;
    }
    /* 9/8 (eta + err + Demmel) <= q_min, with eta = eta_r / r_low: no division */
    eta_r = R(2.0) * (gl * gl) * (tr * ww);
    err = (R(3.0) * rho + R(8.0) * unit) * vs + R(2.0) * unit * (tr + pmax);
    return R(1.125) * eta_r <= (qmin - R(1.125) * (err + R(1.01) * (rhonn_real)L * g1 * pmax)) * r_low;
}

/* The validated configuration: the one the core was compiled for
 * (RHONN_FIXED_CONFIG), the caller's constant (RHONN_CONST_CONFIG), or
 * rhonn_t's copy; see rhonn.h. */
#ifdef RHONN_FIXED_CONFIG
#include RHONN_FIXED_CONFIG_HEADER
#define CFG(net) ((void)(net), &RHONN_FIXED_CONFIG)
/* The loops over the neurons unrolled: each neuron's sizes, covariance form
 * and constants are then known where its code is compiled. */
#define RHONN_NEURON_LOOP _Pragma("GCC unroll 255")
#elif RHONN_CONST_CONFIG
#define CFG(net) ((net)->cfg)
#define RHONN_NEURON_LOOP
#else
#define CFG(net) (&(net)->cfg)
#define RHONN_NEURON_LOOP
#endif

/* A fact the compiler may rely on (GCC, clang); nothing elsewhere. The
 * step's loops over the states state n <= RHONN_MAX_STATES, which check_net
 * guarantees before any step runs: it sizes the loops for the compiler (GCC
 * -O3 otherwise vectorises them past the arrays' ends, and warns) at no
 * cost, where clamping n cost a compare and a select per loop. */
#if defined(__GNUC__) || defined(__clang__)
#define RHONN_ASSUME(c) \
    do {                \
        if (!(c)) {     \
            __builtin_unreachable(); \
        }               \
    } while (0)
#else
#define RHONN_ASSUME(c) ((void)0)
#endif

/* check_net: an initialised identifier whose sizes are within capacity. */
rhonn_status rhonn_internal_check_net(const rhonn_t *net);

/* The input check that opens every step: RHONN_E_INPUT_NONFINITE when a
 * valid x_j or any u_j is not finite, else RHONN_OK. */
rhonn_status rhonn_internal_check_inputs(const rhonn_t *net, const rhonn_real *x, const rhonn_real *u,
                                         const uint8_t *valid);

/* Steps 2-3 of ORDER OF ONE STEP (rhonn.h): the RHONN_VALUES_LEN values
 * that net->term_entry indexes: this sample as the regressor reads it (the
 * first RHONN_SAMPLE_LEN: a missing x_j replaced by xhat_j(k), S(x) per
 * activation group, u, 1), then the compiled entries' values (net->n_entries
 * of them), reading the history. Writes nothing in net. */
void rhonn_internal_features(const rhonn_t *net, const rhonn_real *x, const rhonn_real *u, const uint8_t *valid,
                             rhonn_real *val);

/* rhonn_internal_features for another member of a population, from val
 * holding a member's values that differ from its own only where this
 * sample misses a state (valid[j] == 0; the caller guarantees that every
 * delayed value the two read is the same): x_j rewritten with the member's
 * prediction xhat[j], its S(x_j) and the entries of this sample that read
 * them, with features()' own operations, so val then holds exactly what
 * rhonn_internal_features would for the member. rewritten (NULL: not
 * wanted) gets 1 at the value indices rewritten, 0 at the others of the
 * first RHONN_SAMPLE_LEN + net->n_entries; they depend on valid only. */
void rhonn_internal_held_values(const rhonn_t *net, const rhonn_real *xhat, const uint8_t *valid, rhonn_real *val,
                                uint8_t *rewritten);

/* deepest[j] (RHONN_MAX_STATES of them): the deepest delay at which the
 * regressor reads x_j or S(x_j) from the history (0: only this sample's);
 * returns the deepest at which it reads an input u_j (or the constant). */
uint8_t rhonn_internal_delayed_reads(const rhonn_t *net, uint8_t *deepest);

/* The history part of a step's commit: cur into the ring (when a tap reads
 * it), the head advanced, the valid runs counted. Reads net->started, so it
 * runs before started is set. */
void rhonn_internal_commit_sample(rhonn_t *net, const rhonn_real *cur, const uint8_t *valid);

/* The ring part of rhonn_internal_commit_sample, without the valid runs:
 * cur into the ring (when a tap reads it), the head advanced. With cur
 * NULL only the head is advanced, for a started net: the caller owes the
 * ring that sample at slot net->head (rhonn_internal_store_sample) before
 * anything reads the history. Reads net->started, so it runs before
 * started is set. */
void rhonn_internal_commit_ring(rhonn_t *net, const rhonn_real *cur);

/* The sample part of cur (RHONN_SAMPLE_LEN layout) into ring slot slot. */
void rhonn_internal_store_sample(rhonn_t *net, size_t slot, const rhonn_real *cur);

/* One neuron's learning update into its inactive bank (eq. 7-9), as step 1
 * runs it: sets net->fault_neuron on failure, touches no health counter. */
rhonn_status rhonn_internal_ekf_update(rhonn_t *net, size_t i, rhonn_real e, const rhonn_real *z, rhonn_real *nis,
                                       uint8_t *bounded);

/* P_i(0) in neuron i's storage form (a copy, or its U D U^T factors). */
void rhonn_internal_load_p0(const rhonn_t *net, size_t i, rhonn_real *dst);

/* A refused update of neuron i counted as rhonn_step counts it (health
 * rejected and fail_run); 1 when the run of refusals reached reset_after:
 * the neuron is to be recovered (weights kept, P from P_i(0)). */
int rhonn_internal_count_refusal(rhonn_t *net, size_t i);

/* Whether P_i(0) starts with its proof of definiteness (rhonn_t.cert):
 * what a recovery gives the restarted covariance. */
uint8_t rhonn_internal_p0_proven(const rhonn_t *net, size_t i);

/* rhonn_population.c's proof for every lane at once (for the tests, which
 * hold it to rhonn_proof_holds lane by lane): in[k * RHONN_MAX_POPULATION
 * + m] for k = tr, pzz, vv, zv, pmax, qmin, r_i, inv_s; out[m] 1 where the
 * proof holds for lane m. */
void rhonn_internal_proof_lanes(const rhonn_real *in, size_t L, uint8_t *out);

#endif /* RHONN_INTERNAL_H */
