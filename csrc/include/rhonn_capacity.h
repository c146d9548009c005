/*
 * rhonn_capacity.h - compile-time capacities of the pyrhonn core.
 *
 * Every array in rhonn_t is sized by these macros, so the identifier's RAM is
 * known at link time and firmware can place it in a static. Override any of
 * them on the compiler command line (-DRHONN_MAX_TERMS=12) or in a header
 * named by RHONN_USER_CAPACITY (e.g. -DRHONN_USER_CAPACITY='"my_caps.h"').
 * Every translation unit that sees rhonn_t must use the same values.
 */
#ifndef RHONN_CAPACITY_H
#define RHONN_CAPACITY_H

#ifdef RHONN_USER_CAPACITY
#include RHONN_USER_CAPACITY
#endif

/* n: states, one neuron per state (eq. 3). */
#ifndef RHONN_MAX_STATES
#define RHONN_MAX_STATES 8
#endif

/* m: external inputs (eq. 5). At least 1 so arrays stay non-empty C;
 * a configuration may still use n_inputs = 0. */
#ifndef RHONN_MAX_INPUTS
#define RHONN_MAX_INPUTS 4
#endif

/* L_i: high-order terms (weights) per neuron (eq. 4). */
#ifndef RHONN_MAX_TERMS
#define RHONN_MAX_TERMS 16
#endif

/* |I_j|: factors in one product term (eq. 4). */
#ifndef RHONN_MAX_FACTORS
#define RHONN_MAX_FACTORS 4
#endif

/* l: deepest delayed tap x(k - d), d <= RHONN_MAX_DELAY (Remark 1). */
#ifndef RHONN_MAX_DELAY
#define RHONN_MAX_DELAY 8
#endif

/* Largest exponent d_ij(k) of one factor (eq. 4). */
#ifndef RHONN_MAX_POWER
#define RHONN_MAX_POWER 8
#endif

/* Entries of one L x L symmetric covariance in packed (upper-triangle) form. */
#define RHONN_MAX_PACKED ((RHONN_MAX_TERMS * (RHONN_MAX_TERMS + 1)) / 2)

/* Ring buffer length: the current sample plus RHONN_MAX_DELAY past ones. */
#define RHONN_HISTORY_LEN (RHONN_MAX_DELAY + 1)

/* One sample as the regressor reads it: x (RHONN_MAX_STATES), S(x) for each
 * activation group (RHONN_MAX_STATES groups of RHONN_MAX_STATES), u
 * (RHONN_MAX_INPUTS) and the constant 1. The history holds these. */
#define RHONN_SAMPLE_LEN (RHONN_MAX_STATES * (RHONN_MAX_STATES + 1) + RHONN_MAX_INPUTS + 1)

/* Distinct factor values x_j(k-d)^p, S(x_j(k-d))^p, u_j(k-d)^p, 1 that one
 * configuration reads per step (rhonn_init compiles the terms into a table
 * of them). The default holds every configuration the other capacities
 * allow; a firmware build may lower it to what its configuration needs
 * (the exported capacity header states it). */
#ifndef RHONN_MAX_ENTRIES
#define RHONN_MAX_ENTRIES (RHONN_MAX_STATES * RHONN_MAX_TERMS * RHONN_MAX_FACTORS)
#endif

/* The values a step's regressor reads by index: this sample (RHONN_SAMPLE_LEN,
 * the factors x_j(k), S(x_j(k)), u_j(k) and 1 in place) followed by the
 * entries that are not in it (a delayed tap or a power above 1). */
#define RHONN_VALUES_LEN (RHONN_SAMPLE_LEN + RHONN_MAX_ENTRIES)

#if RHONN_MAX_STATES < 1 || RHONN_MAX_STATES > 255
#error "RHONN_MAX_STATES must be in 1..255"
#endif
#if RHONN_MAX_INPUTS < 1 || RHONN_MAX_INPUTS > 255
#error "RHONN_MAX_INPUTS must be in 1..255 (a plant without inputs uses n_inputs = 0)"
#endif
#if RHONN_MAX_TERMS < 1 || RHONN_MAX_TERMS > 255
#error "RHONN_MAX_TERMS must be in 1..255"
#endif
#if RHONN_MAX_FACTORS < 1 || RHONN_MAX_FACTORS > 255
#error "RHONN_MAX_FACTORS must be in 1..255"
#endif
#if RHONN_MAX_DELAY < 0 || RHONN_MAX_DELAY > 254
#error "RHONN_MAX_DELAY must be in 0..254"
#endif
#if RHONN_MAX_POWER < 1 || RHONN_MAX_POWER > 255
#error "RHONN_MAX_POWER must be in 1..255"
#endif

#if RHONN_MAX_ENTRIES < 1 || RHONN_MAX_ENTRIES > 65535
#error "RHONN_MAX_ENTRIES must be in 1..65535"
#endif
#if RHONN_VALUES_LEN > 65535
#error "RHONN_MAX_STATES, RHONN_MAX_INPUTS and RHONN_MAX_ENTRIES too large: a sample and the entries must fit 65535 values"
#endif

#endif /* RHONN_CAPACITY_H */
