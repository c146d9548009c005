/*
 * fw_app.h - the RHONN identifier as a CAN FD firmware application.
 *
 * One fw_app (caller-owned, no allocation) holds the identifier (rhonn_t),
 * the protocol state and the diagnostics counters. The platform passes
 * every received frame to fw_app_on_frame (or lets fw_app_poll pull them
 * through the HAL); the application answers through the HAL's send:
 *
 *   Measurement  validated, then one rhonn_step, then one Estimate back
 *   Control      Reset / LearningOff / LearningOn / WeightsBegin /
 *                WeightsCommit / WeightsAbort / DiagRequest, each answered
 *                by a ControlAck
 *   WeightLoad   indexed chunk of the staged weights (applied on commit)
 *
 * and sends a Diagnostics frame every diag_period accepted measurements,
 * each followed by one Health frame per neuron (rhonn_get_health). The
 * messages are those of firmware_sim/rhonn_id.dbc.
 *
 * REJECTION. A frame with an unknown identifier, a length other than the
 * DBC's, a signal outside its DBC range, a sequence counter that repeats or
 * jumps, or a command/weight frame that does not fit the current state is
 * rejected: fw_app_on_frame returns the reason, the counters record it, and
 * the identifier (rhonn_t) is not touched - bit for bit. Only an accepted
 * Measurement steps the filter, and only a successful WeightsCommit,
 * Reset, LearningOff or LearningOn changes it otherwise.
 *
 * AUTHENTICATION (FW_SECOC, on unless compiled with -DFW_SECOC=0). Control
 * and WeightLoad frames are SecOC-style secured PDUs (fw_secoc.h): a frame
 * of the right length whose MAC does not verify is rejected as FW_E_AUTH,
 * one whose freshness value is not newer than the last accepted one (a
 * replay) or too far ahead as FW_E_FRESHNESS; neither is answered, both are
 * counted, and nothing else is looked at before the MAC verifies. The key
 * is compiled in (config/fw_secoc_key.h). The freshness value survives
 * Reset; fw_app_get/set_freshness let a platform persist it across power
 * cycles. Measurement frames are not authenticated.
 *
 * SEQUENCE COUNTER. The first Measurement after init or Reset is accepted
 * with any Seq (Estimate.Resync = 1). After that a Measurement must carry
 * last + 1 (mod 65536). Seq == last is a repeat (rejected). Anything else is
 * a jump: rejected, and the counter is re-anchored at the jumped value, so
 * the next consecutive frame is accepted again (with Resync = 1). A random
 * stream is never accepted.
 *
 * GAPS. The filter never learns a sample against a prediction made for
 * another one: the first Measurement accepted after a jump restarts the
 * identifier (rhonn_restart: weights, covariances, learning switch and
 * x_hat kept; that step learns nothing and refills the delayed taps with its
 * own sample) and says Resync = 1. The frame that reveals the gap is
 * rejected, as any jump: it alone could be a stray or stale frame, and the
 * rig's accounting (one rejection per gap, then answers again) stays as it
 * was. So a gap costs the lost frames plus one.
 *
 * LOST FRAMES. A jump d = Seq - last (mod 65536) with 2 <= d <= 32768 is a
 * forward gap: d - 1 frames were lost (lost_frames += d - 1, seq_gaps += 1),
 * also across the wrap 65535 -> 0. A repeat (d = 0) or a backward jump
 * (d > 32768: a reordered or late frame, a restarted sender) loses nothing
 * and counts only as a rejection; a gap of more than 32767 frames (9.8 s at
 * 0.3 ms) cannot be told from a backward jump and is counted as one. The
 * platform adds the frames its receive queue dropped (fw_app_note_rx_drops,
 * e.g. the kernel's SO_RXQ_OVFL count): rx_drops. A dropped Measurement is
 * also in lost_frames once a later one reveals its gap, so on a link that
 * loses nothing else lost_frames == rx_drops, and every Measurement sent is
 * accepted, lost, or rejected: sent = measurements + lost_frames +
 * rejected_seq_repeat + rejected_seq_jump (for a well-formed stream; plus
 * drops at the very end of a stream, which no later frame has revealed yet).
 *
 * TIMING. now_ns is the frame's reception time on the HAL's monotonic clock.
 * CycleTime is the time between two accepted measurements; StepTime runs
 * from reception to the Estimate handed to the HAL (read with hal->now). A
 * StepTime above deadline_ns counts as an overrun; so does every
 * fw_app_note_overrun (the platform's own loop overruns).
 *
 * Every function returns fw_status. Plain C99: no OS calls, no allocation,
 * no stdio, no libm.
 */
#ifndef FW_APP_H
#define FW_APP_H

#include <stddef.h>
#include <stdint.h>

#include "fw_aes_cmac.h"
#include "fw_hal.h"
#include "fw_protocol.h"
#include "fw_secoc.h"
#include "rhonn.h"

#ifdef __cplusplus
extern "C" {
#endif

/* 1: Control and WeightLoad must carry a valid SecOC trailer (fw_secoc.h).
 * 0: the trailer is ignored (a trusted bus; frames keep their length). */
#ifndef FW_SECOC
#define FW_SECOC 1
#endif

/* Static configuration of the application. */
typedef struct {
    /* The identifier, e.g. &LIM_IDENTIFIER from a header written by
     * pyrhonn.export.export_header (firmware_sim/config/lim_identifier.h).
     * Copied by fw_app_init; must have 6 states and 2 inputs (the DBC's). */
    const rhonn_config *identifier;
    uint32_t deadline_ns;   /* StepTime above this is an overrun; 0 = no check */
    uint16_t diag_period;   /* accepted measurements per Diagnostics frame; 0 = on request only */
} fw_app_config;

/* Diagnostics counters: totals since fw_app_init (they wrap), except where noted. */
typedef struct {
    uint32_t frames_in;         /* frames given to fw_app_on_frame */
    uint32_t frames_out;        /* frames the HAL accepted for sending */
    uint32_t rejected;          /* frames rejected, every reason */
    uint32_t rejected_unknown_id;
    uint32_t rejected_length;
    uint32_t rejected_range;
    uint32_t rejected_seq_repeat;
    uint32_t rejected_seq_jump;
    uint32_t rejected_state;    /* command/weight frame not valid now */
    uint32_t rejected_weights;  /* WeightsCommit refused */
    uint32_t measurements;      /* accepted measurements (steps run) */
    uint32_t step_errors;       /* accepted measurements whose rhonn_step failed */
    uint32_t commands;          /* control commands carried out */
    uint32_t weight_chunks;     /* WeightLoad frames accepted */
    uint32_t hal_errors;        /* send or clock failures */
    uint32_t overruns;          /* StepTime > deadline, plus fw_app_note_overrun calls */
    uint32_t cycle_time_ns;     /* last interval between accepted measurements */
    uint32_t step_time_ns;      /* last StepTime */
    uint32_t step_time_max_ns;  /* largest StepTime since the last Diagnostics frame */
    uint32_t step_time_worst_ns;/* largest StepTime since init */
    uint8_t last_reject;        /* fw_status of the last rejected frame (0 when none) */
    uint8_t last_step_status;   /* rhonn_status of the last step */
    uint32_t rejected_auth;     /* command frames whose MAC did not verify */
    uint32_t rejected_freshness;/* command frames replayed, stale or too far ahead */
    uint32_t lost_frames;       /* Measurements the Seq skipped (forward gaps; see LOST FRAMES) */
    uint32_t seq_gaps;          /* forward gaps seen (each also in rejected_seq_jump) */
    uint32_t restarts;          /* identifier restarts after a jump (rhonn_restart) */
    uint32_t rx_drops;          /* frames the platform's receive queue dropped (fw_app_note_rx_drops) */
} fw_counters;

struct fw_app;

/* Step hooks (fw_app_set_step_hooks), for a protocol layer beside the CAN
 * protocol (fw_xcp.h): before_step runs after a Measurement was accepted
 * and before its rhonn_step, so what it changes takes effect between two
 * steps; after_step runs once the step's Estimate went out, with the
 * Measurement's reception time; before_frame runs first in every
 * fw_app_on_frame, before the frame can change anything. Any may be NULL. */
typedef struct {
    void *ctx;
    void (*before_step)(void *ctx, struct fw_app *app);
    void (*after_step)(void *ctx, struct fw_app *app, uint64_t now_ns);
    void (*before_frame)(void *ctx, struct fw_app *app);
} fw_step_hooks;

/* The application. Caller-owned (static on a target); treat the fields as
 * private and use the functions below. */
typedef struct fw_app {
    uint32_t magic;
    fw_hal hal;
    uint32_t deadline_ns;
    uint16_t diag_period;
    uint16_t since_diag;
    uint8_t n_states;
    uint8_t n_terms[RHONN_MAX_STATES];
    rhonn_t net;
    fw_counters counters;
    /* protocol state */
    uint8_t anchored;           /* a Seq is known (last_seq valid) */
    uint8_t resync;             /* the next accepted measurement does not continue the last one */
    uint16_t last_seq;
    uint8_t learning;           /* mirrors rhonn_set_learning */
    uint8_t started;            /* a step succeeded since init/reset */
    uint8_t have_last_time;
    uint64_t last_time_ns;      /* reception time of the last accepted measurement */
    fw_frame tx_estimate;       /* the Estimate frame: set up at init, its payload encoded per measurement */
    uint8_t diag_counter;
    /* weight transfer (staged; the filter is untouched until commit) */
    uint8_t weights_open;
    uint16_t weights_missing;
    rhonn_real w_stage[RHONN_MAX_STATES][RHONN_MAX_TERMS];
    uint8_t w_have[RHONN_MAX_STATES][RHONN_MAX_TERMS];
    /* command authentication (fw_secoc.h) */
    fw_cmac_key secoc_key;      /* the compiled-in key, expanded at init */
    uint64_t secoc_freshness;   /* the last accepted freshness value */
    fw_step_hooks hooks;        /* none after fw_app_init */
} fw_app;

/* Validate the configuration and HAL, set up the identifier. On error the
 * app is left unchanged. FW_E_NULL, FW_E_CONFIG. */
fw_status fw_app_init(fw_app *app, const fw_app_config *cfg, const fw_hal *hal);

/* Handle one received frame (see REJECTION above). data may be NULL only
 * when len is 0; len above 64 is rejected as FW_E_LENGTH. Returns FW_OK,
 * the rejection reason, FW_E_STEP (accepted, step failed, last good
 * estimate sent with the status), or FW_E_HAL (handled, but a frame could
 * not be sent or the clock not read). */
fw_status fw_app_on_frame(fw_app *app, uint32_t id, const uint8_t *data, size_t len, uint64_t now_ns);

/* Take up to max_frames frames from hal->receive and handle each, stamped
 * with hal->now. *handled (may be NULL) receives the number handled. FW_OK
 * when the HAL ran dry or max_frames were handled (per-frame outcomes are
 * in the counters), FW_E_HAL when receive or the clock failed, FW_E_CONFIG
 * when the HAL has no receive function. */
fw_status fw_app_poll(fw_app *app, uint32_t max_frames, uint32_t *handled);

/* Send a Diagnostics frame now. */
fw_status fw_app_send_diagnostics(fw_app *app);

/* Count one overrun detected by the platform (e.g. a late loop wake-up). */
fw_status fw_app_note_overrun(fw_app *app);

/* Count frames the platform's receive queue dropped before the application
 * saw them (e.g. the increase of the kernel's SO_RXQ_OVFL count). */
fw_status fw_app_note_rx_drops(fw_app *app, uint32_t dropped);

/* Copy the counters. */
fw_status fw_app_get_counters(const fw_app *app, fw_counters *out);

/* The identifier, read-only, for the rhonn_get_* functions. */
fw_status fw_app_get_identifier(const fw_app *app, const rhonn_t **net);

/* The last accepted freshness value of the command authentication. */
fw_status fw_app_get_freshness(const fw_app *app, uint64_t *freshness);

/* Restore a freshness value saved before a restart (call after
 * fw_app_init), so that frames recorded before it cannot be replayed after
 * it. FW_E_FRESHNESS when it is below the current value (never back). */
fw_status fw_app_set_freshness(fw_app *app, uint64_t freshness);

/* Install step hooks (NULL: none). FW_E_NULL, FW_E_NOT_INIT. */
fw_status fw_app_set_step_hooks(fw_app *app, const fw_step_hooks *hooks);

/* Freeze (0) or resume (nonzero) learning, as the LearningOff / LearningOn
 * commands do (the Estimate's Learning flag follows). */
fw_status fw_app_set_learning(fw_app *app, int on);

/* Whether learning is on (1) or frozen (0); 0 for a NULL or uninitialised app. */
int fw_app_learning(const fw_app *app);

/* Human-readable name of a status code (a static string). */
const char *fw_status_name(fw_status status);

#ifdef __cplusplus
}
#endif

#endif /* FW_APP_H */
