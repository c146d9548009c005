/*
 * fuzz_input.h - the fuzz targets' reading of their input: bytes, and reals
 * from two bytes each (a sign, a mantissa byte and an exponent spread over
 * 10^lo..10^hi, and, for a few codes, 0, NaN, +-Inf and values near the top
 * of the range), so that well-scaled and hostile data both occur. Past the
 * end of the input every byte reads 0.
 */
#ifndef RHONN_FUZZ_INPUT_H
#define RHONN_FUZZ_INPUT_H

#include <stddef.h>
#include <stdint.h>

#include "rhonn.h"

typedef struct {
    const uint8_t *p;
    size_t n;
} reader;

static inline uint8_t byte(reader *r)
{
    uint8_t b = 0;
    if (r->n > 0u) {
        b = *r->p++;
        r->n--;
    }
    return b;
}

static inline rhonn_real pow10i(int e)
{
    rhonn_real v = 1;
    rhonn_real f = e < 0 ? (rhonn_real)0.1 : (rhonn_real)10;
    int k = e < 0 ? -e : e;
    while (k-- > 0) {
        v *= f;
    }
    return v;
}

/* A real from two bytes: hostile codes first, else sign, mantissa, exponent. */
static inline rhonn_real real(reader *r, int lo, int hi)
{
    const uint8_t a = byte(r), b = byte(r);
    const rhonn_real big = (rhonn_real)(sizeof(rhonn_real) == 4 ? 3.0e38 : 1.0e308);
    switch (a) {
    case 0xFF: return (rhonn_real)0;
    case 0xFE: return big;
    case 0xFD: return -big;
    case 0xFC: return big * (rhonn_real)10; /* +Inf */
    case 0xFB: return (big * (rhonn_real)10) - (big * (rhonn_real)10); /* NaN */
    default: break;
    }
    {
        const int e = lo + (int)(b % (uint8_t)(hi - lo + 1));
        const rhonn_real m = (rhonn_real)1 + (rhonn_real)(a & 0x7Fu) / (rhonn_real)128;
        return (a & 0x80u ? -m : m) * pow10i(e);
    }
}

static inline rhonn_real positive(reader *r, int lo, int hi)
{
    rhonn_real v = real(r, lo, hi);
    return v < 0 ? -v : v;
}

/* The terms of a neuron of nc->n_terms terms: 1 or 2 factors each, of any
 * kind, power 1-3, delays 0-2 (an input's dead time too); with no inputs an
 * input factor reads the constant 1. */
static inline void read_terms(reader *r, rhonn_neuron_config *nc, size_t n_states, size_t n_inputs)
{
    size_t t, f;
    for (t = 0; t < nc->n_terms; ++t) {
        rhonn_term *term = &nc->terms[t];
        const uint8_t nf = (uint8_t)(1u + byte(r) % 2u);
        term->n_factors = nf;
        for (f = 0; f < nf; ++f) {
            rhonn_factor *fa = &term->factors[f];
            const uint8_t code = byte(r);
            fa->kind = (uint8_t)(code % 4u);
            fa->power = (uint8_t)(1u + (code >> 2) % 3u);
            if (fa->kind == RHONN_FACTOR_U) {
                fa->index = (uint8_t)(n_inputs ? (code >> 4) % n_inputs : 0u);
                fa->delay = (uint8_t)((code >> 6) % 3u);
                if (n_inputs == 0u) {
                    fa->delay = 0;
                    fa->kind = RHONN_FACTOR_ONE;
                }
            } else if (fa->kind != RHONN_FACTOR_ONE) {
                fa->index = (uint8_t)((code >> 4) % n_states);
                fa->delay = (uint8_t)((code >> 6) % 3u);
            }
        }
    }
}

#endif /* RHONN_FUZZ_INPUT_H */
