/*
 * fuzz_compare.h - what the fuzz targets compare between two identifiers
 * that must be in the same state: everything rhonn_run promises to leave.
 */
#ifndef RHONN_FUZZ_COMPARE_H
#define RHONN_FUZZ_COMPARE_H

#include <string.h>

#include "rhonn.h"

/* Everything of a that rhonn_run promises, against b (the inactive banks
 * and the z bank not holding z(k-1) are the step's scratch). */
static inline int same_committed(const rhonn_t *a, const rhonn_t *b)
{
    const size_t n = a->cfg.n_states;
    size_t i;
    int same = memcmp(a->xhat, b->xhat, sizeof a->xhat) == 0 && memcmp(a->hist, b->hist, sizeof a->hist) == 0 &&
               memcmp(a->valid_run, b->valid_run, sizeof a->valid_run) == 0 &&
               memcmp(a->bank, b->bank, sizeof a->bank) == 0 && memcmp(a->health, b->health, sizeof a->health) == 0 &&
               a->head == b->head && a->started == b->started && a->steps == b->steps &&
               a->zbank == b->zbank && a->fault_neuron == b->fault_neuron;
    for (i = 0; same && i < n; ++i) {
        const size_t L = a->cfg.neurons[i].n_terms, ba = a->bank[i];
        same = memcmp(a->w[i][ba], b->w[i][ba], L * sizeof(rhonn_real)) == 0 &&
               memcmp(a->p[i][ba], b->p[i][ba], L * (L + 1u) / 2u * sizeof(rhonn_real)) == 0 &&
               memcmp(a->z[a->zbank][i], b->z[b->zbank][i], L * sizeof(rhonn_real)) == 0 &&
               a->cert[i][ba] == b->cert[i][ba];
    }
    return same;
}

#endif
