/*
 * rhonn_warm.h - start an identifier mid-run: a warm start from the running
 * state of another instance of the same identifier (pyrhonn's
 * export_header(..., warm_start=...) writes one as a static const
 * rhonn_warm_state), with nothing but the core's public API.
 *
 * What a warm start restores, bit for bit: the weights w_i(k), each
 * covariance exactly as the core keeps it (rhonn_get_factors: P_i, or its
 * U D U^T factors), the regressor z(k-1) that the next step learns with, the
 * prediction xhat(k), the delayed taps' history and the learning switch.
 * From there every step computes what the exporting instance would have
 * computed: the same predictions, weights and covariances.
 *
 * What it does not restore: the step counter (rhonn_t.steps counts the
 * replayed samples) and the health counters (rhonn_get_health starts from
 * zero, and the last innovation is 0), which only report. rhonn_reset and
 * the automatic covariance reset (reset_after) go back to the
 * configuration's w0 and P(0), as they would in the exporting instance.
 *
 * How: rhonn_init with the configuration, the weights and the stored
 * covariances set, then the last D + 1 samples (D the configuration's deepest
 * delay) stepped with learning frozen, which rebuilds the history, z(k-1)
 * and xhat(k) = w(k)^T z(k-1) from the restored weights. Those samples must
 * have been measured (valid); pyrhonn refuses to export a window with a
 * dropout. C99 and C++ (the exported initialiser is positional).
 */
#ifndef RHONN_WARM_H
#define RHONN_WARM_H

#include "rhonn.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The running state of an identifier with n states, m inputs and deepest
 * delay D. Fields are read by rhonn_warm_start only. */
typedef struct {
    rhonn_real w[RHONN_MAX_STATES][RHONN_MAX_TERMS];          /* w_i(k), L_i entries each */
    rhonn_real factors[RHONN_MAX_STATES][RHONN_MAX_PACKED];   /* as rhonn_get_factors gives them */
    uint8_t learning;                                         /* the learning switch */
    uint16_t n_samples;                                       /* D + 1 .. RHONN_HISTORY_LEN */
    rhonn_real x[RHONN_HISTORY_LEN][RHONN_MAX_STATES];        /* the last samples, oldest first */
    rhonn_real u[RHONN_HISTORY_LEN][RHONN_MAX_INPUTS];        /* their inputs (unused when m = 0) */
} rhonn_warm_state;

/* Initialise net from cfg (the configuration the state was reached with,
 * its own w0 and P0), then restore state (see above). Returns
 * RHONN_E_CONFIG (where names the field) with net unchanged when cfg is
 * invalid; RHONN_E_ARGUMENT when n_samples is below D + 1 or above
 * RHONN_HISTORY_LEN, RHONN_E_VALUE when a weight or covariance is refused by
 * the setters, or a step's status when a sample is refused: net then holds
 * cfg's starting point, as after rhonn_init. */
rhonn_status rhonn_warm_start(rhonn_t *net, const rhonn_config *cfg, const rhonn_warm_state *state,
                              rhonn_config_error *where);

#ifdef __cplusplus
}
#endif

#endif /* RHONN_WARM_H */
