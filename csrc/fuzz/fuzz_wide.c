/*
 * Coverage-guided fuzz target (libFuzzer) for rhonn_run_wide
 * (rhonn_population.h): one identifier's neurons run side by side in the
 * vector lanes must be rhonn_run, bit for bit, whatever the data.
 *
 * Input: a configuration header whose neurons share their size and
 * covariance form (1..8 neurons of 1..8 terms, so that the lanes do run it;
 * every neuron tuned apart: R, eta, Q, P(0), w(0), forgetting, the trace
 * ceiling, reset_after, skip_refused, the innovation gate), a number of samples stepped first with rhonn_step,
 * then the trajectory: per sample a dropout mask, the states and the inputs
 * (reals as fuzz_input.h reads them: hostile values included).
 *
 * The target aborts when rhonn_run_wide and rhonn_run on copies of the same
 * identifier differ in: the status, the samples done, any prediction
 * written, the committed weights and covariances (factors) with their
 * proofs of definiteness (rhonn_t.cert), the regressor z(k-1), the
 * prediction, the history, the health records, the steps, the fault
 * diagnostic; or when the next step after the run differs.
 *
 * It also steps a third copy through the same samples in the lanes, one
 * by one (rhonn_wide_begin, rhonn_wide_step, rhonn_wide_end, the loan
 * given back and taken again at a sample the input picks), against
 * rhonn_step on a fourth, both going on after refused steps, and aborts
 * when a status or prediction differs, when a lent net is not refused by
 * rhonn_step, or when the committed state differs at the end.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "rhonn.h"
#include "rhonn_population.h"
#include "fuzz_input.h"
#include "fuzz_compare.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define WIDE_T 64
#define WIDE_N (RHONN_MAX_STATES < RHONN_MAX_POPULATION ? RHONN_MAX_STATES : RHONN_MAX_POPULATION)

static void make_uniform_config(reader *r, rhonn_config *c)
{
    const uint8_t head = byte(r);
    const size_t n = 1u + head % WIDE_N;
    const size_t L = 1u + (size_t)byte(r) % (RHONN_MAX_TERMS < 8 ? RHONN_MAX_TERMS : 8u);
    size_t i, t, k;
    memset(c, 0, sizeof *c);
    c->n_states = (uint8_t)n;
    c->n_inputs = (uint8_t)(byte(r) % 3u);
    for (i = 0; i < n; ++i) {
        rhonn_neuron_config *nc = &c->neurons[i];
        const uint8_t flags = byte(r);
        nc->n_terms = (uint8_t)L;
        nc->activation = (uint8_t)(flags & 1u);
        nc->covariance = (uint8_t)((head >> 7) & 1u); /* one form for all */
        nc->beta = positive(r, -3, 2);
        nc->eta = positive(r, -2, 0);
        nc->r = positive(r, -12, 6);
        if (flags & 0x04u) {
            nc->forgetting = (rhonn_real)0.5 + (rhonn_real)(byte(r) % 100u) / (rhonn_real)200;
        }
        if (flags & 0x08u) {
            nc->reset_after = (uint16_t)(1u + byte(r) % 4u);
        }
        nc->skip_refused = (uint8_t)((flags >> 6) & 1u); /* a refused update skips this neuron only */
        if (flags & 0x02u) { /* an innovation gate (0.25..8: low enough to trip often) */
            nc->gate = (rhonn_real)(1u + byte(r) % 32u) / (rhonn_real)4;
        }
        for (t = 0, k = 0; t < L; k += L - t, ++t) {
            nc->q[t] = (flags & 0x10u) ? (rhonn_real)0 : positive(r, -14, 3);
            nc->w0[t] = real(r, -3, 1);
            nc->p0[k] = positive(r, -3, 9);
        }
        if (flags & 0x20u) {
            rhonn_real tr = 0;
            for (t = 0, k = 0; t < L; k += L - t, ++t) {
                tr += nc->p0[k];
            }
            nc->p_trace_max = tr * (rhonn_real)(1u + byte(r) % 8u);
        }
        read_terms(r, nc, n, c->n_inputs);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static rhonn_t alone, lanes, single, stepped;
    static rhonn_population_work work, lend;
    static rhonn_real X[WIDE_T * RHONN_MAX_STATES], U[WIDE_T * (RHONN_MAX_INPUTS + 1)];
    static rhonn_real ya[WIDE_T * RHONN_MAX_STATES], yw[WIDE_T * RHONN_MAX_STATES];
    static uint8_t V[WIDE_T * RHONN_MAX_STATES];
    rhonn_config cfg;
    rhonn_status sa, sw;
    size_t n, m, T, pre, k, j, da = 0, dw = 0, regive;
    reader r;

    r.p = data;
    r.n = size;
    make_uniform_config(&r, &cfg);
    if (rhonn_init(&alone, &cfg, NULL) != RHONN_OK) {
        return 0;
    }
    n = cfg.n_states;
    m = cfg.n_inputs;
    pre = byte(&r) % 4u;
    T = 1u + byte(&r) % WIDE_T;
    for (k = 0; k < T; ++k) {
        const uint8_t mask = byte(&r);
        for (j = 0; j < n; ++j) {
            X[k * n + j] = real(&r, -4, 3);
            V[k * n + j] = (uint8_t)(((mask >> j) & 1u) ? 0u : 1u);
        }
        for (j = 0; j < m; ++j) {
            U[k * m + j] = real(&r, -3, 3);
        }
    }
    for (k = 0; k < pre; ++k) { /* from a running state, its outcome whatever it is */
        (void)rhonn_step(&alone, X + (T - 1u - k % T) * n, U + (T - 1u - k % T) * m, V + (T - 1u - k % T) * n, ya);
    }
    regive = byte(&r) % WIDE_T;
    lanes = alone;
    single = alone;
    stepped = alone;
    memset(ya, 0, sizeof ya);
    memset(yw, 0, sizeof yw);
    sa = rhonn_run(&alone, T, X, U, V, ya, &da);
    sw = rhonn_run_wide(&lanes, &work, T, X, U, V, yw, &dw);
    if (sa != sw || da != dw || memcmp(ya, yw, sizeof ya) != 0 || !same_committed(&alone, &lanes)) {
        abort(); /* the lanes are not rhonn_run */
    }
    /* and the next step agrees */
    sa = rhonn_step(&alone, X, U, NULL, ya);
    sw = rhonn_step(&lanes, X, U, NULL, yw);
    if (sa != sw || (sa == RHONN_OK && memcmp(ya, yw, n * sizeof ya[0]) != 0)) {
        abort();
    }

    /* stepped in the lanes sample by sample, on past refusals */
    sw = rhonn_wide_begin(&stepped, &lend);
    if (sw == RHONN_E_CONFIG) {
        return 0; /* the U D U^T form in the portable build: no lanes */
    }
    if (sw != RHONN_OK) {
        abort();
    }
    for (k = 0; k < T; ++k) {
        if (k == regive && (rhonn_wide_end(&stepped, &lend) != RHONN_OK ||
                            rhonn_wide_begin(&stepped, &lend) != RHONN_OK)) {
            abort();
        }
        sa = rhonn_step(&single, X + k * n, U + k * m, V + k * n, ya);
        sw = rhonn_wide_step(&stepped, &lend, X + k * n, U + k * m, V + k * n, yw);
        if (sa != sw || (sa == RHONN_OK && memcmp(ya, yw, n * sizeof ya[0]) != 0)) {
            abort();
        }
    }
    if (rhonn_step(&stepped, X, U, NULL, yw) != RHONN_E_NOT_INIT || rhonn_wide_end(&stepped, &lend) != RHONN_OK ||
        !same_committed(&single, &stepped)) {
        abort();
    }
    return 0;
}
