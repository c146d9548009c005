/*
 * Coverage-guided fuzz target (libFuzzer) for rhonn_run_population
 * (rhonn_population.h): every member of a population must be its own
 * rhonn_run, bit for bit, whatever the data.
 *
 * Input: a structure (1..6 states, 0..2 inputs, 1..8 terms per neuron of
 * any factors, delays included, each neuron's activation and covariance
 * form), 1..RHONN_MAX_POPULATION members of it, each tuned apart (R, eta,
 * Q, P(0), w(0), forgetting, the trace ceiling, reset_after, skip_refused,
 * the innovation gate, x(0); now and then a gate set in force, or a
 * configured trace ceiling lifted, after rhonn_init; the
 * slope beta apart or as member 0's, so that the regressor is shared or
 * not) and stepped a number of samples of its own first, then the
 * trajectory: per sample a dropout mask, the states and the inputs (reals
 * as fuzz_input.h reads them: hostile values included).
 *
 * The target aborts when a member of rhonn_run_population and rhonn_run on
 * a copy of the same identifier differ in: the status, the samples done,
 * any prediction written, everything fuzz_compare.h compares (committed
 * weights, covariances and their proofs, z(k-1), prediction, history ring,
 * health, steps, fault diagnostic); or when the next step differs; or when
 * the call's status is not that of the lowest-indexed member that stopped.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "rhonn.h"
#include "rhonn_population.h"
#include "fuzz_input.h"
#include "fuzz_compare.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define POP_T 64
#define POP_STATES (RHONN_MAX_STATES < 6 ? RHONN_MAX_STATES : 6)

/* The structure every member shares: sizes, forms, activations, terms. */
static void make_structure(reader *r, rhonn_config *c)
{
    size_t i;
    memset(c, 0, sizeof *c);
    c->n_states = (uint8_t)(1u + byte(r) % POP_STATES);
    c->n_inputs = (uint8_t)(byte(r) % 3u);
    for (i = 0; i < c->n_states; ++i) {
        rhonn_neuron_config *nc = &c->neurons[i];
        const uint8_t flags = byte(r);
        nc->n_terms = (uint8_t)(1u + (size_t)byte(r) % (RHONN_MAX_TERMS < 8 ? RHONN_MAX_TERMS : 8u));
        nc->activation = (uint8_t)(flags & 1u);
        nc->covariance = (uint8_t)((flags >> 1) & 1u);
        read_terms(r, nc, c->n_states, c->n_inputs);
    }
}

/* One member's tuning of the structure; beta as member 0's unless a flag
 * asks otherwise. */
static void tune_member(reader *r, rhonn_config *c, const rhonn_config *first)
{
    size_t i, t, k;
    for (i = 0; i < c->n_states; ++i) {
        rhonn_neuron_config *nc = &c->neurons[i];
        const size_t L = nc->n_terms;
        const uint8_t flags = byte(r);
        nc->beta = (first == NULL || (flags & 0x40u)) ? positive(r, -3, 2) : first->neurons[i].beta;
        nc->eta = positive(r, -2, 0);
        nc->r = positive(r, -12, 6);
        nc->forgetting = (flags & 0x04u) ? (rhonn_real)0.5 + (rhonn_real)(byte(r) % 100u) / (rhonn_real)200
                                         : (rhonn_real)0;
        nc->reset_after = (uint16_t)((flags & 0x08u) ? 1u + byte(r) % 4u : 0u);
        nc->skip_refused = (uint8_t)(flags >> 7); /* a refused update skips this neuron only */
        memset(nc->p0, 0, sizeof nc->p0);
        for (t = 0, k = 0; t < L; k += L - t, ++t) {
            nc->q[t] = (flags & 0x10u) ? (rhonn_real)0 : positive(r, -14, 3);
            nc->w0[t] = real(r, -3, 1);
            nc->p0[k] = positive(r, -3, 9);
        }
        nc->p_trace_max = (rhonn_real)0;
        /* an innovation gate in any member (0.25..8: low enough to trip
         * often), run in the lanes with the ungated members */
        nc->gate = (flags & 0x01u) ? (rhonn_real)(1u + byte(r) % 32u) / (rhonn_real)4 : (rhonn_real)0;
        if (flags & 0x20u) {
            rhonn_real tr = 0;
            for (t = 0, k = 0; t < L; k += L - t, ++t) {
                tr += nc->p0[k];
            }
            nc->p_trace_max = tr * (rhonn_real)(1u + byte(r) % 8u);
        }
        c->x0[i] = real(r, -3, 1);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static rhonn_t alone[RHONN_MAX_POPULATION], members[RHONN_MAX_POPULATION];
    static rhonn_population_work work;
    static rhonn_real X[POP_T * RHONN_MAX_STATES], U[POP_T * (RHONN_MAX_INPUTS + 1)];
    static rhonn_real ya[POP_T * RHONN_MAX_STATES], yp[RHONN_MAX_POPULATION * POP_T * RHONN_MAX_STATES];
    static uint8_t V[POP_T * RHONN_MAX_STATES];
    rhonn_t *nets[RHONN_MAX_POPULATION];
    rhonn_status st_pop[RHONN_MAX_POPULATION], st_alone, ret, first_stop = RHONN_OK;
    size_t done_pop[RHONN_MAX_POPULATION], done_alone;
    rhonn_config structure, cfg, cfg0;
    size_t N, n, mi, T, k, j, mb;
    reader r;

    r.p = data;
    r.n = size;
    make_structure(&r, &structure);
    N = 1u + byte(&r) % RHONN_MAX_POPULATION;
    n = structure.n_states;
    mi = structure.n_inputs;
    T = 1u + byte(&r) % POP_T;
    for (k = 0; k < T; ++k) {
        const uint8_t mask = byte(&r);
        for (j = 0; j < n; ++j) {
            X[k * n + j] = real(&r, -4, 3);
            V[k * n + j] = (uint8_t)(((mask >> j) & 1u) ? 0u : 1u);
        }
        for (j = 0; j < mi; ++j) {
            U[k * mi + j] = real(&r, -3, 3);
        }
    }
    for (mb = 0; mb < N; ++mb) {
        const size_t pre = byte(&r) % 4u;
        cfg = structure;
        tune_member(&r, &cfg, mb == 0 ? NULL : &cfg0);
        if (mb == 0) {
            cfg0 = cfg;
        }
        if (rhonn_init(&members[mb], &cfg, NULL) != RHONN_OK) {
            return 0;
        }
        {
            /* calibration in force that the configuration does not hold */
            const uint8_t cal = byte(&r);
            const size_t i = (size_t)(cal >> 5) % n;
            if (cal & 0x01u) {
                (void)rhonn_set_gate(&members[mb], i, (rhonn_real)((cal >> 2) & 7u) / (rhonn_real)2);
            }
            if (cal & 0x02u) {
                (void)rhonn_set_trace_ceiling(&members[mb], i, (rhonn_real)0);
            }
        }
        for (k = 0; k < pre; ++k) { /* from a running state of its own, its outcome whatever it is */
            const size_t s = T - 1u - k % T;
            (void)rhonn_step(&members[mb], X + s * n, U + s * mi, V + s * n, ya);
        }
        alone[mb] = members[mb];
        nets[mb] = &members[mb];
    }
    memset(yp, 0, sizeof yp);
    ret = rhonn_run_population(nets, N, &work, T, X, U, V, yp, st_pop, done_pop, NULL);
    for (mb = 0; mb < N; ++mb) {
        memset(ya, 0, sizeof ya);
        st_alone = rhonn_run(&alone[mb], T, X, U, V, ya, &done_alone);
        if (st_alone != st_pop[mb] || done_alone != done_pop[mb] ||
            memcmp(ya, yp + mb * T * n, done_alone * n * sizeof ya[0]) != 0 ||
            !same_committed(&alone[mb], &members[mb])) {
            abort(); /* the member is not its own run */
        }
        if (first_stop == RHONN_OK) {
            first_stop = st_alone;
        }
        st_alone = rhonn_step(&alone[mb], X, U, NULL, ya);
        if (st_alone != rhonn_step(&members[mb], X, U, NULL, yp) ||
            (st_alone == RHONN_OK && memcmp(ya, yp, n * sizeof ya[0]) != 0)) {
            abort(); /* and the next step agrees */
        }
    }
    if (ret != first_stop) {
        abort(); /* the call reports the lowest-indexed member that stopped */
    }
    return 0;
}
