/*
 * dense_ekf.h - a textbook extended Kalman filter for one RHONN neuron,
 * written the plain dense way, as a baseline for the core's speed
 * (bench/bench_core_vs_dense.py).
 *
 * One neuron with L weights: state w (L), covariance P (L x L, full, not
 * packed), process model F = I, measurement H = z^T (1 x L), process noise Q
 * diagonal, measurement noise R scalar:
 *
 *     S = H P H^T + R          K = P H^T S^-1
 *     w <- w + eta K e         P <- (I - K H) P + Q
 *
 * Every product is a general matrix product (dense_mat_mul), every matrix is
 * stored whole, row-major: the way generic firmware EKF code is written. It
 * checks nothing and never refuses an update. Not part of pyrhonn.
 *
 * DENSE_SINGLE selects float; double otherwise.
 */
#ifndef DENSE_EKF_H
#define DENSE_EKF_H

#ifdef DENSE_SINGLE
typedef float dense_real;
#else
typedef double dense_real;
#endif

/* The most weights one neuron may have. */
#ifndef DENSE_MAX_L
#define DENSE_MAX_L 16
#endif

typedef enum {
    DENSE_OK = 0,
    DENSE_E_ARGUMENT = 1      /* L outside 1..DENSE_MAX_L, or a NULL pointer */
} dense_status;

typedef struct {
    int n;                                  /* L */
    dense_real eta;                         /* learning rate */
    dense_real r;                           /* R */
    dense_real w[DENSE_MAX_L];              /* weights (the state) */
    dense_real p[DENSE_MAX_L * DENSE_MAX_L];/* P, row-major L x L */
    dense_real q[DENSE_MAX_L * DENSE_MAX_L];/* Q, row-major L x L (diagonal) */
    /* scratch of one update */
    dense_real ht[DENSE_MAX_L];             /* H^T (L x 1) */
    dense_real pht[DENSE_MAX_L];            /* P H^T (L x 1) */
    dense_real k[DENSE_MAX_L];              /* K (L x 1) */
    dense_real kh[DENSE_MAX_L * DENSE_MAX_L];   /* K H, then I - K H */
    dense_real pn[DENSE_MAX_L * DENSE_MAX_L];   /* (I - K H) P */
} dense_ekf;

/* C (m x p) = A (m x n) B (n x p), all row-major and compact. */
void dense_mat_mul(const dense_real *a, const dense_real *b, dense_real *c, int m, int n, int p);

/* Set up one neuron: L weights w0, covariance p0 (L x L row-major), the
 * diagonal of Q (L), R and eta. */
dense_status dense_ekf_init(dense_ekf *f, int n, const dense_real *w0, const dense_real *p0,
                            const dense_real *q_diag, dense_real r, dense_real eta);

/* One measurement update with H = z^T and innovation e, then + Q. */
dense_status dense_ekf_update(dense_ekf *f, const dense_real *z, dense_real e);

/* The prediction w^T z. */
dense_real dense_ekf_predict(const dense_ekf *f, const dense_real *z);

#endif /* DENSE_EKF_H */
