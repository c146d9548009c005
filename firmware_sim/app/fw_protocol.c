/*
 * fw_protocol.c - Measurement/Estimate/WeightLoad in physical units over the
 * cantools-generated pack/unpack of rhonn_id.dbc. See fw_protocol.h.
 */
#include "fw_protocol.h"

#include <string.h>

#include "rhonn_id.h"
#include "rhonn_id_limits.h"
#include "rhonn_id_layout.h"

/* Round to the nearest integer, ties to even (Python's round()), for
 * |v| < 2^52 (the caller clips v to the int32 range first). */
static int64_t round_half_even(double v)
{
    int64_t t = (int64_t)v; /* toward zero */
    double frac = v - (double)t;

    if (frac > 0.5 || (frac == 0.5 && (t & 1) != 0)) {
        return t + 1;
    }
    if (frac < -0.5 || (frac == -0.5 && (t & 1) != 0)) {
        return t - 1;
    }
    return t;
}

fw_status fw_quantise(double value, double scale, int32_t raw_min, int32_t raw_max, int32_t *raw,
                      uint8_t *saturated)
{
    double v;
    int64_t r;
    uint8_t sat = 0;

    if (raw == NULL) {
        return FW_E_NULL;
    }
    if (!(scale > 0.0) || raw_min > raw_max) {
        return FW_E_RANGE;
    }
    v = value / scale; /* as cantools: (value - offset) / scale, offset 0 */
    if (v != v) {
        r = 0;
        sat = 1;
    } else if (v < (double)raw_min - 1.0) { /* also -inf; keeps the cast below defined */
        r = raw_min;
        sat = 1;
    } else if (v > (double)raw_max + 1.0) {
        r = raw_max;
        sat = 1;
    } else {
        r = round_half_even(v);
        if (r < raw_min) {
            r = raw_min;
            sat = 1;
        } else if (r > raw_max) {
            r = raw_max;
            sat = 1;
        }
    }
    *raw = (int32_t)r;
    if (saturated != NULL) {
        *saturated = sat;
    }
    return FW_OK;
}

/* The rare path below stays out of line: inlined, it made quantise_f32 save
 * the eight registers its 64-bit arithmetic needs on every call (GCC). */
#if defined(__GNUC__) || defined(__clang__)
#define FW_RARE __attribute__((noinline, cold))
#else
#define FW_RARE
#endif

/* quantise_f32 in integer arithmetic only, for any float: the float's
 * significand times N is exact in 64 bits, and rounding it is a shift. */
static FW_RARE int32_t quantise_exact(float value, uint32_t inv_scale, int32_t raw_min, int32_t raw_max, uint8_t *sat)
{
    uint32_t bits, mant, biased;
    uint64_t p, n;
    int64_t r;
    int e; /* |value| = mant * 2^e exactly */

    memcpy(&bits, &value, sizeof bits);
    biased = (bits >> 23) & 0xFFu;
    mant = bits & 0x7FFFFFu;
    if (biased == 0xFFu) {
        /* NaN: 0; +-inf: the nearer end */
        *sat = 1;
        return mant != 0u ? 0 : (bits >> 31) != 0u ? raw_min : raw_max;
    }
    if (biased != 0u) {
        mant |= 0x800000u;
    } else {
        biased = 1u; /* subnormal */
    }
    e = (int)biased - 150;
    /* |value| * N = p * 2^e exactly: p < 2^24 * 2^24 = 2^48. */
    p = (uint64_t)mant * inv_scale;
    if (e > 8) {
        /* mant >= 2^23 (normal), so |value| * N >= 2^32: beyond any int32 range */
        n = (uint64_t)1 << 40;
    } else if (e >= 0) {
        n = p << e; /* < 2^56 */
    } else if (e < -49) {
        n = 0; /* p * 2^e < 2^48 * 2^-50: below 1/2 */
    } else {
        /* p * 2^e rounded to nearest, ties to even (Python's round()): q
         * keeps one bit below the units (the half), and the bits shifted
         * out of q say whether p is past the half */
        const unsigned s1 = (unsigned)-e - 1u;
        const uint64_t q = p >> s1;
        n = q >> 1;
        if ((q & 1u) != 0u && ((n & 1u) != 0u || (q << s1) != p)) {
            ++n;
        }
    }
    r = (bits >> 31) != 0u ? -(int64_t)n : (int64_t)n;
    if (r < raw_min) {
        *sat = 1;
        return raw_min;
    }
    if (r > raw_max) {
        *sat = 1;
        return raw_max;
    }
    return (int32_t)r;
}

/* fw_quantise_f32 for valid arguments (1 <= inv_scale <= 2^24, raw_min <=
 * raw_max): the raw value, round_half_even(value * N) of the exact product,
 * clipped. *sat is set to 1 when the value was clipped or not finite and
 * left alone otherwise, so one flag collects a frame's signals.
 *
 * Fast path, in float: y = fl(value * N). Where |y| < 2^23 every
 * half-integer is a float, so none lies between the exact product and y
 * (it would be nearer than y), and both round to the same integer, unless
 * y itself is halfway: then the exact product may lie on either side. That
 * case, |y| >= 2^22, inf and NaN go to quantise_exact. (Needs
 * -ffp-contract=off and round-to-nearest, as all of the firmware: a fused
 * or reassociated (y + c) - c would not round y.) */
#if defined(__GNUC__) || defined(__clang__)
__attribute__((always_inline)) /* six calls a frame: each one's N and range become constants */
#endif
static inline int32_t quantise_f32(float value, uint32_t inv_scale, int32_t raw_min, int32_t raw_max, uint8_t *sat)
{
    const float y = value * (float)inv_scale;
    if (y > -0x1p22f && y < 0x1p22f) { /* false for NaN */
        /* y to the nearest integer, ties to even, in two roundings: adding
         * 1.5 * 2^23 leaves no fraction bits in the sum (its ulp is 1 for
         * |y| < 2^22), and subtracting it again is exact. f = y - n is
         * exact, |f| <= 1/2, and 1/2 only when y is halfway. */
        const float n = (y + 0x1.8p23f) - 0x1.8p23f;
        const float f = y - n;
        if (f != 0.5f && f != -0.5f) {
            const int32_t r = (int32_t)n;
            if (r < raw_min) {
                *sat = 1;
                return raw_min;
            }
            if (r > raw_max) {
                *sat = 1;
                return raw_max;
            }
            return r;
        }
    }
    return quantise_exact(value, inv_scale, raw_min, raw_max, sat);
}

fw_status fw_quantise_f32(float value, uint32_t inv_scale, int32_t raw_min, int32_t raw_max, int32_t *raw,
                          uint8_t *saturated)
{
    uint8_t sat = 0;

    if (raw == NULL) {
        return FW_E_NULL;
    }
    if (inv_scale == 0u || inv_scale > FW_INV_SCALE_MAX || raw_min > raw_max) {
        return FW_E_RANGE;
    }
    *raw = quantise_f32(value, inv_scale, raw_min, raw_max, &sat);
    if (saturated != NULL) {
        *saturated = sat;
    }
    return FW_OK;
}

/* Scale a raw value to physical units as cantools does (see fw_protocol.h):
 * the float32 build divides by N = 1/scale in float, the double build
 * multiplies by the scale in double (the generated *_decode()). */
#if defined(RHONN_SINGLE)
#define FW_DECODE(decode_fn, raw, SIG) ((float)(raw) / (float)SIG##_INV_SCALE)
#else
#define FW_DECODE(decode_fn, raw, SIG) ((rhonn_real)decode_fn(raw))
#endif

/* A signal's raw value within its DBC range: the test of the generated
 * *_is_in_range(), with the bounds rhonn_id_limits.h states for it, made
 * inline (not a call per signal and frame) as one unsigned comparison:
 * raw - min wraps above max - min exactly when raw is outside [min, max]. */
#define FW_IN_RANGE(raw, SIG) \
    ((uint32_t)(raw) - (uint32_t)(SIG##_RAW_MIN) <= (uint32_t)(SIG##_RAW_MAX) - (uint32_t)(SIG##_RAW_MIN))

fw_status fw_measurement_decode(const uint8_t *data, size_t len, fw_measurement *m)
{
    struct rhonn_id_measurement_t f;
    fw_measurement out;
    int in_range;

    if (m == NULL) {
        return FW_E_NULL;
    }
    if (len != RHONN_ID_MEASUREMENT_LENGTH) {
        return FW_E_LENGTH;
    }
    if (data == NULL) {
        return FW_E_NULL;
    }
    if (rhonn_id_measurement_unpack(&f, data, len) != 0) {
        return FW_E_LENGTH;
    }
    /* A state flagged invalid is not range-checked: the rig may send a
     * sentinel there, and the core ignores it. Inputs are always used. */
    in_range = FW_MEASUREMENT_IN_RANGE(f);
    if (!in_range) {
        return FW_E_RANGE;
    }
    out.seq = f.seq;
    FW_MEASUREMENT_FILL(out, f);
    *m = out;
    return FW_OK;
}

/* One estimate through its signal's scaling into a field of the given type
 * (the DBC range fits it), or-ing the saturation into sat: quantise_f32 in
 * the float32 build, fw_quantise in the double build (fw_protocol.h). */
#if defined(RHONN_SINGLE)
#define FW_QUANTISE(field, type, value, SIG) \
    ((field) = (type)quantise_f32((value), SIG##_INV_SCALE, SIG##_RAW_MIN, SIG##_RAW_MAX, &sat))
#else
#define FW_QUANTISE(field, type, value, SIG)                                                           \
    do {                                                                                               \
        int32_t raw_;                                                                                  \
        uint8_t sat_ = 0;                                                                              \
        (void)fw_quantise((double)(value), SIG##_SCALE, SIG##_RAW_MIN, SIG##_RAW_MAX, &raw_, &sat_); \
        (field) = (type)raw_;                                                                          \
        sat |= sat_;                                                                                   \
    } while (0)
#endif

fw_status fw_estimate_encode(const fw_estimate *e, uint8_t *data, size_t size, uint8_t *saturated)
{
    struct rhonn_id_estimate_t f;
    uint8_t sat = 0;

    if (e == NULL || data == NULL) {
        return FW_E_NULL;
    }
    if (size < RHONN_ID_ESTIMATE_LENGTH) {
        return FW_E_LENGTH;
    }
    if (!rhonn_id_estimate_step_status_is_in_range(e->step_status)) {
        return FW_E_RANGE;
    }
    (void)rhonn_id_estimate_init(&f);
    f.seq = e->seq;
    f.step_status = e->step_status;
    f.learning = e->learning ? 1u : 0u;
    f.resync = e->resync ? 1u : 0u;
    FW_ESTIMATE_FILL(f, e);
    f.saturated = sat;
    if (rhonn_id_estimate_pack(data, &f, size) != (int)RHONN_ID_ESTIMATE_LENGTH) {
        return FW_E_LENGTH;
    }
    if (saturated != NULL) {
        *saturated = sat;
    }
    return FW_OK;
}

fw_status fw_weight_chunk_decode(const uint8_t *data, size_t len, fw_weight_chunk *c)
{
    struct rhonn_id_weight_load_t f;
    fw_weight_chunk out;
    uint8_t k;

    if (c == NULL) {
        return FW_E_NULL;
    }
    if (len != RHONN_ID_WEIGHT_LOAD_LENGTH) {
        return FW_E_LENGTH;
    }
    if (data == NULL) {
        return FW_E_NULL;
    }
    if (rhonn_id_weight_load_unpack(&f, data, len) != 0) {
        return FW_E_LENGTH;
    }
    if (!rhonn_id_weight_load_neuron_is_in_range(f.neuron) || !rhonn_id_weight_load_first_is_in_range(f.first)
        || !rhonn_id_weight_load_count_is_in_range(f.count) || f.count > FW_WEIGHTS_PER_FRAME) {
        return FW_E_RANGE;
    }
    memset(&out, 0, sizeof out);
    out.neuron = f.neuron;
    out.first = f.first;
    out.count = f.count;
    out.w[0] = f.w00;
    out.w[1] = f.w01;
    out.w[2] = f.w02;
    out.w[3] = f.w03;
    out.w[4] = f.w04;
    out.w[5] = f.w05;
    out.w[6] = f.w06;
    out.w[7] = f.w07;
    out.w[8] = f.w08;
    out.w[9] = f.w09;
    out.w[10] = f.w10;
    out.w[11] = f.w11;
    /* The generated range check of a float signal is false for NaN and
     * for values beyond the DBC's +-3.4e38 (so for +-Inf too). All twelve
     * signals share one range; W00's check stands for each. */
    for (k = 0; k < out.count; ++k) {
        if (!rhonn_id_weight_load_w00_is_in_range(out.w[k])) {
            return FW_E_RANGE;
        }
    }
    for (k = out.count; k < FW_WEIGHTS_PER_FRAME; ++k) {
        out.w[k] = 0.0f; /* past count: ignored */
    }
    *c = out;
    return FW_OK;
}
