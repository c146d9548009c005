/*
 * core_vs_dense.c - the LIM identifier step through the pyrhonn core, through
 * the textbook dense EKF (dense_ekf.h) and through the generic-library EKF
 * (generic_ekf.h), in one process, on the same samples. Built and driven by
 * bench/bench_core_vs_dense.py, which generates bench_config.h (the
 * identifier, pyrhonn.export) and the data file.
 *
 *     core_vs_dense predict DATA T          the three runs' predictions, raw, to stdout
 *     core_vs_dense time DATA T REPEATS     best ns per step of each (and of the core and
 *                                           the dense EKF with learning off), to stdout
 *     core_vs_dense count-core DATA T       one core run (for callgrind)
 *     core_vs_dense count-dense DATA T      one dense run (for callgrind)
 *     core_vs_dense count-generic DATA T    one generic-library run (for callgrind)
 *     core_vs_dense count-core-frozen DATA T    one core run with learning off
 *     core_vs_dense count-dense-frozen DATA T   one dense run that only predicts
 *
 * A run minus the same run frozen is what learning costs: the EKF updates and
 * their bookkeeping, with the regressor and the prediction taken out.
 *
 * DATA holds, as raw rhonn_real, row-major, for its N >= T rows: X (N x n),
 * U (N x m) and the regressors Z (N x sum of L_i), one block after the other
 * (a run uses the first T rows): row k is z_0(k) .. z_{n-1}(k), the values
 * the core forms at sample k (recorded from pyrhonn's Identifier). The core
 * forms them itself from X and U; the two other EKFs are handed them.
 *
 * The dense and generic runs are the same series-parallel identifier: at
 * sample k >= 1, neuron i learns e = x_i(k) - xhat_i(k) with z_i(k-1); then
 * it predicts xhat_i(k+1) = w_i^T z_i(k). No dropouts (every sample valid).
 */
#define _POSIX_C_SOURCE 199309L
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rhonn.h"
#include "dense_ekf.h"
#include "generic_ekf.h"
#include "bench_config.h"   /* static const rhonn_config bench_config */

/* The two filters must run in the same precision. */
typedef char bench_same_precision[sizeof(rhonn_real) == sizeof(dense_real) ? 1 : -1];

#if defined(__GNUC__) || defined(__clang__)
#define BENCH_NOINLINE __attribute__((noinline))
#else
#define BENCH_NOINLINE
#endif

typedef struct {
    size_t T, n, m, nz;
    size_t z_off[RHONN_MAX_STATES];   /* offset of z_i in a row of Z */
    rhonn_real *x, *u, *z;
} bench_data;

rhonn_status bench_run_core(rhonn_t *net, const bench_data *d, rhonn_real *xhat, size_t *done);
void bench_run_dense(dense_ekf *f, const bench_data *d, rhonn_real *xhat, int learning);
void bench_run_generic(generic_ekf *g, const bench_data *d, rhonn_real *xhat, int learning);

static int fail(const char *what)
{
    fprintf(stderr, "core_vs_dense: %s\n", what);
    return 2;
}

static int load(const char *path, size_t T, bench_data *d)
{
    FILE *fh;
    size_t i, row, rows, got;
    long bytes;
    rhonn_real *x0, *u0, *z0;
    d->n = bench_config.n_states;
    d->m = bench_config.n_inputs;
    d->nz = 0;
    for (i = 0; i < d->n; ++i) {
        d->z_off[i] = d->nz;
        d->nz += bench_config.neurons[i].n_terms;
    }
    row = (d->n + d->m + d->nz) * sizeof(rhonn_real);
    fh = fopen(path, "rb");
    if (fh == NULL)
        return fail("cannot open the data file");
    if (fseek(fh, 0, SEEK_END) != 0 || (bytes = ftell(fh)) < 0 || fseek(fh, 0, SEEK_SET) != 0) {
        fclose(fh);
        return fail("cannot size the data file");
    }
    rows = (size_t)bytes / row;
    if ((size_t)bytes % row != 0 || rows < T) {
        fclose(fh);
        return fail("the data file does not hold at least T rows of X, U and Z");
    }
    /* The file holds X, U and Z of all its rows, one block after the other;
     * the run uses their first T rows. */
    x0 = malloc((size_t)bytes);
    if (x0 == NULL) {
        fclose(fh);
        return fail("out of memory");
    }
    got = fread(x0, 1, (size_t)bytes, fh);
    fclose(fh);
    if (got != (size_t)bytes)
        return fail("cannot read the data file");
    u0 = x0 + rows * d->n;
    z0 = u0 + rows * d->m;
    d->T = T;
    d->x = x0;
    d->u = u0;
    d->z = z0;
    return 0;
}

/* Both baselines start from the config's P0, unpacked to a full L x L. */
static int init_baselines(dense_ekf *f, generic_ekf *g)
{
    size_t i;
    for (i = 0; i < bench_config.n_states; ++i) {
        const rhonn_neuron_config *nc = &bench_config.neurons[i];
        const int L = nc->n_terms;
        dense_real p0[DENSE_MAX_L * DENSE_MAX_L];
        int r, c, at = 0;
        if (L > DENSE_MAX_L)
            return fail("a neuron has more terms than DENSE_MAX_L");
        for (r = 0; r < L; ++r)           /* packed upper triangle -> full symmetric */
            for (c = r; c < L; ++c, ++at)
                p0[r * L + c] = p0[c * L + r] = nc->p0[at];
        if (dense_ekf_init(&f[i], L, nc->w0, p0, nc->q, nc->r, nc->eta) != DENSE_OK)
            return fail("dense_ekf_init refused the configuration");
        if (generic_ekf_init(&g[i], L, nc->w0, p0, nc->q, nc->r, nc->eta) != GENERIC_OK)
            return fail("generic_ekf_init refused the configuration");
    }
    return 0;
}

static int init_core(rhonn_t *net)
{
    return rhonn_init(net, &bench_config, NULL) == RHONN_OK ? 0 : fail("rhonn_init refused the configuration");
}

BENCH_NOINLINE rhonn_status bench_run_core(rhonn_t *net, const bench_data *d, rhonn_real *xhat, size_t *done)
{
    size_t k;
    for (k = 0; k < d->T; ++k) {
        rhonn_status st = rhonn_step(net, d->x + k * d->n, d->u + k * d->m, NULL, xhat + k * d->n);
        if (st != RHONN_OK) {
            *done = k;
            return st;
        }
    }
    *done = d->T;
    return RHONN_OK;
}

/* A baseline's run over the recorded regressors, one neuron at a time: learn
 * from sample k's error with z(k-1) (unless learning is 0), then predict with
 * z(k). The generic EKF counts the updates it skips (S not positive) itself;
 * the run goes on, as the library's caller would. */
#define BENCH_RUN_BASELINE(name, filter, learn, predict)                                      \
    BENCH_NOINLINE void name(filter *f, const bench_data *d, rhonn_real *xhat, int learning)  \
    {                                                                                           \
        size_t k, i;                                                                            \
        for (k = 0; k < d->T; ++k) {                                                            \
            const rhonn_real *x = d->x + k * d->n;                                              \
            const rhonn_real *z = d->z + k * d->nz;                                             \
            rhonn_real *out = xhat + k * d->n;                                                  \
            for (i = 0; i < d->n; ++i) {                                                        \
                if (k > 0 && learning)                                                          \
                    (void)learn(&f[i], z - d->nz + d->z_off[i],                                 \
                                x[i] - out[(ptrdiff_t)i - (ptrdiff_t)d->n]);                    \
                out[i] = predict(&f[i], z + d->z_off[i]);                                       \
            }                                                                                   \
        }                                                                                       \
    }

BENCH_RUN_BASELINE(bench_run_dense, dense_ekf, dense_ekf_update, dense_ekf_predict)
BENCH_RUN_BASELINE(bench_run_generic, generic_ekf, generic_ekf_step, generic_ekf_predict)

static double now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

/* Best of `reps` runs of one filter, alternating with the others (so a burst
 * of load hits all alike): the running minimum of ns per run. */
static void keep_best(double *best, double t0, double t1, long r)
{
    if (r == 0 || t1 - t0 < *best)
        *best = t1 - t0;
}

/* Times one run (a statement) into the running best of repeat r. */
#define BENCH_TIMED(best, r, run)                      \
    do {                                               \
        const double t0_ = now_ns();                   \
        run;                                           \
        keep_best(&(best), t0_, now_ns(), (r));        \
    } while (0)

int main(int argc, char **argv)
{
    static rhonn_t net;
    static dense_ekf dense[RHONN_MAX_STATES];
    static generic_ekf generic[RHONN_MAX_STATES];
    bench_data d;
    rhonn_real *xc, *xd, *xg;
    rhonn_status st = RHONN_OK;
    size_t done = 0;
    long T, reps = 1;
    const char *mode;

    if (argc < 4 || (strcmp(argv[1], "time") == 0 && argc < 5))
        return fail("usage: core_vs_dense predict|time|count-core|count-dense|count-generic|count-core-frozen|"
                    "count-dense-frozen DATA T [REPEATS]");
    mode = argv[1];
    T = strtol(argv[3], NULL, 10);
    if (argc > 4)
        reps = strtol(argv[4], NULL, 10);
    if (T < 1 || reps < 1)
        return fail("T and REPEATS must be positive");
    if (load(argv[2], (size_t)T, &d) != 0)
        return 2;
    xc = malloc(3 * d.T * d.n * sizeof(rhonn_real));
    if (xc == NULL)
        return fail("out of memory");
    xd = xc + d.T * d.n;
    xg = xd + d.T * d.n;
    memset(xc, 0, 3 * d.T * d.n * sizeof(rhonn_real));

    if (strcmp(mode, "predict") == 0) {
        if (init_core(&net) != 0 || init_baselines(dense, generic) != 0)
            return 2;
        st = bench_run_core(&net, &d, xc, &done);
        bench_run_dense(dense, &d, xd, 1);
        bench_run_generic(generic, &d, xg, 1);
        fprintf(stderr, "core: %s after %lu steps\n", rhonn_status_name(st), (unsigned long)done);
        {
            long refused = 0;
            size_t i;
            for (i = 0; i < d.n; ++i)
                refused += generic[i].refused;
            fprintf(stderr, "generic: %ld updates refused\n", refused);
        }
        if (fwrite(xc, sizeof(rhonn_real), 3 * d.T * d.n, stdout) != 3 * d.T * d.n)
            return fail("cannot write the predictions");
    } else if (strcmp(mode, "time") == 0) {
        double best_core = 0, best_dense = 0, best_generic = 0, best_core_frozen = 0, best_dense_frozen = 0;
        size_t frozen_done = 0;
        long r;
        for (r = 0; r < reps; ++r) {
            if (init_core(&net) != 0 || init_baselines(dense, generic) != 0)
                return 2;
            BENCH_TIMED(best_core, r, st = bench_run_core(&net, &d, xc, &done));
            BENCH_TIMED(best_dense, r, bench_run_dense(dense, &d, xd, 1));
            BENCH_TIMED(best_generic, r, bench_run_generic(generic, &d, xg, 1));
            /* the same runs with learning off (count-*-frozen) */
            if (init_core(&net) != 0 || rhonn_set_learning(&net, 0) != RHONN_OK || init_baselines(dense, generic) != 0)
                return 2;
            BENCH_TIMED(best_core_frozen, r, (void)bench_run_core(&net, &d, xc, &frozen_done));
            BENCH_TIMED(best_dense_frozen, r, bench_run_dense(dense, &d, xd, 0));
        }
        printf("core_ns_per_step %.3f\ndense_ns_per_step %.3f\ngeneric_ns_per_step %.3f\n"
               "core_frozen_ns_per_step %.3f\ndense_frozen_ns_per_step %.3f\n"
               "core_status %s\ncore_steps %lu\n",
               best_core / (double)d.T, best_dense / (double)d.T, best_generic / (double)d.T,
               best_core_frozen / (double)d.T, best_dense_frozen / (double)d.T,
               rhonn_status_name(st), (unsigned long)done);
    } else if (strcmp(mode, "count-core") == 0 || strcmp(mode, "count-core-frozen") == 0) {
        if (init_core(&net) != 0)
            return 2;
        if (strcmp(mode, "count-core-frozen") == 0 && rhonn_set_learning(&net, 0) != RHONN_OK)
            return fail("rhonn_set_learning refused");
        st = bench_run_core(&net, &d, xc, &done);
        printf("core_status %s\ncore_steps %lu\n", rhonn_status_name(st), (unsigned long)done);
    } else if (strcmp(mode, "count-dense") == 0 || strcmp(mode, "count-dense-frozen") == 0) {
        if (init_baselines(dense, generic) != 0)
            return 2;
        bench_run_dense(dense, &d, xd, strcmp(mode, "count-dense") == 0);
    } else if (strcmp(mode, "count-generic") == 0) {
        if (init_baselines(dense, generic) != 0)
            return 2;
        bench_run_generic(generic, &d, xg, 1);
    } else {
        return fail("unknown mode (predict, time, count-core, count-dense, count-generic, count-core-frozen, "
                    "count-dense-frozen)");
    }
    free(xc);
    free(d.x);
    return 0;
}
