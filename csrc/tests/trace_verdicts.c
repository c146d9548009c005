/* Prints, step by step, the status and every committed full-form covariance
 * (C99 hex floats) of identifiers run where definiteness is at stake: small
 * and zero Q, tiny R, nearly collinear regressors, large P0, a motor-like
 * ramp, scales from 1e-6 to 1e6, covariances set from outside, bounded
 * forgetting through a quiet stretch (the ceiling switching it on and off),
 * an innovation gate skipping an outlier. CTest runs it
 * from the default core, which proves most covariances definite from
 * rounding-error bounds instead of factorising them, and from a core built
 * with RHONN_CERTIFY=0, which always factorises, and requires byte-identical
 * output: the shortcut must never change a verdict or a bit. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "rhonn.h"

static uint32_t lcg(uint32_t *s)
{
    *s = *s * 1664525u + 1013904223u;
    return *s >> 8;
}

static double uniform(uint32_t *s)
{
    return (double)lcg(s) / 16777216.0 * 2.0 - 1.0;
}

static void term(rhonn_neuron_config *nc, uint8_t kind0, uint8_t idx0, uint8_t kind1, uint8_t idx1)
{
    rhonn_term *t = &nc->terms[nc->n_terms++];
    t->n_factors = kind1 == 255u ? 1u : 2u;
    t->factors[0].kind = kind0;
    t->factors[0].index = idx0;
    t->factors[0].power = 1;
    t->factors[1].kind = kind1 == 255u ? 0u : kind1;
    t->factors[1].index = idx1;
    t->factors[1].power = 1;
}

/* Scenario sc: 3 states, 2 inputs, full form; q, R, P0 and the data's
 * scale from the scenario number. */
static unsigned long proven; /* commits whose P carries the proof (stderr) */

static int run(unsigned sc)
{
    static const double qs[] = {1e-3, 1e-6, 0.0, 1e-9, 1e-2, 1e-4};
    static const double rs[] = {0.1, 1e-6, 1e-3, 1e-8, 1.0, 1e-4};
    static const double p0s[] = {100.0, 1e4, 1.0, 6.8e6, 10.0, 1e-3};
    static const double scales[] = {1.0, 1e3, 1e-3, 1.0, 1e6, 1e-6};
    static rhonn_t net;
    rhonn_config c;
    uint32_t seed = 12345u + 977u * sc;
    const double q = qs[sc % 6u], r = rs[(sc / 6u) % 6u], p0 = p0s[(sc + sc / 6u) % 6u];
    const double scale = scales[(sc / 3u) % 6u];
    size_t i, j, k, L, pi;

    memset(&c, 0, sizeof c);
    c.n_states = 3;
    c.n_inputs = 2;
    for (i = 0; i < c.n_states; ++i) {
        rhonn_neuron_config *nc = &c.neurons[i];
        nc->activation = RHONN_LOGISTIC;
        nc->beta = (rhonn_real)1.0;
        nc->eta = (rhonn_real)1.0;
        nc->r = (rhonn_real)r;
        term(nc, RHONN_FACTOR_X, (uint8_t)i, 255u, 0);          /* raw own state */
        term(nc, RHONN_FACTOR_X, (uint8_t)((i + 1u) % 3u), 255u, 0); /* nearly collinear with it */
        term(nc, RHONN_FACTOR_S, (uint8_t)i, RHONN_FACTOR_U, 0);
        term(nc, RHONN_FACTOR_U, 1, RHONN_FACTOR_X, (uint8_t)((i + 2u) % 3u));
        if (i > 0u) {
            term(nc, RHONN_FACTOR_ONE, 0, 255u, 0);             /* a bias */
            term(nc, RHONN_FACTOR_S, (uint8_t)((i + 1u) % 3u), RHONN_FACTOR_S, (uint8_t)((i + 2u) % 3u));
        }
        if (sc % 3u == 1u) {
            nc->forgetting = (rhonn_real)(sc % 2u ? 0.99 : 0.9);
        }
        if (sc % 4u == 2u) {
            nc->gate = (rhonn_real)16.0;
        }
        for (L = 0, pi = 0; L < nc->n_terms; ++L) {
            size_t c2;
            nc->q[L] = (rhonn_real)(q * (1.0 + 0.1 * (double)L));
            for (c2 = L; c2 < nc->n_terms; ++c2, ++pi) {
                nc->p0[pi] = c2 == L ? (rhonn_real)p0 : (rhonn_real)0.0;
            }
        }
    }
    if (rhonn_init(&net, &c, NULL) != RHONN_OK) {
        printf("scenario %u: init refused\n", sc);
        return 0;
    }
    for (k = 0; k < 400; ++k) {
        rhonn_real x[3], u[2], y[3], p[RHONN_MAX_PACKED];
        const double t = 3e-4 * (double)(k < 250u || k >= 330u ? k : 250u); /* quiet from 250 to 329 */
        rhonn_status st;
        /* a ramp that moves from the first sample, its near copy, and noise */
        x[0] = (rhonn_real)(scale * (0.5 + 0.3 * t + 1e-4 * uniform(&seed)));
        x[1] = (rhonn_real)(scale * (0.5 + 0.3 * t + 1e-3 * uniform(&seed)));
        x[2] = (rhonn_real)(scale * sin(40.0 * t) + 0.01 * uniform(&seed));
        u[0] = (rhonn_real)(k < 200u ? 10.0 : 10.0 + uniform(&seed));
        u[1] = (rhonn_real)(cos(25.0 * t));
        if (k >= 250u && k < 330u) {
            x[0] = (rhonn_real)(scale * 0.575);
            x[1] = (rhonn_real)(scale * 0.575);
            u[0] = (rhonn_real)10.0;
        }
        if (k == 360u) {
            x[2] = (rhonn_real)(1e3 * scale); /* an outlier */
        }
        if (k == 150u) {
            /* a nearly singular covariance set from outside */
            const size_t L1 = c.neurons[1].n_terms;
            for (pi = 0; pi < L1 * (L1 + 1u) / 2u; ++pi) {
                p[pi] = (rhonn_real)1.0;
            }
            for (L = 0, pi = 0; L < L1; pi += L1 - L, ++L) {
                p[pi] = (rhonn_real)(1.0 + 1e-3 * (double)(L + 1u));
            }
            printf("set %s\n", rhonn_status_name(rhonn_set_covariance(&net, 1, p, L1 * (L1 + 1u) / 2u)));
        }
        st = rhonn_step(&net, x, u, NULL, y);
        for (i = 0; i < c.n_states; ++i) {
            proven += net.cert[i][net.bank[i]];
        }
        printf("%u %lu %s", sc, (unsigned long)k, rhonn_status_name(st));
        for (i = 0; i < c.n_states && (k % 20u == 0u || st != RHONN_OK); ++i) {
            const size_t Li = c.neurons[i].n_terms, np = Li * (Li + 1u) / 2u;
            if (rhonn_get_covariance(&net, i, p, np) != RHONN_OK) {
                return 1;
            }
            for (j = 0; j < np; ++j) {
                printf(" %a", (double)p[j]);
            }
        }
        printf("\n");
    }
    return 0;
}

int main(void)
{
    unsigned sc;
    for (sc = 0; sc < 36u; ++sc) {
        if (run(sc) != 0) {
            return 1;
        }
    }
    fprintf(stderr, "neuron-steps whose covariance carries the proof: %lu\n", proven);
    return 0;
}
