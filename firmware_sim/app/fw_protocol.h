/*
 * fw_protocol.h - the identifier's CAN messages in physical units, on top of
 * the pack/unpack code cantools generates from rhonn_id.dbc
 * (firmware_sim/generated/rhonn_id.[ch]). This layer maps signals to state
 * and input indices and fixes the two conversions the generated code leaves
 * open. What they compute is cantools' conversion in Python, in double:
 *
 *   decode  physical = raw * scale, rounded to rhonn_real (a float32 build
 *           sees exactly np.float32(decoded));
 *   encode  raw = round(value / scale), nearest, ties to even, then
 *           saturated to the signal's DBC range.
 *
 * The double build computes them so, in double (the generated *_decode(),
 * fw_quantise()). The float32 build, the firmware's precision, runs on FPUs
 * without double precision, so it uses no double at all: with N = 1/scale,
 * an integer (rhonn_id_limits.h's INV_SCALE),
 *
 *   decode  physical = (float)raw / (float)N, one correctly rounded float
 *           division of two exact values;
 *   encode  raw = round_half_even(value * N) of the exact product
 *           (fw_quantise_f32()): from the float product where that
 *           decides it, else in 64-bit integer arithmetic.
 *
 * These give cantools' bits for every raw value and every float32: the
 * generator emits N only for scales whose double is within 2^-54 of 1/N
 * (generate_protocol.inverse_scale, docs/firmware-protocol.md, "Scaling
 * without double arithmetic"). So an Estimate's raw value is within half
 * an LSB of value / scale (unless saturated), and a decoded value is the
 * float nearest raw * scale.
 *
 * Which signals are the states and inputs, and their order, comes from the
 * generated rhonn_id_layout.h: for the committed rhonn_id.dbc the LIM's,
 * x = [q_m, v, lambda_a, lambda_b, i_a, i_b], u = [u_a, u_b]
 * (pyrhonn.plants.lim.STATE_NAMES / INPUT_NAMES); for another identifier's
 * DBC (pyrhonn export --dbc) its own, generated into a build directory
 * (tools/generate_protocol.py --dbc).
 */
#ifndef FW_PROTOCOL_H
#define FW_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>

#include "fw_hal.h"
#include "rhonn.h"

#ifdef __cplusplus
extern "C" {
#endif

#include "rhonn_id_layout.h" /* FW_N_STATES, FW_N_INPUTS: the DBC's (the LIM: 6 and 2) */
#define FW_WEIGHTS_PER_FRAME 12u /* 64 bytes: 4 header, 12 x 4 weights, 12 SecOC trailer */

/* A decoded Measurement frame. */
typedef struct {
    uint16_t seq;
    uint8_t valid[FW_N_STATES];   /* 1 = measured, 0 = dropped/held */
    rhonn_real x[FW_N_STATES];    /* decoded even when not valid (then unchecked) */
    rhonn_real u[FW_N_INPUTS];
} fw_measurement;

/* The content of an Estimate frame before scaling. */
typedef struct {
    uint16_t seq;
    uint8_t step_status;          /* rhonn_status, 0..15 */
    uint8_t learning;             /* 0/1 */
    uint8_t resync;               /* 0/1 */
    rhonn_real xhat[FW_N_STATES];
} fw_estimate;

/* A decoded WeightLoad frame (values past count are not filled). */
typedef struct {
    uint8_t neuron;
    uint8_t first;
    uint8_t count;
    float w[FW_WEIGHTS_PER_FRAME];
} fw_weight_chunk;

/* Decode and check a Measurement: FW_E_LENGTH unless len is the DBC length,
 * FW_E_RANGE when a valid state or any input is outside its DBC range.
 * *m is written only on FW_OK. */
fw_status fw_measurement_decode(const uint8_t *data, size_t len, fw_measurement *m);

/* Scale, round (ties to even) and saturate e into an Estimate frame of
 * size >= 16 bytes. *saturated (may be NULL) receives 1 when some value was
 * clipped to its range (the frame's Saturated flag says the same). A
 * non-finite value is sent as 0 and counts as saturated. FW_E_RANGE when
 * step_status > 15, FW_E_LENGTH when size is too small. */
fw_status fw_estimate_encode(const fw_estimate *e, uint8_t *data, size_t size, uint8_t *saturated);

/* Decode a WeightLoad frame: FW_E_LENGTH, or FW_E_RANGE when Neuron, First
 * or Count is outside its DBC range or one of the count values is not a
 * finite float within the DBC range. (Whether the indices fit the
 * identifier is the application's check.) *c is written only on FW_OK. */
fw_status fw_weight_chunk_decode(const uint8_t *data, size_t len, fw_weight_chunk *c);

/* One value through the estimate scaling, in double (the double build's):
 * raw = round_half_even(value / scale) clipped to [raw_min, raw_max];
 * *saturated = 1 when clipped or not finite (then raw is 0; -inf and +inf
 * go to the ends). FW_E_RANGE unless scale > 0 and raw_min <= raw_max.
 * Exposed for the protocol tests. */
fw_status fw_quantise(double value, double scale, int32_t raw_min, int32_t raw_max, int32_t *raw,
                      uint8_t *saturated);

/* The same for a float value and the scale 1/inv_scale (the float32
 * build's), without double arithmetic: raw = round_half_even(value *
 * inv_scale), the exact product, clipped as fw_quantise. Equal to
 * fw_quantise(value, fl64(1 / inv_scale), ...) for every float value when
 * inv_scale passes the generator's bound (see the top of this file).
 * FW_E_RANGE unless 1 <= inv_scale <= FW_INV_SCALE_MAX and raw_min <= raw_max. */
#define FW_INV_SCALE_MAX 16777216u /* 2^24: exact in float */
fw_status fw_quantise_f32(float value, uint32_t inv_scale, int32_t raw_min, int32_t raw_max, int32_t *raw,
                          uint8_t *saturated);

#ifdef __cplusplus
}
#endif

#endif /* FW_PROTOCOL_H */
