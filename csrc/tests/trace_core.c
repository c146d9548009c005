/* Prints every prediction of a fixed identifier over a fixed trajectory as
 * C99 hex floats, then again with the windup options and the gate on (both
 * covariance forms, bounded forgetting through a quiet stretch, an outlier
 * the gate skips) with the covariances read now and then. CTest runs it
 * from differently built cores (generic and RHONN_UNROLL) and requires
 * byte-identical output: unrolling may change speed, never a single bit. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "rhonn.h"

static void add_term(rhonn_neuron_config *nc, uint8_t kind0, uint8_t idx0, uint8_t kind1, uint8_t idx1,
                     uint8_t delay1, uint8_t power1)
{
    rhonn_term *t = &nc->terms[nc->n_terms++];
    t->n_factors = kind1 == 255u ? 1u : 2u;
    t->factors[0].kind = kind0;
    t->factors[0].index = idx0;
    t->factors[0].power = 1;
    if (kind1 != 255u) {
        t->factors[1].kind = kind1;
        t->factors[1].index = idx1;
        t->factors[1].delay = delay1;
        t->factors[1].power = power1;
    }
}

static int run(int options)
{
    static rhonn_t net;
    rhonn_config c;
    size_t i, j, k, L, pi;

    memset(&c, 0, sizeof c);
    c.n_states = 5;
    c.n_inputs = 2;
    for (i = 0; i < c.n_states; ++i) {
        rhonn_neuron_config *nc = &c.neurons[i];
        nc->activation = (uint8_t)(i % 2u);
        nc->beta = (rhonn_real)(0.5 + 0.25 * (double)i);
        nc->eta = (rhonn_real)0.9;
        nc->r = (rhonn_real)0.05;
        /* neuron i has 1 + 3 i terms: every size the unrolled build switches on */
        for (L = 0; L < 1u + 3u * i && L < (size_t)RHONN_MAX_TERMS; ++L) {
            switch (L % 4u) {
            case 0: add_term(nc, RHONN_FACTOR_S, (uint8_t)(L % 5u), 255u, 0, 0, 1); break;
            case 1: add_term(nc, RHONN_FACTOR_S, (uint8_t)i, RHONN_FACTOR_S, (uint8_t)((L + 1u) % 5u), 0, 2); break;
            case 2: add_term(nc, RHONN_FACTOR_U, (uint8_t)(L % 2u), RHONN_FACTOR_X, (uint8_t)(L % 5u), 2, 1); break;
            default: add_term(nc, RHONN_FACTOR_ONE, 0, RHONN_FACTOR_S, (uint8_t)((L + 2u) % 5u), 1, 1); break;
            }
        }
        for (L = 0, pi = 0; L < nc->n_terms; ++L) {
            size_t c2;
            nc->q[L] = (rhonn_real)1e-3;
            for (c2 = L; c2 < nc->n_terms; ++c2, ++pi) {
                nc->p0[pi] = c2 == L ? (rhonn_real)100.0 : (rhonn_real)0.0;
            }
        }
        if (options) {
            nc->covariance = (uint8_t)(i % 2u);
            nc->forgetting = i % 3u == 0u ? (rhonn_real)0.99 : i % 3u == 1u ? (rhonn_real)0.9 : (rhonn_real)0.0;
            nc->gate = i >= 3u ? (rhonn_real)9.0 : (rhonn_real)0.0;
        }
    }
    if (rhonn_init(&net, &c, NULL) != RHONN_OK) {
        fprintf(stderr, "rhonn_init failed\n");
        return 2;
    }
    for (k = 0; k < 3000; ++k) {
        rhonn_real x[5], u[2], y[5];
        uint8_t valid[5];
        double t = 0.01 * (double)(options && k >= 1000u && k < 2000u ? 1000u : k); /* quiet */
        for (j = 0; j < 5; ++j) {
            x[j] = (rhonn_real)(sin((1.0 + 0.3 * (double)j) * t) + 0.2 * cos(3.7 * t * (double)(j + 1)));
            valid[j] = (uint8_t)((k + 7u * j) % 23u != 0u);
        }
        u[0] = (rhonn_real)sin(0.7 * t);
        u[1] = (rhonn_real)cos(0.4 * t);
        if (options && k >= 1000u && k < 2000u) {
            valid[0] = valid[1] = valid[2] = valid[3] = valid[4] = 1;
            if (k % 97u == 0u) {
                x[3] = (rhonn_real)1e4; /* an outlier */
            }
        }
        if (rhonn_step(&net, x, u, valid, y) != RHONN_OK) {
            fprintf(stderr, "rhonn_step failed at %u\n", (unsigned)k);
            return 3;
        }
        for (j = 0; j < 5; ++j) {
            printf(j ? " %a" : "%a", (double)y[j]);
        }
        printf("\n");
        for (i = 0; options && k % 50u == 0u && i < c.n_states; ++i) {
            rhonn_real p[RHONN_MAX_PACKED];
            rhonn_health h;
            const size_t np = (size_t)c.neurons[i].n_terms * (c.neurons[i].n_terms + 1u) / 2u;
            if (rhonn_get_covariance(&net, i, p, np) != RHONN_OK || rhonn_get_health(&net, i, &h) != RHONN_OK) {
                return 4;
            }
            for (j = 0; j < np; ++j) {
                printf(j ? " %a" : "P %a", (double)p[j]);
            }
            printf(" | %u %u %u %a\n", (unsigned)h.updates, (unsigned)h.gated, (unsigned)h.bounded, (double)h.trace_p);
        }
    }
    return 0;
}

int main(void)
{
    int st = run(0);
    return st != 0 ? st : run(1);
}
