/* exactly_definite.h - the host C tests' and the core fuzz target's check
 * that a packed symmetric covariance is positive definite, in long double
 * and without any allowance. Include after rhonn.h. */
#ifndef RHONN_EXACTLY_DEFINITE_H
#define RHONN_EXACTLY_DEFINITE_H

#include <stddef.h>

/* L D L^T of the packed upper triangle p (L x L, row by row) in long double:
 * 1 when every pivot is positive (positive definite to far below the working
 * precision's rounding), 0 when one is not. */
static int exactly_definite(const rhonn_real *p, size_t L)
{
    long double a[RHONN_MAX_TERMS][RHONN_MAX_TERMS];
    size_t i, j, k, idx = 0;
    for (i = 0; i < L; ++i) {
        for (j = i; j < L; ++j, ++idx) {
            a[i][j] = a[j][i] = (long double)p[idx];
        }
    }
    for (j = 0; j < L; ++j) {
        long double d = a[j][j];
        for (k = 0; k < j; ++k) {
            d -= a[j][k] * a[j][k] / a[k][k];
        }
        if (!(d > 0)) {
            return 0;
        }
        a[j][j] = d; /* L D L^T: a[k][k] holds d_k, a[i][k] holds l_ik d_k */
        for (i = j + 1u; i < L; ++i) {
            long double v = a[i][j];
            for (k = 0; k < j; ++k) {
                v -= a[i][k] * a[j][k] / a[k][k];
            }
            a[i][j] = v;
        }
    }
    return 1;
}

#endif
