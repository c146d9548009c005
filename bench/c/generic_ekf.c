/* generic_ekf.c - the generic-library EKF of generic_ekf.h. */
#include "generic_ekf.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#ifdef DENSE_SINGLE
#define GENERIC_SQRT sqrtf
#else
#define GENERIC_SQRT sqrt
#endif

/* c (m x p) = a (m x n) b (n x p), accumulated in c itself: c may alias
 * neither a nor b, but the compiler cannot know it, so every partial sum goes
 * through memory, as in a library that takes plain pointers. */
static void product(const dense_real *a, const dense_real *b, dense_real *c, int m, int n, int p)
{
    int i, j, l;
    for (i = 0; i < m; ++i)
        for (j = 0; j < p; ++j) {
            c[i * p + j] = 0;
            for (l = 0; l < n; ++l)
                c[i * p + j] += a[i * n + l] * b[l * p + j];
        }
}

static void transpose(const dense_real *a, dense_real *t, int m, int n)
{
    int i, j;
    for (i = 0; i < m; ++i)
        for (j = 0; j < n; ++j)
            t[j * m + i] = a[i * n + j];
}

static void sum(const dense_real *a, const dense_real *b, dense_real *c, int m, int n)
{
    int i;
    for (i = 0; i < m * n; ++i)
        c[i] = a[i] + b[i];
}

/* inv = a^-1 for a symmetric positive definite m x m: a = C C^T (Cholesky),
 * then C^-1 by forward substitution and a^-1 = C^-T C^-1. Returns nonzero when
 * a pivot is not positive. */
static int cholesky_inverse(const dense_real *a, dense_real *inv, int m)
{
    dense_real c[GENERIC_M * GENERIC_M], ci[GENERIC_M * GENERIC_M];
    int i, j, l;
    for (i = 0; i < m; ++i)
        for (j = 0; j <= i; ++j) {
            dense_real s = a[i * m + j];
            for (l = 0; l < j; ++l)
                s -= c[i * m + l] * c[j * m + l];
            if (i == j) {
                if (!(s > 0))
                    return 1;
                c[i * m + i] = GENERIC_SQRT(s);
            } else {
                c[i * m + j] = s / c[j * m + j];
            }
        }
    for (i = 0; i < m; ++i) {
        ci[i * m + i] = 1 / c[i * m + i];
        for (j = 0; j < i; ++j) {
            dense_real s = 0;
            for (l = j; l < i; ++l)
                s -= c[i * m + l] * ci[l * m + j];
            ci[i * m + j] = s / c[i * m + i];
        }
        for (j = i + 1; j < m; ++j)
            ci[i * m + j] = 0;
    }
    for (i = 0; i < m; ++i)
        for (j = 0; j < m; ++j) {
            inv[i * m + j] = 0;
            for (l = i > j ? i : j; l < m; ++l)
                inv[i * m + j] += ci[l * m + i] * ci[l * m + j];
        }
    return 0;
}

/* predict: w = f(w) = w; P = F P F^T + Q */
static void predict(generic_ekf *g)
{
    const int n = g->n;
    product(g->f, g->p, g->fp, n, n, n);
    transpose(g->f, g->ft, n, n);
    product(g->fp, g->ft, g->fpft, n, n, n);
    sum(g->fpft, g->q, g->p, n, n);
}

generic_status generic_ekf_init(generic_ekf *g, int n, const dense_real *w0, const dense_real *p0,
                                const dense_real *q_diag, dense_real r, dense_real eta)
{
    int i, j;
    if (g == NULL || w0 == NULL || p0 == NULL || q_diag == NULL || n < 1 || n > DENSE_MAX_L)
        return GENERIC_E_ARGUMENT;
    g->n = n;
    g->eta = eta;
    g->refused = 0;
    g->r[0] = r;
    for (i = 0; i < n; ++i) {
        g->w[i] = w0[i];
        for (j = 0; j < n; ++j) {
            g->p[i * n + j] = p0[i * n + j];
            g->q[i * n + j] = i == j ? q_diag[i] : (dense_real)0;
            g->f[i * n + j] = i == j ? (dense_real)1 : (dense_real)0;
        }
    }
    return GENERIC_OK;
}

generic_status generic_ekf_step(generic_ekf *g, const dense_real *z, dense_real e)
{
    const int n = g->n, m = GENERIC_M;
    dense_real hpht[GENERIC_M * GENERIC_M], s[GENERIC_M * GENERIC_M], s_inv[GENERIC_M * GENERIC_M];
    dense_real innov[GENERIC_M];
    int i;

    /* update: G = P H^T (H P H^T + R)^-1, w += G (eta e), P = (I - G H) P */
    transpose(z, g->ht, m, n);
    product(g->p, g->ht, g->pht, n, n, m);
    product(z, g->p, g->hp, m, n, n);
    product(g->hp, g->ht, hpht, m, n, m);
    sum(hpht, g->r, s, m, m);
    if (cholesky_inverse(s, s_inv, m) != 0) {
        ++g->refused;
        predict(g);
        return GENERIC_E_NOT_PD;
    }
    product(g->pht, s_inv, g->gain, n, m, m);
    innov[0] = g->eta * e;
    product(g->gain, innov, g->step, n, m, 1);
    sum(g->w, g->step, g->w, n, 1);
    product(g->gain, z, g->gh, n, m, n);
    for (i = 0; i < n * n; ++i)
        g->gh[i] = -g->gh[i];
    for (i = 0; i < n; ++i)
        g->gh[i * n + i] += 1;
    product(g->gh, g->p, g->ghp, n, n, n);
    memcpy(g->p, g->ghp, (size_t)(n * n) * sizeof(dense_real));
    predict(g);
    return GENERIC_OK;
}

dense_real generic_ekf_predict(const generic_ekf *g, const dense_real *z)
{
    dense_real y;
    product(z, g->w, &y, 1, g->n, 1);
    return y;
}
