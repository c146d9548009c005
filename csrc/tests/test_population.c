/* test_population.c - rhonn_run_population is N rhonn_run calls, bit for
 * bit: predictions, statuses, steps run and the state each member is left
 * in (weights, stored covariances, prediction, health, and the steps that
 * follow), for the float and double builds, both covariance forms,
 * forgetting, the trace ceiling, automatic resets, members that stop,
 * dropouts, delayed taps, betas that differ; and its argument checks.
 *
 * RHONN_POP_BENCH=T (environment) also times one LIM-sized population of 8
 * against 8 rhonn_run calls over T samples, for profiling; no timing is
 * asserted. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "check.h"
#include "rhonn.h"
#include "rhonn_population.h"
#include "rhonn_internal.h"

#define POP_T 400
#ifdef RHONN_SINGLE
#define BIG FLT_MAX
#else
#define BIG DBL_MAX
#endif
#define MAXN RHONN_MAX_POPULATION
/* rhonn_run_wide runs U D U^T neurons in the lanes in the vector build */
#ifndef RHONN_WIDE_UD
#define RHONN_WIDE_UD 1
#endif

static rhonn_term term1(uint8_t kind, uint8_t index, uint8_t delay)
{
    rhonn_term t;
    memset(&t, 0, sizeof t);
    t.n_factors = 1;
    t.factors[0].kind = kind;
    t.factors[0].index = index;
    t.factors[0].delay = delay;
    t.factors[0].power = 1;
    return t;
}

static rhonn_term term2(uint8_t kind, uint8_t i1, uint8_t i2, uint8_t power2)
{
    rhonn_term t = term1(kind, i1, 0);
    t.n_factors = 2;
    t.factors[1].kind = kind;
    t.factors[1].index = i2;
    t.factors[1].power = power2;
    return t;
}

/* The LIM identifier's structure (firmware-lim: 6 states, 2 inputs, a
 * 2-term U D U^T position neuron, 5-7 terms elsewhere); variant k tunes it
 * differently. delayed adds taps x1(k-2) and u1(k-1) and a power of this
 * sample's x4 (which the dropouts miss: each member's own x4^2 in a hold). */
static rhonn_config lim_config(unsigned k, int delayed, int ud_all)
{
    static const uint8_t S = RHONN_FACTOR_S, X = RHONN_FACTOR_X, U = RHONN_FACTOR_U;
    rhonn_config c;
    const rhonn_real f = (rhonn_real)(1.0 + 0.25 * (double)k);
    size_t i, t;
    memset(&c, 0, sizeof c);
    c.n_states = 6;
    c.n_inputs = 2;
    c.neurons[0].n_terms = 2;
    c.neurons[0].terms[0] = term1(X, 0, 0);
    c.neurons[0].terms[1] = term1(X, 1, 0);
    c.neurons[0].covariance = RHONN_COV_UD;
    c.neurons[1].n_terms = 7;
    c.neurons[1].terms[0] = term1(X, 1, 0);
    c.neurons[1].terms[1] = term1(S, 1, 0);
    c.neurons[1].terms[2] = term1(S, 0, 0);
    c.neurons[1].terms[3] = term2(S, 2, 5, 1);
    c.neurons[1].terms[4] = term2(S, 3, 4, 1);
    c.neurons[1].terms[5] = term2(S, 2, 4, 2);
    c.neurons[1].terms[6] = term2(S, 3, 5, 1);
    for (i = 2; i < 4; ++i) {
        c.neurons[i].n_terms = 5;
        c.neurons[i].terms[0] = term1(S, (uint8_t)i, 0);
        c.neurons[i].terms[1] = term1(S, 4, 0);
        c.neurons[i].terms[2] = term1(S, 5, 0);
        c.neurons[i].terms[3] = term2(S, 0, 4, 1);
        c.neurons[i].terms[4] = term2(S, 0, 5, 1);
    }
    for (i = 4; i < 6; ++i) {
        c.neurons[i].n_terms = 6;
        c.neurons[i].terms[0] = term1(S, (uint8_t)i, 0);
        c.neurons[i].terms[1] = term1(S, 2, 0);
        c.neurons[i].terms[2] = term1(S, 3, 0);
        c.neurons[i].terms[3] = term2(S, 1, 2, 1);
        c.neurons[i].terms[4] = term2(S, 1, 3, 1);
        c.neurons[i].terms[5] = term1(U, (uint8_t)(i - 4), 0);
    }
    if (delayed) {
        c.neurons[2].terms[4] = term1(X, 0, 2);
        c.neurons[4].terms[4] = term1(U, 0, 1);
        c.neurons[3].terms[4] = term1(X, 3, 0);
        c.neurons[3].terms[4].factors[0].power = 2;
    }
    for (i = 0; i < 6; ++i) {
        rhonn_neuron_config *nc = &c.neurons[i];
        const size_t L = nc->n_terms;
        size_t pi = 0, e;
        nc->activation = RHONN_LOGISTIC;
        nc->beta = (rhonn_real)1.0;
        nc->eta = (rhonn_real)(1.0 / (1.0 + 0.1 * (double)k));
        nc->r = (rhonn_real)(0.05 * (double)f);
        if (ud_all) {
            nc->covariance = RHONN_COV_UD;
        }
        for (t = 0; t < L; ++t) {
            nc->q[t] = (rhonn_real)(1e-3 * (double)f * (double)f);
            nc->w0[t] = (rhonn_real)(0.01 * (double)(t + 1u));
            for (e = t; e < L; ++e, ++pi) {
                nc->p0[pi] = e == t ? (rhonn_real)(10.0 * (double)f) : (rhonn_real)0.0;
            }
        }
    }
    c.x0[1] = (rhonn_real)(0.1 * (double)k);
    return c;
}

/* A quiet stretch in the trajectories (samples 150..299 hold sample 150,
 * all measured; bounded forgetting reaches its ceiling there) and an
 * outlier (x2 + 50 at sample 200, 330 with the hold), when set. */
static int hold_quiet = 0, add_outlier = 0;

static int held(size_t k)
{
    return hold_quiet && k >= 150u && k < 300u;
}

/* A smooth, exciting, deterministic trajectory; from sample 120 on, 4 in
 * every 37 have states 0 and 3 not measured (NaN). */
static void trajectory(rhonn_real *X, rhonn_real *U, uint8_t *valid, size_t T, int dropouts)
{
    size_t k, j;
    for (k = 0; k < T; ++k) {
        const double t = 0.01 * (double)(held(k) ? 150u : k);
        U[2 * k] = (rhonn_real)(0.8 * sin(1.3 * t));
        U[2 * k + 1] = (rhonn_real)(0.8 * cos(0.9 * t));
        for (j = 0; j < 6; ++j) {
            X[6 * k + j] = (rhonn_real)(0.5 * sin((0.7 + 0.31 * (double)j) * t + (double)j) + 0.2 * cos(2.1 * t));
            valid[6 * k + j] = 1;
        }
        if (add_outlier && k == (hold_quiet ? 330u : 200u)) {
            X[6 * k + 1] += (rhonn_real)50.0;
        }
        if (dropouts && k >= 120 && k % 37u < 4u && !held(k)) { /* state 0 is read through a delayed tap too */
            valid[6 * k + 0] = 0;
            valid[6 * k + 3] = 0;
            X[6 * k + 0] = (rhonn_real)NAN;
            X[6 * k + 3] = (rhonn_real)NAN;
        }
    }
}

/* Every observable of two identifiers is the same, bit for bit, and so are
 * the next steps. */
static int same_state(rhonn_t *a, rhonn_t *b, const rhonn_real *x, const rhonn_real *u)
{
    rhonn_real va[RHONN_MAX_PACKED], vb[RHONN_MAX_PACKED], ya[RHONN_MAX_STATES], yb[RHONN_MAX_STATES];
    rhonn_health ha, hb;
    size_t i, s;
    const size_t n = a->cfg.n_states;
    int same = memcmp(a->xhat, b->xhat, sizeof a->xhat) == 0 && a->steps == b->steps &&
               a->fault_neuron == b->fault_neuron && a->started == b->started && a->head == b->head &&
               memcmp(a->valid_run, b->valid_run, sizeof a->valid_run) == 0 &&
               memcmp(a->hist, b->hist, sizeof a->hist) == 0 &&
               memcmp(a->bank, b->bank, sizeof a->bank) == 0 && a->zbank == b->zbank;
    for (i = 0; i < n; ++i) {
        const size_t L = a->cfg.neurons[i].n_terms, P = L * (L + 1u) / 2u;
        same &= rhonn_get_weights(a, i, va, L) == RHONN_OK && rhonn_get_weights(b, i, vb, L) == RHONN_OK &&
                memcmp(va, vb, L * sizeof va[0]) == 0;
        same &= rhonn_get_factors(a, i, va, P) == RHONN_OK && rhonn_get_factors(b, i, vb, P) == RHONN_OK &&
                memcmp(va, vb, P * sizeof va[0]) == 0;
        same &= memcmp(a->z[a->zbank][i], b->z[b->zbank][i], L * sizeof va[0]) == 0;
        same &= rhonn_get_health(a, i, &ha) == RHONN_OK && rhonn_get_health(b, i, &hb) == RHONN_OK &&
                memcmp(&ha.innovation, &hb.innovation, sizeof ha.innovation) == 0 &&
                memcmp(&ha.nis, &hb.nis, sizeof ha.nis) == 0 && memcmp(&ha.trace_p, &hb.trace_p, sizeof ha.trace_p) == 0 &&
                ha.updates == hb.updates && ha.rejected == hb.rejected && ha.resets == hb.resets &&
                ha.bounded == hb.bounded && ha.gated == hb.gated && ha.fail_run == hb.fail_run;
    }
    for (s = 0; s < 3; ++s) {
        const rhonn_status sa = rhonn_step(a, x + s * n, u + s * 2u, NULL, ya);
        const rhonn_status sb = rhonn_step(b, x + s * n, u + s * 2u, NULL, yb);
        same &= sa == sb && (sa != RHONN_OK || memcmp(ya, yb, n * sizeof ya[0]) == 0);
    }
    return same;
}

/* The committed covariances carry the same proofs of definiteness (which
 * the lanes' vector proof and rhonn.c's scalar one must agree on). */
static int same_proofs(const rhonn_t *a, const rhonn_t *b)
{
    size_t i;
    int same = 1;
    for (i = 0; i < a->cfg.n_states; ++i) {
        same &= a->cert[i][a->bank[i]] == b->cert[i][b->bank[i]];
    }
    return same;
}

static rhonn_t alone[MAXN], members[MAXN];
static rhonn_population_work work;
/* When set, called on each member (index m) after its rhonn_init, before
 * it is copied: calibration in force that its configuration does not hold. */
static void (*after_init)(rhonn_t *net, size_t m) = NULL;
static rhonn_real X[POP_T * 6], U[POP_T * 2], Xhat_alone[MAXN][POP_T * 6], Xhat_pop[MAXN * POP_T * 6];
static uint8_t V[POP_T * 6];

/* Members nets (configs cfg[0..N)), pre-stepped pre[m] samples, run both
 * ways; every member the same. Returns the number of members that stopped. */
static size_t compare(const rhonn_config *cfg, size_t N, const size_t *pre, int dropouts)
{
    rhonn_t *nets[MAXN];
    rhonn_status st_alone[MAXN], st_pop[MAXN];
    size_t done_alone[MAXN], done_pop[MAXN];
    size_t m, k, stopped = 0;
    rhonn_status ret;
    trajectory(X, U, V, POP_T, dropouts);
    memset(Xhat_pop, 0, sizeof Xhat_pop);
    memset(Xhat_alone, 0, sizeof Xhat_alone);
    for (m = 0; m < N; ++m) {
        CHECK_STATUS(rhonn_init(&alone[m], &cfg[m], NULL), RHONN_OK);
        if (after_init != NULL) {
            after_init(&alone[m], m);
        }
        for (k = 0; pre != NULL && k < pre[m]; ++k) {
            CHECK_STATUS(rhonn_step(&alone[m], X + 6u * (POP_T - 1u - k), U + 2u * (POP_T - 1u - k), NULL, NULL),
                         RHONN_OK);
        }
        members[m] = alone[m];
        nets[m] = &members[m];
        st_alone[m] = rhonn_run(&alone[m], POP_T, X, U, dropouts ? V : NULL, Xhat_alone[m], &done_alone[m]);
    }
    ret = rhonn_run_population(nets, N, &work, POP_T, X, U, dropouts ? V : NULL, Xhat_pop, st_pop, done_pop, NULL);
    for (m = 0; m < N; ++m) {
        CHECK(st_pop[m] == st_alone[m]);
        CHECK(done_pop[m] == done_alone[m]);
        CHECK(memcmp(Xhat_pop + m * POP_T * 6u, Xhat_alone[m], done_alone[m] * 6u * sizeof(rhonn_real)) == 0);
        CHECK(same_proofs(&members[m], &alone[m]));
        CHECK(same_state(&members[m], &alone[m], X, U));
        stopped += st_alone[m] != RHONN_OK;
    }
    m = 0;
    while (m < N && st_alone[m] == RHONN_OK) {
        ++m;
    }
    CHECK(ret == (m < N ? st_alone[m] : RHONN_OK)); /* the lowest-indexed member that stopped */
    return stopped;
}

static void lim_population_equals_eight_runs(void)
{
    rhonn_config cfg[MAXN];
    size_t m;
    for (m = 0; m < MAXN; ++m) {
        cfg[m] = lim_config((unsigned)m, 0, 0);
    }
    CHECK(compare(cfg, MAXN, NULL, 0) == 0);
}

static void dropouts_delays_and_differing_betas_equal_single_runs(void)
{
    rhonn_config cfg[MAXN];
    size_t m;
    for (m = 0; m < MAXN; ++m) {
        cfg[m] = lim_config((unsigned)m, 1, 0);
    }
    CHECK(compare(cfg, 5, NULL, 1) == 0); /* the same betas: the regressor shared where it can be */
    cfg[3].neurons[2].beta = (rhonn_real)0.5;
    cfg[3].neurons[4].beta = (rhonn_real)2.0;
    CHECK(compare(cfg, MAXN, NULL, 1) == 0); /* betas differ: each member its own regressor */
}

static void factored_covariances_equal_single_runs(void)
{
    rhonn_config cfg[MAXN];
    size_t m;
    for (m = 0; m < 3; ++m) {
        cfg[m] = lim_config((unsigned)m, 1, 1);
    }
    CHECK(compare(cfg, 3, NULL, 1) == 0);
}

static void members_continue_from_their_own_state(void)
{
    rhonn_config cfg[MAXN];
    const size_t pre[4] = {0, 3, 7, 1};
    size_t m;
    for (m = 0; m < 4; ++m) {
        cfg[m] = lim_config((unsigned)m, 1, 0);
    }
    CHECK(compare(cfg, 4, pre, 1) == 0);
}

/* Members stepped apart before the call hold different inputs in their
 * history rings: a tap on u(k-2) is not shared (nor is a hold's regressor
 * formed from another member's) before two samples of the call are in. */
static void an_input_tap_reads_each_member_s_own_history_at_first(void)
{
    rhonn_config cfg[MAXN];
    const size_t pre[4] = {1, 3, 2, 5};
    size_t m;
    for (m = 0; m < 4; ++m) {
        cfg[m] = lim_config((unsigned)m, 0, 0);
        cfg[m].neurons[4].terms[4] = term1(RHONN_FACTOR_U, 0, 2);
    }
    CHECK(compare(cfg, 4, pre, 0) == 0);
    CHECK(compare(cfg, 4, pre, 1) == 0);
}

static void forgetting_ceiling_and_resets_equal_single_runs(void)
{
    rhonn_config cfg[MAXN];
    size_t m, i;
    int ud;
    /* members with and without each, then (the kernels skip the work for a
     * neuron where no member has it) with neither, in both covariance forms */
    for (ud = 0; ud < 2; ++ud) {
        for (m = 0; m < 6; ++m) {
            cfg[m] = lim_config((unsigned)m, 0, ud);
            for (i = 0; i < 6; ++i) {
                cfg[m].neurons[i].forgetting = m % 2u ? (rhonn_real)0.98 : (rhonn_real)0.0;
                cfg[m].neurons[i].p_trace_max =
                    m >= 2u ? (rhonn_real)(11.0 * 7.0 * (1.0 + 0.25 * (double)m)) : (rhonn_real)0.0;
            }
        }
        CHECK(compare(cfg, 6, NULL, 1) == 0);
        for (m = 0; m < 6; ++m) {
            for (i = 0; i < 6; ++i) {
                cfg[m].neurons[i].forgetting = (rhonn_real)0.0;
                cfg[m].neurons[i].p_trace_max = (rhonn_real)0.0;
            }
        }
        CHECK(compare(cfg, 6, NULL, 1) == 0);
    }
}

/* Forgetting with lambda = 1e-3 multiplies P by 1000 a step up to a trace
 * ceiling near the top of the range (p_trace_max: bounded forgetting lets
 * it get that far): member 1 stops at the first refused update (as alone),
 * member 2 (reset_after = 1) resets P to P(0) and goes on; member 0 is
 * well tuned. */
static void refused_updates_stop_or_reset_a_member_as_alone(void)
{
    rhonn_config cfg[MAXN];
    rhonn_health h;
    size_t m, i, resets = 0;
    for (m = 0; m < 3; ++m) {
        cfg[m] = lim_config(0, 0, 0);
    }
    for (m = 1; m < 3; ++m) {
        for (i = 0; i < 6; ++i) { /* neuron 0 in the U D U^T form too */
            cfg[m].neurons[i].forgetting = (rhonn_real)1e-3;
            cfg[m].neurons[i].p_trace_max = (rhonn_real)(BIG / 8);
            cfg[m].neurons[i].reset_after = (uint16_t)(m == 2u ? 1u : 0u);
        }
    }
    CHECK(compare(cfg, 3, NULL, 0) == 1u);
    for (i = 0; i < 6; ++i) {
        CHECK_STATUS(rhonn_get_health(&alone[2], i, &h), RHONN_OK);
        resets += h.resets;
    }
    CHECK(resets > 0u); /* the scenario does reach the refusals it is about */
}

/* The member whose sample the shared regressor reads (the lowest-indexed
 * running one) stops mid-run: the next takes over, its history ring whole
 * though the run kept only the first member's up to date (delayed taps
 * read it from then on). */
static void a_stopping_first_member_hands_the_shared_regressor_on(void)
{
    rhonn_config cfg[MAXN];
    size_t m, i;
    for (m = 0; m < 4; ++m) {
        cfg[m] = lim_config((unsigned)m, 1, 0);
    }
    for (i = 0; i < 6; ++i) { /* P grows a step until an update is refused, which stops it */
        cfg[0].neurons[i].forgetting = (rhonn_real)0.5;
        cfg[0].neurons[i].p_trace_max = (rhonn_real)(BIG / 8); /* a ceiling too high to stop it */
    }
    CHECK(compare(cfg, 4, NULL, 0) == 1u);
    CHECK(alone[0].steps > 3u && alone[0].steps < POP_T / 2u); /* past the deepest tap (2), long before the end */
}

/* A member whose prediction overflows stops there (E_DIVERGED); the others
 * run to the end. */
static void a_diverging_member_stops_and_the_others_go_on(void)
{
    rhonn_config cfg[MAXN];
    size_t m;
    for (m = 0; m < 3; ++m) {
        cfg[m] = lim_config((unsigned)m, 0, 0);
    }
    /* weights near the top of the range: the first prediction overflows */
    for (m = 0; m < 5; ++m) {
        cfg[1].neurons[3].w0[m] = (rhonn_real)0.9 * BIG;
    }
    CHECK(compare(cfg, 3, NULL, 0) >= 1u);
    CHECK(rhonn_run(&alone[0], 1, X, U, NULL, Xhat_alone[0], NULL) == RHONN_OK);
}


static void arguments_and_structures_are_checked(void)
{
    rhonn_config a = lim_config(0, 0, 0), b = lim_config(1, 0, 0);
    rhonn_t *nets[MAXN + 1];
    rhonn_population_error where;
    rhonn_status st[2];
    size_t done[2], m;
    trajectory(X, U, V, 4, 0);
    CHECK_STATUS(rhonn_init(&members[0], &a, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_init(&members[1], &b, NULL), RHONN_OK);
    nets[0] = &members[0];
    nets[1] = &members[1];
    CHECK_STATUS(rhonn_run_population(NULL, 2, &work, 4, X, U, NULL, Xhat_pop, st, done, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_run_population(nets, 2, NULL, 4, X, U, NULL, Xhat_pop, st, done, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_run_population(nets, 2, &work, 4, NULL, U, NULL, Xhat_pop, st, done, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_run_population(nets, 2, &work, 4, X, NULL, NULL, Xhat_pop, st, done, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_run_population(nets, 0, &work, 4, X, U, NULL, Xhat_pop, st, done, NULL), RHONN_E_ARGUMENT);
    for (m = 0; m <= MAXN; ++m) {
        nets[m] = &members[m % 2u];
    }
    CHECK_STATUS(rhonn_run_population(nets, MAXN + 1u, &work, 4, X, U, NULL, Xhat_pop, st, done, NULL),
                 RHONN_E_ARGUMENT);
    nets[1] = &members[0]; /* one rhonn_t twice */
    CHECK_STATUS(rhonn_run_population(nets, 2, &work, 4, X, U, NULL, Xhat_pop, st, done, NULL), RHONN_E_ARGUMENT);
    nets[1] = &members[1];
    memset(&members[2], 0, sizeof members[2]);
    nets[2] = &members[2];
    CHECK_STATUS(rhonn_run_population(nets, 3, &work, 4, X, U, NULL, Xhat_pop, st, done, NULL), RHONN_E_NOT_INIT);
    /* a term that differs: refused, naming the member, neuron and term */
    b.neurons[4].terms[2] = term1(RHONN_FACTOR_X, 3, 0);
    CHECK_STATUS(rhonn_init(&members[1], &b, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_run_population(nets, 2, &work, 4, X, U, NULL, Xhat_pop, st, done, &where), RHONN_E_CONFIG);
    CHECK(where.member == 1u && where.field == (uint8_t)RHONN_FIELD_FACTOR_KIND && where.neuron == 4u &&
          where.term == 2u && where.factor == 0u);
    b = lim_config(1, 0, 0);
    b.neurons[0].covariance = RHONN_COV_FULL;
    CHECK_STATUS(rhonn_init(&members[1], &b, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_run_population(nets, 2, &work, 4, X, U, NULL, Xhat_pop, st, done, &where), RHONN_E_CONFIG);
    CHECK(where.member == 1u && where.field == (uint8_t)RHONN_FIELD_COVARIANCE && where.neuron == 0u);
    /* nothing ran: the members are as initialised */
    CHECK(members[0].steps == 0u && members[1].steps == 0u);
    /* a non-finite input stops every member at that sample */
    b = lim_config(1, 0, 0);
    CHECK_STATUS(rhonn_init(&members[1], &b, NULL), RHONN_OK);
    U[2 * 2 + 1] = (rhonn_real)NAN;
    CHECK_STATUS(rhonn_run_population(nets, 2, &work, 4, X, U, NULL, Xhat_pop, st, done, NULL),
                 RHONN_E_INPUT_NONFINITE);
    CHECK(st[0] == RHONN_E_INPUT_NONFINITE && st[1] == RHONN_E_INPUT_NONFINITE && done[0] == 2u && done[1] == 2u);
    CHECK(members[0].steps == 2u && members[1].steps == 2u);
}

/* ------------------------------------------------------------------------ */
/* rhonn_run_wide: one identifier's neurons in the lanes, as rhonn_run. */

/* An identifier of n states (2..8) and 2 inputs whose neurons share their
 * size (8 terms, 6 for n = 2): neuron i reads the S(x_j) from its own state
 * round, S(x_i) S(x_i+1), an input and the x_j, so every lane's regressor
 * differs; variant k tunes it apart. delayed puts taps x0(k-2) and u1(k-1)
 * into neurons 0 and 1; ud makes every neuron U D U^T. */
static rhonn_config uniform_config(unsigned k, size_t n, int delayed, int ud)
{
    static const uint8_t S = RHONN_FACTOR_S, Xk = RHONN_FACTOR_X, Uk = RHONN_FACTOR_U;
    rhonn_config c;
    const rhonn_real f = (rhonn_real)(1.0 + 0.25 * (double)k);
    const size_t L = n == 2u ? 6u : 8u;
    size_t i, j, t;
    memset(&c, 0, sizeof c);
    c.n_states = (uint8_t)n;
    c.n_inputs = 2;
    for (i = 0; i < n; ++i) {
        rhonn_neuron_config *nc = &c.neurons[i];
        size_t pi = 0, e;
        t = 0;
        for (j = 0; j < n && j < 6u; ++j) {
            nc->terms[t++] = term1(S, (uint8_t)((i + j) % n), 0);
        }
        nc->terms[t++] = term2(S, (uint8_t)i, (uint8_t)((i + 1u) % n), 1);
        nc->terms[t++] = term1(Uk, (uint8_t)(i % 2u), 0);
        for (j = 0; t < L; ++j) {
            nc->terms[t++] = term1(Xk, (uint8_t)((i + j) % n), 0);
        }
        nc->n_terms = (uint8_t)L;
        nc->activation = RHONN_LOGISTIC;
        nc->beta = (rhonn_real)1.0;
        nc->eta = (rhonn_real)(1.0 / (1.0 + 0.1 * (double)(k + i)));
        nc->r = (rhonn_real)(0.05 * (double)f * (1.0 + 0.1 * (double)i));
        nc->covariance = (uint8_t)(ud ? RHONN_COV_UD : RHONN_COV_FULL);
        for (t = 0; t < L; ++t) {
            nc->q[t] = (rhonn_real)(1e-3 * (double)f * (double)f);
            nc->w0[t] = (rhonn_real)(0.01 * (double)(t + 1u + i));
            for (e = t; e < L; ++e, ++pi) {
                nc->p0[pi] = e == t ? (rhonn_real)(10.0 * (double)f) : (rhonn_real)0.0;
            }
        }
    }
    if (delayed) {
        c.neurons[0].terms[L - 1u] = term1(Xk, 0, 2);
        c.neurons[1].terms[L - 1u] = term1(Uk, 1, 1);
    }
    c.x0[1] = (rhonn_real)(0.1 * (double)k);
    return c;
}

/* A trajectory for n states (the first 6 as trajectory(), the others their
 * own waves), with dropouts as there. */
static void wide_trajectory(rhonn_real *x, rhonn_real *u, uint8_t *v, size_t n, size_t T, int dropouts)
{
    size_t k, j;
    trajectory(X, U, V, T, dropouts);
    for (k = 0; k < T; ++k) {
        u[2 * k] = U[2 * k];
        u[2 * k + 1] = U[2 * k + 1];
        for (j = 0; j < n; ++j) {
            const double t = 0.01 * (double)(held(k) ? 150u : k);
            x[n * k + j] = j < 6u ? X[6 * k + j] : (rhonn_real)(0.4 * sin((0.5 + 0.2 * (double)j) * t));
            v[n * k + j] = j < 6u ? V[6 * k + j] : 1u;
        }
    }
}

static rhonn_real WX[POP_T * 8], WU[POP_T * 2], Wout_alone[POP_T * 8], Wout_wide[POP_T * 8];
static uint8_t WV[POP_T * 8];

static rhonn_t stepped;
static rhonn_population_work lend;
static rhonn_real Wout_stepped[POP_T * 8];

/* T samples stepped in the lanes one by one (rhonn_wide_step) from the
 * state start, into stepped: the loan given back and taken again halfway,
 * stopping where rhonn_run stops; *done the steps that ran. Returns the
 * status (RHONN_E_CONFIG: the lanes cannot hold it). */
static rhonn_status wide_steps(const rhonn_t *start, size_t T, const uint8_t *v, size_t *done)
{
    const size_t n = start->cfg.n_states;
    rhonn_status st;
    size_t k;
    stepped = *start;
    *done = 0;
    st = rhonn_wide_begin(&stepped, &lend);
    if (st != RHONN_OK) {
        return st;
    }
    for (k = 0; k < T; ++k) {
        if (k == T / 2u) { /* nothing changes */
            CHECK_STATUS(rhonn_wide_end(&stepped, &lend), RHONN_OK);
            CHECK_STATUS(rhonn_wide_begin(&stepped, &lend), RHONN_OK);
        }
        st = rhonn_wide_step(&stepped, &lend, WX + k * n, WU + 2u * k, v != NULL ? v + k * n : NULL,
                             Wout_stepped + k * n);
        if (st != RHONN_OK) {
            break;
        }
        *done = k + 1u;
    }
    CHECK_STATUS(rhonn_wide_end(&stepped, &lend), RHONN_OK);
    return st;
}

/* cfg run by rhonn_run, by rhonn_run_wide and stepped in the lanes
 * (wide_steps), from pre samples in: the same status, steps, predictions
 * and state. Returns the status. */
static rhonn_status wide_compare(const rhonn_config *cfg, size_t pre, int dropouts)
{
    const size_t n = cfg->n_states;
    rhonn_status sa, sw, ss;
    size_t da = 99, dw = 77, ds = 55, k;
    wide_trajectory(WX, WU, WV, n, POP_T, dropouts);
    CHECK_STATUS(rhonn_init(&alone[0], cfg, NULL), RHONN_OK);
    for (k = 0; k < pre; ++k) {
        CHECK_STATUS(rhonn_step(&alone[0], WX + n * (POP_T - 1u - k), WU + 2u * (POP_T - 1u - k), NULL, NULL),
                     RHONN_OK);
    }
    members[0] = alone[0];
    memset(Wout_alone, 0, sizeof Wout_alone);
    memset(Wout_wide, 0, sizeof Wout_wide);
    memset(Wout_stepped, 0, sizeof Wout_stepped);
    ss = wide_steps(&alone[0], POP_T, dropouts ? WV : NULL, &ds);
    sa = rhonn_run(&alone[0], POP_T, WX, WU, dropouts ? WV : NULL, Wout_alone, &da);
    sw = rhonn_run_wide(&members[0], &work, POP_T, WX, WU, dropouts ? WV : NULL, Wout_wide, &dw);
    CHECK(sa == sw);
    CHECK(da == dw);
    CHECK(memcmp(Wout_alone, Wout_wide, sizeof Wout_alone) == 0);
    CHECK(same_proofs(&members[0], &alone[0]));
    if (ss != RHONN_E_CONFIG) { /* the lanes can hold it: stepped there as run */
        CHECK(ss == sa);
        CHECK(ds == da);
        CHECK(memcmp(Wout_alone, Wout_stepped, sizeof Wout_alone) == 0);
        CHECK(same_proofs(&stepped, &alone[0]));
        alone[1] = alone[0]; /* same_state steps both on */
        CHECK(same_state(&stepped, &alone[1], WX, WU));
    }
    CHECK(same_state(&members[0], &alone[0], WX, WU));
    return sa;
}

/* Did the last rhonn_run_wide run cfg in the lanes (each neuron's R in
 * its lane of the workspace, which a scalar run leaves alone)? */
static int ran_in_lanes(const rhonn_config *cfg)
{
    size_t i;
    int lanes = 1;
    for (i = 0; i < cfg->n_states; ++i) {
        lanes &= memcmp(&work.r[0][i], &cfg->neurons[i].r, sizeof work.r[0][i]) == 0;
    }
    return lanes;
}

static void wide_runs_equal_single_runs_full_and_factored(void)
{
    rhonn_config cfg;
    size_t n;
    int ud;
    for (ud = 0; ud < 2; ++ud) {
        for (n = 2; n <= MAXN && n <= (size_t)RHONN_MAX_STATES; n += 2u) {
            cfg = uniform_config((unsigned)n, n, 0, ud);
            memset(&work, 0, sizeof work);
            CHECK_STATUS(wide_compare(&cfg, 0, 0), RHONN_OK);
            /* the lanes ran it (the U D U^T form needs the vector build) */
            CHECK(ran_in_lanes(&cfg) == (!ud || RHONN_WIDE_UD));
            cfg = uniform_config((unsigned)n + 1u, n, 1, ud); /* delayed taps, dropouts */
            CHECK_STATUS(wide_compare(&cfg, 0, 1), RHONN_OK);
            CHECK_STATUS(wide_compare(&cfg, 5, 1), RHONN_OK); /* from a running state */
        }
    }
}

static void wide_runs_forget_bound_and_reset_neuron_by_neuron(void)
{
    rhonn_config cfg;
    rhonn_health h;
    size_t i, resets = 0;
    int ud;
    for (ud = 0; ud < 2; ++ud) {
        /* neurons apart: some forget, some have the ceiling, some both */
        cfg = uniform_config(2, 6, 1, ud);
        for (i = 0; i < 6; ++i) {
            cfg.neurons[i].forgetting = i % 2u ? (rhonn_real)0.98 : (rhonn_real)0.0;
            /* above trace P(0) = 8 x 10 x 1.5 */
            cfg.neurons[i].p_trace_max = i >= 2u ? (rhonn_real)(130.0 * (1.0 + 0.1 * (double)i)) : (rhonn_real)0.0;
        }
        CHECK_STATUS(wide_compare(&cfg, 0, 1), RHONN_OK);
        /* forgetting 0.1 up to a ceiling near the top of the range takes
         * the full form's P out of definiteness: neuron 2 resets
         * (reset_after 1) and goes on, then neuron 4 (reset_after 0) stops
         * the run; the U D U^T form keeps going */
        cfg = uniform_config(0, 6, 0, ud);
        for (i = 0; i < 6; ++i) {
            cfg.neurons[i].forgetting = (i == 2u || i == 4u) ? (rhonn_real)0.1 : (rhonn_real)0.0;
            cfg.neurons[i].p_trace_max = (i == 2u || i == 4u) ? (rhonn_real)(BIG / 8) : (rhonn_real)0.0;
            cfg.neurons[i].reset_after = (uint16_t)(i == 2u ? 1u : 0u);
        }
        if (ud) {
            CHECK_STATUS(wide_compare(&cfg, 0, 0), RHONN_OK);
        } else {
            CHECK(wide_compare(&cfg, 0, 0) != RHONN_OK);
            CHECK(alone[0].fault_neuron == 4u && members[0].fault_neuron == 4u);
        }
        CHECK_STATUS(rhonn_get_health(&alone[0], 2, &h), RHONN_OK);
        resets += h.resets;
        cfg.neurons[4].forgetting = (rhonn_real)0.0; /* then only the resets */
        CHECK_STATUS(wide_compare(&cfg, 0, 1), RHONN_OK);
        CHECK_STATUS(rhonn_get_health(&alone[0], 2, &h), RHONN_OK);
        resets += h.resets;
    }
    CHECK(resets > 0u); /* the scenario does reach the recovery it is about */
}

static void wide_run_stops_where_a_single_run_stops(void)
{
    rhonn_config cfg = uniform_config(1, 6, 0, 0);
    size_t t;
    /* neuron 3's prediction overflows at once */
    for (t = 0; t < 5; ++t) {
        cfg.neurons[3].w0[t] = (rhonn_real)0.9 * BIG;
    }
    CHECK_STATUS(wide_compare(&cfg, 0, 0), RHONN_E_DIVERGED);
    CHECK(members[0].fault_neuron == 3u);
    /* a non-finite input at sample 7: 7 steps run, the state after them */
    cfg = uniform_config(1, 6, 0, 0);
    CHECK_STATUS(rhonn_init(&alone[0], &cfg, NULL), RHONN_OK);
    members[0] = alone[0];
    wide_trajectory(WX, WU, WV, 6, POP_T, 0);
    WU[2 * 7] = (rhonn_real)NAN;
    {
        size_t da = 0, dw = 0;
        CHECK_STATUS(rhonn_run(&alone[0], POP_T, WX, WU, NULL, Wout_alone, &da), RHONN_E_INPUT_NONFINITE);
        CHECK_STATUS(rhonn_run_wide(&members[0], &work, POP_T, WX, WU, NULL, Wout_wide, &dw),
                     RHONN_E_INPUT_NONFINITE);
        CHECK(da == 7u && dw == 7u);
        WU[2 * 7] = (rhonn_real)0.0;
        CHECK(same_state(&members[0], &alone[0], WX, WU));
    }
}

static void wide_run_of_other_structures_is_the_scalar_run(void)
{
    /* sizes that differ (the firmware's LIM), and a U D U^T neuron among full ones */
    rhonn_config cfg = lim_config(3, 1, 0);
    size_t i;
    memset(&work, 0, sizeof work);
    CHECK_STATUS(wide_compare(&cfg, 0, 1), RHONN_OK);
    CHECK(!ran_in_lanes(&cfg));
    cfg = uniform_config(3, 6, 1, 0);
    cfg.neurons[5].covariance = RHONN_COV_UD;
    CHECK_STATUS(wide_compare(&cfg, 2, 1), RHONN_OK);
    for (i = 0; i < 6; ++i) {
        cfg.neurons[i].covariance = RHONN_COV_FULL;
    }
    CHECK_STATUS(wide_compare(&cfg, 2, 1), RHONN_OK);
}

/* The lanes are advised where the structure fits and the neurons fill the
 * vector unit enough (this build's: no target clones, 128-bit vectors). */
static void wide_runs_are_advised_where_they_pay(void)
{
    rhonn_config cfg = uniform_config(0, 8, 0, 0);
    CHECK(rhonn_wide_pays(NULL) == 0);
    memset(&members[1], 0, sizeof members[1]);
    CHECK(rhonn_wide_pays(&members[1]) == 0); /* not set up */
    CHECK_STATUS(rhonn_init(&members[0], &cfg, NULL), RHONN_OK);
    CHECK(rhonn_wide_pays(&members[0]) == 1); /* 8 neurons fill 8 lanes */
    cfg = uniform_config(0, 2, 0, 0);
    CHECK_STATUS(rhonn_init(&members[0], &cfg, NULL), RHONN_OK);
    CHECK(rhonn_wide_pays(&members[0]) == 0); /* 2 of 8 lanes: the scalar run is faster */
    cfg = lim_config(0, 0, 0);
    CHECK_STATUS(rhonn_init(&members[0], &cfg, NULL), RHONN_OK);
    CHECK(rhonn_wide_pays(&members[0]) == 0); /* sizes differ: no lanes at all */
}

/* A loan's calls are checked, a refused one changes nothing, and a lent
 * net is refused by everything else until it is given back. */
static void wide_loans_are_checked_and_guarded(void)
{
    rhonn_config cfg = uniform_config(0, 6, 0, 0);
    rhonn_real w[8], y[8];
    rhonn_t before;
    wide_trajectory(WX, WU, WV, 6, 8, 0);
    CHECK_STATUS(rhonn_init(&members[0], &cfg, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_wide_begin(NULL, &lend), RHONN_E_NULL);
    CHECK_STATUS(rhonn_wide_begin(&members[0], NULL), RHONN_E_NULL);
    memset(&members[1], 0, sizeof members[1]);
    CHECK_STATUS(rhonn_wide_begin(&members[1], &lend), RHONN_E_NOT_INIT);
    cfg = lim_config(0, 0, 0); /* sizes differ: the lanes cannot hold it */
    CHECK_STATUS(rhonn_init(&members[1], &cfg, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_wide_begin(&members[1], &lend), RHONN_E_CONFIG);
    CHECK_STATUS(rhonn_step(&members[1], WX, WU, NULL, y), RHONN_OK); /* and it is still its own */
    /* not lent: stepping or ending is refused */
    CHECK_STATUS(rhonn_wide_step(&members[0], &lend, WX, WU, NULL, y), RHONN_E_NOT_INIT);
    CHECK_STATUS(rhonn_wide_end(&members[0], &lend), RHONN_E_NOT_INIT);

    CHECK_STATUS(rhonn_wide_begin(&members[0], &lend), RHONN_OK);
    CHECK_STATUS(rhonn_wide_step(&members[0], &lend, WX, WU, NULL, y), RHONN_OK);
    /* lent: everything else refuses it, a second loan too */
    CHECK_STATUS(rhonn_wide_begin(&members[0], &work), RHONN_E_NOT_INIT);
    CHECK_STATUS(rhonn_step(&members[0], WX, WU, NULL, y), RHONN_E_NOT_INIT);
    CHECK_STATUS(rhonn_get_weights(&members[0], 0, w, 8), RHONN_E_NOT_INIT);
    CHECK_STATUS(rhonn_reset(&members[0]), RHONN_E_NOT_INIT);
    CHECK_STATUS(rhonn_run_wide(&members[0], &work, 2, WX, WU, NULL, Wout_wide, NULL), RHONN_E_NOT_INIT);
    CHECK(rhonn_wide_pays(&members[0]) == 0);
    /* the wrong workspace, NULL arguments: refused, nothing changed */
    memcpy(&before, &members[0], sizeof before);
    CHECK_STATUS(rhonn_wide_step(&members[0], &work, WX, WU, NULL, y), RHONN_E_ARGUMENT);
    CHECK_STATUS(rhonn_wide_end(&members[0], &work), RHONN_E_ARGUMENT);
    CHECK_STATUS(rhonn_wide_step(NULL, &lend, WX, WU, NULL, y), RHONN_E_NULL);
    CHECK_STATUS(rhonn_wide_step(&members[0], NULL, WX, WU, NULL, y), RHONN_E_NULL);
    CHECK_STATUS(rhonn_wide_step(&members[0], &lend, NULL, WU, NULL, y), RHONN_E_NULL);
    CHECK_STATUS(rhonn_wide_step(&members[0], &lend, WX, NULL, NULL, y), RHONN_E_NULL);
    CHECK_STATUS(rhonn_wide_step(&members[0], &lend, WX, WU, NULL, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_wide_end(NULL, &lend), RHONN_E_NULL);
    CHECK_STATUS(rhonn_wide_end(&members[0], NULL), RHONN_E_NULL);
    CHECK(memcmp(&before, &members[0], sizeof before) == 0);
    CHECK(lend.holder == &members[0]);
    /* given back: its own again, and stepping on where the lanes left it */
    CHECK_STATUS(rhonn_wide_end(&members[0], &lend), RHONN_OK);
    CHECK_STATUS(rhonn_get_weights(&members[0], 0, w, 8), RHONN_OK);
    CHECK_STATUS(rhonn_step(&members[0], WX + 6, WU + 2, NULL, y), RHONN_OK);
    CHECK(members[0].steps == 2u);

    /* a run on the lending workspace forgets the loan: the lent net stays
     * refused (its learning state is gone) until rhonn_init */
    CHECK_STATUS(rhonn_wide_begin(&members[0], &lend), RHONN_OK);
    cfg = uniform_config(1, 6, 0, 0);
    CHECK_STATUS(rhonn_init(&members[2], &cfg, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_run_wide(&members[2], &lend, 4, WX, WU, NULL, Wout_wide, NULL), RHONN_OK);
    CHECK(lend.holder == NULL);
    CHECK_STATUS(rhonn_wide_end(&members[0], &lend), RHONN_E_ARGUMENT);
    CHECK_STATUS(rhonn_step(&members[0], WX, WU, NULL, y), RHONN_E_NOT_INIT);
    cfg = uniform_config(0, 6, 0, 0);
    CHECK_STATUS(rhonn_init(&members[0], &cfg, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_step(&members[0], WX, WU, NULL, y), RHONN_OK);
}

/* Steps in the lanes go on after a refused step as rhonn_step does: an
 * input that is not finite; a neuron whose forgetting takes P out of
 * definiteness, refused at step after step while the others learn on. */
static void wide_steps_go_on_after_a_refusal_as_single_steps(void)
{
    rhonn_config cfg;
    rhonn_real ya[8], yb[8];
    size_t k, i, refused = 0, on_after = 0;
    int scenario;
    for (scenario = 0; scenario < 2; ++scenario) {
        cfg = uniform_config(scenario ? 0u : 2u, 6, !scenario, 0);
        for (i = 0; scenario && i < 6; ++i) {
            cfg.neurons[i].forgetting = (i == 2u || i == 4u) ? (rhonn_real)0.1 : (rhonn_real)0.0;
            cfg.neurons[i].p_trace_max = (i == 2u || i == 4u) ? (rhonn_real)(BIG / 8) : (rhonn_real)0.0;
            cfg.neurons[i].reset_after = (uint16_t)(i == 2u ? 1u : 0u);
        }
        wide_trajectory(WX, WU, WV, 6, 60, !scenario);
        if (!scenario) {
            WX[6 * 11 + 2] = (rhonn_real)NAN;
            WV[6 * 11 + 2] = 1u;
        }
        CHECK_STATUS(rhonn_init(&alone[0], &cfg, NULL), RHONN_OK);
        stepped = alone[0];
        CHECK_STATUS(rhonn_wide_begin(&stepped, &lend), RHONN_OK);
        for (k = 0; k < 60; ++k) {
            const uint8_t *v = scenario ? NULL : WV + 6 * k;
            const rhonn_status sa = rhonn_step(&alone[0], WX + 6 * k, WU + 2 * k, v, ya);
            const rhonn_status sb = rhonn_wide_step(&stepped, &lend, WX + 6 * k, WU + 2 * k, v, yb);
            CHECK(sa == sb);
            CHECK(sa != RHONN_OK || memcmp(ya, yb, sizeof ya[0] * 6) == 0);
            on_after += sa == RHONN_OK && refused > 0u;
            refused += sa != RHONN_OK;
        }
        CHECK_STATUS(rhonn_wide_end(&stepped, &lend), RHONN_OK);
        CHECK(stepped.fault_neuron == alone[0].fault_neuron);
        WX[6 * 11 + 2] = (rhonn_real)0.0;
        CHECK(same_proofs(&stepped, &alone[0]));
        CHECK(same_state(&stepped, &alone[0], WX, WU));
    }
    CHECK(refused > 1u && on_after > 0u); /* refusals, with steps going on after them */
}

static void wide_run_arguments_are_checked(void)
{
    rhonn_config cfg = uniform_config(0, 6, 0, 0);
    size_t done = 5;
    wide_trajectory(WX, WU, WV, 6, 4, 0);
    CHECK_STATUS(rhonn_init(&members[0], &cfg, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_run_wide(&members[0], NULL, 4, WX, WU, NULL, Wout_wide, &done), RHONN_E_NULL);
    CHECK(done == 0u);
    CHECK_STATUS(rhonn_run_wide(NULL, &work, 4, WX, WU, NULL, Wout_wide, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_run_wide(&members[0], &work, 4, NULL, WU, NULL, Wout_wide, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_run_wide(&members[0], &work, 4, WX, NULL, NULL, Wout_wide, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_run_wide(&members[0], &work, 4, WX, WU, NULL, NULL, NULL), RHONN_E_NULL);
    CHECK_STATUS(rhonn_run_wide(&members[0], &work, 0, NULL, NULL, NULL, NULL, &done), RHONN_OK);
    CHECK(done == 0u && members[0].steps == 0u);
    memset(&members[1], 0, sizeof members[1]);
    CHECK_STATUS(rhonn_run_wide(&members[1], &work, 4, WX, WU, NULL, Wout_wide, NULL), RHONN_E_NOT_INIT);
}

/* The lanes' proof of definiteness (every lane at once) gives each lane
 * rhonn_proof_holds' verdict: on random inputs, with qmin put within a few
 * ulps either side of where the final inequality turns, and with the
 * non-finite, zero and subnormal inputs each early exit is about. */
static rhonn_real lcg_unit(unsigned long *state)
{
    *state = *state * 6364136223846793005ul + 1442695040888963407ul;
    return (rhonn_real)((double)(*state >> 11) / 9007199254740992.0);
}

static void lanes_prove_as_the_scalar_proof(void)
{
    static const rhonn_real specials[] = {(rhonn_real)0.0, (rhonn_real)-0.0, (rhonn_real)NAN, (rhonn_real)INFINITY,
                                          (rhonn_real)-1.0, BIG, (rhonn_real)1e-40};
    const size_t nspec = sizeof specials / sizeof specials[0];
    rhonn_real in[8 * MAXN];
    uint8_t out[MAXN];
    unsigned long state = 12345u;
    size_t round, m, agree = 0, held = 0, total = 0;
    for (round = 0; round < 4000u; ++round) {
        const size_t L = 1u + round % 16u;
        for (m = 0; m < MAXN; ++m) {
            const rhonn_real unit = RHONN_EPSILON * (rhonn_real)0.5;
            const rhonn_real gl = (rhonn_real)1.01 * (rhonn_real)L * unit;
            const rhonn_real g1 = (rhonn_real)1.01 * (rhonn_real)(L + 1u) * unit;
            rhonn_real tr = (rhonn_real)pow(10.0, 6.0 * (double)lcg_unit(&state) - 2.0);
            rhonn_real pzz = tr * lcg_unit(&state), vv = tr * tr * lcg_unit(&state);
            rhonn_real zv = tr * lcg_unit(&state), pmax = tr * lcg_unit(&state);
            rhonn_real r_i = (rhonn_real)pow(10.0, 4.0 * (double)lcg_unit(&state) - 3.0);
            rhonn_real inv_s = (rhonn_real)1.0 / (r_i + pzz);
            /* the qmin at which the last inequality turns, nudged by a few ulps */
            const rhonn_real ww = (rhonn_real)L * pzz, r_low = r_i - gl * ww, rho = g1 * (r_i + zv) * inv_s;
            const rhonn_real vs = vv * inv_s, eta_r = (rhonn_real)2.0 * (gl * gl) * (tr * ww);
            const rhonn_real err = ((rhonn_real)3.0 * rho + (rhonn_real)8.0 * unit) * vs +
                                   (rhonn_real)2.0 * unit * (tr + pmax);
            rhonn_real qmin = (rhonn_real)1.125 * eta_r / r_low +
                              (rhonn_real)1.125 * (err + (rhonn_real)1.01 * (rhonn_real)L * g1 * pmax);
            qmin *= (rhonn_real)1.0 + (rhonn_real)((int)(round % 7u) - 3) * RHONN_EPSILON;
            if (round % 5u == 4u) { /* one input special */
                const rhonn_real sp = specials[(size_t)(lcg_unit(&state) * (rhonn_real)nspec) % nspec];
                switch ((size_t)(lcg_unit(&state) * (rhonn_real)8.0) % 8u) {
                case 0: tr = sp; break;
                case 1: pzz = sp; break;
                case 2: vv = sp; break;
                case 3: zv = sp; break;
                case 4: pmax = sp; break;
                case 5: qmin = sp; break;
                case 6: r_i = sp; break;
                default: inv_s = sp; break;
                }
            }
            in[0 * MAXN + m] = tr;
            in[1 * MAXN + m] = pzz;
            in[2 * MAXN + m] = vv;
            in[3 * MAXN + m] = zv;
            in[4 * MAXN + m] = pmax;
            in[5 * MAXN + m] = qmin;
            in[6 * MAXN + m] = r_i;
            in[7 * MAXN + m] = inv_s;
        }
        rhonn_internal_proof_lanes(in, L, out);
        for (m = 0; m < MAXN; ++m) {
            const int scalar = rhonn_proof_holds(in[m], in[MAXN + m], in[2 * MAXN + m], in[3 * MAXN + m],
                                                 in[4 * MAXN + m], in[5 * MAXN + m], in[6 * MAXN + m],
                                                 in[7 * MAXN + m], L);
            agree += (size_t)(out[m] == (uint8_t)scalar);
            held += (size_t)scalar;
            ++total;
        }
    }
    CHECK(agree == total);
    CHECK(held > total / 5u && held < total - total / 5u); /* both verdicts well represented */
}

/* Bounded forgetting (rhonn.h WINDUP PROTECTION) through a quiet stretch,
 * where the ceiling switches it off and on, lane by lane: the population,
 * the wide run and the steps in the lanes are single runs, bit for bit, in
 * both forms; and the ceiling did bind (lifted, the runs differ). */
static void bounded_forgetting_at_its_ceiling_equals_single_runs(void)
{
    rhonn_config cfg[MAXN], one;
    size_t m, i, k;
    int ud, differ = 0;
    hold_quiet = 1;
    for (ud = 0; ud < 2; ++ud) {
        for (m = 0; m < 6; ++m) {
            cfg[m] = lim_config((unsigned)m, 1, ud);
            for (i = 0; i < 6; ++i) {
                cfg[m].neurons[i].forgetting = m % 3u == 0u ? (rhonn_real)0.0 : m % 3u == 1u ? (rhonn_real)0.9
                                                                                            : (rhonn_real)0.99;
                cfg[m].neurons[i].q[0] = (rhonn_real)0.0;
                cfg[m].neurons[i].p_trace_max = m >= 4u ? (rhonn_real)(1.5 * 10.0 * (1.0 + 0.25 * (double)m) * 7.0)
                                                        : (rhonn_real)0.0;
            }
        }
        CHECK(compare(cfg, 6, NULL, 1) == 0);
        /* the ceiling lifted, member 1 runs otherwise (its quiet stretch
         * is refused for good, or at least its predictions differ) */
        one = cfg[1];
        for (i = 0; i < 6; ++i) {
            one.neurons[i].p_trace_max = (rhonn_real)(BIG / 8);
        }
        CHECK_STATUS(rhonn_init(&alone[1], &one, NULL), RHONN_OK);
        CHECK_STATUS(rhonn_init(&alone[0], &cfg[1], NULL), RHONN_OK);
        CHECK_STATUS(rhonn_run(&alone[0], POP_T, X, U, V, Xhat_alone[0], NULL), RHONN_OK);
        differ += rhonn_run(&alone[1], POP_T, X, U, V, Xhat_alone[1], NULL) != RHONN_OK ||
                  memcmp(Xhat_alone[0], Xhat_alone[1], POP_T * 6u * sizeof(rhonn_real)) != 0;
        /* one identifier's neurons in the lanes */
        one = uniform_config(1, 6, 1, ud);
        for (i = 0; i < 6; ++i) {
            one.neurons[i].forgetting = i % 2u ? (rhonn_real)0.9 : (rhonn_real)0.995;
            for (k = 0; k < one.neurons[i].n_terms; ++k) {
                one.neurons[i].q[k] = i < 3u ? (rhonn_real)0.0 : one.neurons[i].q[k];
            }
        }
        CHECK_STATUS(wide_compare(&one, 0, 1), RHONN_OK);
        CHECK(ran_in_lanes(&one) == (!ud || RHONN_WIDE_UD));
    }
    CHECK(differ == 2);
    hold_quiet = 0;
}

/* Gates set in force after rhonn_init (rhonn_set_gate,
 * rhonn_set_trace_ceiling): member 3 gates neuron 1 and member 4 bounds
 * every trace, though their configurations have neither. */
static void calibrate_members(rhonn_t *net, size_t m)
{
    size_t i;
    if (m == 3u) {
        CHECK_STATUS(rhonn_set_gate(net, 1, (rhonn_real)4.0), RHONN_OK);
    }
    if (m == 4u) {
        for (i = 0; i < 6; ++i) {
            CHECK_STATUS(rhonn_set_trace_ceiling(net, i, (rhonn_real)(10.0 * (1.0 + 0.25 * 4.0) * 8.0)), RHONN_OK);
        }
    }
}

/* rhonn.h INNOVATION GATE in the lanes: a population mixing members without
 * a gate, with one on every neuron, on one neuron, one too high to trip,
 * one set in force by rhonn_set_gate, and gates with refusals skipped and
 * recovered (forgetting that takes P out of definiteness), over dropouts
 * and an outlier; members continuing from their own states. Each member
 * is its own rhonn_run, bit for bit (health counters, refusals and resets
 * included), in both covariance forms; the lanes ran them (loaded with
 * every member's gate in force), and the outlier tripped the gates where
 * they are low enough and nowhere else. */
static void gated_members_in_the_lanes_equal_single_runs(void)
{
    rhonn_config cfg[MAXN];
    rhonn_health h;
    const size_t N = MAXN >= 7 ? 7u : MAXN;
    size_t pre[MAXN];
    size_t m, i;
    uint32_t gated[MAXN], rejected[MAXN];
    int ud;
    add_outlier = 1;
    after_init = calibrate_members;
    for (ud = 0; ud < 2; ++ud) {
        for (m = 0; m < N; ++m) {
            cfg[m] = lim_config((unsigned)m, 1, ud);
            pre[m] = 3u * m;
            for (i = 0; i < 6; ++i) {
                rhonn_neuron_config *nc = &cfg[m].neurons[i];
                nc->gate = m == 1u ? (rhonn_real)9.0        /* every neuron */
                           : m == 2u && i == 1u ? (rhonn_real)9.0 /* the outlier's neuron only */
                           : m == 5u ? (rhonn_real)1e30     /* never trips */
                           : m == 6u ? (rhonn_real)2.0      /* with refusals */
                           : (rhonn_real)0.0;
                if (m == 6u) {
                    nc->forgetting = (rhonn_real)1e-3;
                    nc->p_trace_max = (rhonn_real)(BIG / 8);
                    nc->skip_refused = (uint8_t)(i != 0u);
                    nc->reset_after = (uint16_t)(i % 2u ? 3u : 0u);
                }
            }
        }
        memset(&work, 0, sizeof work);
        (void)compare(cfg, N, pre, 1);
        for (m = 0; m < N; ++m) {
            gated[m] = 0;
            rejected[m] = 0;
            /* the lanes were loaded, with each member's gate in force */
            CHECK(memcmp(&work.r[1][m], &cfg[m].neurons[1].r, sizeof work.r[1][m]) == 0);
            CHECK(work.gate[1][m] == (m == 3u ? (rhonn_real)4.0 : cfg[m].neurons[1].gate));
            for (i = 0; i < 6; ++i) {
                CHECK_STATUS(rhonn_get_health(&members[m], i, &h), RHONN_OK);
                gated[m] += h.gated;
                rejected[m] += h.rejected;
                CHECK(h.gated == 0u || (m == 1u || m == 6u || i == 1u));
            }
        }
        CHECK(gated[0] == 0u && gated[4] == 0u && gated[5] == 0u);
        CHECK(gated[1] > 0u && gated[2] > 0u && gated[3] > 0u && (N < 7u || gated[6] > 0u));
        /* gates and refusals in one member (in the U D U^T form its
         * prediction overflows first, which no neuron can skip) */
        CHECK(N < 7u || ud || rejected[6] > 0u);
    }
    after_init = NULL;
    add_outlier = 0;
}

/* A member with an innovation gate runs in the lanes, bit for bit, and the
 * gate does skip the outlier. One identifier whose neurons have gates (one
 * that trips at the outlier, one with forgetting that refuses updates,
 * skipped and recovered, one too high to trip) runs in its lanes too, as
 * rhonn_run_wide and stepping in the lanes, both forms, bit for bit with
 * rhonn_run, and a gate does not change whether the lanes are advised. */
static void gated_members_and_neurons_run_as_single_runs(void)
{
    rhonn_config cfg[MAXN], one;
    rhonn_health h;
    const size_t n8 = 8 <= RHONN_MAX_STATES ? 8u : 6u;
    size_t m, i, gated = 0;
    int ud;
    add_outlier = 1;
    for (m = 0; m < 4; ++m) {
        cfg[m] = lim_config((unsigned)m, 1, 0);
    }
    cfg[2].neurons[1].gate = (rhonn_real)9.0;
    CHECK(compare(cfg, 4, NULL, 1) == 0);
    for (m = 0; m < 4; ++m) {
        for (i = 0; i < 6; ++i) {
            CHECK_STATUS(rhonn_get_health(&members[m], i, &h), RHONN_OK);
            gated += h.gated;
            CHECK(h.gated == 0u || (m == 2u && i == 1u));
        }
    }
    CHECK(gated > 0u); /* the outlier was gated */
    CHECK(work.holder == NULL);
    /* one identifier */
    one = uniform_config(0, n8, 0, 0);
    one.neurons[3].gate = (rhonn_real)9.0;
    CHECK_STATUS(rhonn_init(&members[0], &one, NULL), RHONN_OK);
    CHECK(rhonn_wide_pays(&members[0]) == (one.n_states == 8u));
    CHECK_STATUS(rhonn_wide_begin(&members[0], &lend), RHONN_OK);
    CHECK_STATUS(rhonn_wide_end(&members[0], &lend), RHONN_OK);
    for (ud = 0; ud < 2; ++ud) {
        uint32_t g[8] = {0, 0, 0, 0, 0, 0, 0, 0}, r[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        one = uniform_config(0, 6, 1, ud);
        one.neurons[1].gate = (rhonn_real)9.0;
        one.neurons[2].gate = (rhonn_real)2.0;
        one.neurons[2].forgetting = (rhonn_real)1e-3;
        one.neurons[2].p_trace_max = (rhonn_real)(BIG / 8);
        one.neurons[2].skip_refused = 1;
        one.neurons[2].reset_after = 2;
        one.neurons[5].gate = (rhonn_real)1e30;
        memset(&work, 0, sizeof work);
        CHECK_STATUS(wide_compare(&one, 0, 1), RHONN_OK);
        CHECK(ran_in_lanes(&one) == (!ud || RHONN_WIDE_UD));
        for (i = 0; i < 6; ++i) {
            CHECK_STATUS(rhonn_get_health(&members[0], i, &h), RHONN_OK);
            g[i] = h.gated;
            r[i] = h.rejected;
        }
        /* the outlier gated in neuron 1; neuron 2, forgetting, is gated
         * step after step in the U D U^T form, its updates refused (and
         * skipped) in the full form, where P grows until nothing trips */
        CHECK(g[1] > 0u && (ud ? g[2] > 0u : r[2] > 0u));
        CHECK(g[0] == 0u && g[3] == 0u && g[4] == 0u && g[5] == 0u);
        CHECK(r[0] == 0u && r[1] == 0u);
    }
    add_outlier = 0;
}

/* rhonn.h REFUSALS, NEURON BY NEURON in the lanes: forgetting with
 * lambda = 1e-3 up to a ceiling near the top of the range takes P out of
 * definiteness, so updates are refused step after step. Member 1 skips
 * every refused neuron and runs to the end, member 2 skips and recovers
 * every third refusal in a row (reset_after 3), member 3 skips only in
 * neurons 1..3 and stops at the first refusal of another, member 0 is well
 * tuned: each is its own rhonn_run, bit for bit, and the lanes ran them
 * (no fall back to single runs). */
static void skipped_refusals_in_the_lanes_equal_single_runs(void)
{
    rhonn_config cfg[MAXN];
    rhonn_health h;
    size_t m, i, rejected[4] = {0, 0, 0, 0}, resets = 0;
    int ud;
    for (ud = 0; ud < 2; ++ud) {
        for (m = 0; m < 4; ++m) {
            cfg[m] = lim_config((unsigned)m, 1, ud);
        }
        for (m = 1; m < 4; ++m) {
            for (i = 0; i < 6; ++i) {
                cfg[m].neurons[i].forgetting = (rhonn_real)1e-3;
                cfg[m].neurons[i].p_trace_max = (rhonn_real)(BIG / 8);
                cfg[m].neurons[i].skip_refused = (uint8_t)(m < 3u || (i >= 1u && i <= 3u));
                cfg[m].neurons[i].reset_after = (uint16_t)(m == 2u ? 3u : 0u);
            }
        }
        memset(&work, 0, sizeof work);
        (void)compare(cfg, 4, NULL, 1);
        for (m = 0; m < 4; ++m) {
            /* the lanes were loaded: the members ran in them */
            CHECK(memcmp(&work.r[1][m], &cfg[m].neurons[1].r, sizeof work.r[1][m]) == 0);
            for (i = 0; i < 6; ++i) {
                CHECK_STATUS(rhonn_get_health(&members[m], i, &h), RHONN_OK);
                rejected[m] += h.rejected;
                resets += m == 2u ? h.resets : 0u;
            }
        }
        /* skipping every refusal, the full form runs to the end (the U D U^T
         * form's prediction may overflow, which no neuron can skip) */
        CHECK(ud || members[1].steps >= POP_T);
    }
    /* the scenario reaches what it is about: refusals skipped, recovered */
    CHECK(rejected[0] == 0u && rejected[1] > 2u && rejected[2] > 2u && resets > 0u);
}

/* The same in one identifier's lanes (rhonn_run_wide, stepping in the
 * lanes): neurons 2 and 4 are refused step after step; neuron 4 skips,
 * neuron 2 skips and recovers every second refusal in a row. */
static void skipped_refusals_in_a_wide_run_equal_a_single_run(void)
{
    rhonn_config cfg;
    rhonn_health h;
    rhonn_real ya[8], yb[8];
    size_t i, k, rejected = 0;
    int ud, same;
    for (ud = 0; ud < 2; ++ud) {
        cfg = uniform_config(0, 6, 1, ud);
        for (i = 0; i < 6; ++i) {
            cfg.neurons[i].forgetting = (i == 2u || i == 4u) ? (rhonn_real)1e-3 : (rhonn_real)0.0;
            cfg.neurons[i].p_trace_max = (i == 2u || i == 4u) ? (rhonn_real)(BIG / 8) : (rhonn_real)0.0;
            cfg.neurons[i].reset_after = (uint16_t)(i == 2u ? 2u : 0u);
            cfg.neurons[i].skip_refused = (uint8_t)(i == 2u || i == 4u);
        }
        memset(&work, 0, sizeof work);
        CHECK_STATUS(wide_compare(&cfg, 0, 1), RHONN_OK);
        CHECK(ran_in_lanes(&cfg) == (!ud || RHONN_WIDE_UD));
        for (i = 0; i < 6; ++i) {
            CHECK_STATUS(rhonn_get_health(&members[0], i, &h), RHONN_OK);
            rejected += h.rejected;
            CHECK(h.rejected == 0u || i == 2u || i == 4u);
        }
        /* step by step in the lanes */
        CHECK_STATUS(rhonn_init(&alone[0], &cfg, NULL), RHONN_OK);
        stepped = alone[0];
        if (!ud || RHONN_WIDE_UD) {
            CHECK_STATUS(rhonn_wide_begin(&stepped, &lend), RHONN_OK);
            for (k = 0, same = 1; k < 60 && same; ++k) {
                const rhonn_status sa = rhonn_step(&alone[0], WX + 6 * k, WU + 2 * k, WV + 6 * k, ya);
                const rhonn_status sb = rhonn_wide_step(&stepped, &lend, WX + 6 * k, WU + 2 * k, WV + 6 * k, yb);
                same = sa == RHONN_OK && sb == RHONN_OK && memcmp(ya, yb, sizeof ya[0] * 6) == 0;
            }
            CHECK(same);
            CHECK_STATUS(rhonn_wide_end(&stepped, &lend), RHONN_OK);
            CHECK(same_proofs(&stepped, &alone[0]));
            CHECK(same_state(&stepped, &alone[0], WX, WU));
        }
    }
    CHECK(rejected > 2u); /* refusals were skipped */
}

static double seconds(void)
{
    return (double)clock() / (double)CLOCKS_PER_SEC;
}

static void bench(size_t T)
{
    static rhonn_real bx[6 * 100000], bu[2 * 100000], by[6 * 100000];
    static uint8_t bv[6 * 100000];
    rhonn_config cfg[MAXN];
    rhonn_t *nets[MAXN];
    size_t m;
    double t0, t1, t2;
    T = T > 100000u / MAXN ? 100000u / MAXN : T;
    trajectory(bx, bu, bv, T, 0);
    for (m = 0; m < MAXN; ++m) {
        cfg[m] = lim_config((unsigned)m, 0, 0);
        (void)rhonn_init(&alone[m], &cfg[m], NULL);
        (void)rhonn_init(&members[m], &cfg[m], NULL);
        nets[m] = &members[m];
    }
    t0 = seconds();
    for (m = 0; m < MAXN; ++m) {
        (void)rhonn_run(&alone[m], T, bx, bu, NULL, by + m * T * 6u, NULL);
    }
    t1 = seconds();
    (void)rhonn_run_population(nets, MAXN, &work, T, bx, bu, NULL, by, NULL, NULL, NULL);
    t2 = seconds();
    if (getenv("RHONN_POP_BENCH_ONLY") != NULL) { /* for a profiler: the population alone, 20 times more */
        for (m = 0; m < 20u; ++m) {
            (void)rhonn_run_population(nets, MAXN, &work, T, bx, bu, NULL, by, NULL, NULL, NULL);
        }
    }
    printf("bench: %u samples, %d members: %.3f s alone, %.3f s population (x%.2f)\n", (unsigned)T, MAXN, t1 - t0,
           t2 - t1, (t1 - t0) / (t2 - t1));
}

int main(void)
{
    const char *b = getenv("RHONN_POP_BENCH");
    RUN(lim_population_equals_eight_runs);
    RUN(dropouts_delays_and_differing_betas_equal_single_runs);
    RUN(factored_covariances_equal_single_runs);
    RUN(members_continue_from_their_own_state);
    RUN(an_input_tap_reads_each_member_s_own_history_at_first);
    RUN(forgetting_ceiling_and_resets_equal_single_runs);
    RUN(refused_updates_stop_or_reset_a_member_as_alone);
    RUN(a_stopping_first_member_hands_the_shared_regressor_on);
    RUN(a_diverging_member_stops_and_the_others_go_on);
    RUN(arguments_and_structures_are_checked);
    RUN(lanes_prove_as_the_scalar_proof);
    RUN(wide_runs_equal_single_runs_full_and_factored);
    RUN(wide_runs_forget_bound_and_reset_neuron_by_neuron);
    RUN(wide_run_stops_where_a_single_run_stops);
    RUN(wide_run_of_other_structures_is_the_scalar_run);
    RUN(wide_runs_are_advised_where_they_pay);
    RUN(wide_run_arguments_are_checked);
    RUN(wide_loans_are_checked_and_guarded);
    RUN(wide_steps_go_on_after_a_refusal_as_single_steps);
    RUN(bounded_forgetting_at_its_ceiling_equals_single_runs);
    RUN(gated_members_and_neurons_run_as_single_runs);
    RUN(gated_members_in_the_lanes_equal_single_runs);
    RUN(skipped_refusals_in_the_lanes_equal_single_runs);
    RUN(skipped_refusals_in_a_wide_run_equal_a_single_run);
    if (b != NULL) {
        bench((size_t)strtoul(b, NULL, 10));
    }
    return CHECK_SUMMARY();
}
