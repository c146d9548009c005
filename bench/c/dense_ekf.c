/* dense_ekf.c - the textbook dense EKF of dense_ekf.h. */
#include "dense_ekf.h"

#include <stddef.h>

void dense_mat_mul(const dense_real *a, const dense_real *b, dense_real *c, int m, int n, int p)
{
    int i, j, l;
    for (i = 0; i < m; ++i) {
        for (j = 0; j < p; ++j) {
            dense_real acc = 0;
            for (l = 0; l < n; ++l)
                acc += a[i * n + l] * b[l * p + j];
            c[i * p + j] = acc;
        }
    }
}

static void mat_add(const dense_real *a, const dense_real *b, dense_real *c, int m, int n)
{
    int i;
    for (i = 0; i < m * n; ++i)
        c[i] = a[i] + b[i];
}

static void mat_transpose(const dense_real *a, dense_real *t, int m, int n)
{
    int i, j;
    for (i = 0; i < m; ++i)
        for (j = 0; j < n; ++j)
            t[j * m + i] = a[i * n + j];
}

dense_status dense_ekf_init(dense_ekf *f, int n, const dense_real *w0, const dense_real *p0,
                            const dense_real *q_diag, dense_real r, dense_real eta)
{
    int i, j;
    if (f == NULL || w0 == NULL || p0 == NULL || q_diag == NULL || n < 1 || n > DENSE_MAX_L)
        return DENSE_E_ARGUMENT;
    f->n = n;
    f->eta = eta;
    f->r = r;
    for (i = 0; i < n; ++i) {
        f->w[i] = w0[i];
        for (j = 0; j < n; ++j) {
            f->p[i * n + j] = p0[i * n + j];
            f->q[i * n + j] = i == j ? q_diag[i] : (dense_real)0;
        }
    }
    return DENSE_OK;
}

dense_status dense_ekf_update(dense_ekf *f, const dense_real *z, dense_real e)
{
    const int n = f->n;
    dense_real s, s_inv;
    int i, j;

    /* H = z^T (1 x n), H^T (n x 1) */
    mat_transpose(z, f->ht, 1, n);
    /* P H^T (n x 1) */
    dense_mat_mul(f->p, f->ht, f->pht, n, n, 1);
    /* S = H P H^T + R (1 x 1) */
    dense_mat_mul(z, f->pht, &s, 1, n, 1);
    s += f->r;
    s_inv = (dense_real)1 / s;
    /* K = P H^T S^-1 (n x 1) */
    dense_mat_mul(f->pht, &s_inv, f->k, n, 1, 1);
    /* w <- w + eta K e */
    for (i = 0; i < n; ++i)
        f->w[i] += f->eta * f->k[i] * e;
    /* I - K H (n x n) */
    dense_mat_mul(f->k, z, f->kh, n, 1, n);
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j)
            f->kh[i * n + j] = (i == j ? (dense_real)1 : (dense_real)0) - f->kh[i * n + j];
    /* P <- (I - K H) P + Q */
    dense_mat_mul(f->kh, f->p, f->pn, n, n, n);
    mat_add(f->pn, f->q, f->p, n, n);
    return DENSE_OK;
}

dense_real dense_ekf_predict(const dense_ekf *f, const dense_real *z)
{
    dense_real y;
    dense_mat_mul(z, f->w, &y, 1, f->n, 1);
    return y;
}
