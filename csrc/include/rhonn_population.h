/*
 * rhonn_population.h - a population of identifiers of the same structure
 * run over one trajectory in one call (tuning: the candidate configurations
 * of a search evaluated together).
 *
 * The members share their structure (states, inputs, every neuron's terms,
 * activation and covariance form) and differ in their tuning: x0, beta,
 * eta_i, R_i, Q_i, w_i(0), P_i(0), forgetting, p_trace_max, reset_after
 * (everything rhonn_init accepts that is not structure), and in their
 * running state (each member continues from wherever its rhonn_t is).
 *
 * BIT FOR BIT. Every member performs exactly the floating-point operations
 * of rhonn_step, in the same order, so its predictions, weights,
 * covariances, health counters and history after rhonn_run_population are
 * those rhonn_run would give on that member alone (build the core with
 * -ffp-contract=off, as always). What differs is the layout: the members'
 * learning state and EKF arithmetic (eq. 7-8 with the positive definiteness
 * check for RHONN_COV_FULL, Bierman and Agee-Turner for RHONN_COV_UD, the
 * prediction of eq. 3) are kept structure-of-arrays in the caller's
 * workspace, member innermost, so one operation is done for every member
 * at once (a vector of the compiler's, or a loop it may vectorise; see
 * RHONN_POP_VECTOR in rhonn_population.c), and the members' dependency
 * chains (the dot products, the divisions) run side by side instead of
 * one after the other. The portable build (RHONN_POP_VECTOR=0) runs the
 * U D U^T neurons through rhonn.c's own kernel, member by member.
 *
 * THE REGRESSOR is computed once for the population when it must be the
 * same for every member: the members' activations and betas agree (so do
 * S(x) and the compiled terms), the sample is fully measured (no member's
 * own prediction stands in for a state) and the history the taps read
 * agrees. When a state is missing (a hold) and the history the taps read
 * still agrees, it is computed once and each member rewrites only the
 * missing states' values with its own prediction, and the terms that read
 * them. Otherwise each member forms its own, as rhonn_step does.
 *
 * INNOVATION GATES run in the lanes: each member's gate in force
 * (rhonn_neuron_config.gate, or rhonn_set_gate's) is tested on its own
 * e^2 / s, after the test of s and before anything of the update is
 * kept, as rhonn_step tests it; a gated member keeps that neuron's weights
 * and covariance for the step, its health counts the skip (gated,
 * innovation, nis; fail_run unchanged), and members with and without
 * gates run together. The trace ceilings are the members' in force too.
 * SKIP_REFUSED is: a member whose update of a neuron with skip_refused is
 * refused keeps that neuron's weights and covariance for the step and goes
 * on, as rhonn_step does (rhonn.h REFUSALS, NEURON BY NEURON).
 *
 * A MEMBER THAT FAILS stops there, exactly as rhonn_run stops: its rhonn_t
 * holds the state after its last good step, status[m] says why and done[m]
 * how many steps ran; the other members go on to the end.
 *
 * The workspace is scratch, caller-owned (large: sizeof(rhonn_population_work)
 * grows with RHONN_MAX_POPULATION x the capacities), and holds nothing
 * between calls but a loan (STEPPING IN THE LANES below). Place it on a
 * cache line (64 bytes): a vector of 8 lanes then never straddles two,
 * which the kernels feel (10-15 % measured with AVX-512). Nothing here
 * allocates, prints or recurses.
 */
#ifndef RHONN_POPULATION_H
#define RHONN_POPULATION_H

#include "rhonn.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Members one call runs: the width of the structure-of-arrays lanes. */
#ifndef RHONN_MAX_POPULATION
#define RHONN_MAX_POPULATION 8
#endif
#if RHONN_MAX_POPULATION < 1 || RHONN_MAX_POPULATION > 255
#error "RHONN_MAX_POPULATION must be in 1..255"
#endif

/* Which member's structure differs from member 0's (RHONN_E_CONFIG). */
typedef struct {
    uint8_t member;     /* index of the member */
    uint8_t field;      /* rhonn_field: N_STATES, N_INPUTS, N_TERMS, ACTIVATION, COVARIANCE,
                         * N_FACTORS, FACTOR_KIND, FACTOR_INDEX, FACTOR_DELAY, FACTOR_POWER */
    uint8_t neuron;     /* neuron, term and factor of the field, when it belongs to one */
    uint8_t term;
    uint8_t factor;
} rhonn_population_error;

/* Scratch of one call; every array is [...][member], member innermost. */
typedef struct {
    /* w_i and the stored covariance (P_i, or its U D U^T factors) of each
     * member, double-buffered: bank wb (pb[i]) holds the committed values,
     * the other one the step's candidates; a member's candidates are
     * committed when all its neurons passed */
    rhonn_real w[2][RHONN_MAX_STATES][RHONN_MAX_TERMS][RHONN_MAX_POPULATION];
    rhonn_real p[2][RHONN_MAX_STATES][RHONN_MAX_PACKED][RHONN_MAX_POPULATION];
    rhonn_real z[2][RHONN_MAX_STATES][RHONN_MAX_TERMS][RHONN_MAX_POPULATION]; /* z(k-1), z(k) */
    rhonn_real xhat[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    rhonn_real xnew[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    /* each member's tuning, per neuron */
    rhonn_real r[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    rhonn_real eta[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    rhonn_real inv_lambda[RHONN_MAX_STATES][RHONN_MAX_POPULATION];  /* 1 / forgetting; 1 when off */
    rhonn_real forget_ceiling[RHONN_MAX_STATES][RHONN_MAX_POPULATION]; /* rhonn_t.forget_ceiling */
    rhonn_real p_trace_max[RHONN_MAX_STATES][RHONN_MAX_POPULATION]; /* in force (rhonn_t.trace_max); 0 when off */
    rhonn_real gate[RHONN_MAX_STATES][RHONN_MAX_POPULATION];        /* in force (rhonn_t.gate); 0 when off */
    rhonn_real q[RHONN_MAX_STATES][RHONN_MAX_TERMS][RHONN_MAX_POPULATION];
    rhonn_real q_min[RHONN_MAX_STATES][RHONN_MAX_POPULATION];  /* min_t q (rhonn_t.q_min) */
    /* full form: the committed P carries rhonn.c's proof of definiteness
     * (rhonn_t.cert), and the step's candidate does */
    uint8_t cert[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    uint8_t cert_new[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    /* kernel scratch */
    rhonn_real zeros[RHONN_MAX_POPULATION];  /* +0 for every member: the sums' start */
    rhonn_real e[RHONN_MAX_POPULATION];
    rhonn_real ilam_step[RHONN_MAX_POPULATION]; /* the step's 1 / lambda: inv_lambda, or 1 at the ceiling */
    rhonn_real innov[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    rhonn_real nis[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    rhonn_real pz[RHONN_MAX_TERMS][RHONN_MAX_POPULATION];
    rhonn_real f[RHONN_MAX_PACKED][RHONN_MAX_POPULATION];     /* U D U^T factors of the check */
    rhonn_real sc[RHONN_MAX_TERMS][RHONN_MAX_POPULATION];
    rhonn_real tk[RHONN_MAX_TERMS][RHONN_MAX_POPULATION];
    rhonn_real dk[RHONN_MAX_TERMS][RHONN_MAX_POPULATION];
    rhonn_real uw[RHONN_MAX_PACKED][RHONN_MAX_POPULATION];    /* U D U^T form: U~ */
    rhonn_real ua[5][RHONN_MAX_TERMS][RHONN_MAX_POPULATION];  /* f, v, b, d~, a */
    /* the regressor */
    rhonn_real cur[RHONN_MAX_POPULATION][RHONN_SAMPLE_LEN];   /* each member's sample, to commit */
    rhonn_real val[RHONN_VALUES_LEN];                        /* one member's values (rhonn.h) */
    uint8_t rewritten[RHONN_VALUES_LEN];                     /* a hold's member values (rhonn_run_population) */
    uint8_t held_term[RHONN_MAX_STATES][RHONN_MAX_TERMS];    /* a hold's member terms */
    /* per member and neuron: 1 = learning this step, updated, bounded,
     * recovered, skipped by the innovation gate */
    uint8_t learn[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    uint8_t updated[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    uint8_t bounded[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    uint8_t recovered[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    uint8_t gated[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    uint8_t kstatus[RHONN_MAX_POPULATION];        /* the kernel's status per member */
    uint8_t k_moved, k_refused;                   /* some learning lane passed, was refused */
    uint8_t zb;                                   /* which z bank holds z(k-1) */
    uint8_t wb;                                   /* which w bank is committed */
    uint8_t pb[RHONN_MAX_STATES];                 /* which P bank of neuron i is committed */
    uint8_t ceiling[RHONN_MAX_STATES];            /* some lane of neuron i has the trace ceiling on */
    uint8_t forgets[RHONN_MAX_STATES];            /* some lane of neuron i forgets */
    uint8_t gating[RHONN_MAX_STATES];             /* some lane of neuron i has an innovation gate on */
    /* The samples of the last steps in which every member read the same
     * one: a member other than the step's lead gets them into its history
     * ring only before the ring is read or the member handed back. */
    rhonn_real ring[RHONN_HISTORY_LEN][RHONN_SAMPLE_LEN];
    uint8_t ring_last;                            /* the row of ring holding the newest */
    uint8_t owed[RHONN_MAX_POPULATION];           /* newest of them member m's ring lacks */
    /* Each member's bookkeeping, kept in its lane for the call and written
     * into its rhonn_t when the member is handed back (at a stop or at the
     * end): its flags and valid runs, its banks' flips, its health since
     * the call began. */
    uint8_t started[RHONN_MAX_POPULATION];                     /* rhonn_t.started */
    uint8_t learning[RHONN_MAX_POPULATION];                    /* rhonn_t.learning */
    uint8_t need[RHONN_MAX_STATES][RHONN_MAX_POPULATION];      /* rhonn_t.own_need */
    uint8_t vrun[RHONN_MAX_STATES][RHONN_MAX_POPULATION];      /* rhonn_t.valid_run */
    uint8_t first_run[RHONN_MAX_STATES][RHONN_MAX_POPULATION]; /* rhonn_t.first_run */
    uint8_t flips[RHONN_MAX_STATES][RHONN_MAX_POPULATION];     /* 1: rhonn_t.bank[i] flips */
    uint8_t run_ended[RHONN_MAX_STATES][RHONN_MAX_POPULATION]; /* 1: health fail_run is 0 */
    uint8_t has_last[RHONN_MAX_STATES][RHONN_MAX_POPULATION];  /* 1: health innovation, nis */
    uint32_t n_updates[RHONN_MAX_STATES][RHONN_MAX_POPULATION]; /* health counters to add */
    uint32_t n_bounded[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    uint32_t n_resets[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    uint32_t n_gated[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    rhonn_real last_innov[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    rhonn_real last_nis[RHONN_MAX_STATES][RHONN_MAX_POPULATION];
    /* updates of neuron i that every member made alike, not yet counted
     * into the lanes above */
    uint32_t n_alike[RHONN_MAX_STATES];
    /* The identifier whose learning state the lanes hold between
     * rhonn_wide_begin and rhonn_wide_end; NULL after any other call. */
    const rhonn_t *holder;
} rhonn_population_work;

/* Run the N members nets[0..N) (each set up by rhonn_init, all of the same
 * structure, no rhonn_t given twice) over one trajectory, as N calls of
 * rhonn_run would. X is T x n_states, U is T x n_inputs (may be NULL when
 * n_inputs == 0), valid is T x n_states or NULL, all row-major and shared by
 * the members; Xhat receives N x T x n_states: member m's row t, the
 * prediction made at sample t, at Xhat[(m T + t) n_states ...].
 * status[m] and done[m] (either may be NULL) receive each member's status
 * and steps run; a member that fails stops as rhonn_run does (see above).
 *
 * Returns RHONN_OK when every member ran all T steps, else the status of the
 * lowest-indexed member that stopped. Before anything runs:
 * RHONN_E_NULL for a NULL nets, nets[m], work, X, Xhat (or U with inputs);
 * RHONN_E_ARGUMENT for N outside 1..RHONN_MAX_POPULATION or a rhonn_t given
 * twice; RHONN_E_NOT_INIT for a member not set up; RHONN_E_CONFIG when a
 * member's structure differs from member 0's, *where (if not NULL) naming
 * the member and the field. Then status[] and done[] are not written. */
rhonn_status rhonn_run_population(rhonn_t *const *nets, size_t N, rhonn_population_work *work, size_t T,
                                  const rhonn_real *X, const rhonn_real *U, const uint8_t *valid,
                                  rhonn_real *Xhat, rhonn_status *status, size_t *done,
                                  rhonn_population_error *where);

/* ONE IDENTIFIER, ITS NEURONS SIDE BY SIDE. The neurons of one identifier
 * are independent filters (eq. 7-8 per neuron), so where they share their
 * size and covariance form the same lanes can hold them instead of members:
 * rhonn_run_wide runs net over a trajectory exactly as rhonn_run does (the
 * same arguments, status, *done, predictions and state, bit for bit: each
 * lane performs rhonn_step's operations on its neuron; only the step's
 * scratch in rhonn_t, the inactive banks and the z bank not holding
 * z(k-1), may hold other values), with neuron i's
 * learning state and EKF arithmetic in lane i of the workspace, every
 * neuron's update done at once. It does so when every neuron has the same
 * number of terms and the same covariance form, at most
 * RHONN_MAX_POPULATION neurons (and, for the U D U^T form, the vector
 * build, RHONN_POP_VECTOR), with or without innovation gates (tested in
 * each neuron's lane where rhonn_step tests them); for any other
 * configuration it is rhonn_run. For a
 * host with a vector unit (on a scalar FPU the lanes only add work), and
 * for identifiers with enough neurons to fill it: see rhonn_wide_pays.
 *
 * As rhonn_run: RHONN_E_NOT_INIT for a net not set up, RHONN_E_NULL for a
 * NULL net, X or Xhat (or U with inputs) when T > 0, and RHONN_E_NULL for
 * a NULL work; a step that fails stops the run with the state after the
 * last good step (work holds nothing after the call). */
rhonn_status rhonn_run_wide(rhonn_t *net, rhonn_population_work *work, size_t T, const rhonn_real *X,
                            const rhonn_real *U, const uint8_t *valid, rhonn_real *Xhat, size_t *done);

/* Whether rhonn_run_wide runs net in the lanes and that is expected to be
 * faster than rhonn_run on this CPU: the structure fits (above) and net has
 * enough neurons for the vector unit the kernels run on (the lanes cost
 * about the same for 1 neuron as for RHONN_MAX_POPULATION; measured, with
 * 8 lanes: from 3-4 neurons with AVX-512, 2-3 with AVX2 in float, 3-7 with
 * 128-bit vectors, by form and precision; see rhonn_population.c). 0 for a
 * NULL net or one not set up. Both runs give the same results: this is
 * only about speed. */
int rhonn_wide_pays(const rhonn_t *net);

/* STEPPING IN THE LANES. rhonn_run_wide loads the lanes at the start of a
 * call and stores them back at the end, which costs more than the lanes
 * save when a call is one sample. To step sample by sample in the lanes,
 * the lanes keep net's learning state from one step to the next:
 *
 *   rhonn_wide_begin(net, work)   lends net's committed weights, covariances
 *       (with their proofs of definiteness) and z(k-1) to work's lanes;
 *   rhonn_wide_step(net, work, x, u, valid, xhat_next)   one rhonn_step,
 *       bit for bit, in the lanes (the same arguments and statuses; the rest
 *       of net -- the prediction, history, health counters, steps, the
 *       fault diagnostic -- is kept up to date in net at every step);
 *   rhonn_wide_end(net, work)     gives the state back: net is then what
 *       the same rhonn_step calls would have left (as rhonn_run_wide: only
 *       the step's scratch, the inactive banks and the z bank not holding
 *       z(k-1), may hold other values).
 *
 * While lent, every other function of the core given net refuses it as not
 * set up (RHONN_E_NOT_INIT), so nothing reads the weights it no longer
 * holds or steps it outside the lanes; and work must not be given to any
 * other call (rhonn_run_wide and rhonn_run_population use it as scratch
 * and forget the loan: net then stays refused until rhonn_init sets it up
 * again, its learning state lost). A step that fails (any status but
 * RHONN_OK) leaves the lanes holding the state after the last good step,
 * as rhonn_step leaves net; stepping on or ending the loan are both fine.
 *
 * rhonn_wide_begin: RHONN_E_NULL for a NULL net or work; RHONN_E_NOT_INIT
 * for a net not set up or already lent; RHONN_E_CONFIG when the lanes cannot
 * hold net (its neurons differ in size or form, or they are more than
 * RHONN_MAX_POPULATION: rhonn_run_wide would run it as rhonn_run).
 * rhonn_wide_step and rhonn_wide_end: RHONN_E_NULL for a NULL net or work
 * (or x, xhat_next, or u with inputs); RHONN_E_NOT_INIT for a net not lent;
 * RHONN_E_ARGUMENT when it is lent to another workspace. A refused call
 * changes nothing. */
rhonn_status rhonn_wide_begin(rhonn_t *net, rhonn_population_work *work);
rhonn_status rhonn_wide_step(rhonn_t *net, rhonn_population_work *work, const rhonn_real *x, const rhonn_real *u,
                             const uint8_t *valid, rhonn_real *xhat_next);
rhonn_status rhonn_wide_end(rhonn_t *net, rhonn_population_work *work);

#ifdef __cplusplus
}
#endif

#endif /* RHONN_POPULATION_H */
