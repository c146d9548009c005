/* The firmware's LIM identifier (firmware_sim/config/lim_identifier.h) over a
 * hostile sample stream, every result printed as C99 hex floats. CTest runs
 * it against the core compiled for that one configuration
 * (RHONN_FIXED_CONFIG) and against the general core, and requires
 * byte-identical output: compiling the configuration in may change speed and
 * size, never a bit. The stream has dropouts of single states and of all of
 * them, a non-finite input (refused), learning frozen and resumed, a break
 * (rhonn_restart), a reset, weights and a covariance set from outside (the
 * definiteness proof starts over), a covariance the full form refuses, and
 * gates and trace ceilings calibrated mid-run (rhonn_set_gate,
 * rhonn_set_trace_ceiling: the fixed build takes them at run time too). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "lim_identifier.h"
#include "rhonn.h"

#define N 6
#define M 2
#define STEPS 4000

static uint32_t lcg_state = 20261125u;

static double uniform(void) /* [0, 1) */
{
    lcg_state = lcg_state * 1664525u + 1013904223u;
    return (double)(lcg_state >> 8) / 16777216.0;
}

static void print_reals(const char *what, const rhonn_real *v, size_t len)
{
    size_t j;
    printf("%s", what);
    for (j = 0; j < len; ++j) {
        printf(" %a", (double)v[j]);
    }
    printf("\n");
}

static void print_state(const rhonn_t *net)
{
    rhonn_real buf[RHONN_MAX_PACKED];
    rhonn_health h;
    size_t i;
    for (i = 0; i < N; ++i) {
        const size_t L = LIM_IDENTIFIER.neurons[i].n_terms;
        if (rhonn_get_weights(net, i, buf, L) == RHONN_OK) {
            print_reals(" w", buf, L);
        }
        if (rhonn_get_factors(net, i, buf, L * (L + 1u) / 2u) == RHONN_OK) {
            print_reals(" f", buf, L * (L + 1u) / 2u);
        }
        if (rhonn_get_health(net, i, &h) == RHONN_OK) {
            printf(" h %a %a %a %lu %lu %lu %lu %lu %u\n", (double)h.innovation, (double)h.nis, (double)h.trace_p,
                   (unsigned long)h.updates, (unsigned long)h.rejected, (unsigned long)h.resets,
                   (unsigned long)h.bounded, (unsigned long)h.gated, (unsigned)h.fail_run);
        }
    }
}

int main(void)
{
    static rhonn_t net;
    rhonn_config_error where;
    rhonn_real x[N], u[M], xhat[N], t_s;
    uint8_t valid[N];
    size_t k, j;

    if (rhonn_init(&net, &LIM_IDENTIFIER, &where) != RHONN_OK) {
        fprintf(stderr, "rhonn_init refused the LIM identifier (field %u)\n", (unsigned)where.field);
        return 1;
    }
    for (k = 0; k < STEPS; ++k) {
        rhonn_status st;
        t_s = (rhonn_real)((double)k * 3e-4);
        /* a LIM-like trajectory: the states within their rig's ranges, noisy */
        x[0] = (rhonn_real)(0.3 * (double)t_s + 0.01 * uniform());
        x[1] = (rhonn_real)(1.5 * (1.0 - 1.0 / (1.0 + (double)t_s)) + 0.02 * uniform());
        x[2] = (rhonn_real)(0.4 * (uniform() - 0.5));
        x[3] = (rhonn_real)(0.4 * (uniform() - 0.5));
        x[4] = (rhonn_real)(8.0 * (uniform() - 0.5));
        x[5] = (rhonn_real)(8.0 * (uniform() - 0.5));
        u[0] = (rhonn_real)(200.0 * (uniform() - 0.5));
        u[1] = (rhonn_real)(200.0 * (uniform() - 0.5));
        for (j = 0; j < N; ++j) {
            valid[j] = (uint8_t)(uniform() > 0.05); /* single dropouts */
        }
        if (k >= 1500u && k < 1510u) {
            memset(valid, 0, sizeof valid); /* a blackout */
        }
        if (k == 700u) {
            u[1] = (rhonn_real)NAN; /* refused: nothing changes */
        }
        if (k == 900u) {
            rhonn_set_learning(&net, 0);
        }
        if (k == 1100u) {
            rhonn_set_learning(&net, 1);
        }
        if (k == 1200u || k == 1400u) { /* calibrated: on, then off again */
            for (j = 0; j < N; ++j) {
                const rhonn_neuron_config *nc = &LIM_IDENTIFIER.neurons[j];
                rhonn_real trace0 = (rhonn_real)0.0;
                size_t t, d = 0;
                for (t = 0; t < nc->n_terms; d += nc->n_terms - t, ++t) {
                    trace0 += nc->p0[d];
                }
                printf("calibrate %d %d\n", (int)rhonn_set_gate(&net, j, k == 1200u && j % 2u == 0u ? (rhonn_real)0.5 : 0),
                       (int)rhonn_set_trace_ceiling(&net, j, k == 1200u && j % 2u == 1u ? trace0 : 0));
            }
        }
        if (k == 2000u) {
            printf("restart %d\n", (int)rhonn_restart(&net));
        }
        if (k == 2500u) {
            rhonn_real w[8], p[36];
            const size_t L = LIM_IDENTIFIER.neurons[3].n_terms;
            for (j = 0; j < L; ++j) {
                w[j] = (rhonn_real)(0.1 * (double)j);
            }
            for (j = 0; j < L * (L + 1u) / 2u; ++j) {
                p[j] = (rhonn_real)0.0;
            }
            for (j = 0; j < L; ++j) {
                p[j * L - j * (j - 1u) / 2u] = (rhonn_real)(5.0 + (double)j);
            }
            p[1] = (rhonn_real)1.0;
            printf("set %d %d\n", (int)rhonn_set_weights(&net, 3, w, L), (int)rhonn_set_covariance(&net, 3, p, L * (L + 1u) / 2u));
            p[1] = (rhonn_real)100.0; /* not definite: refused, nothing changes */
            printf("set refused %d\n", (int)rhonn_set_covariance(&net, 3, p, L * (L + 1u) / 2u));
        }
        if (k == 3000u) {
            printf("reset %d\n", (int)rhonn_reset(&net));
        }
        st = rhonn_step(&net, x, u, valid, xhat);
        printf("%lu %d", (unsigned long)k, (int)st);
        print_reals("", xhat, N);
        if (k % 250u == 0u || k + 1u == STEPS) {
            print_state(&net);
        }
    }
    return 0;
}
