/*
 * rhonn_warm.c - warm start from an exported running state (rhonn_warm.h),
 * through the public API of rhonn.h only.
 */
#include "rhonn_warm.h"

/* Deepest delayed tap the configuration reads (validated config). */
static size_t deepest_delay(const rhonn_config *cfg)
{
    size_t i, t, f, d = 0;
    for (i = 0; i < cfg->n_states; ++i) {
        const rhonn_neuron_config *nc = &cfg->neurons[i];
        for (t = 0; t < nc->n_terms; ++t) {
            for (f = 0; f < nc->terms[t].n_factors; ++f) {
                const rhonn_factor *fa = &nc->terms[t].factors[f];
                if (fa->kind != (uint8_t)RHONN_FACTOR_ONE && fa->delay > d) {
                    d = fa->delay;
                }
            }
        }
    }
    return d;
}

static rhonn_status restore(rhonn_t *net, const rhonn_config *cfg, const rhonn_warm_state *state)
{
    rhonn_status st = RHONN_OK;
    size_t i, s;

    if ((size_t)state->n_samples < deepest_delay(cfg) + 1u || (size_t)state->n_samples > (size_t)RHONN_HISTORY_LEN) {
        return RHONN_E_ARGUMENT;
    }
    for (i = 0; i < cfg->n_states && st == RHONN_OK; ++i) {
        const size_t L = cfg->neurons[i].n_terms;
        st = rhonn_set_weights(net, i, state->w[i], L);
        if (st == RHONN_OK) {
            st = rhonn_set_factors(net, i, state->factors[i], L * (L + 1u) / 2u);
        }
    }
    /* Frozen steps: the history, z(k-1) and xhat(k) from the restored
     * weights; weights and covariances are not touched. */
    if (st == RHONN_OK) {
        st = rhonn_set_learning(net, 0);
    }
    for (s = 0; s < (size_t)state->n_samples && st == RHONN_OK; ++s) {
        st = rhonn_step(net, state->x[s], state->u[s], NULL, NULL);
    }
    if (st == RHONN_OK) {
        st = rhonn_set_learning(net, state->learning);
    }
    return st;
}

rhonn_status rhonn_warm_start(rhonn_t *net, const rhonn_config *cfg, const rhonn_warm_state *state,
                              rhonn_config_error *where)
{
    rhonn_status st;

    if (net == NULL || cfg == NULL || state == NULL) {
        return RHONN_E_NULL;
    }
    st = rhonn_init(net, cfg, where);
    if (st != RHONN_OK) {
        return st;
    }
    st = restore(net, cfg, state);
    if (st != RHONN_OK) {
        (void)rhonn_reset(net);
    }
    return st;
}
