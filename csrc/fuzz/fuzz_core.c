/*
 * Coverage-guided fuzz target (libFuzzer) for the core's public API: a
 * configuration and a sequence of calls, both taken from the input.
 *
 * Input: a configuration header, then records, each [op][payload...]:
 *   op % 8 == 0..4  rhonn_step with x, u and valid flags from the next bytes
 *   op % 8 == 5     rhonn_restart
 *   op % 8 == 6     by bits 3-4: rhonn_set_learning (on or off from the op's
 *                   high bit), or rhonn_set_trace_ceiling or rhonn_set_gate
 *                   of neuron (op >> 5) with a real from the next bytes
 *   op % 8 == 7     rhonn_set_covariance with a matrix from the next bytes
 * Reals come from two bytes each: a sign, a mantissa byte and an exponent
 * spread over 10^-12..10^12 (and, for a few codes, 0, NaN, +-Inf and values
 * near the top of the range), so well-scaled and hostile data both occur.
 *
 * Besides crashes and sanitizer reports (build with
 * -fsanitize=fuzzer,address,undefined), the target aborts when a promise of
 * rhonn.h is broken:
 *   - after every RHONN_OK step, each committed P_i is positive definite:
 *     a Cholesky factorisation at working precision, written here
 *     independently of the core, succeeds on P scaled to a unit-order
 *     diagonal with a rounding allowance of 64 L eps on it (full form: no
 *     eigenvalue clearly below zero; see cholesky_ok), or every factor d_j
 *     is a positive finite number and U is finite (U D U^T form, definite by
 *     construction);
 *   - a full-form P_i the core marks as proven definite in exact arithmetic
 *     (rhonn_t.cert, which lets it skip the factorisation) passes a long
 *     double factorisation with no allowance at all;
 *   - every learning update the step committed used an innovation variance
 *     s_i = R_i + z^T P_i z >= R_i (read back from the health record as
 *     e_i^2 / (e_i^2 / s_i));
 *   - a call that does not return RHONN_OK leaves weights, covariances,
 *     prediction and history exactly as they were (only health counters and
 *     the fault diagnostic may change);
 *   - the covariance rhonn_get_covariance reads is one rhonn_set_covariance
 *     accepts, and writing it back (on a copy of the identifier) keeps the
 *     stored covariance bit for bit; for the U D U^T form it is definite in
 *     exact arithmetic (the long double factorisation, no allowance);
 *   - the innovation gate: an update committed with e^2 / s above the
 *     neuron's gate, or a gated update (health gated counted) that changed
 *     the neuron's weights or covariance, aborts;
 *   - skip_refused: a step that returned RHONN_OK while counting a refusal
 *     (health rejected) that was not a recovery (health resets) is one whose
 *     neuron has skip_refused set, and that neuron kept its weights and
 *     covariance;
 *   - the calibration setters: a ceiling or gate is accepted exactly when it
 *     is finite and >= 0 (a ceiling 0 or >= trace P_i(0), summed as the core
 *     sums it), the getter then reads it bit for bit, and the filter is not
 *     changed either way; the gate and ceiling checks above use the values
 *     in force;
 *   - bounded forgetting: without Q and without a trace bound, a step's
 *     trace P_i is at most max(c_i, the trace before) (c_i = trace P_i(0)),
 *     to rounding: forgetting never lifts it above its ceiling.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "rhonn.h"
#include "fuzz_input.h"
#include "../tests/exactly_definite.h" /* for a covariance the core marks as proven definite (rhonn_t.cert) */

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void make_config(reader *r, rhonn_config *c)
{
    size_t i, t;
    memset(c, 0, sizeof *c);
    c->n_states = (uint8_t)(1u + byte(r) % 4u);
    c->n_inputs = (uint8_t)(byte(r) % 3u);
    for (i = 0; i < c->n_states; ++i) {
        rhonn_neuron_config *nc = &c->neurons[i];
        const uint8_t flags = byte(r);
        const size_t L = 1u + byte(r) % 6u;
        size_t k = 0;
        nc->n_terms = (uint8_t)L;
        nc->activation = (uint8_t)(flags & 1u);
        nc->covariance = (uint8_t)((flags >> 1) & 1u);
        nc->beta = positive(r, -3, 2);
        nc->eta = positive(r, -2, 0);
        nc->r = positive(r, -12, 6);
        if (flags & 0x04u) {
            nc->forgetting = (rhonn_real)0.9 + (rhonn_real)(byte(r) % 100u) / (rhonn_real)1000;
        }
        if (flags & 0x08u) {
            nc->reset_after = (uint16_t)(1u + byte(r) % 4u);
        }
        for (t = 0; t < L; ++t) {
            const rhonn_real p = positive(r, -3, 9);
            nc->q[t] = (flags & 0x10u) ? (rhonn_real)0 : positive(r, -14, 3);
            nc->w0[t] = real(r, -3, 1);
            nc->p0[k] = p;
            k += L - t;
        }
        if (flags & 0x20u) {
            rhonn_real tr = 0;
            for (t = 0, k = 0; t < L; k += L - t, ++t) {
                tr += nc->p0[k];
            }
            nc->p_trace_max = tr * (rhonn_real)(1u + byte(r) % 8u);
        }
        if (flags & 0x40u) {
            nc->gate = (rhonn_real)(1u + byte(r) % 30u);
        }
        nc->skip_refused = (uint8_t)(flags >> 7);
        nc->wait_for_history = (uint8_t)(nc->n_terms & 1u);
        read_terms(r, nc, c->n_states, c->n_inputs);
    }
}

/* 2^-floor(e/2) for v = m 2^e, by repeated halving (independent of the
 * core's bit manipulation): v times its square lies in [1, 4). */
static rhonn_real pow2_scale(rhonn_real v)
{
    rhonn_real s = 1;
    while (v * s * s >= 4) {
        s *= (rhonn_real)0.5;
    }
    while (v * s * s < 1) {
        s *= 2;
    }
    return s;
}

/* Cholesky L L^T at working precision, written apart from the core
 * (top-down, where the core factorises bottom-up), of P scaled by powers of
 * two to a diagonal in [1, 4) and shifted by the rounding allowance
 * delta = 64 L eps trace: 0 when it fails, i.e. when the scaled P has an
 * eigenvalue below about -delta, clearly indefinite at this precision. The
 * allowance is needed because no working-precision test agrees with another
 * near singularity: a covariance the core's own factorisation finds
 * positive can give a slightly negative pivot in another order (float
 * [[388673, -195308.188], [-195308.188, 98142.3672]], determinant 177 against
 * products of 3.8e10), and a float32 filter reaches such nearly singular
 * covariances after one update with a small R. */
static int cholesky_ok(const rhonn_real *p, size_t L)
{
    const rhonn_real eps = sizeof(rhonn_real) == 4 ? (rhonn_real)1.2e-7 : (rhonn_real)2.3e-16;
    rhonn_real a[RHONN_MAX_TERMS][RHONN_MAX_TERMS], sc[RHONN_MAX_TERMS], tr = 0, delta;
    size_t i, j, k, idx = 0;
    for (i = 0; i < L; idx += L - i, ++i) {
        if (!(p[idx] > 0) || p[idx] - p[idx] != 0) {
            return 0;
        }
        sc[i] = pow2_scale(p[idx]);
    }
    for (i = 0, idx = 0; i < L; ++i) {
        for (j = i; j < L; ++j, ++idx) {
            a[i][j] = a[j][i] = p[idx] * sc[i] * sc[j];
        }
        tr += a[i][i];
    }
    delta = 64 * (rhonn_real)L * eps * tr;
    for (i = 0; i < L; ++i) {
        a[i][i] += delta;
    }
    for (j = 0; j < L; ++j) {
        rhonn_real d = a[j][j], s, prev = 0;
        int it;
        for (k = 0; k < j; ++k) {
            d -= a[j][k] * a[j][k];
        }
        if (!(d > 0) || d - d != d - d) {
            return 0;
        }
        /* sqrt without libm: Newton from above */
        s = d > 1 ? d : 1;
        for (it = 0; it < 400 && s != prev; ++it) {
            prev = s;
            s = (rhonn_real)0.5 * (s + d / s);
        }
        a[j][j] = s;
        for (i = j + 1u; i < L; ++i) {
            rhonn_real v = a[i][j];
            for (k = 0; k < j; ++k) {
                v -= a[i][k] * a[j][k];
            }
            a[i][j] = v / a[j][j];
        }
    }
    return 1;
}

/* The covariance read is one the setter accepts, and writing it back keeps
 * the stored covariance bit for bit (on a copy: a full-form P set from
 * outside loses its proof of definiteness, which the fuzzing of the steps
 * after would miss). */
static void check_round_trip(const rhonn_t *net, size_t i, const rhonn_real *p, const rhonn_real *f, size_t np)
{
    static rhonn_t copy;
    rhonn_real g[RHONN_MAX_PACKED];
    size_t idx;
    int finite = 1;
    for (idx = 0; idx < np; ++idx) {
        finite &= p[idx] - p[idx] == 0;
    }
    if (!finite) {
        return; /* a product of finite factors that overflowed: no covariance to write */
    }
    copy = *net;
    if (rhonn_set_covariance(&copy, i, p, np) != RHONN_OK || rhonn_get_factors(&copy, i, g, np) != RHONN_OK ||
        memcmp(f, g, np * sizeof g[0]) != 0) {
        abort(); /* the setter refused what the getter read, or the round trip changed it */
    }
}

static void check_invariants(const rhonn_t *net, const uint32_t *updates_before)
{
    const long double eps = sizeof(rhonn_real) == 4 ? 1.2e-7L : 2.3e-16L;
    size_t i, r, c;
    for (i = 0; i < net->cfg.n_states; ++i) {
        const rhonn_neuron_config *nc = &net->cfg.neurons[i];
        const size_t L = nc->n_terms, np = L * (L + 1u) / 2u;
        rhonn_real f[RHONN_MAX_PACKED], p[RHONN_MAX_PACKED];
        rhonn_health h;
        size_t idx;
        if (rhonn_get_factors(net, i, f, np) != RHONN_OK || rhonn_get_covariance(net, i, p, np) != RHONN_OK ||
            rhonn_get_health(net, i, &h) != RHONN_OK) {
            abort();
        }
        check_round_trip(net, i, p, f, np);
        if (nc->covariance == RHONN_COV_UD) {
            int finite = 1, normal = 1;
            for (r = 0, idx = 0; r < L; ++r) {
                for (c = r; c < L; ++c, ++idx) {
                    if (f[idx] - f[idx] != f[idx] - f[idx] || (c == r && !(f[idx] > 0))) {
                        abort(); /* a factor D <= 0 or a non-finite U after RHONN_OK */
                    }
                    finite &= p[idx] - p[idx] == 0;
                    normal &= c != r || p[idx] >= (sizeof(rhonn_real) == 4 ? (rhonn_real)1.2e-38 : (rhonn_real)2.3e-308);
                }
            }
            if (finite && normal && !exactly_definite(p, L)) {
                abort(); /* the covariance read of a U D U^T neuron is not definite */
            }
        } else if (!cholesky_ok(p, L)) {
            abort(); /* a committed full P that is not positive definite */
        } else if (net->cert[i][net->bank[i]] && !exactly_definite(p, L)) {
            abort(); /* a P the core calls proven definite that is not */
        }
        /* the update this step committed used s = R + z^T P z >= R:
         * s = e^2 / (e^2 / s) from the health record, to a few ulps */
        if (updates_before != NULL && h.updates != updates_before[i] && h.nis - h.nis == 0 &&
            (long double)h.nis >= (sizeof(rhonn_real) == 4 ? 1.2e-38L : 2.3e-308L) && h.innovation != 0) {
            /* (an e^2 / s that overflowed or fell below the normal range
             * cannot be read back to a few ulps) */
            const long double e = (long double)h.innovation;
            const long double s = e * e / (long double)h.nis;
            if (s < (long double)nc->r * (1.0L - 16.0L * eps)) {
                abort(); /* an update committed with s below R */
            }
        }
        if (updates_before != NULL && h.updates != updates_before[i] && net->gate[i] > 0 && h.nis > net->gate[i]) {
            abort(); /* an update the gate in force should have skipped was committed */
        }
    }
}

/* The committed state (the inactive bank is scratch that a refused step may
 * have written, by design). */
typedef struct {
    rhonn_real w[RHONN_MAX_STATES][RHONN_MAX_TERMS];
    rhonn_real p[RHONN_MAX_STATES][RHONN_MAX_PACKED];
    uint8_t bank[RHONN_MAX_STATES];
    rhonn_real xhat[RHONN_MAX_STATES];
    rhonn_real hist[RHONN_HISTORY_LEN][RHONN_SAMPLE_LEN];
    uint8_t valid_run[RHONN_MAX_STATES];
    uint8_t head, started, learning, zbank;
    uint32_t steps;
} filter_state;

static void capture(const rhonn_t *net, filter_state *s)
{
    size_t i;
    memset(s, 0, sizeof *s);
    for (i = 0; i < RHONN_MAX_STATES; ++i) {
        memcpy(s->w[i], net->w[i][net->bank[i]], sizeof s->w[i]);
        memcpy(s->p[i], net->p[i][net->bank[i]], sizeof s->p[i]);
    }
    memcpy(s->bank, net->bank, sizeof s->bank);
    memcpy(s->xhat, net->xhat, sizeof s->xhat);
    memcpy(s->hist, net->hist, sizeof s->hist);
    memcpy(s->valid_run, net->valid_run, sizeof s->valid_run);
    s->head = net->head;
    s->started = net->started;
    s->learning = net->learning;
    s->zbank = net->zbank;
    s->steps = net->steps;
}

/* After an OK step: a neuron the gate skipped kept its weights and
 * covariance; a neuron that forgets without Q or a trace bound ended with
 * trace P at most max(c_i, its trace before), c_i = trace P_i(0) (rhonn.h
 * WINDUP PROTECTION), to rounding. */
static void check_gate_and_ceiling(const rhonn_t *net, const filter_state *before, const uint32_t *gated,
                                   const uint32_t *rejected, const uint32_t *resets, const rhonn_real *traces)
{
    const long double eps = sizeof(rhonn_real) == 4 ? 1.2e-7L : 2.3e-16L;
    size_t i;
    for (i = 0; i < net->cfg.n_states; ++i) {
        const rhonn_neuron_config *nc = &net->cfg.neurons[i];
        const size_t L = nc->n_terms;
        rhonn_health h;
        size_t t, k;
        int q_zero = 1;
        if (rhonn_get_health(net, i, &h) != RHONN_OK) {
            abort();
        }
        const int skipped = h.rejected != rejected[i] && h.resets == resets[i];
        if (skipped && nc->skip_refused == 0u) {
            abort(); /* a step refused by a neuron without skip_refused returned RHONN_OK */
        }
        if ((h.gated != gated[i] || skipped) &&
            (memcmp(net->w[i][net->bank[i]], before->w[i], L * sizeof(rhonn_real)) != 0 ||
             memcmp(net->p[i][net->bank[i]], before->p[i], L * (L + 1u) / 2u * sizeof(rhonn_real)) != 0)) {
            abort(); /* a gated or skipped update changed the neuron */
        }
        for (t = 0; t < L; ++t) {
            q_zero &= nc->q[t] == 0;
        }
        if (q_zero && net->trace_max[i] == 0 && nc->forgetting > 0 && nc->forgetting < 1 &&
            h.trace_p - h.trace_p == 0 && traces[i] - traces[i] == 0) {
            long double c = 0, bound;
            for (t = 0, k = 0; t < L; k += L - t, ++t) {
                c += (long double)nc->p0[k];
            }
            bound = c > (long double)traces[i] ? c : (long double)traces[i];
            if ((long double)h.trace_p > bound * (1.0L + 64.0L * (long double)L * eps)) {
                abort(); /* forgetting lifted trace P above its ceiling */
            }
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static rhonn_t net;
    rhonn_config cfg;
    reader r;
    size_t ops = 0;

    r.p = data;
    r.n = size;
    make_config(&r, &cfg);
    if (rhonn_init(&net, &cfg, NULL) != RHONN_OK) {
        return 0;
    }
    check_invariants(&net, NULL);
    while (r.n > 0u && ops++ < 512u) {
        const uint8_t op = byte(&r);
        filter_state before, after;
        uint32_t updates[RHONN_MAX_STATES], gated[RHONN_MAX_STATES], rejected[RHONN_MAX_STATES],
            resets[RHONN_MAX_STATES];
        rhonn_real traces[RHONN_MAX_STATES];
        rhonn_status st;
        size_t j;
        capture(&net, &before);
        for (j = 0; j < RHONN_MAX_STATES; ++j) {
            rhonn_health h;
            updates[j] = net.health[j].updates;
            gated[j] = net.health[j].gated;
            rejected[j] = net.health[j].rejected;
            resets[j] = net.health[j].resets;
            traces[j] = j < cfg.n_states && rhonn_get_health(&net, j, &h) == RHONN_OK ? h.trace_p : 0;
        }
        switch (op % 8u) {
        case 5:
            st = rhonn_restart(&net);
            break;
        case 6: {
            const size_t i = (size_t)(op >> 5) % cfg.n_states;
            const unsigned which = (op >> 3) & 3u;
            if (which < 2u) {
                st = rhonn_set_learning(&net, op >> 7);
            } else {
                const rhonn_real v = real(&r, -6, 6);
                rhonn_real was, now, p0 = 0;
                rhonn_status checked;
                int valid;
                size_t t, k;
                for (t = 0, k = 0; t < cfg.neurons[i].n_terms; k += cfg.neurons[i].n_terms - t, ++t) {
                    p0 += cfg.neurons[i].p0[k]; /* trace P_i(0) in the core's order */
                }
                if ((which == 2u ? rhonn_get_trace_ceiling(&net, i, &was) : rhonn_get_gate(&net, i, &was)) != RHONN_OK) {
                    abort();
                }
                checked = which == 2u ? rhonn_check_trace_ceiling(&net, i, v) : rhonn_check_gate(&net, i, v);
                st = which == 2u ? rhonn_set_trace_ceiling(&net, i, v) : rhonn_set_gate(&net, i, v);
                if (checked != st) {
                    abort(); /* the check alone said otherwise than the setter */
                }
                valid = v - v == 0 && v >= 0 && (which == 3u || v == 0 || v >= p0);
                if ((which == 2u ? rhonn_get_trace_ceiling(&net, i, &now) : rhonn_get_gate(&net, i, &now)) != RHONN_OK ||
                    (st == RHONN_OK) != valid || (st != RHONN_OK && st != RHONN_E_VALUE) ||
                    memcmp(&now, st == RHONN_OK ? &v : &was, sizeof now) != 0) {
                    abort(); /* accepted what is invalid, refused what is valid, or read back another value */
                }
                capture(&net, &after);
                if (memcmp(&before, &after, sizeof before) != 0) {
                    abort(); /* a setter changed the filter */
                }
            }
            break;
        }
        case 7: {
            const size_t i = (size_t)(op >> 3) % cfg.n_states;
            const size_t L = cfg.neurons[i].n_terms;
            rhonn_real p[RHONN_MAX_PACKED];
            for (j = 0; j < L * (L + 1u) / 2u; ++j) {
                p[j] = real(&r, -6, 6);
            }
            st = rhonn_set_covariance(&net, i, p, L * (L + 1u) / 2u);
            break;
        }
        default: {
            rhonn_real x[RHONN_MAX_STATES], u[RHONN_MAX_INPUTS + 1], y[RHONN_MAX_STATES];
            uint8_t valid[RHONN_MAX_STATES];
            const uint8_t mask = byte(&r);
            for (j = 0; j < cfg.n_states; ++j) {
                x[j] = real(&r, -4, 3);
                valid[j] = (uint8_t)(((mask >> j) & 1u) ? 0u : 1u);
            }
            for (j = 0; j < cfg.n_inputs; ++j) {
                u[j] = real(&r, -3, 3);
            }
            st = rhonn_step(&net, x, u, valid, y);
            break;
        }
        }
        if (st == RHONN_OK) {
            check_invariants(&net, updates);
            if (op % 8u <= 4u) {
                check_gate_and_ceiling(&net, &before, gated, rejected, resets, traces);
            }
        } else {
            capture(&net, &after);
            if (memcmp(&before, &after, sizeof before) != 0) {
                abort(); /* a refused call changed the filter */
            }
        }
    }
    return 0;
}
