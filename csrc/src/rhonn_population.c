/*
 * rhonn_population.c - N identifiers of one structure over one trajectory
 * (rhonn_population.h).
 *
 * The learning state of the members (w, the stored covariances, z, xhat)
 * is kept structure-of-arrays in the workspace for the call, member
 * innermost, and every operation of the kernels (eq. 7-8, the check of
 * P(k+1), the U D U^T updates) and of the prediction (eq. 3) is done for
 * all members at once: one vector operation (RHONN_POP_VECTOR) or a loop
 * over members (m < RHONN_MAX_POPULATION, a constant trip count). Each
 * member's element is the operation rhonn.c's scalar step does at that
 * point, on that member's numbers, the same operands in the same order, so
 * the results are the same bits. Members that do not take part (not
 * learning this step, stopped, or beyond N) compute on their stale lanes
 * and their results are thrown away, which keeps the arithmetic free of
 * branches. The innovation gate is tested on the kernel's e^2 / s, lane by
 * lane, where rhonn.c tests it (gate_lanes). The bookkeeping is rhonn.c's:
 * a refusal and a recovery member by member (off the hot path); the valid
 * runs, health counters and bank flips of each member held in its lane for
 * the call, step by step for every lane at once (an update every member
 * made alike counted once, in n_alike), and written into its rhonn_t when
 * the member is handed back.
 *
 * Build with -std=c99 -ffp-contract=off, as rhonn.c.
 */
#include "rhonn_population.h"
#include "rhonn_internal.h"

#ifdef RHONN_SINGLE
typedef uint32_t pop_bits;
#else
typedef uint64_t pop_bits;
#endif

#if defined(__GNUC__) || defined(__clang__)
#define POP_RESTRICT __restrict__
/* compiled inside each caller, so inside each target clone of the kernel */
#define POP_ALWAYS_INLINE static __inline__ __attribute__((always_inline))
#else
#define POP_RESTRICT restrict
#define POP_ALWAYS_INLINE static
#endif

#define NPOP ((size_t)RHONN_MAX_POPULATION)

/* The step's bookkeeping loops over lanes, kept out of line: inlined into
 * the step's loop nest, GCC 12 leaves them scalar; alone, it vectorises
 * them (measured with -fopt-info-vec). */
#if defined(__GNUC__) || defined(__clang__)
#define POP_LANES static __attribute__((noinline))
#else
#define POP_LANES static
#endif

#if defined(__GNUC__) && !defined(__clang__)
#define POP_UNROLL _Pragma("GCC unroll 16")
#else
#define POP_UNROLL
#endif

/* RHONN_POP_VECTOR=1 (the default with GCC and clang, for a population
 * of 2, 4, 8, ... members): the kernels are written with the
 * compilers' generic vector types, one vector holding a value of every
 * member, so each operation of eq. 7-8 is one vector operation on every
 * target (the compiler splits a vector wider than the hardware's, SSE2's
 * 2 doubles, into several). 0, or another compiler: the same kernel as
 * loops over members, which compilers vectorise at their discretion. The
 * same IEEE operations either way, element by element. */
#ifndef RHONN_POP_VECTOR
#if (defined(__GNUC__) || defined(__clang__)) && (RHONN_MAX_POPULATION & (RHONN_MAX_POPULATION - 1)) == 0
#define RHONN_POP_VECTOR 1
#else
#define RHONN_POP_VECTOR 0
#endif
#endif

/* RHONN_TARGET_CLONES=1 (GCC, x86-64 with glibc's ifunc; the Python
 * extension sets it): the kernels are also compiled for wider vector units
 * and the widest the CPU has is picked at load time, so 8 members are one
 * AVX-512 vector in double, one AVX2 vector in float. The same IEEE
 * operations on every width (and no contraction: -ffp-contract=off), so the
 * same bits. No AVX2 clone in double: GCC 12 carries a 64-byte vector
 * through the stack there, and it ran slower than the SSE2 default
 * (measured: 0.86x against 1.8x the sequential runs). */
#ifndef RHONN_TARGET_CLONES
#define RHONN_TARGET_CLONES 0
#endif
/* RHONN_POP_TARGET (a string, "avx2" or "avx512f"; GCC, x86-64, without
 * RHONN_TARGET_CLONES): the kernels compiled for that one vector unit
 * instead, as its clone is, and rhonn.c as it is. bench/bench_wide.py builds
 * the core so to measure each unit a CPU has, not only its widest. The CPU
 * must have the unit. */
#if defined(RHONN_POP_TARGET) && !RHONN_TARGET_CLONES && defined(__GNUC__) && !defined(__clang__) \
    && defined(__x86_64__)
#define POP_CLONES __attribute__((target(RHONN_POP_TARGET)))
#elif RHONN_TARGET_CLONES && defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#ifdef RHONN_SINGLE
#define POP_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define POP_CLONES __attribute__((target_clones("avx512f", "default")))
#endif
#else
#define POP_CLONES
#endif

/* Finite: v - v is 0 for a finite v and NaN for NaN and +-Inf. A plain
 * floating-point operation (rhonn.c tests the exponent bits; the verdict is
 * the same), so the loops over members stay vectorisable. */
#define LANE_FINITE(v) (((v) - (v)) == R(0.0))

/* Lane vectors: entry idx of an array [...][member] starts at idx * NPOP. */
#define LANE(a, idx) ((a) + (size_t)(idx) * NPOP)

#if RHONN_POP_VECTOR
#ifdef RHONN_SINGLE
typedef uint32_t pop_ubits;
#define POP_EXP_SHIFT 23
#define POP_EXP_FIELD 0xFF
#define POP_SCALE_TOP 255  /* 2^-floor(e/2) = bits (255 - floor((b + 129) / 2)) << 23 */
#define POP_SCALE_ADD 129
#define POP_ABS_MASK 0x7FFFFFFFu
#else
typedef uint64_t pop_ubits;
#define POP_EXP_SHIFT 52
#define POP_EXP_FIELD 0x7FF
#define POP_SCALE_TOP 2047 /* 2^-floor(e/2) = bits (2047 - floor((b + 1025) / 2)) << 52 */
#define POP_SCALE_ADD 1025
#define POP_ABS_MASK 0x7FFFFFFFFFFFFFFFull
#endif
/* A value of every member; aligned as rhonn_real, so a vector is read and
 * written in place in the workspace's [...][member] arrays. */
typedef rhonn_real lanev __attribute__((vector_size(sizeof(rhonn_real) * RHONN_MAX_POPULATION),
                                        aligned(sizeof(rhonn_real))));
typedef pop_ubits lanei __attribute__((vector_size(sizeof(rhonn_real) * RHONN_MAX_POPULATION),
                                       aligned(sizeof(rhonn_real))));
#define V(a, idx) (*(lanev *)LANE(a, idx))
#define VC(a, idx) (*(const lanev *)LANE(a, idx))
#endif

/* Each member's status from the kernel's verdicts, in rhonn.c's order: the
 * innovation (s finite and s >= R; for the U D U^T form, s finite), the
 * weights finite (wsum, the sum of w - w over the new weights, is 0), P(k+1)
 * positive definite (pd_ok 1) and then, for the full form, which way a
 * refused P failed (a non-finite entry, or not definite); for the U D U^T
 * form (fsum not NULL: the sum of f - f over its factors), definite factors
 * that are not finite. With them, which lanes of neuron i learned and
 * passed (updated) and whether any did (k_moved) or any learning lane was
 * refused (k_refused): summed here, lane by lane, as the statuses are
 * written (read back as one vector, bytes just stored one by one cost a
 * stalled load). */
POP_ALWAYS_INLINE void verdicts(rhonn_population_work *wk, size_t i, const rhonn_real *Pn, size_t packed,
                                const rhonn_real *s, const rhonn_real *rr, const rhonn_real *wsum,
                                const rhonn_real *pd_ok, const rhonn_real *fsum)
{
    uint8_t moved = 0, refused = 0;
    size_t m, c;
#if RHONN_POP_VECTOR
    {
        /* Nearly every call: every lane passed, whose statuses follow from
         * the masks at once (the same tests; else the lane by lane below) */
        const lanev sv = VC(s, 0), wv = VC(wsum, 0), pv = VC(pd_ok, 0);
        lanei ok = (lanei)((sv - sv) == R(0.0)) & (lanei)((wv - wv) == R(0.0)) & (lanei)(pv == R(1.0));
        pop_ubits every = ~(pop_ubits)0;
        if (fsum != NULL) {
            const lanev fv = VC(fsum, 0);
            ok &= (lanei)((fv - fv) == R(0.0));
        } else {
            ok &= (lanei)(sv >= VC(rr, 0));
        }
        for (m = 0; m < NPOP; ++m) {
            every &= ok[m];
        }
        if (every != 0u) {
            for (m = 0; m < NPOP; ++m) {
                wk->kstatus[m] = (uint8_t)RHONN_OK;
                wk->updated[i][m] = wk->learn[i][m];
                moved |= wk->learn[i][m];
            }
            wk->k_moved = moved;
            wk->k_refused = 0;
            return;
        }
    }
#endif
    for (m = 0; m < NPOP; ++m) {
        rhonn_status st = RHONN_OK;
        if (!(LANE_FINITE(s[m]) && (fsum != NULL || s[m] >= rr[m]))) {
            st = RHONN_E_INNOVATION;
        } else if (!LANE_FINITE(wsum[m])) {
            st = RHONN_E_DIVERGED;
        } else if (fsum != NULL) {
            st = pd_ok[m] != R(1.0) ? RHONN_E_NOT_PD : !LANE_FINITE(fsum[m]) ? RHONN_E_COVARIANCE : RHONN_OK;
        } else if (pd_ok[m] != R(1.0)) {
            st = RHONN_E_NOT_PD; /* which way it failed, off the hot path */
            for (c = 0; c < packed; ++c) {
                if (!LANE_FINITE(Pn[c * NPOP + m])) {
                    st = RHONN_E_COVARIANCE;
                }
            }
        }
        wk->kstatus[m] = (uint8_t)st;
        {
            const uint8_t learn = wk->learn[i][m], up = (uint8_t)(learn & (uint8_t)(st == RHONN_OK));
            wk->updated[i][m] = up;
            moved |= up;
            refused |= (uint8_t)(learn & (up ^ 1u));
        }
    }
    wk->k_moved = moved;
    wk->k_refused = refused;
}

#if !RHONN_POP_VECTOR
/* rhonn.c's definiteness proof (certified_update: see its comment for the
 * bounds) for member m of a full-form update, from the lane arrays: P the
 * committed covariance (proven definite in exact arithmetic), z, v = P z,
 * inv_s = 1 / s, Pn the update. 1 when it proves Pn definite with the margin
 * under which the plain factorisation accepts it, so that skipping the
 * factorisation changes no verdict; 0 when it cannot. */
static int lane_proof(const rhonn_real *P, const rhonn_real *z, const rhonn_real *v, rhonn_real inv_s,
                      const rhonn_real *Pn, rhonn_real qmin, rhonn_real r_i, size_t L, size_t m)
{
    rhonn_real tr = R(0.0), pzz = R(0.0), vv = R(0.0), zv = R(0.0), pmax = R(0.0);
    size_t r, idx;
    for (r = 0, idx = 0; r < L; idx += L - r, ++r) {
        const rhonn_real d = P[idx * NPOP + m], zr = z[r * NPOP + m], vr = v[r * NPOP + m];
        const rhonn_real az = zr < R(0.0) ? -zr : zr, av = vr < R(0.0) ? -vr : vr;
        const rhonn_real dn = Pn[idx * NPOP + m];
        tr += d;
        pzz += (d * zr) * zr;
        vv += vr * vr;
        zv += az * av;
        pmax = dn > pmax ? dn : pmax;
    }
    return rhonn_proof_holds(tr, pzz, vv, zv, pmax, qmin, r_i, inv_s, L);
}

/* Which members' updates the proof covers (fast[m]: a learning member whose
 * committed P carries a proof, without forgetting or a trace bound this
 * step, proven). Returns 1 when it covers every learning member: the
 * factorisation is skipped. */
static int lane_proofs(rhonn_population_work *wk, size_t i, size_t L, const rhonn_real *inv_s, uint8_t *fast)
{
    const rhonn_real *P = &wk->p[wk->pb[i]][i][0][0], *Pn = &wk->p[wk->pb[i] ^ 1u][i][0][0];
    int all = 1;
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        fast[m] = (uint8_t)(wk->learn[i][m] && wk->cert[i][m] && wk->ilam_step[m] == R(1.0) &&
                            !wk->bounded[i][m] &&
                            lane_proof(P, &wk->z[wk->zb][i][0][0], &wk->pz[0][0], inv_s[m], Pn, wk->q_min[i][m],
                                       wk->r[i][m], L, m));
        all &= fast[m] || !wk->learn[i][m];
    }
    return all;
}
#endif

/* The verdict of the check with the proofs: a member whose update was
 * proven, or whose P passed the factorisation shifted by
 * 17 L gamma_{L+1} (rhonn.c shifted_check: that also proves it), or else
 * passed the plain one. shifted_ok and plain_ok as the check gives them
 * (plain_ok NULL when it was not run); sets the members' new proofs. */
static void proof_verdicts(rhonn_population_work *wk, size_t i, const uint8_t *fast, const rhonn_real *shifted_ok,
                           const rhonn_real *plain_ok, rhonn_real *ok)
{
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        const int proven = fast[m] || shifted_ok[m] == R(1.0);
        wk->cert_new[i][m] = (uint8_t)proven;
        ok[m] = proven || (plain_ok != NULL && plain_ok[m] == R(1.0)) ? R(1.0) : R(0.0);
    }
}

/* Does any learning member still need the plain factorisation's verdict? */
static int plain_needed(const rhonn_population_work *wk, size_t i, const uint8_t *fast, const rhonn_real *shifted_ok)
{
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        if (wk->learn[i][m] && !fast[m] && shifted_ok[m] != R(1.0)) {
            return 1;
        }
    }
    return 0;
}

#if !RHONN_POP_VECTOR
/* For the tests (rhonn_internal.h): this build proves lane by lane with
 * rhonn_proof_holds itself. */
void rhonn_internal_proof_lanes(const rhonn_real *in, size_t L, uint8_t *out)
{
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        out[m] = (uint8_t)rhonn_proof_holds(in[m], in[NPOP + m], in[2u * NPOP + m], in[3u * NPOP + m],
                                            in[4u * NPOP + m], in[5u * NPOP + m], in[6u * NPOP + m],
                                            in[7u * NPOP + m], L);
    }
}

/* rhonn.c's half_exponent_scale (2^-floor(e/2) for v = m 2^e) in unsigned
 * arithmetic on the biased exponent b: 1023 - floor((b - 1023) / 2) =
 * 2047 - floor((b + 1025) / 2), the same value for every b (0..2047; float:
 * 127 - floor((b - 127) / 2) = 255 - floor((b + 129) / 2)). */
static rhonn_real half_exponent_scale(rhonn_real v)
{
    union { rhonn_real f; pop_bits u; } b;
    b.f = v;
#ifdef RHONN_SINGLE
    b.u = (255u - (((b.u >> 23) & 0xFFu) + 129u) / 2u) << 23;
#else
    b.u = (pop_bits)(2047u - (unsigned)(((b.u >> 52) & 0x7FFu) + 1025u) / 2u) << 52;
#endif
    return b.f;
}

/* rhonn.c's dot(): two accumulators, even and odd entries, then s0 + s1;
 * entries c of a and b (lane vectors at strides of NPOP) for every member. */
static void lane_dot(const rhonn_real *POP_RESTRICT a, const rhonn_real *POP_RESTRICT b, size_t len,
                     rhonn_real *POP_RESTRICT out)
{
    rhonn_real s0[RHONN_MAX_POPULATION], s1[RHONN_MAX_POPULATION];
    size_t c, m;
    for (m = 0; m < NPOP; ++m) {
        s0[m] = R(0.0);
        s1[m] = R(0.0);
    }
    for (c = 0; c + 1u < len; c += 2u) {
        const rhonn_real *POP_RESTRICT a0 = LANE(a, c), *POP_RESTRICT b0 = LANE(b, c);
        const rhonn_real *POP_RESTRICT a1 = LANE(a, c + 1u), *POP_RESTRICT b1 = LANE(b, c + 1u);
        for (m = 0; m < NPOP; ++m) {
            s0[m] += a0[m] * b0[m];
            s1[m] += a1[m] * b1[m];
        }
    }
    if (c < len) {
        const rhonn_real *POP_RESTRICT a0 = LANE(a, c), *POP_RESTRICT b0 = LANE(b, c);
        for (m = 0; m < NPOP; ++m) {
            s0[m] += a0[m] * b0[m];
        }
    }
    for (m = 0; m < NPOP; ++m) {
        out[m] = s0[m] + s1[m];
    }
}

/* The check of full_kernel_loops (rhonn.c scaled_udu + udu_factor) with
 * shift[m] subtracted from each scaled diagonal entry (0: the plain check,
 * x - 0 being x bit for bit): pd_ok[m] 1 when member m passed. */
static void loops_check(rhonn_population_work *wk, const rhonn_real *POP_RESTRICT Pn, size_t L, const size_t *rs,
                        const rhonn_real *POP_RESTRICT shift, rhonn_real *POP_RESTRICT pd_ok)
{
    rhonn_real *POP_RESTRICT F = &wk->f[0][0];
    rhonn_real *POP_RESTRICT sc = &wk->sc[0][0];
    rhonn_real *POP_RESTRICT tk = &wk->tk[0][0];
    rhonn_real *POP_RESTRICT dk = &wk->dk[0][0];
    size_t r, m, j, k;

    /* The check (rhonn.c scaled_udu + udu_factor): diagonal normal and
     * finite, scaled by powers of two to [1, 4), every pivot positive. */
    for (m = 0; m < NPOP; ++m) {
        pd_ok[m] = R(1.0);
    }
    for (r = 0; r < L; ++r) {
        const rhonn_real *POP_RESTRICT d = LANE(Pn, rs[r]);
        rhonn_real *POP_RESTRICT sr = LANE(sc, r);
        for (m = 0; m < NPOP; ++m) {
            /* normal and finite: MIN_NORMAL <= v <= MAX (false for NaN) */
            pd_ok[m] = d[m] >= RHONN_MIN_NORMAL ? (d[m] <= RHONN_MAX_REAL ? pd_ok[m] : R(0.0)) : R(0.0);
            sr[m] = half_exponent_scale(d[m]);
        }
    }
    for (j = L; j-- > 0u;) {
        const rhonn_real *POP_RESTRICT uj = LANE(F, rs[j] + 1u);
        const rhonn_real *POP_RESTRICT sj = LANE(sc, j);
        const size_t tail = L - 1u - j;
        rhonn_real dj[RHONN_MAX_POPULATION], inv[RHONN_MAX_POPULATION];
        size_t ii;
        {
            const rhonn_real *POP_RESTRICT pjj = LANE(Pn, rs[j]);
            for (m = 0; m < NPOP; ++m) {
                dj[m] = (pjj[m] * sj[m]) * sj[m] - shift[m];
            }
        }
        for (k = 0; k < tail; ++k) {
            const rhonn_real *POP_RESTRICT dd = LANE(dk, j + 1u + k), *POP_RESTRICT uk = LANE(uj, k);
            rhonn_real *POP_RESTRICT tt = LANE(tk, k);
            for (m = 0; m < NPOP; ++m) {
                tt[m] = dd[m] * uk[m];
                dj[m] -= uk[m] * tt[m];
            }
        }
        {
            rhonn_real *POP_RESTRICT dd = LANE(dk, j), *POP_RESTRICT fj = LANE(F, rs[j]);
            for (m = 0; m < NPOP; ++m) {
                dd[m] = dj[m];
                fj[m] = dj[m];
                inv[m] = R(1.0) / dj[m];
            }
        }
        for (m = 0; m < NPOP; ++m) {
            pd_ok[m] = dj[m] > R(0.0) ? (dj[m] <= RHONN_MAX_REAL ? pd_ok[m] : R(0.0)) : R(0.0);
        }
        for (ii = 0; ii < j; ++ii) {
            rhonn_real *POP_RESTRICT fi = LANE(F, rs[ii] + (j - ii));
            const rhonn_real *POP_RESTRICT pij = LANE(Pn, rs[ii] + (j - ii));
            const rhonn_real *POP_RESTRICT si = LANE(sc, ii);
            rhonn_real a[RHONN_MAX_POPULATION];
            for (m = 0; m < NPOP; ++m) {
                a[m] = (pij[m] * si[m]) * sj[m];
            }
            for (k = 0; k < tail; ++k) {
                const rhonn_real *POP_RESTRICT fk = LANE(fi, 1u + k), *POP_RESTRICT tt = LANE(tk, k);
                for (m = 0; m < NPOP; ++m) {
                    a[m] -= fk[m] * tt[m];
                }
            }
            for (m = 0; m < NPOP; ++m) {
                fi[m] = a[m] * inv[m];
            }
        }
    }
}

/* ------------------------------------------------------------------------ */
/* The full-form kernel (rhonn.c ekf_kernel, then pd_check), every member at
 * once: eq. 8 s = R + z^T P z, eq. 7 w + (eta e / s) P z and
 * P - (P z)(P z)^T / s (/ lambda) + Q, the trace ceiling, and the U D U^T
 * factorisation of the scaled P(k+1) whose pivots must be positive. Writes
 * each member's status (the first check it fails, in rhonn.c's order). The
 * arithmetic loops carry no branch; the verdicts are gathered apart. */
static void full_kernel_loops(rhonn_population_work *wk, size_t i, size_t L)
{
    const rhonn_real *POP_RESTRICT P = &wk->p[wk->pb[i]][i][0][0];
    rhonn_real *POP_RESTRICT Pn = &wk->p[wk->pb[i] ^ 1u][i][0][0];
    const rhonn_real *POP_RESTRICT z = &wk->z[wk->zb][i][0][0];
    const rhonn_real *POP_RESTRICT w = &wk->w[wk->wb][i][0][0];
    rhonn_real *POP_RESTRICT wn = &wk->w[wk->wb ^ 1u][i][0][0];
    rhonn_real *POP_RESTRICT pz = &wk->pz[0][0];
    const rhonn_real *POP_RESTRICT rr = wk->r[i];
    const rhonn_real *POP_RESTRICT eta = wk->eta[i];
    rhonn_real *POP_RESTRICT ilam = wk->ilam_step;
    const rhonn_real *POP_RESTRICT ilam_cfg = wk->inv_lambda[i];
    const rhonn_real *POP_RESTRICT ceil_i = wk->forget_ceiling[i];
    const rhonn_real *POP_RESTRICT ptm = wk->p_trace_max[i];
    const rhonn_real *POP_RESTRICT q = &wk->q[i][0][0];
    const rhonn_real *POP_RESTRICT e = wk->e;
    rhonn_real *POP_RESTRICT nis = wk->nis[i];
    rhonn_real s[RHONN_MAX_POPULATION], inv_s[RHONN_MAX_POPULATION], gain[RHONN_MAX_POPULATION];
    rhonn_real acc[RHONN_MAX_POPULATION], kr[RHONN_MAX_POPULATION], scale[RHONN_MAX_POPULATION];
    /* the verdicts as numbers, so their loops vectorise with the rest: pd_ok
     * is 1 while every pivot passed, 0 after; wsum is the sum of w - w over
     * the new weights, 0 when all are finite, NaN otherwise */
    rhonn_real pd_ok[RHONN_MAX_POPULATION], wsum[RHONN_MAX_POPULATION];
    uint8_t fast[RHONN_MAX_POPULATION];
    size_t rs[RHONN_MAX_TERMS];
    size_t r, c, m, len;
    const size_t packed = L * (L + 1u) / 2u;

    rs[0] = 0;
    for (r = 0; r + 1u < L; ++r) {
        rs[r + 1u] = rs[r] + (L - r);
    }
    /* pz = P z from the packed triangle: row r scatters z_r P(r, c > r)
     * into pz[c], then adds its own dot product (rhonn.c's order). */
    for (c = 0; c < L * NPOP; ++c) {
        pz[c] = R(0.0);
    }
    for (r = 0; r < L; ++r) {
        const rhonn_real *POP_RESTRICT row = LANE(P, rs[r]);
        const rhonn_real *POP_RESTRICT zr = LANE(z, r);
        len = L - r;
        for (c = 1; c < len; ++c) {
            const rhonn_real *POP_RESTRICT pc = LANE(row, c);
            rhonn_real *POP_RESTRICT out = LANE(pz, r + c);
            for (m = 0; m < NPOP; ++m) {
                out[m] += pc[m] * zr[m];
            }
        }
        lane_dot(row, zr, len, acc);
        {
            rhonn_real *POP_RESTRICT out = LANE(pz, r);
            for (m = 0; m < NPOP; ++m) {
                out[m] += acc[m];
            }
        }
    }
    /* eq. 8: s = R + z^T P z, M = 1 / s; eq. 7's gain eta e M */
    lane_dot(z, pz, L, acc);
    for (m = 0; m < NPOP; ++m) {
        s[m] = rr[m] + acc[m];
        inv_s[m] = R(1.0) / s[m];
        nis[m] = e[m] * (e[m] * inv_s[m]);
        gain[m] = eta[m] * e[m] * inv_s[m];
    }
    /* eq. 7: w + (eta e M) P z */
    for (r = 0; r < L; ++r) {
        const rhonn_real *POP_RESTRICT wr = LANE(w, r), *POP_RESTRICT pr = LANE(pz, r);
        rhonn_real *POP_RESTRICT out = LANE(wn, r);
        for (m = 0; m < NPOP; ++m) {
            out[m] = wr[m] + gain[m] * pr[m];
        }
    }
    /* Bounded forgetting (rhonn.c ekf_kernel): 1 / lambda where the trace
     * of P - (P z)(P z)^T M, its diagonal as formed below, stays within the
     * ceiling after it; else 1 (a lane that does not forget has 1 anyway). */
    for (m = 0; m < NPOP; ++m) {
        acc[m] = R(0.0);
    }
    for (r = 0; r < L; ++r) {
        const rhonn_real *POP_RESTRICT d = LANE(P, rs[r]), *POP_RESTRICT pr = LANE(pz, r);
        for (m = 0; m < NPOP; ++m) {
            acc[m] += d[m] - (pr[m] * inv_s[m]) * pr[m];
        }
    }
    for (m = 0; m < NPOP; ++m) {
        ilam[m] = acc[m] * ilam_cfg[m] <= ceil_i[m] ? ilam_cfg[m] : R(1.0);
    }
    /* eq. 7: (P - (P z)(P z)^T M) / lambda + Q. Without forgetting rhonn.c
     * skips the division; multiplying by 1 instead is exact. */
    for (r = 0; r < L; ++r) {
        const rhonn_real *POP_RESTRICT row = LANE(P, rs[r]);
        rhonn_real *POP_RESTRICT out = LANE(Pn, rs[r]);
        const rhonn_real *POP_RESTRICT pr = LANE(pz, r);
        const rhonn_real *POP_RESTRICT qr = LANE(q, r);
        len = L - r;
        for (m = 0; m < NPOP; ++m) {
            kr[m] = pr[m] * inv_s[m];
        }
        for (c = 0; c < len; ++c) {
            const rhonn_real *POP_RESTRICT pc = LANE(row, c), *POP_RESTRICT zc = LANE(pz, r + c);
            rhonn_real *POP_RESTRICT oc = LANE(out, c);
            for (m = 0; m < NPOP; ++m) {
                oc[m] = (pc[m] - kr[m] * zc[m]) * ilam[m];
            }
        }
        for (m = 0; m < NPOP; ++m) {
            out[m] += qr[m];
        }
    }
    /* The trace ceiling: scaled by p_trace_max / trace when above it (a
     * scale of exactly 1 elsewhere changes nothing). */
    for (m = 0; m < NPOP; ++m) {
        acc[m] = R(0.0);
    }
    for (r = 0; r < L; ++r) {
        const rhonn_real *POP_RESTRICT d = LANE(Pn, rs[r]);
        for (m = 0; m < NPOP; ++m) {
            acc[m] += d[m];
        }
    }
    for (m = 0; m < NPOP; ++m) {
        const int over = (ptm[m] > R(0.0)) & (acc[m] > ptm[m]);
        scale[m] = over ? ptm[m] / acc[m] : R(1.0);
        wk->bounded[i][m] = (uint8_t)over;
    }
    for (c = 0; c < packed; ++c) {
        rhonn_real *POP_RESTRICT pc = LANE(Pn, c);
        for (m = 0; m < NPOP; ++m) {
            pc[m] *= scale[m];
        }
    }
    /* The check: the proofs, then the shifted factorisation, then the
     * plain one, each only for what the one before left open. */
    if (lane_proofs(wk, i, L, inv_s, fast)) {
        for (m = 0; m < NPOP; ++m) {
            wk->cert_new[i][m] = fast[m];
            pd_ok[m] = R(1.0);
        }
    } else {
        rhonn_real shift[RHONN_MAX_POPULATION], shifted_ok[RHONN_MAX_POPULATION];
        for (m = 0; m < NPOP; ++m) {
            shift[m] = rhonn_proof_shift(L);
        }
        loops_check(wk, Pn, L, rs, shift, shifted_ok);
        if (plain_needed(wk, i, fast, shifted_ok)) {
            rhonn_real plain_ok[RHONN_MAX_POPULATION];
            for (m = 0; m < NPOP; ++m) {
                shift[m] = R(0.0);
            }
            loops_check(wk, Pn, L, rs, shift, plain_ok);
            proof_verdicts(wk, i, fast, shifted_ok, plain_ok, pd_ok);
        } else {
            proof_verdicts(wk, i, fast, shifted_ok, NULL, pd_ok);
        }
    }
    /* The verdicts, in rhonn.c's order: the innovation (s finite and
     * s >= R), the weights finite, then P positive definite, and which way a
     * refused P failed (a non-finite entry, or not definite). */
    for (m = 0; m < NPOP; ++m) {
        wsum[m] = R(0.0);
    }
    for (r = 0; r < L; ++r) {
        const rhonn_real *POP_RESTRICT wr = LANE(wn, r);
        for (m = 0; m < NPOP; ++m) {
            wsum[m] += wr[m] - wr[m];
        }
    }
    verdicts(wk, i, Pn, packed, s, rr, wsum, pd_ok, NULL);
}

POP_CLONES static void full_kernel(rhonn_population_work *wk, size_t i, size_t L)
{
    full_kernel_loops(wk, i, L);
}
#else

/* The trace ceiling's factor: p_trace_max / trace where the trace is above
 * a ceiling, exactly 1 elsewhere (scaling by it changes nothing), member by
 * member (a vector compare's mask converts poorly on some targets, and
 * this runs once per neuron); marks the members bounded. */
static void trace_scale(rhonn_population_work *wk, size_t i, const rhonn_real *trace, rhonn_real *scale)
{
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        const rhonn_real ptm = wk->p_trace_max[i][m];
        const int over = ptm > R(0.0) && trace[m] > ptm;
        scale[m] = over ? ptm / trace[m] : R(1.0);
        wk->bounded[i][m] = (uint8_t)over;
    }
}

/* Whether some member of neuron i has the trace ceiling on. Where none
 * has, the ceiling's work (a trace, a scaling by exactly 1) changes nothing
 * and is skipped; no member is bounded (the step clears bounded before the
 * kernels). Constant for a call: see lane_flags. */
static int any_ceiling(const rhonn_population_work *wk, size_t i)
{
    return wk->ceiling[i];
}

/* Whether some member of neuron i forgets (1 / lambda is exactly 1 for the
 * others): where none does, the multiplication by 1 is skipped, as rhonn.c
 * skips it. Constant for a call: see lane_flags. */
static int any_forgetting(const rhonn_population_work *wk, size_t i)
{
    return wk->forgets[i];
}

/* e^2 / s into nis and eq. 7's w + (eta e / s) k, k = P z, into the
 * candidate weights (rhonn.c: nis = e (e M), gain = eta e M, w + gain k);
 * returns the sum of w - w over them: 0 when all are finite, else NaN. */
POP_ALWAYS_INLINE void weights_update(rhonn_population_work *wk, size_t i, size_t L, const rhonn_real *inv_s,
                                      const rhonn_real *k, rhonn_real *wsum_out)
{
    const rhonn_real *w = &wk->w[wk->wb][i][0][0];
    rhonn_real *wn = &wk->w[wk->wb ^ 1u][i][0][0];
    const lanev e = VC(wk->e, 0), inv = VC(inv_s, 0);
    const lanev gain = VC(wk->eta[i], 0) * e * inv;
    lanev wsum = e - e;
    size_t r;
    V(wk->nis[i], 0) = e * (e * inv);
    for (r = 0; r < L; ++r) {
        const lanev wr = VC(w, r) + gain * VC(k, r);
        V(wn, r) = wr;
        wsum += wr - wr;
    }
    V(wsum_out, 0) = wsum;
}

/* The full-form kernel (rhonn.c ekf_kernel, then pd_check), every member at
 * once, operation for operation: eq. 8 s = R + z^T P z, eq. 7
 * w + (eta e / s) P z and (P - (P z)(P z)^T / s) / lambda + Q, the trace
 * ceiling, and the U D U^T factorisation of the scaled P(k+1), whose
 * pivots must be positive. No branch on a member's numbers: the verdicts
 * are gathered as masks and read at the end. */
/* rhonn_proof_holds (rhonn_internal.h) for every member at once: the same
 * operations on each lane's numbers, in the same order, so each lane's
 * verdict is the scalar one (the tests compare the proofs' flags with
 * rhonn_run's); its early exits become a mask. holds[m] is all ones where
 * the proof holds, else 0. */
POP_ALWAYS_INLINE void vec_proof_holds(const lanev *tr_, const lanev *pzz, const lanev *vv, const lanev *zv,
                                       const lanev *pmax_, const lanev *qmin_, const lanev *r_, const lanev *inv_s,
                                       size_t L, pop_ubits *holds)
{
    const lanev tr = *tr_, pmax = *pmax_, qmin = *qmin_, r_i = *r_;
    const rhonn_real unit = RHONN_EPSILON * R(0.5);
    const rhonn_real gl = R(1.01) * (rhonn_real)L * unit, g1 = R(1.01) * (rhonn_real)(L + 1u) * unit;
    const lanev ww = (rhonn_real)L * *pzz;
    const lanev r_low = r_i - gl * ww;
    const lanev rho = g1 * (r_i + *zv) * *inv_s;
    const lanev vs = *vv * *inv_s;
    const lanev eta_r = R(2.0) * (gl * gl) * (tr * ww);
    const lanev err = (R(3.0) * rho + R(8.0) * unit) * vs + R(2.0) * unit * (tr + pmax);
    const lanei ok = (lanei)(qmin >= R(16.0) * RHONN_MIN_NORMAL) & (lanei)(r_low > R(0.0)) &
                     (lanei)(rho <= R(0.25)) & (lanei)(tr + vs <= RHONN_MAX_REAL * R(0.25)) &
                     (lanei)(pmax <= RHONN_MAX_REAL);
    const lanei all = ok & (lanei)(R(1.125) * eta_r <=
                                   (qmin - R(1.125) * (err + R(1.01) * (rhonn_real)L * g1 * pmax)) * r_low);
    *(lanei *)holds = all;
}

/* For the tests (rhonn_internal.h): vec_proof_holds on lanes given as
 * arrays, in[k * RHONN_MAX_POPULATION + m] for k = tr, pzz, vv, zv, pmax,
 * qmin, r_i, inv_s; out[m] 1 where the proof holds. */
void rhonn_internal_proof_lanes(const rhonn_real *in, size_t L, uint8_t *out)
{
    pop_ubits holds[RHONN_MAX_POPULATION];
    size_t m;
    vec_proof_holds(&VC(in, 0), &VC(in, 1), &VC(in, 2), &VC(in, 3), &VC(in, 4), &VC(in, 5), &VC(in, 6),
                    &VC(in, 7), L, holds);
    for (m = 0; m < NPOP; ++m) {
        out[m] = (uint8_t)(holds[m] != 0u);
    }
}

/* lane_proofs of the loop kernel with the sums over the terms done for
 * every member at once (the largest diagonal by a mask: no NaN reaches it,
 * as P and the gain's products are finite here), then each member's tail
 * (rhonn_proof_holds). */
POP_ALWAYS_INLINE int vec_proofs(rhonn_population_work *wk, size_t i, size_t L, const size_t *rs,
                                 const rhonn_real *inv_s, uint8_t *fast)
{
    const rhonn_real *P = &wk->p[wk->pb[i]][i][0][0], *Pn = &wk->p[wk->pb[i] ^ 1u][i][0][0];
    const rhonn_real *z = &wk->z[wk->zb][i][0][0], *pz = &wk->pz[0][0];
    const lanev zero = VC(wk->zeros, 0);
    lanev tr = zero, pzz = zero, vv = zero, zv = zero, pmax = zero;
    pop_ubits a_holds[RHONN_MAX_POPULATION];
    size_t r, m;
    uint8_t all = 1;
    for (r = 0; r < L; ++r) {
        const lanev d = VC(P, rs[r]), zr = VC(z, r), vr = VC(pz, r), dn = VC(Pn, rs[r]);
        const lanev az = (lanev)((lanei)zr & (pop_ubits)POP_ABS_MASK);
        const lanev av = (lanev)((lanei)vr & (pop_ubits)POP_ABS_MASK);
        const lanei gt = (lanei)(dn > pmax);
        tr += d;
        pzz += (d * zr) * zr;
        vv += vr * vr;
        zv += az * av;
        pmax = (lanev)(((lanei)dn & gt) | ((lanei)pmax & ~gt));
    }
    vec_proof_holds(&tr, &pzz, &vv, &zv, &pmax, &VC(wk->q_min[i], 0), &VC(wk->r[i], 0), &VC(inv_s, 0), L, a_holds);
    {
        /* fast = learn & cert & (1 / lambda == 1) & !bounded & the proof, as
         * masks of every lane at once (the flags are 0 or 1) */
        lanei learn, flags, keep;
        for (m = 0; m < NPOP; ++m) {
            learn[m] = wk->learn[i][m];
            flags[m] = (pop_ubits)(wk->cert[i][m] != 0u) & (pop_ubits)(wk->bounded[i][m] ^ 1u);
        }
        keep = learn & flags & (lanei)(VC(wk->ilam_step, 0) == R(1.0)) & *(const lanei *)a_holds;
        for (m = 0; m < NPOP; ++m) {
            fast[m] = (uint8_t)keep[m];
            all &= (uint8_t)(keep[m] | (learn[m] ^ 1u));
        }
    }
    return all;
}

/* The check of full_kernel (rhonn.c scaled_udu + udu_factor) with shift[m]
 * subtracted from each scaled diagonal entry (0: the plain check, x - 0
 * being x bit for bit): out_ok[m] 1 when member m passed. Off the hot path
 * (the proofs cover most updates): compiled once, not into every size of
 * the kernel. */
POP_CLONES static void vec_check(rhonn_population_work *wk, const rhonn_real *Pn, size_t L, const size_t *rs,
                                 const rhonn_real *shift, rhonn_real *out_ok)
{
    rhonn_real *F = &wk->f[0][0], *sc = &wk->sc[0][0];
    rhonn_real *tk = &wk->tk[0][0], *dk = &wk->dk[0][0];
    const lanev one = VC(wk->zeros, 0) + R(1.0);
    size_t r, j, k, ii, m;

    /* The check (rhonn.c scaled_udu + udu_factor): each diagonal normal and
     * finite (MIN_NORMAL <= v <= MAX, false for NaN) and scaled by 2^-h,
     * h = floor(e / 2), built from its exponent bits; then every pivot
     * positive and finite. */
    for (r = 0; r < L; ++r) {
        const lanev d = VC(Pn, rs[r]);
        const lanei b = ((lanei)d >> POP_EXP_SHIFT) & POP_EXP_FIELD;
        V(sc, r) = (lanev)((POP_SCALE_TOP - ((b + POP_SCALE_ADD) >> 1)) << POP_EXP_SHIFT);
    }
    for (j = L; j-- > 0u;) {
        const size_t tail = L - 1u - j;
        const lanev sj = V(sc, j);
        lanev dj = (VC(Pn, rs[j]) * sj) * sj - VC(shift, 0), inv;
        for (k = 0; k < tail; ++k) {
            const lanev ujk = V(F, rs[j] + 1u + k), t = V(dk, j + 1u + k) * ujk;
            V(tk, k) = t;
            dj -= ujk * t;
        }
        V(dk, j) = dj;
        V(F, rs[j]) = dj;
        inv = one / dj;
        for (ii = 0; ii < j; ++ii) {
            const size_t at = rs[ii] + (j - ii);
            lanev a = (VC(Pn, at) * V(sc, ii)) * sj;
            for (k = 0; k < tail; ++k) {
                a -= V(F, at + 1u + k) * V(tk, k);
            }
            V(F, at) = a * inv;
        }
    }
    /* the pivots' verdict, member by member from the stored d_j and the
     * diagonal (vector compares' masks convert poorly on some targets) */
    for (m = 0; m < NPOP; ++m) {
        out_ok[m] = R(1.0);
    }
    for (r = 0; r < L; ++r) {
        const rhonn_real *d = LANE(Pn, rs[r]), *pv = LANE(dk, r);
        for (m = 0; m < NPOP; ++m) {
            const int good = d[m] >= RHONN_MIN_NORMAL && d[m] <= RHONN_MAX_REAL && pv[m] > R(0.0) &&
                             pv[m] <= RHONN_MAX_REAL;
            out_ok[m] = good ? out_ok[m] : R(0.0);
        }
    }
}

POP_ALWAYS_INLINE void full_kernel_body(rhonn_population_work *wk, size_t i, size_t L)
{
    const rhonn_real *P = &wk->p[wk->pb[i]][i][0][0];
    rhonn_real *Pn = &wk->p[wk->pb[i] ^ 1u][i][0][0];
    const rhonn_real *z = &wk->z[wk->zb][i][0][0];
    const rhonn_real *q = &wk->q[i][0][0];
    rhonn_real *pz = &wk->pz[0][0];
    const lanev rr = VC(wk->r[i], 0);
    const lanev zero = VC(wk->zeros, 0);
    const lanev one = zero + R(1.0);
    lanev s, inv_s, acc, s0, s1, scale, ilam = one;
    size_t rs[RHONN_MAX_TERMS];
    size_t r, c, len;
    const size_t packed = L * (L + 1u) / 2u;
    rhonn_real out_s[RHONN_MAX_POPULATION], out_wsum[RHONN_MAX_POPULATION], out_ok[RHONN_MAX_POPULATION];
    rhonn_real tmp[RHONN_MAX_POPULATION];
    uint8_t fast[RHONN_MAX_POPULATION];
    size_t m;
    int forgets;

    rs[0] = 0;
    POP_UNROLL
    for (r = 0; r + 1u < L; ++r) {
        rs[r + 1u] = rs[r] + (L - r);
    }
    /* pz = P z from the packed triangle: row r scatters z_r P(r, c > r)
     * into pz[c], then adds its own dot product (two accumulators, even
     * and odd entries: rhonn.c's dot) */
    POP_UNROLL
    for (r = 0; r < L; ++r) {
        V(pz, r) = zero;
    }
    POP_UNROLL
    for (r = 0; r < L; ++r) {
        const lanev zr = VC(z, r);
        len = L - r;
        for (c = 1; c < len; ++c) {
            V(pz, r + c) += VC(P, rs[r] + c) * zr;
        }
        s0 = zero;
        s1 = zero;
        for (c = 0; c + 1u < len; c += 2u) {
            s0 += VC(P, rs[r] + c) * VC(z, r + c);
            s1 += VC(P, rs[r] + c + 1u) * VC(z, r + c + 1u);
        }
        if (c < len) {
            s0 += VC(P, rs[r] + c) * VC(z, r + c);
        }
        V(pz, r) += s0 + s1;
    }
    /* eq. 8: s = R + z^T P z, M = 1 / s; eq. 7's gain eta e M */
    s0 = zero;
    s1 = zero;
    POP_UNROLL
    for (c = 0; c + 1u < L; c += 2u) {
        s0 += VC(z, c) * V(pz, c);
        s1 += VC(z, c + 1u) * V(pz, c + 1u);
    }
    if (c < L) {
        s0 += VC(z, c) * V(pz, c);
    }
    s = rr + (s0 + s1);
    inv_s = one / s;
    /* eq. 7: w + (eta e M) P z */
    V(tmp, 0) = inv_s;
    weights_update(wk, i, L, tmp, pz, out_wsum);
    /* eq. 7: (P - (P z)(P z)^T M) / lambda + Q. Without forgetting rhonn.c
     * skips the division; a member without it among members with it
     * multiplies by 1, which is exact. */
    forgets = any_forgetting(wk, i);
    if (forgets) {
        /* bounded forgetting (rhonn.c ekf_kernel): 1 / lambda where the
         * trace of P - (P z)(P z)^T M, its diagonal as formed below, stays
         * within the ceiling after it; else 1 */
        const lanev ilam_cfg = VC(wk->inv_lambda[i], 0);
        lanei forget;
        acc = zero;
        POP_UNROLL
        for (r = 0; r < L; ++r) {
            acc += VC(P, rs[r]) - (V(pz, r) * inv_s) * V(pz, r);
        }
        forget = (lanei)(acc * ilam_cfg <= VC(wk->forget_ceiling[i], 0));
        ilam = (lanev)(((lanei)ilam_cfg & forget) | ((lanei)one & ~forget));
    }
    V(wk->ilam_step, 0) = ilam;
    POP_UNROLL
    for (r = 0; r < L; ++r) {
        const lanev kr = V(pz, r) * inv_s;
        len = L - r;
        if (forgets) {
            for (c = 0; c < len; ++c) {
                V(Pn, rs[r] + c) = (VC(P, rs[r] + c) - kr * V(pz, r + c)) * ilam;
            }
        } else {
            for (c = 0; c < len; ++c) {
                V(Pn, rs[r] + c) = VC(P, rs[r] + c) - kr * V(pz, r + c);
            }
        }
        V(Pn, rs[r]) += VC(q, r);
    }
    /* The trace ceiling: P(k+1) scaled by p_trace_max / trace when above
     * it; by exactly 1 elsewhere, which changes nothing. */
    if (any_ceiling(wk, i)) {
        acc = zero;
        POP_UNROLL
        for (r = 0; r < L; ++r) {
            acc += V(Pn, rs[r]);
        }
        V(out_s, 0) = acc;
        trace_scale(wk, i, out_s, tmp);
        scale = VC(tmp, 0);
        for (c = 0; c < packed; ++c) {
            V(Pn, c) *= scale;
        }
    }
    /* The check: the proofs, then the shifted factorisation, then the
     * plain one, each only for what the one before left open. */
    V(tmp, 0) = inv_s;
    if (vec_proofs(wk, i, L, rs, tmp, fast)) {
        for (m = 0; m < NPOP; ++m) {
            wk->cert_new[i][m] = fast[m];
            out_ok[m] = R(1.0);
        }
    } else {
        rhonn_real shifted_ok[RHONN_MAX_POPULATION];
        V(tmp, 0) = zero + rhonn_proof_shift(L);
        vec_check(wk, Pn, L, rs, tmp, shifted_ok);
        if (plain_needed(wk, i, fast, shifted_ok)) {
            rhonn_real plain_ok[RHONN_MAX_POPULATION];
            vec_check(wk, Pn, L, rs, wk->zeros, plain_ok);
            proof_verdicts(wk, i, fast, shifted_ok, plain_ok, out_ok);
        } else {
            proof_verdicts(wk, i, fast, shifted_ok, NULL, out_ok);
        }
    }
    for (m = 0; m < NPOP; ++m) {
        out_s[m] = s[m];
        tmp[m] = rr[m];
    }
    verdicts(wk, i, Pn, packed, out_s, tmp, out_wsum, out_ok, NULL);
}

/* body(wk, i, L) compiled once per size up to 8 terms (a constant L, its
 * loops unrolled), the same operations in the same order as the runtime-L
 * copy that runs larger neurons. */
#define POP_BY_SIZE(body, wk, i, L)                                                                                  \
    switch (L) {                                                                                                     \
    case 1: body(wk, i, 1); return;                                                                                  \
    case 2: body(wk, i, 2); return;                                                                                  \
    case 3: body(wk, i, 3); return;                                                                                  \
    case 4: body(wk, i, 4); return;                                                                                  \
    case 5: body(wk, i, 5); return;                                                                                  \
    case 6: body(wk, i, 6); return;                                                                                  \
    case 7: body(wk, i, 7); return;                                                                                  \
    case 8: body(wk, i, 8); return;                                                                                  \
    default: body(wk, i, L);                                                                                         \
    }

POP_CLONES static void full_kernel(rhonn_population_work *wk, size_t i, size_t L)
{
    POP_BY_SIZE(full_kernel_body, wk, i, L)
}

/* The U D U^T form (rhonn.c ekf_ud), every member at once, operation for
 * operation. Measurement (Bierman): f = U^T z, v = D f, a_0 = R,
 * a_j = a_{j-1} + f_j v_j, d_j a_{j-1} / a_j, U(k,j) + (-f_j / a_{j-1}) b_k,
 * the gain b / s; then D / lambda and + Q by Agee and Turner's rank-one
 * updates P + q_J e_J e_J^T. */
POP_ALWAYS_INLINE void ud_kernel_body(rhonn_population_work *wk, size_t i, size_t L)
{
    const rhonn_real *F = &wk->p[wk->pb[i]][i][0][0];
    rhonn_real *Fn = &wk->p[wk->pb[i] ^ 1u][i][0][0];
    const rhonn_real *z = &wk->z[wk->zb][i][0][0];
    const rhonn_real *q = &wk->q[i][0][0];
    rhonn_real *wu = &wk->uw[0][0];
    rhonn_real *f = &wk->ua[0][0][0], *v = &wk->ua[1][0][0], *b = &wk->ua[2][0][0], *dt = &wk->ua[3][0][0];
    rhonn_real *a = &wk->ua[4][0][0];
    uint8_t zero_q[RHONN_MAX_POPULATION];
    int any_q;
    const lanev rr = VC(wk->r[i], 0), ilam_cfg = VC(wk->inv_lambda[i], 0);
    const lanev zero = VC(wk->zeros, 0);
    const lanev one = zero + R(1.0);
    lanev alpha, inv_prev, fsum, tr;
    rhonn_real out_s[RHONN_MAX_POPULATION], out_wsum[RHONN_MAX_POPULATION], out_ok[RHONN_MAX_POPULATION];
    rhonn_real out_fsum[RHONN_MAX_POPULATION], tmp[RHONN_MAX_POPULATION];
    size_t rs[RHONN_MAX_TERMS];
    size_t j, k, c, m;
    const size_t packed = L * (L + 1u) / 2u;

    rs[0] = 0;
    POP_UNROLL
    for (j = 0; j + 1u < L; ++j) {
        rs[j + 1u] = rs[j] + (L - j);
    }
    /* f = U^T z (U unit upper triangular), v = D f */
    POP_UNROLL
    for (j = 0; j < L; ++j) {
        V(f, j) = VC(z, j);
    }
    POP_UNROLL
    for (k = 0; k < L; ++k) {
        for (j = k + 1u; j < L; ++j) {
            V(f, j) += VC(F, rs[k] + (j - k)) * VC(z, k);
        }
    }
    POP_UNROLL
    for (j = 0; j < L; ++j) {
        V(v, j) = VC(F, rs[j]) * V(f, j);
    }
    /* Bierman's update, column by column; wu receives U~ with a unit diagonal */
    alpha = rr;
    inv_prev = zero;
    POP_UNROLL
    for (j = 0; j < L; ++j) {
        const lanev lam = -V(f, j) * inv_prev;
        const lanev alpha_new = alpha + V(f, j) * V(v, j);
        const lanev inv = one / alpha_new;
        V(dt, j) = VC(F, rs[j]) * (alpha * inv);
        for (k = 0; k < j; ++k) {
            const size_t idx = rs[k] + (j - k);
            const lanev ukj = VC(F, idx);
            V(wu, idx) = ukj + lam * V(b, k);
            V(b, k) += ukj * V(v, j);
        }
        V(wu, rs[j]) = one;
        V(b, j) = V(v, j);
        alpha = alpha_new;
        inv_prev = inv;
    }
    V(tmp, 0) = inv_prev;
    weights_update(wk, i, L, tmp, b, out_wsum);
    /* / lambda where trace(U~ D~ U~^T) / lambda stays within the ceiling
     * (rhonn.c ekf_ud: bounded forgetting); rhonn.c skips it without
     * forgetting, and * 1 is exact */
    if (any_forgetting(wk, i)) {
        lanev ilam;
        lanei forget;
        tr = zero;
        for (j = 0; j < L; ++j) {
            lanev col = one;
            for (k = 0; k < j; ++k) {
                const lanev u = V(wu, rs[k] + (j - k));
                col += u * u;
            }
            tr += V(dt, j) * col;
        }
        forget = (lanei)(tr * ilam_cfg <= VC(wk->forget_ceiling[i], 0));
        ilam = (lanev)(((lanei)ilam_cfg & forget) | ((lanei)one & ~forget));
        for (j = 0; j < L; ++j) {
            V(dt, j) *= ilam;
        }
    }
    /* The measurement's factors into the new bank, then + Q in place by
     * rank-one updates (rhonn.c ekf_ud, operation for operation). rhonn.c
     * skips them for a neuron whose Q is all zero: here they run unless
     * every member's Q is zero, and a member with a zero Q gets the
     * measurement's factors back afterwards. */
    POP_UNROLL
    for (j = 0; j < L; ++j) {
        V(Fn, rs[j]) = V(dt, j);
        for (k = 0; k < j; ++k) {
            V(Fn, rs[k] + (j - k)) = V(wu, rs[k] + (j - k));
        }
    }
    any_q = 0;
    for (m = 0; m < NPOP; ++m) {
        zero_q[m] = 1;
        for (j = 0; j < L; ++j) {
            zero_q[m] = (uint8_t)(zero_q[m] && q[j * NPOP + m] == R(0.0));
        }
        any_q |= !zero_q[m];
    }
    if (any_q) {
        size_t J;
        POP_UNROLL
        for (J = 0; J < L; ++J) {
            lanev cw = VC(q, J), dj = V(Fn, rs[J]), dn = dj + cw, inv_dn = one / dn, bj, ratio = dj * inv_dn;
            cw = cw * ratio;
            V(Fn, rs[J]) = dn;
            for (k = 0; k < J; ++k) {
                V(a, k) = -V(Fn, rs[k] + (J - k));
                V(Fn, rs[k] + (J - k)) *= ratio;
            }
            for (j = J; j-- > 0u;) {
                const lanev p = V(a, j);
                dj = V(Fn, rs[j]);
                dn = dj + cw * (p * p);
                inv_dn = one / dn;
                bj = (cw * p) * inv_dn;
                ratio = dj * inv_dn;
                cw = cw * ratio;
                V(Fn, rs[j]) = dn;
                for (k = 0; k < j; ++k) {
                    const lanev u = V(Fn, rs[k] + (j - k));
                    V(Fn, rs[k] + (j - k)) = u * ratio + bj * V(a, k);
                    V(a, k) -= p * u;
                }
            }
        }
        for (m = 0; m < NPOP; ++m) {
            if (zero_q[m]) {
                for (j = 0; j < L; ++j) {
                    Fn[rs[j] * NPOP + m] = dt[j * NPOP + m];
                    for (k = 0; k < j; ++k) {
                        Fn[(rs[k] + (j - k)) * NPOP + m] = wu[(rs[k] + (j - k)) * NPOP + m];
                    }
                }
            }
        }
    }
    {
        /* rhonn.c: a d~_j that underflowed (or is NaN) refuses; 1 or 0 by
         * a mask on 1's bits */
        lanei pos = (lanei)(one > zero);
        for (j = 0; j < L; ++j) {
            pos &= (lanei)(V(Fn, rs[j]) > zero);
        }
        V(out_ok, 0) = (lanev)((lanei)one & pos);
    }
    /* The trace ceiling: trace(U D U^T) = sum_j d_j (1 + sum_{i<j} U(i,j)^2);
     * above p_trace_max, D scaled by p_trace_max / trace (by 1 elsewhere). */
    if (any_ceiling(wk, i)) {
        tr = zero;
        for (j = 0; j < L; ++j) {
            lanev col = one;
            for (k = 0; k < j; ++k) {
                const lanev u = V(Fn, rs[k] + (j - k));
                col += u * u;
            }
            tr += V(Fn, rs[j]) * col;
        }
        V(out_s, 0) = tr;
        trace_scale(wk, i, out_s, tmp);
        for (j = 0; j < L; ++j) {
            V(Fn, rs[j]) *= VC(tmp, 0);
            V(out_s, 0) = V(Fn, rs[j]);
            for (m = 0; m < NPOP; ++m) {
                out_ok[m] = out_s[m] > R(0.0) ? out_ok[m] : R(0.0); /* scaled into underflow */
            }
        }
    }
    fsum = zero;
    POP_UNROLL
    for (c = 0; c < packed; ++c) {
        fsum += V(Fn, c) - V(Fn, c);
    }
    V(out_s, 0) = alpha;
    V(out_fsum, 0) = fsum;
    verdicts(wk, i, Fn, packed, out_s, wk->r[i], out_wsum, out_ok, out_fsum);
}

POP_CLONES static void ud_kernel(rhonn_population_work *wk, size_t i, size_t L)
{
    POP_BY_SIZE(ud_kernel_body, wk, i, L)
}

#endif

/* The U D U^T neurons' update: the vector kernel above, or (portable
 * build) rhonn.c's own kernel member by member, on the member's lane
 * copied into its committed bank and the candidate copied back. */
static void ud_update(rhonn_population_work *wk, rhonn_t *const *nets, size_t N, size_t i, size_t L)
{
#if RHONN_POP_VECTOR
    (void)nets;
    (void)N;
    ud_kernel(wk, i, L);
#else
    size_t m, t;
    wk->k_moved = 0;
    wk->k_refused = 0;
    for (m = 0; m < NPOP; ++m) {
        wk->updated[i][m] = 0;
    }
    for (m = 0; m < N; ++m) {
        rhonn_t *net = nets[m];
        const size_t b = net->bank[i];
        rhonn_real zk[RHONN_MAX_TERMS], nis = R(0.0);
        uint8_t bnd = 0;
        if (!wk->learn[i][m]) {
            continue;
        }
        for (t = 0; t < L; ++t) {
            zk[t] = wk->z[wk->zb][i][t][m];
            net->w[i][b][t] = wk->w[wk->wb][i][t][m];
        }
        for (t = 0; t < L * (L + 1u) / 2u; ++t) {
            net->p[i][b][t] = wk->p[wk->pb[i]][i][t][m];
        }
        wk->kstatus[m] = (uint8_t)rhonn_internal_ekf_update(net, i, wk->e[m], zk, &nis, &bnd);
        wk->updated[i][m] = (uint8_t)(wk->kstatus[m] == (uint8_t)RHONN_OK);
        wk->k_moved |= wk->updated[i][m];
        wk->k_refused |= (uint8_t)(wk->updated[i][m] ^ 1u);
        wk->nis[i][m] = nis;
        wk->bounded[i][m] = bnd;
        for (t = 0; t < L; ++t) {
            wk->w[wk->wb ^ 1u][i][t][m] = net->w[i][b ^ 1u][t];
        }
        for (t = 0; t < L * (L + 1u) / 2u; ++t) {
            wk->p[wk->pb[i] ^ 1u][i][t][m] = net->p[i][b ^ 1u][t];
        }
    }
#endif
}

/* xhat(k+1) = w(k+1)^T z(k) (eq. 3) of every neuron, every member at once:
 * rhonn.c's running sum, term by term from 0. */
POP_ALWAYS_INLINE void predict_slot(rhonn_population_work *wk, size_t i, size_t L, size_t zb)
{
    const rhonn_real *w = &wk->w[wk->wb ^ 1u][i][0][0], *z = &wk->z[zb][i][0][0];
    size_t t;
#if RHONN_POP_VECTOR
    lanev acc = VC(wk->zeros, 0);
    for (t = 0; t < L; ++t) {
        acc += VC(w, t) * VC(z, t);
    }
    V(wk->xnew[i], 0) = acc;
#else
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        wk->xnew[i][m] = R(0.0);
    }
    for (t = 0; t < L; ++t) {
        for (m = 0; m < NPOP; ++m) {
            wk->xnew[i][m] += w[t * NPOP + m] * z[t * NPOP + m];
        }
    }
#endif
}

POP_CLONES static void predict(rhonn_population_work *wk, const rhonn_t *net, size_t zb)
{
    const rhonn_config *cfg = CFG(net);
    size_t i;
    for (i = 0; i < cfg->n_states; ++i) {
        predict_slot(wk, i, cfg->neurons[i].n_terms, zb);
    }
}

/* A refused update recovered (reset_after): the weights kept, the
 * covariance restarted from neuron's P(0) with P(0)'s proof, into the
 * candidates of slot i, lane m (rhonn.c refused()). */
static void recover_lane(rhonn_population_work *wk, const rhonn_t *net, size_t neuron, size_t i, size_t m)
{
    const size_t L = CFG(net)->neurons[neuron].n_terms;
    rhonn_real p0[RHONN_MAX_PACKED];
    size_t t;
    for (t = 0; t < L; ++t) {
        wk->w[wk->wb ^ 1u][i][t][m] = wk->w[wk->wb][i][t][m];
    }
    rhonn_internal_load_p0(net, neuron, p0); /* P(0) or its factors */
    for (t = 0; t < L * (L + 1u) / 2u; ++t) {
        wk->p[wk->pb[i] ^ 1u][i][t][m] = p0[t];
    }
    wk->cert_new[i][m] = rhonn_internal_p0_proven(net, neuron);
    wk->bounded[i][m] = 0;
    wk->recovered[i][m] = 1;
}

/* A refused update skipped (skip_refused): w(k+1) = w(k) into the
 * candidates of slot i, lane m; the lane is not updated, so its P(k) is
 * kept as for a lane that did not learn (rhonn.c refused()). */
static void skip_lane(rhonn_population_work *wk, size_t i, size_t L, size_t m)
{
    size_t t;
    for (t = 0; t < L; ++t) {
        wk->w[wk->wb ^ 1u][i][t][m] = wk->w[wk->wb][i][t][m];
    }
    wk->updated[i][m] = 0;
    wk->bounded[i][m] = 0;
}

/* ------------------------------------------------------------------------ */
/* Loading and storing a member's lane */

static int is_ud(const rhonn_t *net, size_t i)
{
    return CFG(net)->neurons[i].covariance == (uint8_t)RHONN_COV_UD;
}

/* Member net's committed state and tuning into lane m. */
/* Which neurons (of the first n) have the trace ceiling on in some lane,
 * which forget in some lane and which have an innovation gate on in some
 * lane, once the lanes are loaded: any_ceiling and any_forgetting read them
 * in every kernel call, the step reads gating after it. */
static void lane_flags(rhonn_population_work *wk, size_t n)
{
    size_t i, m;
    for (i = 0; i < n; ++i) {
        uint8_t ceiling = 0, forgets = 0, gating = 0;
        for (m = 0; m < NPOP; ++m) {
            ceiling |= (uint8_t)(wk->p_trace_max[i][m] > R(0.0));
            forgets |= (uint8_t)(wk->inv_lambda[i][m] != R(1.0));
            gating |= (uint8_t)(wk->gate[i][m] > R(0.0));
        }
        wk->ceiling[i] = ceiling;
        wk->forgets[i] = forgets;
        wk->gating[i] = gating;
    }
}

static void load_lane(rhonn_population_work *wk, const rhonn_t *net, size_t m)
{
    const rhonn_config *cfg = CFG(net);
    size_t i, t;
    for (i = 0; i < cfg->n_states; ++i) {
        const rhonn_neuron_config *nc = &cfg->neurons[i];
        const size_t L = nc->n_terms, b = net->bank[i];
        for (t = 0; t < L; ++t) {
            wk->w[wk->wb][i][t][m] = net->w[i][b][t];
            wk->z[wk->zb][i][t][m] = net->z[net->zbank][i][t];
            wk->q[i][t][m] = nc->q[t];
        }
        for (t = 0; t < L * (L + 1u) / 2u; ++t) {
            wk->p[wk->pb[i]][i][t][m] = net->p[i][b][t];
        }
        wk->cert[i][m] = nc->covariance == (uint8_t)RHONN_COV_UD ? 0u : net->cert[i][b];
        wk->q_min[i][m] = net->q_min[i];
        wk->xhat[i][m] = net->xhat[i];
        wk->r[i][m] = nc->r;
        wk->eta[i][m] = nc->eta;
        /* rhonn.c inverse_forgetting, with 1 (exact) for off */
        wk->inv_lambda[i][m] = (nc->forgetting > R(0.0) && nc->forgetting < R(1.0)) ? R(1.0) / nc->forgetting
                                                                                     : R(1.0);
        wk->forget_ceiling[i][m] = net->forget_ceiling[i];
        /* the trace ceiling and the gate in force (rhonn_set_trace_ceiling,
         * rhonn_set_gate; the configuration's until set) */
        wk->p_trace_max[i][m] = net->trace_max[i];
        wk->gate[i][m] = net->gate[i];
        wk->need[i][m] = net->own_need[i];
        wk->vrun[i][m] = net->valid_run[i];
        wk->first_run[i][m] = net->first_run[i];
        wk->flips[i][m] = 0;
        wk->run_ended[i][m] = 0;
        wk->has_last[i][m] = 0;
        wk->n_updates[i][m] = 0;
        wk->n_bounded[i][m] = 0;
        wk->n_resets[i][m] = 0;
        wk->n_gated[i][m] = 0;
        wk->last_innov[i][m] = R(0.0);
        wk->last_nis[i][m] = R(0.0);
    }
    wk->started[m] = (uint8_t)(net->started != 0u); /* 0 or 1: the lanes' flags are combined with & */
    wk->learning[m] = (uint8_t)(net->learning != 0u);
}

/* Member m's history ring brought up to date: the shared samples it was
 * owed, oldest first, into the slots its head passed (when more than the
 * ring holds were owed, the older ones would have been overwritten). */
static void pay_ring(rhonn_population_work *wk, rhonn_t *net, size_t m)
{
    const size_t len = (size_t)RHONN_HISTORY_LEN;
    size_t s;
    for (s = wk->owed[m]; s-- > 0u;) {
        rhonn_internal_store_sample(net, ((size_t)net->head + len - s) % len,
                                    wk->ring[((size_t)wk->ring_last + len - s) % len]);
    }
    wk->owed[m] = 0;
}

/* The updates of neuron i every member made alike (n_alike), counted into
 * every lane's own bookkeeping: before the members' counts part (a
 * refusal, a step in which they differ) and before a member is handed
 * back. A lane that stopped earlier is never handed back again. */
static void count_alike(rhonn_population_work *wk, size_t i)
{
    const uint32_t u = wk->n_alike[i];
    size_t m;
    if (u == 0u) {
        return;
    }
    for (m = 0; m < NPOP; ++m) {
        wk->n_updates[i][m] += u;
        wk->flips[i][m] = (uint8_t)(wk->flips[i][m] ^ (u & 1u));
        wk->run_ended[i][m] = 1;
        wk->has_last[i][m] = 1;
    }
    wk->n_alike[i] = 0;
}

/* Lane m's committed state back into its member, which committed ran
 * steps in the call: the banks flipped as its updates flipped them, the
 * weights and the stored covariance (P or its factors) into the committed
 * banks, z(k-1) into its z bank, its prediction, valid runs and health, and
 * the samples its history ring is owed. (Its started flag and history head
 * are kept in net as the run goes.) */
static void store_lane(rhonn_population_work *wk, rhonn_t *net, size_t m, size_t ran)
{
    const rhonn_config *cfg = CFG(net);
    size_t i, t;
    net->steps += (uint32_t)ran; /* wraps, as step by step */
    net->zbank = (uint8_t)(net->zbank ^ (ran & 1u));
    for (i = 0; i < cfg->n_states; ++i) {
        const size_t L = cfg->neurons[i].n_terms;
        rhonn_health *h = &net->health[i];
        size_t b;
        count_alike(wk, i);
        net->bank[i] = (uint8_t)(net->bank[i] ^ wk->flips[i][m]);
        b = net->bank[i];
        for (t = 0; t < L; ++t) {
            net->w[i][b][t] = wk->w[wk->wb][i][t][m];
            net->z[net->zbank][i][t] = wk->z[wk->zb][i][t][m];
        }
        for (t = 0; t < L * (L + 1u) / 2u; ++t) {
            net->p[i][b][t] = wk->p[wk->pb[i]][i][t][m];
        }
        /* the lane's proof of definiteness goes with its P (rhonn_t.cert) */
        net->cert[i][b] = cfg->neurons[i].covariance == (uint8_t)RHONN_COV_UD ? 0u : wk->cert[i][m];
        net->cert[i][b ^ 1u] = 0;
        net->xhat[i] = wk->xhat[i][m];
        net->valid_run[i] = wk->vrun[i][m];
        h->updates += wk->n_updates[i][m];
        h->bounded += wk->n_bounded[i][m];
        h->resets += wk->n_resets[i][m];
        h->gated += wk->n_gated[i][m];
        if (wk->has_last[i][m]) {
            h->innovation = wk->last_innov[i][m];
            h->nis = wk->last_nis[i][m];
        }
        if (wk->run_ended[i][m]) {
            h->fail_run = 0;
        }
    }
    pay_ring(wk, net, m);
}

/* Does member b's structure equal member a's? RHONN_E_CONFIG with *where
 * naming the first difference. */
static rhonn_status same_structure(const rhonn_config *a, const rhonn_config *b, size_t member,
                                   rhonn_population_error *where)
{
    size_t i, t, f;
    uint8_t field = (uint8_t)RHONN_FIELD_NONE;
    size_t fi = 0, ft = 0, ff = 0;
    if (a->n_states != b->n_states) {
        field = (uint8_t)RHONN_FIELD_N_STATES;
    } else if (a->n_inputs != b->n_inputs) {
        field = (uint8_t)RHONN_FIELD_N_INPUTS;
    }
    for (i = 0; i < a->n_states && field == (uint8_t)RHONN_FIELD_NONE; ++i) {
        const rhonn_neuron_config *na = &a->neurons[i], *nb = &b->neurons[i];
        fi = i;
        if (na->n_terms != nb->n_terms) {
            field = (uint8_t)RHONN_FIELD_N_TERMS;
        } else if (na->activation != nb->activation) {
            field = (uint8_t)RHONN_FIELD_ACTIVATION;
        } else if (na->covariance != nb->covariance) {
            field = (uint8_t)RHONN_FIELD_COVARIANCE;
        }
        for (t = 0; t < na->n_terms && field == (uint8_t)RHONN_FIELD_NONE; ++t) {
            ft = t;
            if (na->terms[t].n_factors != nb->terms[t].n_factors) {
                field = (uint8_t)RHONN_FIELD_N_FACTORS;
            }
            for (f = 0; f < na->terms[t].n_factors && field == (uint8_t)RHONN_FIELD_NONE; ++f) {
                const rhonn_factor *x = &na->terms[t].factors[f], *y = &nb->terms[t].factors[f];
                ff = f;
                if (x->kind != y->kind) {
                    field = (uint8_t)RHONN_FIELD_FACTOR_KIND;
                } else if (x->index != y->index) {
                    field = (uint8_t)RHONN_FIELD_FACTOR_INDEX;
                } else if (x->delay != y->delay) {
                    field = (uint8_t)RHONN_FIELD_FACTOR_DELAY;
                } else if (x->power != y->power) {
                    field = (uint8_t)RHONN_FIELD_FACTOR_POWER;
                }
            }
        }
    }
    if (field == (uint8_t)RHONN_FIELD_NONE) {
        return RHONN_OK;
    }
    if (where != NULL) {
        where->member = (uint8_t)member;
        where->field = field;
        where->neuron = (uint8_t)fi;
        where->term = (uint8_t)ft;
        where->factor = (uint8_t)ff;
    }
    return RHONN_E_CONFIG;
}

/* Do two members read the same S(x) through the same compiled entries
 * (the same activation groups with the same betas)? */
static int same_features(const rhonn_t *a, const rhonn_t *b)
{
    size_t g, i;
    if (a->n_groups != b->n_groups || a->n_entries != b->n_entries) {
        return 0;
    }
    for (g = 0; g < a->n_groups; ++g) {
        if (a->group_activation[g] != b->group_activation[g] || a->group_beta[g] != b->group_beta[g]) {
            return 0;
        }
    }
    for (i = 0; i < CFG(a)->n_states; ++i) {
        if (a->group_of[i] != b->group_of[i]) {
            return 0;
        }
    }
    return 1;
}

/* The sample part of the values just computed, kept for member m's commit. */
static void keep_sample(rhonn_population_work *wk, size_t m)
{
    size_t j;
    for (j = 0; j < (size_t)RHONN_SAMPLE_LEN; ++j) {
        wk->cur[m][j] = wk->val[j];
    }
}

/* Term t of neuron i from the step's values: rhonn.c step 4's product,
 * factor by factor in the same order. */
POP_ALWAYS_INLINE rhonn_real term_value(const rhonn_t *net, const rhonn_real *val, size_t i, size_t t)
{
    const uint16_t *te = net->term_entry[i][t];
    const size_t nf = CFG(net)->neurons[i].terms[t].n_factors;
    rhonn_real prod = val[te[0]];
    size_t f;
    for (f = 1; f < nf; ++f) {
        prod *= val[te[f]];
    }
    return prod;
}

/* z(k) of one member from the step's values into lane m of bank zb, or
 * into every lane when it is the regressor all members share. */
static void lane_regressor(rhonn_population_work *wk, const rhonn_t *net, const rhonn_real *val, size_t zb, size_t m,
                           int every_lane)
{
    const rhonn_config *cfg = CFG(net);
    size_t i, t, k;
    for (i = 0; i < cfg->n_states; ++i) {
        for (t = 0; t < cfg->neurons[i].n_terms; ++t) {
            const rhonn_real prod = term_value(net, val, i, t);
            if (every_lane) { /* the shared regressor, stored once into every lane */
                for (k = 0; k < NPOP; ++k) {
                    wk->z[zb][i][t][k] = prod;
                }
            } else {
                wk->z[zb][i][t][m] = prod;
            }
        }
    }
}

/* How many of the newest history slots every member holds a value alike
 * in, after a step whose sample held it alike for all (agreed: before). */
static uint8_t slots_agreeing(uint8_t agreed, int shareable, int all_fresh, int all_started, size_t maxd)
{
    if (!shareable) {
        return 0u;
    }
    if (all_fresh) {
        return (uint8_t)maxd; /* members that had not started filled every slot with it */
    }
    return (uint8_t)(!all_started ? 1u : agreed < maxd ? agreed + 1u : maxd);
}

/* Member m's values formed from its own net (its ring paid what it is owed
 * first; a missing x_i reads net->xhat, which the caller has set where it
 * matters), kept as the sample in row keep of wk->cur, and the regressor
 * from them into lane m of bank zb, or into every lane. */
static void own_regressor(rhonn_population_work *wk, rhonn_t *net, size_t m, const rhonn_real *x,
                          const rhonn_real *u, const uint8_t *v, size_t zb, size_t keep, int every_lane)
{
    pay_ring(wk, net, m);
    rhonn_internal_features(net, x, u, v, wk->val);
    keep_sample(wk, keep);
    lane_regressor(wk, net, wk->val, zb, m, every_lane);
}

/* z(k) of every member in a hold (see rhonn_population.h): the lead's
 * values into every lane, then for each other member its own prediction of
 * the missing states rewritten into them (rhonn_internal_held_values), and
 * the terms that read one of those values recomputed into its lane; each
 * member's sample kept for its own ring, which is paid what it is owed
 * first (its commit stores this sample). */
static void held_regressors(rhonn_population_work *wk, rhonn_t *const *nets, size_t N, size_t lead,
                            const uint8_t *alive, const uint8_t *fail, const rhonn_real *x, const rhonn_real *u,
                            const uint8_t *v, size_t zb)
{
    const rhonn_t *ln = nets[lead];
    const rhonn_config *cfg = CFG(ln);
    rhonn_real xm[RHONN_MAX_STATES];
    size_t i, t, f, m;
    int first = 1;
    for (i = 0; i < cfg->n_states; ++i) { /* a missing x_i reads the lead's prediction */
        nets[lead]->xhat[i] = wk->xhat[i][lead];
    }
    own_regressor(wk, nets[lead], lead, x, u, v, zb, lead, 1);
    for (m = 0; m < N; ++m) {
        if (!alive[m] || fail[m] || m == lead) {
            continue;
        }
        for (i = 0; i < cfg->n_states; ++i) {
            xm[i] = wk->xhat[i][m];
        }
        pay_ring(wk, nets[m], m);
        rhonn_internal_held_values(ln, xm, v, wk->val, first ? wk->rewritten : NULL);
        if (first) { /* the terms that read a rewritten value: the same for every member */
            for (i = 0; i < cfg->n_states; ++i) {
                for (t = 0; t < cfg->neurons[i].n_terms; ++t) {
                    const uint16_t *te = ln->term_entry[i][t];
                    uint8_t r = 0;
                    for (f = 0; f < cfg->neurons[i].terms[t].n_factors; ++f) {
                        r |= wk->rewritten[te[f]];
                    }
                    wk->held_term[i][t] = r;
                }
            }
            first = 0;
        }
        for (i = 0; i < cfg->n_states; ++i) {
            for (t = 0; t < cfg->neurons[i].n_terms; ++t) {
                if (wk->held_term[i][t]) {
                    wk->z[zb][i][t][m] = term_value(ln, wk->val, i, t);
                }
            }
        }
        keep_sample(wk, m);
    }
}

/* Which lanes learn neuron i this step (ready, x_i measured, their valid
 * run long enough: rhonn.c step 1), the innovation x_i - xhat_i of every
 * lane; *any: some lane learns, *all: every alive lane does. */
POP_LANES void learn_lanes(rhonn_population_work *wk, size_t i, const uint8_t *ready, const uint8_t *alive,
                           uint8_t measured, rhonn_real xi, uint8_t *any, uint8_t *all)
{
    uint8_t a = 0, l = 1;
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        wk->learn[i][m] = (uint8_t)(ready[m] & measured & (uint8_t)(wk->vrun[i][m] >= wk->need[i][m]));
        wk->updated[i][m] = 0; /* where no lane learns, the kernel does not run */
        wk->bounded[i][m] = 0;
        wk->recovered[i][m] = 0;
        wk->gated[i][m] = 0;
    }
    for (m = 0; m < NPOP; ++m) {
        wk->innov[i][m] = xi - wk->xhat[i][m];
        wk->e[m] = wk->innov[i][m];
    }
    for (m = 0; m < NPOP; ++m) {
        a |= wk->learn[i][m];
        l &= (uint8_t)(wk->learn[i][m] | (alive[m] ^ 1u));
    }
    *any = a;
    *all = l;
}

/* The commit of neuron i in a step in which every member committed and
 * updated it, or none did, with no refusal (rhonn.c's commit): the valid
 * run of x_i counted (first: 0xFF for a lane's first sample), the
 * prediction kept, and where they updated, the update counted once for all
 * (n_alike) and its health and proof kept in every lane. */
POP_LANES void commit_alike(rhonn_population_work *wk, size_t i, uint8_t measured, const uint8_t *first,
                            uint8_t moved)
{
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        wk->vrun[i][m] = rhonn_run_next(wk->vrun[i][m], (uint8_t)(first[m] & wk->first_run[i][m]), measured);
    }
    for (m = 0; m < NPOP; ++m) {
        wk->xhat[i][m] = wk->xnew[i][m];
    }
    if (!moved) {
        return;
    }
    wk->n_alike[i] += 1u;
    if (wk->ceiling[i]) { /* only the trace ceiling bounds an update */
        for (m = 0; m < NPOP; ++m) {
            wk->n_bounded[i][m] += wk->bounded[i][m];
        }
    }
    for (m = 0; m < NPOP; ++m) {
        wk->cert[i][m] = wk->cert_new[i][m];
    }
    for (m = 0; m < NPOP; ++m) {
        wk->last_innov[i][m] = wk->innov[i][m];
        wk->last_nis[i][m] = wk->nis[i][m];
    }
}

/* The innovation gate of neuron i (rhonn.c ekf_kernel, ekf_ud: after the
 * test of s, before anything is written), lane by lane on the kernel's
 * results: a learning lane whose s passed (its status is not
 * RHONN_E_INNOVATION) and whose e^2 / s is above its gate in force (> 0)
 * skips the update. Whatever the kernel found after that test (weights not
 * finite, P not definite) is not looked at, as rhonn.c does not reach it:
 * the lane neither updates nor is refused; it is marked gated and no
 * longer learns this step (its candidates are thrown away: w(k) and P(k)
 * kept). Sets the kernel's k_moved and k_refused anew; returns 1 when some
 * lane was gated. */
POP_LANES uint8_t gate_lanes(rhonn_population_work *wk, size_t i)
{
    uint8_t moved = 0, refused = 0, any = 0;
    size_t m;
    for (m = 0; m < NPOP; ++m) {
        const rhonn_real g = wk->gate[i][m];
        const uint8_t skip = (uint8_t)(wk->learn[i][m] & (uint8_t)(wk->kstatus[m] != (uint8_t)RHONN_E_INNOVATION) &
                                       (uint8_t)(g > R(0.0)) & (uint8_t)(wk->nis[i][m] > g));
        const uint8_t keep = (uint8_t)(skip ^ 1u);
        wk->gated[i][m] = skip;
        wk->learn[i][m] &= keep;
        wk->updated[i][m] &= keep;
        wk->bounded[i][m] &= keep;
        moved |= wk->updated[i][m];
        refused |= (uint8_t)(wk->learn[i][m] & (wk->updated[i][m] ^ 1u));
        any |= skip;
    }
    wk->k_moved = moved;
    wk->k_refused = refused;
    return any;
}

/* ------------------------------------------------------------------------ */

rhonn_status rhonn_run_population(rhonn_t *const *nets, size_t N, rhonn_population_work *work, size_t T,
                                  const rhonn_real *X, const rhonn_real *U, const uint8_t *valid,
                                  rhonn_real *Xhat, rhonn_status *status, size_t *done,
                                  rhonn_population_error *where)
{
    rhonn_population_work *const wk = work;
    rhonn_status st[RHONN_MAX_POPULATION];
    uint8_t alive[RHONN_MAX_POPULATION], fail[RHONN_MAX_POPULATION];
    size_t ran[RHONN_MAX_POPULATION];
    size_t n, mi, L, m, m2, i, t, k, maxd;
    /* deepest[j]: the deepest history slot the taps read x_j (or S(x_j))
     * from, deepest_u the inputs'; agree[j], agree_u: how many of the
     * newest slots every member holds the same x_j, the same inputs in
     * (none known at first: members stepped apart before the call) */
    uint8_t deepest[RHONN_MAX_STATES], agree[RHONN_MAX_STATES], deepest_u, agree_u = 0;
    int shareable = 1;
    rhonn_status ret;

    if (nets == NULL || work == NULL) {
        return RHONN_E_NULL;
    }
    if (N < 1u || N > NPOP) {
        return RHONN_E_ARGUMENT;
    }
    for (m = 0; m < N; ++m) {
        if (nets[m] == NULL) {
            return RHONN_E_NULL;
        }
        for (m2 = 0; m2 < m; ++m2) {
            if (nets[m2] == nets[m]) {
                return RHONN_E_ARGUMENT; /* one state cannot be two members */
            }
        }
        ret = rhonn_internal_check_net(nets[m]);
        if (ret != RHONN_OK) {
            return ret;
        }
    }
    for (m = 1; m < N; ++m) {
        ret = same_structure(CFG(nets[0]), CFG(nets[m]), m, where);
        if (ret != RHONN_OK) {
            return ret;
        }
        shareable = shareable && same_features(nets[0], nets[m]);
    }
    n = CFG(nets[0])->n_states;
    mi = CFG(nets[0])->n_inputs;
    maxd = nets[0]->max_delay;
    if (T > 0u && (X == NULL || Xhat == NULL || (U == NULL && mi > 0u))) {
        return RHONN_E_NULL;
    }
    /* Each member's lane, and copies of member 0 in the unused ones (finite
     * numbers to compute on, thrown away). A loan the lanes held is
     * forgotten: its net stays refused rather than take these lanes. */
    wk->holder = NULL;
    wk->zb = 0;
    wk->wb = 0;
    for (m = 0; m < NPOP; ++m) {
        wk->zeros[m] = R(0.0);
    }
    for (i = 0; i < (size_t)RHONN_MAX_STATES; ++i) {
        wk->pb[i] = 0;
        wk->n_alike[i] = 0;
    }
    wk->ring_last = 0;
    for (m = 0; m < NPOP; ++m) {
        load_lane(wk, nets[m < N ? m : 0u], m);
        wk->owed[m] = 0;
        alive[m] = (uint8_t)(m < N);
        st[m] = RHONN_OK;
        ran[m] = 0;
    }
    lane_flags(wk, n);
    deepest_u = rhonn_internal_delayed_reads(nets[0], deepest);
    for (i = 0; i < (size_t)RHONN_MAX_STATES; ++i) {
        agree[i] = 0;
    }

    for (k = 0; k < T; ++k) {
        const rhonn_real *x = X + k * n;
        const rhonn_real *u = mi > 0u ? U + k * mi : U;
        const uint8_t *v = valid != NULL ? valid + k * n : NULL;
        const size_t zb_new = wk->zb ^ 1u;
        int all_valid = 1, any_alive = 0, all_fresh = 1, all_started = 1, taps_agree, shared, held;
        uint8_t moved[RHONN_MAX_STATES]; /* some member updated neuron i */
        uint8_t ready[RHONN_MAX_POPULATION], first[RHONN_MAX_POPULATION];
        uint8_t keep[RHONN_MAX_POPULATION]; /* committed this step */
        uint8_t alike[RHONN_MAX_STATES];     /* no refusal, and every member learned neuron i or none */
        uint8_t stopped = 0;                 /* a member stopped in this step */
        rhonn_real finite[RHONN_MAX_POPULATION];
        size_t lead = NPOP;
        int owing = 0; /* some member is owed this step's sample (see pay_ring) */

        for (m = 0; m < N; ++m) {
            fail[m] = 0;
            any_alive |= alive[m];
        }
        if (!any_alive) {
            break;
        }
        /* The inputs are the same for every member: checked once. */
        ret = rhonn_internal_check_inputs(nets[0], x, u, v);
        if (ret != RHONN_OK) {
            for (m = 0; m < N; ++m) {
                if (alive[m]) {
                    st[m] = ret;
                    alive[m] = 0;
                    store_lane(wk, nets[m], m, ran[m]);
                }
            }
            break;
        }
        if (v != NULL) {
            for (i = 0; i < n; ++i) {
                all_valid &= v[i] != 0u;
            }
        }

        /* Which members learn at all this step (a member that fails at a
         * neuron drops out of the later ones: ready is cleared with fail). */
        for (m = 0; m < NPOP; ++m) {
            ready[m] = (uint8_t)(alive[m] & wk->started[m] & wk->learning[m]);
        }

        /* 1. Learn, neuron by neuron (rhonn.c step 1). */
        for (i = 0; i < n; ++i) {
            const int ud = is_ud(nets[0], i);
            const uint8_t measured = (uint8_t)(v == NULL || v[i] != 0u);
            uint8_t any_learn = 0, all_learn = 1, refused = 0, moved_i = 0, gated_i = 0;
            L = CFG(nets[0])->neurons[i].n_terms;
            learn_lanes(wk, i, ready, alive, measured, x[i], &any_learn, &all_learn);
            /* Where no member learns this neuron (its measurement missing,
             * learning off, the first sample), nothing of the kernel's would
             * be used: it is not run. */
            if (any_learn) {
                if (!ud) {
                    full_kernel(wk, i, L);
                } else {
                    ud_update(wk, nets, N, i, L);
                }
            }
            if (any_learn && wk->gating[i]) { /* the innovation gate: a gated lane no longer learns */
                gated_i = gate_lanes(wk, i);
                all_learn = (uint8_t)(all_learn & (gated_i ^ 1u));
            }
            if (any_learn) { /* the kernel's verdicts (see verdicts()) */
                moved_i = wk->k_moved;
                refused = wk->k_refused;
            }
            for (t = 0; t < L && !all_learn; ++t) { /* w(k+1) = w(k) where a member does not learn */
                rhonn_real *wn = wk->w[wk->wb ^ 1u][i][t];
                const rhonn_real *wo = wk->w[wk->wb][i][t];
                for (m = 0; m < NPOP; ++m) {
                    wn[m] = wk->learn[i][m] ? wn[m] : wo[m];
                }
            }
            alike[i] = (uint8_t)(!refused && !gated_i && (all_learn || !any_learn));
            if (refused) {
                count_alike(wk, i); /* the refusals below read the members' health */
            }
            for (m = 0; refused && m < N; ++m) {
                rhonn_t *net = nets[m];
                if (!wk->learn[i][m] || wk->updated[i][m]) {
                    continue;
                }
                /* a refused update: rhonn.c's bookkeeping and recovery */
                net->fault_neuron = (uint8_t)i;
                if (wk->run_ended[i][m]) { /* an update since the call began ended the run */
                    net->health[i].fail_run = 0;
                    wk->run_ended[i][m] = 0;
                }
                if (!rhonn_internal_count_refusal(net, i)) {
                    if (CFG(net)->neurons[i].skip_refused != 0u) {
                        skip_lane(wk, i, L, m); /* this neuron's update skipped, the member goes on */
                        continue;
                    }
                    fail[m] = 1;
                    ready[m] = 0;
                    st[m] = (rhonn_status)wk->kstatus[m];
                    continue;
                }
                recover_lane(wk, net, i, i, m);
                wk->updated[i][m] = 1;
                moved_i = 1;
            }
            moved[i] = moved_i;
        }

        /* 2-4. The regressor z(k): once for all when it must be the same
         * (see rhonn_population.h), else member by member. */
        for (m = 0; m < N; ++m) {
            if (alive[m] && !fail[m]) {
                lead = lead < NPOP ? lead : m;
                all_fresh &= !wk->started[m];
                all_started &= wk->started[m] != 0u;
            }
        }
        taps_agree = agree_u >= deepest_u;
        for (i = 0; i < n; ++i) {
            taps_agree &= agree[i] >= deepest[i];
        }
        shared = shareable && all_valid && lead < NPOP && (all_fresh || (all_started && taps_agree));
        /* a hold: the members' values differ only in the missing states' */
        held = shareable && !all_valid && lead < NPOP && all_started && taps_agree;
        if (shared) {
            /* the lead's ring paid first (a new lead: the one before stopped) */
            own_regressor(wk, nets[lead], lead, x, u, v, zb_new, 0, 1);
        } else if (held) {
            held_regressors(wk, nets, N, lead, alive, fail, x, u, v, zb_new);
        } else {
            for (m = 0; m < N; ++m) {
                if (alive[m] && !fail[m]) {
                    rhonn_t *net = nets[m];
                    for (i = 0; i < n; ++i) { /* a missing x_i reads the member's prediction */
                        net->xhat[i] = wk->xhat[i][m];
                    }
                    own_regressor(wk, net, m, x, u, v, zb_new, m, 0);
                }
            }
        }
        /* xhat(k+1) = w(k+1)^T z(k) (eq. 3), every member at once */
        predict(wk, nets[0], zb_new);

        /* Commit, member by member; a member that failed stops here with
         * its state as before this step. */
        for (m = 0; m < NPOP; ++m) {
            finite[m] = R(0.0);
            first[m] = (uint8_t)(wk->started[m] ? 0u : 0xFFu); /* rhonn.c count_runs */
            keep[m] = 0;
        }
        for (i = 0; i < n; ++i) {
            for (m = 0; m < NPOP; ++m) {
                finite[m] += wk->xnew[i][m] - wk->xnew[i][m]; /* 0 while finite */
            }
        }
        for (m = 0; m < N; ++m) {
            rhonn_t *net = nets[m];
            if (!alive[m]) {
                continue;
            }
            for (i = 0; i < n && finite[m] != R(0.0) && !fail[m]; ++i) {
                if (!LANE_FINITE(wk->xnew[i][m])) {
                    net->fault_neuron = (uint8_t)i;
                    st[m] = RHONN_E_DIVERGED;
                    fail[m] = 1;
                }
            }
            if (fail[m]) {
                alive[m] = 0;
                stopped = 1;
                store_lane(wk, net, m, ran[m]);
                continue;
            }
            if (shared && m != lead && wk->started[m] && maxd > 0u) {
                /* the lead's ring holds this sample; the others are owed it */
                rhonn_internal_commit_ring(net, NULL);
                wk->owed[m] = (uint8_t)(wk->owed[m] < (uint8_t)RHONN_HISTORY_LEN ? wk->owed[m] + 1u
                                                                               : (uint8_t)RHONN_HISTORY_LEN);
                owing = 1;
            } else {
                rhonn_internal_commit_ring(net, wk->cur[shared ? 0u : m]);
            }
            if (!wk->started[m]) {
                wk->started[m] = 1;
                net->started = 1;
            }
            for (i = 0; i < n; ++i) {
                Xhat[(m * T + k) * n + i] = wk->xnew[i][m];
            }
            keep[m] = 1;
            ran[m] = k + 1u;
        }
        /* The committed members' valid runs and health (rhonn.c's commit),
         * then every lane's proofs and predictions at once (those of members
         * that stopped are never read again). */
        for (i = 0; i < n; ++i) {
            const uint8_t measured = (uint8_t)(v == NULL || v[i] != 0u);
            uint8_t kept = 0;
            if (alike[i] && !stopped) {
                /* every member committed, each updated neuron i or none did
                 * (no refusal): counted once for all, in n_alike */
                commit_alike(wk, i, measured, first, moved[i]);
                continue;
            }
            count_alike(wk, i);
            for (m = 0; m < NPOP; ++m) {
                const uint8_t run = wk->vrun[i][m];
                const uint8_t up = (uint8_t)(wk->updated[i][m] & keep[m]);
                const uint8_t fresh = (uint8_t)(up & (wk->recovered[i][m] ^ 1u)); /* not a recovery */
                const uint8_t gk = (uint8_t)(wk->gated[i][m] & keep[m]); /* skipped by the gate */
                const uint8_t seen = (uint8_t)(fresh | gk);                /* health innovation, nis */
                wk->vrun[i][m] = keep[m] ? rhonn_run_next(run, (uint8_t)(first[m] & wk->first_run[i][m]), measured)
                                         : run;
                wk->flips[i][m] ^= up;
                wk->run_ended[i][m] |= up;
                wk->n_resets[i][m] += (uint32_t)(up & wk->recovered[i][m]);
                wk->n_updates[i][m] += fresh;
                wk->n_bounded[i][m] += (uint32_t)(fresh & wk->bounded[i][m]);
                wk->n_gated[i][m] += gk;
                wk->has_last[i][m] |= seen;
                wk->last_innov[i][m] = seen ? wk->innov[i][m] : wk->last_innov[i][m];
                wk->last_nis[i][m] = seen ? wk->nis[i][m] : wk->last_nis[i][m];
                wk->cert[i][m] = wk->updated[i][m] ? wk->cert_new[i][m] : wk->cert[i][m];
                wk->xhat[i][m] = wk->xnew[i][m];
                kept |= (uint8_t)(keep[m] & (wk->updated[i][m] ^ 1u));
            }
            if (moved[i] && kept) {
                /* P(k+1) = P(k) for a member that did not update, into the
                 * bank that becomes committed (where no member moved, the
                 * banks do not flip) */
                const size_t Li = CFG(nets[0])->neurons[i].n_terms, pb = wk->pb[i];
                for (t = 0; t < Li * (Li + 1u) / 2u; ++t) {
                    rhonn_real *pn = wk->p[pb ^ 1u][i][t];
                    const rhonn_real *po = wk->p[pb][i][t];
                    for (m = 0; m < NPOP; ++m) {
                        pn[m] = wk->updated[i][m] ? pn[m] : po[m];
                    }
                }
            }
        }
        if (owing) {
            wk->ring_last = (uint8_t)((wk->ring_last + 1u) % (unsigned)RHONN_HISTORY_LEN);
            for (t = 0; t < (size_t)RHONN_SAMPLE_LEN; ++t) {
                wk->ring[wk->ring_last][t] = wk->cur[0][t];
            }
        }
        /* every member's candidates are now its committed values (a member
         * that stopped was stored above, from the banks before the flip) */
        wk->zb = (uint8_t)zb_new;
        wk->wb = (uint8_t)(wk->wb ^ 1u);
        for (i = 0; i < n; ++i) {
            wk->pb[i] = (uint8_t)(wk->pb[i] ^ moved[i]);
        }
        /* The newest slot holds the same inputs in every member, and the
         * same x_i when x_i was measured (the same structure reading the
         * same sample); members that had not started filled every slot
         * with it. */
        agree_u = slots_agreeing(agree_u, shareable, all_fresh, all_started, maxd);
        for (i = 0; i < n; ++i) {
            agree[i] = (v != NULL && v[i] == 0u) ? 0u
                                                  : slots_agreeing(agree[i], shareable, all_fresh, all_started, maxd);
        }
    }

    for (m = 0; m < N; ++m) {
        if (alive[m]) {
            store_lane(wk, nets[m], m, ran[m]);
        }
    }
    ret = RHONN_OK;
    for (m = N; m-- > 0u;) {
        if (status != NULL) {
            status[m] = st[m];
        }
        if (done != NULL) {
            done[m] = ran[m];
        }
        if (st[m] != RHONN_OK) {
            ret = st[m];
        }
    }
    return ret;
}

/* ------------------------------------------------------------------------ */
/* One identifier, its neurons side by side (rhonn_run_wide): the member
 * kernels above on "neuron slot" 0 of the workspace, lane i holding neuron
 * i. The bookkeeping around them is rhonn.c's step_checked, neuron by
 * neuron in index order, so that a refusal, a recovery or a diverging
 * prediction ends the step exactly where rhonn_step ends it. */

/* Does net's structure fit the lanes: every neuron the same size and
 * covariance form, one lane each? */
static int wide_fits(const rhonn_t *net)
{
    const rhonn_config *cfg = CFG(net);
    size_t i;
    if (cfg->n_states > NPOP) {
        return 0;
    }
#if !RHONN_POP_VECTOR
    if (is_ud(net, 0)) {
        return 0; /* the portable U D U^T update runs rhonn.c's kernel member by member */
    }
#endif
    for (i = 0; i < cfg->n_states; ++i) {
        if (cfg->neurons[i].n_terms != cfg->neurons[0].n_terms ||
            cfg->neurons[i].covariance != cfg->neurons[0].covariance) {
            return 0;
        }
    }
    return 1;
}

/* The fewest neurons for which the lanes beat rhonn_run, by the vector
 * unit the kernels run on. The lanes cost about the same whatever number of
 * neurons they hold (RHONN_MAX_POPULATION lanes are computed), rhonn_run
 * costs in proportion: measured on an x86-64 (same-run ratios of the two
 * over 2-8 neurons of 8 terms, each form and precision), the lanes pay from
 * 4 full-form neurons (3 U D U^T) in double with AVX-512, 3 (2) in float
 * with AVX-512 or AVX2, and from 7 (5) in double, 5 (3) in float with
 * 128-bit vectors (SSE2: the default clone, the CMake build; NEON alike).
 * Scaled for another RHONN_MAX_POPULATION. */
static size_t wide_min_neurons(int ud)
{
    size_t at8;
#ifdef RHONN_SINGLE
    at8 = ud ? 3u : 5u;
#else
    at8 = ud ? 5u : 7u;
#endif
#if RHONN_TARGET_CLONES && defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
    if (__builtin_cpu_supports("avx512f")) {
#ifdef RHONN_SINGLE
        at8 = ud ? 2u : 3u;
#else
        at8 = ud ? 3u : 4u;
#endif
    }
#ifdef RHONN_SINGLE
    else if (__builtin_cpu_supports("avx2")) {
        at8 = ud ? 2u : 3u;
    }
#endif
#endif
    return (at8 * NPOP + 7u) / 8u;
}

int rhonn_wide_pays(const rhonn_t *net)
{
    if (rhonn_internal_check_net(net) != RHONN_OK || !wide_fits(net)) {
        return 0;
    }
    return CFG(net)->n_states >= wide_min_neurons(is_ud(net, 0));
}

/* Neuron i's committed state and tuning into lane i (lanes past the last
 * neuron: copies of neuron 0, finite numbers to compute on, thrown away). */
static void wide_load(rhonn_population_work *wk, const rhonn_t *net)
{
    const rhonn_config *cfg = CFG(net);
    const size_t n = cfg->n_states, L = cfg->neurons[0].n_terms;
    size_t m, t;
    wk->zb = 0;
    wk->wb = 0;
    wk->pb[0] = 0;
    for (m = 0; m < NPOP; ++m) {
        const size_t i = m < n ? m : 0u, b = net->bank[i];
        const rhonn_neuron_config *nc = &cfg->neurons[i];
        wk->zeros[m] = R(0.0);
        for (t = 0; t < L; ++t) {
            wk->w[0][0][t][m] = net->w[i][b][t];
            wk->z[0][0][t][m] = net->z[net->zbank][i][t];
            wk->q[0][t][m] = nc->q[t];
        }
        for (t = 0; t < L * (L + 1u) / 2u; ++t) {
            wk->p[0][0][t][m] = net->p[i][b][t];
        }
        wk->cert[0][m] = nc->covariance == (uint8_t)RHONN_COV_UD ? 0u : net->cert[i][b];
        wk->q_min[0][m] = net->q_min[i];
        wk->xhat[0][m] = net->xhat[i];
        wk->r[0][m] = nc->r;
        wk->eta[0][m] = nc->eta;
        wk->inv_lambda[0][m] = (nc->forgetting > R(0.0) && nc->forgetting < R(1.0)) ? R(1.0) / nc->forgetting
                                                                                     : R(1.0);
        wk->forget_ceiling[0][m] = net->forget_ceiling[i];
        wk->p_trace_max[0][m] = net->trace_max[i]; /* in force, as load_lane */
        wk->gate[0][m] = net->gate[i];
    }
    lane_flags(wk, 1);
}

/* The lanes' committed state back into net's committed banks (the rest of
 * net is kept up to date as the run goes). */
static void wide_store(const rhonn_population_work *wk, rhonn_t *net)
{
    const rhonn_config *cfg = CFG(net);
    const size_t L = cfg->neurons[0].n_terms;
    size_t i, t;
    for (i = 0; i < cfg->n_states; ++i) {
        const size_t b = net->bank[i];
        for (t = 0; t < L; ++t) {
            net->w[i][b][t] = wk->w[wk->wb][0][t][i];
            net->z[net->zbank][i][t] = wk->z[wk->zb][0][t][i];
        }
        for (t = 0; t < L * (L + 1u) / 2u; ++t) {
            net->p[i][b][t] = wk->p[wk->pb[0]][0][t][i];
        }
        net->cert[i][b] = wk->cert[0][i];
    }
}

/* xhat(k+1) = w(k+1)^T z(k) (eq. 3) of every neuron at once. */
POP_CLONES static void wide_predict(rhonn_population_work *wk, size_t L, size_t zb)
{
    predict_slot(wk, 0u, L, zb);
}

/* Step 1 of rhonn.c's step_checked for every neuron at once: the learning
 * flags and innovations, the kernel, then the verdicts in neuron order (the
 * innovation gate after the test of s, as gate_lanes; a refusal counted;
 * recovered with reset_after, else the step stops there with its status).
 * Returns RHONN_OK or the refused neuron's status. */
static rhonn_status wide_learn(rhonn_population_work *wk, rhonn_t *net, const rhonn_real *x, const uint8_t *v,
                               uint8_t *moved)
{
    const rhonn_config *cfg = CFG(net);
    const size_t n = cfg->n_states, L = cfg->neurons[0].n_terms;
    const int on = net->started && net->learning;
    int any_learn = 0;
    size_t i;
    for (i = 0; i < NPOP; ++i) {
        const int learns = i < n && on && (v == NULL || v[i] != 0u) && net->valid_run[i] >= net->own_need[i];
        wk->learn[0][i] = (uint8_t)learns;
        wk->updated[0][i] = 0;
        wk->bounded[0][i] = 0;
        wk->recovered[0][i] = 0;
        wk->gated[0][i] = 0;
        /* a state not measured may be NaN: its lane's results are not used */
        wk->e[i] = i < n ? x[i] - wk->xhat[0][i] : R(0.0);
        any_learn |= learns;
    }
    *moved = 0;
    if (!any_learn) {
        return RHONN_OK;
    }
#if RHONN_POP_VECTOR
    if (is_ud(net, 0)) {
        ud_kernel(wk, 0u, L);
    } else {
        full_kernel(wk, 0u, L);
    }
#else
    full_kernel(wk, 0u, L); /* wide_fits: not the U D U^T form in this build */
#endif
    for (i = 0; i < n; ++i) {
        const rhonn_real g = wk->gate[0][i];
        if (!wk->learn[0][i]) {
            continue;
        }
        if (wk->kstatus[i] != (uint8_t)RHONN_E_INNOVATION && g > R(0.0) && wk->nis[0][i] > g) {
            wk->gated[0][i] = 1; /* skipped by the gate: w and P kept (wide_step) */
            wk->updated[0][i] = 0; /* the kernel's verdicts set it where the update passed */
            wk->bounded[0][i] = 0;
            continue;
        }
        if (wk->kstatus[i] == (uint8_t)RHONN_OK) {
            wk->updated[0][i] = 1;
            *moved = 1;
            continue;
        }
        /* a refused update: rhonn.c's refused() */
        net->fault_neuron = (uint8_t)i;
        if (!rhonn_internal_count_refusal(net, i)) {
            if (cfg->neurons[i].skip_refused != 0u) {
                wk->bounded[0][i] = 0; /* skipped: not updated, the step goes on (w kept by wide_step) */
                continue;
            }
            return (rhonn_status)wk->kstatus[i];
        }
        recover_lane(wk, net, i, 0u, i);
        wk->updated[0][i] = 1;
        *moved = 1;
    }
    return RHONN_OK;
}

/* One step (rhonn.c step_checked after the argument checks). */
static rhonn_status wide_step(rhonn_population_work *wk, rhonn_t *net, const rhonn_real *x, const rhonn_real *u,
                              const uint8_t *v, rhonn_real *xhat_next)
{
    const rhonn_config *cfg = CFG(net);
    const size_t n = cfg->n_states, L = cfg->neurons[0].n_terms, packed = L * (L + 1u) / 2u;
    const size_t zb_new = wk->zb ^ 1u;
    const int ud = is_ud(net, 0);
    rhonn_status st;
    size_t i, t;
    uint8_t moved;

    st = rhonn_internal_check_inputs(net, x, u, v);
    if (st != RHONN_OK) {
        return st;
    }
    st = wide_learn(wk, net, x, v, &moved);
    if (st != RHONN_OK) {
        return st;
    }
    /* a neuron that did not learn keeps w (the prediction reads the
     * candidate bank) */
    for (i = 0; i < n; ++i) {
        if (!wk->updated[0][i]) {
            for (t = 0; t < L; ++t) {
                wk->w[wk->wb ^ 1u][0][t][i] = wk->w[wk->wb][0][t][i];
            }
        }
    }

    /* 2-4. The sample, z(k) and xhat(k+1), the first neuron whose
     * prediction is not finite stopping the step. */
    rhonn_internal_features(net, x, u, v, wk->val);
    for (i = 0; i < n; ++i) {
        for (t = 0; t < L; ++t) {
            wk->z[zb_new][0][t][i] = term_value(net, wk->val, i, t);
        }
    }
    wide_predict(wk, L, zb_new);
    for (i = 0; i < n; ++i) {
        if (!LANE_FINITE(wk->xnew[0][i])) {
            net->fault_neuron = (uint8_t)i;
            return RHONN_E_DIVERGED;
        }
    }

    /* Commit. */
    rhonn_internal_commit_sample(net, wk->val, v);
    for (i = 0; i < n; ++i) {
        if (wk->updated[0][i]) {
            rhonn_health *h = &net->health[i];
            if (wk->recovered[0][i]) {
                h->resets += 1u;
            } else {
                h->innovation = wk->e[i];
                h->nis = wk->nis[0][i];
                h->updates += 1u;
                h->bounded += wk->bounded[0][i];
            }
            h->fail_run = 0;
            net->bank[i] = (uint8_t)(net->bank[i] ^ 1u);
            wk->cert[0][i] = (uint8_t)(ud ? 0u : wk->cert_new[0][i]); /* the U D U^T form has no proof */
        } else {
            if (wk->gated[0][i]) { /* skipped by the innovation gate: counted */
                rhonn_health *h = &net->health[i];
                h->innovation = wk->e[i];
                h->nis = wk->nis[0][i];
                h->gated += 1u;
            }
            if (moved) {
                /* P(k+1) = P(k): into the bank that becomes committed */
                for (t = 0; t < packed; ++t) {
                    wk->p[wk->pb[0] ^ 1u][0][t][i] = wk->p[wk->pb[0]][0][t][i];
                }
            }
        }
        net->xhat[i] = wk->xnew[0][i];
        wk->xhat[0][i] = wk->xnew[0][i];
        xhat_next[i] = wk->xnew[0][i];
    }
    wk->zb = (uint8_t)zb_new;
    wk->wb = (uint8_t)(wk->wb ^ 1u);
    wk->pb[0] = (uint8_t)(wk->pb[0] ^ moved);
    net->zbank = (uint8_t)(net->zbank ^ 1u);
    net->started = 1;
    net->steps += 1u;
    return RHONN_OK;
}

rhonn_status rhonn_run_wide(rhonn_t *net, rhonn_population_work *work, size_t T, const rhonn_real *X,
                            const rhonn_real *U, const uint8_t *valid, rhonn_real *Xhat, size_t *done)
{
    rhonn_status st;
    size_t n, mi, k;
    if (work == NULL) {
        if (done != NULL) {
            *done = 0;
        }
        return RHONN_E_NULL;
    }
    st = rhonn_internal_check_net(net);
    if (st != RHONN_OK || T == 0u || !wide_fits(net)) {
        return rhonn_run(net, T, X, U, valid, Xhat, done); /* its checks, or the scalar run */
    }
    n = CFG(net)->n_states;
    mi = CFG(net)->n_inputs;
    if (done != NULL) {
        *done = 0;
    }
    if (X == NULL || Xhat == NULL || (U == NULL && mi > 0u)) {
        return RHONN_E_NULL;
    }
    work->holder = NULL; /* a loan the lanes held is forgotten (rhonn_wide_begin) */
    wide_load(work, net);
    for (k = 0; k < T; ++k) {
        st = wide_step(work, net, X + k * n, mi > 0u ? U + k * mi : U, valid != NULL ? valid + k * n : NULL,
                       Xhat + k * n);
        if (st != RHONN_OK) {
            break;
        }
        if (done != NULL) {
            *done = k + 1u;
        }
    }
    wide_store(work, net);
    return st;
}

/* ------------------------------------------------------------------------ */
/* Stepping in the lanes */

/* RHONN_OK when work holds net's loan; the refusal otherwise. */
static rhonn_status check_loan(const rhonn_t *net, const rhonn_population_work *work)
{
    if (net == NULL || work == NULL) {
        return RHONN_E_NULL;
    }
    if (net->magic != (uint32_t)RHONN_LENT_MAGIC) {
        return RHONN_E_NOT_INIT;
    }
    return work->holder == net ? RHONN_OK : RHONN_E_ARGUMENT;
}

rhonn_status rhonn_wide_begin(rhonn_t *net, rhonn_population_work *work)
{
    rhonn_status st;
    if (work == NULL) {
        return RHONN_E_NULL;
    }
    st = rhonn_internal_check_net(net); /* refuses a NULL net, or one already lent */
    if (st != RHONN_OK) {
        return st;
    }
    if (!wide_fits(net)) {
        return RHONN_E_CONFIG;
    }
    wide_load(work, net);
    work->holder = net;
    net->magic = (uint32_t)RHONN_LENT_MAGIC;
    return RHONN_OK;
}

rhonn_status rhonn_wide_step(rhonn_t *net, rhonn_population_work *work, const rhonn_real *x, const rhonn_real *u,
                             const uint8_t *valid, rhonn_real *xhat_next)
{
    const rhonn_status st = check_loan(net, work);
    if (st != RHONN_OK) {
        return st;
    }
    if (x == NULL || xhat_next == NULL || (u == NULL && CFG(net)->n_inputs > 0u)) {
        return RHONN_E_NULL;
    }
    /* wide_step as rhonn_run_wide runs it: a failure leaves the committed
     * lanes as they were, the state after the last good step */
    return wide_step(work, net, x, u, valid, xhat_next);
}

rhonn_status rhonn_wide_end(rhonn_t *net, rhonn_population_work *work)
{
    const rhonn_status st = check_loan(net, work);
    if (st != RHONN_OK) {
        return st;
    }
    wide_store(work, net);
    work->holder = NULL;
    net->magic = (uint32_t)RHONN_MAGIC;
    return RHONN_OK;
}
