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

/* The validated configuration: rhonn_t's copy, or the caller's constant
 * (RHONN_CONST_CONFIG, see rhonn.h). */
#if RHONN_CONST_CONFIG
#define CFG(net) ((net)->cfg)
#else
#define CFG(net) (&(net)->cfg)
#endif

/* check_net: an initialised identifier whose sizes are within capacity. */
rhonn_status rhonn_internal_check_net(const rhonn_t *net);

/* The input check that opens every step: RHONN_E_INPUT_NONFINITE when a
 * valid x_j or any u_j is not finite, else RHONN_OK. */
rhonn_status rhonn_internal_check_inputs(const rhonn_t *net, const rhonn_real *x, const rhonn_real *u,
                                         const uint8_t *valid);

/* Steps 2-3 of ORDER OF ONE STEP (rhonn.h): this sample as the regressor
 * reads it (cur, RHONN_SAMPLE_LEN values: a missing x_j replaced by
 * xhat_j(k), S(x) per activation group, u, 1) and the values of the compiled
 * entries (fv, net->n_entries values), reading the history. Writes nothing
 * in net. */
void rhonn_internal_features(const rhonn_t *net, const rhonn_real *x, const rhonn_real *u, const uint8_t *valid,
                             rhonn_real *cur, rhonn_real *fv);

/* The history part of a step's commit: cur into the ring (when a tap reads
 * it), the head advanced, the valid runs counted. Reads net->started, so it
 * runs before started is set. */
void rhonn_internal_commit_sample(rhonn_t *net, const rhonn_real *cur, const uint8_t *valid);

/* One neuron's learning update into its inactive bank (eq. 7-9), as step 1
 * runs it: sets net->fault_neuron on failure, touches no health counter. */
rhonn_status rhonn_internal_ekf_update(rhonn_t *net, size_t i, rhonn_real e, const rhonn_real *z, rhonn_real *nis,
                                       uint8_t *bounded);

/* P_i(0) in neuron i's storage form (a copy, or its U D U^T factors). */
void rhonn_internal_load_p0(const rhonn_t *net, size_t i, rhonn_real *dst);

#endif /* RHONN_INTERNAL_H */
