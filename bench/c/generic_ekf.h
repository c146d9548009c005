/*
 * generic_ekf.h - one RHONN neuron's EKF written the way a generic embedded
 * EKF library is: TinyEKF's sequence of a measurement update followed by a
 * prediction, each built from general matrix routines, as a second baseline
 * for the core's speed (bench/bench_core_vs_dense.py). Not part of pyrhonn.
 *
 * The filter of dense_ekf.h (state w, L x L covariance P, F = I, H = z^T,
 * Q diagonal, R scalar), but in the form such a library runs it, with none
 * of this problem's structure used:
 *
 *   update    H^T = transpose(H);  P H^T;  H P;  S = (H P) H^T + R;
 *             S^-1 by Cholesky (a general M x M inverse, here M = 1);
 *             G = (P H^T) S^-1;  w <- w + G (eta e);
 *             P <- (I - G H) P     (G H negated, the identity added)
 *   predict   w <- f(w) = w;  P <- (F P) F^T + Q   (F = I stored whole,
 *             F^T formed by transposing it)
 *
 * Every product is a general loop that accumulates in its output array, as
 * TinyEKF's matrix product does. It checks nothing but the definiteness of S
 * that the Cholesky factorisation needs. Its arithmetic differs from
 * dense_ekf.h's only in rounding.
 *
 * DENSE_SINGLE selects float; double otherwise (as dense_ekf.h).
 */
#ifndef GENERIC_EKF_H
#define GENERIC_EKF_H

#include "dense_ekf.h"   /* dense_real, DENSE_MAX_L */

/* The measurement's size: one neuron measures one state. */
#define GENERIC_M 1

typedef enum {
    GENERIC_OK = 0,
    GENERIC_E_ARGUMENT = 1,   /* L outside 1..DENSE_MAX_L, or a NULL pointer */
    GENERIC_E_NOT_PD = 2      /* S has no Cholesky factor: the update was skipped */
} generic_status;

typedef struct {
    int n;                                      /* L */
    dense_real eta;                             /* learning rate */
    dense_real w[DENSE_MAX_L];                  /* weights (the state) */
    dense_real p[DENSE_MAX_L * DENSE_MAX_L];    /* P, row-major L x L */
    dense_real q[DENSE_MAX_L * DENSE_MAX_L];    /* Q, row-major L x L (diagonal) */
    dense_real f[DENSE_MAX_L * DENSE_MAX_L];    /* F = I, stored whole */
    dense_real r[GENERIC_M * GENERIC_M];        /* R */
    long refused;                               /* updates refused so far (S not positive) */
    /* scratch of one step */
    dense_real ht[DENSE_MAX_L * GENERIC_M];     /* H^T */
    dense_real pht[DENSE_MAX_L * GENERIC_M];    /* P H^T */
    dense_real hp[GENERIC_M * DENSE_MAX_L];     /* H P */
    dense_real gain[DENSE_MAX_L * GENERIC_M];   /* G */
    dense_real step[DENSE_MAX_L];               /* G (eta e) */
    dense_real gh[DENSE_MAX_L * DENSE_MAX_L];   /* G H, then I - G H */
    dense_real ghp[DENSE_MAX_L * DENSE_MAX_L];  /* (I - G H) P */
    dense_real fp[DENSE_MAX_L * DENSE_MAX_L];   /* F P */
    dense_real ft[DENSE_MAX_L * DENSE_MAX_L];   /* F^T */
    dense_real fpft[DENSE_MAX_L * DENSE_MAX_L]; /* F P F^T */
} generic_ekf;

/* Set up one neuron: L weights w0, covariance p0 (L x L row-major), the
 * diagonal of Q (L), R and eta. */
generic_status generic_ekf_init(generic_ekf *g, int n, const dense_real *w0, const dense_real *p0,
                                const dense_real *q_diag, dense_real r, dense_real eta);

/* One measurement update with H = z^T and innovation e, then one
 * prediction (F = I, + Q). An update whose S has no Cholesky factor is
 * skipped and counted in `refused`; the prediction still runs. */
generic_status generic_ekf_step(generic_ekf *g, const dense_real *z, dense_real e);

/* The prediction w^T z. */
dense_real generic_ekf_predict(const generic_ekf *g, const dense_real *z);

#endif /* GENERIC_EKF_H */
