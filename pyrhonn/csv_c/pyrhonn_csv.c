/* The CSV text codec of pyrhonn's data files and predictions (host only, not
 * part of the core): doubles written as their shortest round-trip decimal,
 * laid out as Python's repr() lays it out, and blocks of numeric CSV lines
 * parsed into columns, correctly rounded.
 *
 * Included by the cffi extension pyrhonn._csv (pyrhonn/_build.py), after the
 * tables that _build.py computes with exact integers:
 *   PYRHONN_POW5_INV[q] = floor(2^(bits(5^q) - 1 + 125) / 5^q) + 1, q = 0..341
 *   PYRHONN_POW5[i]     = floor(5^i * 2^(125 - bits(5^i))),           i = 0..325
 *   PYRHONN_POW5_128[q + 342] = 5^q normalized to 128 bits (top bit set),
 *                      rounded down, q = -342..308, with its binary exponent
 *                      PYRHONN_POW5_128_EXP[q + 342] (5^q ~ value * 2^exp)
 * each as {low 64 bits, high 64 bits}.
 *
 * Writing: the shortest digits are found by the Ryu algorithm (Adams, 2018:
 * "Ryu: fast float-to-string conversion"); the decimal is the shortest that
 * reads back as the same double, the nearest to it when several are as
 * short, as repr() picks it.
 * Reading: a cell of at most 19 significant digits is converted exactly
 * (Clinger's fast path, else a 128-bit product with 5^q bounded well enough
 * to round, as Lemire's "Number parsing at a gigabyte per second", 2021);
 * the rare cell that is not decided so (a tie, a subnormal, more digits) is
 * converted by strtod_l in the C locale. */
#include <locale.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

__extension__ typedef unsigned __int128 pyrhonn_u128;

#define PYRHONN_CSV_CELL_MAX 24 /* "-1.2345678901234567e-308" */

/* ---- writing -------------------------------------------------------------------------------- */

static uint32_t pyrhonn_pow5bits(int32_t e) { return (uint32_t)(((uint32_t)e * 1217359u) >> 19) + 1u; }
static uint32_t pyrhonn_log10_pow2(int32_t e) { return ((uint32_t)e * 78913u) >> 18; }
static uint32_t pyrhonn_log10_pow5(int32_t e) { return ((uint32_t)e * 732923u) >> 20; }

static int pyrhonn_multiple_of_pow5(uint64_t v, uint32_t p)
{
    uint32_t count = 0;
    while (v != 0 && v % 5 == 0) {
        v /= 5;
        count++;
    }
    return count >= p;
}

static int pyrhonn_multiple_of_pow2(uint64_t v, uint32_t p) { return (v & ((1ull << p) - 1)) == 0; }

static uint64_t pyrhonn_mul_shift(uint64_t m, const uint64_t *mul, int32_t j)
{
    pyrhonn_u128 low = (pyrhonn_u128)m * mul[0];
    pyrhonn_u128 high = (pyrhonn_u128)m * mul[1];
    return (uint64_t)(((low >> 64) + high) >> (j - 64));
}

/* The shortest decimal digits of a finite nonzero double |x| (its bits):
 * *digits * 10^*exponent. */
static void pyrhonn_shortest(uint64_t bits, uint64_t *digits, int32_t *exponent)
{
    const uint64_t mantissa = bits & ((1ull << 52) - 1);
    const uint32_t biased = (uint32_t)((bits >> 52) & 0x7ffu);
    int32_t e2;
    uint64_t m2, mv, vr, vp, vm, output;
    uint32_t mm_shift, removed = 0;
    int32_t e10;
    int even, vm_zeros = 0, vr_zeros = 0;
    uint8_t last_removed = 0;
    if (biased == 0) {
        e2 = 1 - 1023 - 52 - 2;
        m2 = mantissa;
    } else {
        e2 = (int32_t)biased - 1023 - 52 - 2;
        m2 = (1ull << 52) | mantissa;
    }
    even = (m2 & 1) == 0;
    mv = 4 * m2;
    mm_shift = (mantissa != 0 || biased <= 1) ? 1u : 0u;
    if (e2 >= 0) {
        const uint32_t q = pyrhonn_log10_pow2(e2) - (e2 > 3);
        const int32_t k = 125 + (int32_t)pyrhonn_pow5bits((int32_t)q) - 1;
        const int32_t i = -e2 + (int32_t)q + k;
        e10 = (int32_t)q;
        vr = pyrhonn_mul_shift(mv, PYRHONN_POW5_INV[q], i);
        vp = pyrhonn_mul_shift(mv + 2, PYRHONN_POW5_INV[q], i);
        vm = pyrhonn_mul_shift(mv - 1 - mm_shift, PYRHONN_POW5_INV[q], i);
        if (q <= 21) {
            if (mv % 5 == 0) {
                vr_zeros = pyrhonn_multiple_of_pow5(mv, q);
            } else if (even) {
                vm_zeros = pyrhonn_multiple_of_pow5(mv - 1 - mm_shift, q);
            } else {
                vp -= (uint64_t)pyrhonn_multiple_of_pow5(mv + 2, q);
            }
        }
    } else {
        const uint32_t q = pyrhonn_log10_pow5(-e2) - (-e2 > 1);
        const int32_t i = -e2 - (int32_t)q;
        const int32_t k = (int32_t)pyrhonn_pow5bits(i) - 125;
        const int32_t j = (int32_t)q - k;
        e10 = (int32_t)q + e2;
        vr = pyrhonn_mul_shift(mv, PYRHONN_POW5[i], j);
        vp = pyrhonn_mul_shift(mv + 2, PYRHONN_POW5[i], j);
        vm = pyrhonn_mul_shift(mv - 1 - mm_shift, PYRHONN_POW5[i], j);
        if (q <= 1) {
            vr_zeros = 1;
            if (even) {
                vm_zeros = mm_shift == 1;
            } else {
                --vp;
            }
        } else if (q < 63) {
            vr_zeros = pyrhonn_multiple_of_pow2(mv, q);
        }
    }
    if (vm_zeros || vr_zeros) {
        /* drop digits while the bounds differ, then while vm ends in 0 (when it is itself exact) */
        for (int pass = 0; pass < 2; pass++) {
            while (pass == 0 ? vp / 10 > vm / 10 : (vm_zeros && vm % 10 == 0)) {
                vm_zeros &= vm % 10 == 0;
                vr_zeros &= last_removed == 0;
                last_removed = (uint8_t)(vr % 10);
                vr /= 10;
                vp /= 10;
                vm /= 10;
                removed++;
            }
        }
        if (vr_zeros && last_removed == 5 && vr % 2 == 0) {
            last_removed = 4; /* a tie: to the even digit */
        }
        output = vr + (uint64_t)((vr == vm && (!even || !vm_zeros)) || last_removed >= 5);
    } else {
        int round_up = 0;
        if (vp / 100 > vm / 100) {
            round_up = vr % 100 >= 50;
            vr /= 100;
            vp /= 100;
            vm /= 100;
            removed += 2;
        }
        while (vp / 10 > vm / 10) {
            round_up = vr % 10 >= 5;
            vr /= 10;
            vp /= 10;
            vm /= 10;
            removed++;
        }
        output = vr + (uint64_t)(vr == vm || round_up);
    }
    *digits = output;
    *exponent = e10 + (int32_t)removed;
}

static const char pyrhonn_pairs[201] =
    "00010203040506070809101112131415161718192021222324252627282930313233343536373839"
    "40414243444546474849505152535455565758596061626364656667686970717273747576777879"
    "8081828384858687888990919293949596979899";

/* x as repr() writes it ("0.1", "1e-05", "1.5e+16", "-0.0", "100.0") at out;
 * x finite. At most 24 bytes; returns the count. */
static size_t pyrhonn_write_double(double x, char *out)
{
    uint64_t bits, digits;
    int32_t exponent, decpt, n = 0;
    char text[20];
    size_t at = 0;
    memcpy(&bits, &x, sizeof bits);
    if (bits >> 63) {
        out[at++] = '-';
    }
    if ((bits & ~(1ull << 63)) == 0) {
        memcpy(out + at, "0.0", 3);
        return at + 3;
    }
    pyrhonn_shortest(bits & ~(1ull << 63), &digits, &exponent);
    while (digits >= 100) { /* two digits a division */
        const uint64_t pair = digits % 100;
        digits /= 100;
        memcpy(text + 18 - n, pyrhonn_pairs + 2 * pair, 2);
        n += 2;
    }
    while (digits != 0) {
        text[19 - n++] = (char)('0' + digits % 10);
        digits /= 10;
    }
    {
        const char *d = text + 20 - n;
        decpt = n + exponent; /* x = 0.DIGITS * 10^decpt */
        if (decpt <= -4 || decpt > 16) {
            int32_t e = decpt - 1;
            out[at++] = d[0];
            if (n > 1) {
                out[at++] = '.';
                memcpy(out + at, d + 1, (size_t)(n - 1));
                at += (size_t)(n - 1);
            }
            out[at++] = 'e';
            out[at++] = e < 0 ? '-' : '+';
            e = e < 0 ? -e : e;
            if (e >= 100) {
                out[at++] = (char)('0' + e / 100);
            }
            out[at++] = (char)('0' + e / 10 % 10);
            out[at++] = (char)('0' + e % 10);
        } else if (decpt <= 0) {
            out[at++] = '0';
            out[at++] = '.';
            memset(out + at, '0', (size_t)(-decpt));
            at += (size_t)(-decpt);
            memcpy(out + at, d, (size_t)n);
            at += (size_t)n;
        } else if (decpt < n) {
            memcpy(out + at, d, (size_t)decpt);
            at += (size_t)decpt;
            out[at++] = '.';
            memcpy(out + at, d + decpt, (size_t)(n - decpt));
            at += (size_t)(n - decpt);
        } else {
            memcpy(out + at, d, (size_t)n);
            at += (size_t)n;
            memset(out + at, '0', (size_t)(decpt - n));
            at += (size_t)(decpt - n);
            out[at++] = '.';
            out[at++] = '0';
        }
    }
    return at;
}

/* Rows of CSV text: ``rows`` lines of ``cols`` cells from the row-major
 * ``values``, separated by ``sep``, each line ended by '\n'. A cell whose
 * ``show`` byte is 0 (``show`` NULL: none) or whose value is not finite is
 * empty; a column whose ``integer`` byte is 1 holds whole numbers below 2^53
 * in magnitude, written without a decimal point. ``out`` holds ``cap`` bytes.
 * Returns the bytes written; -1 when ``out`` is too small, -2 - (row * cols
 * + col) for a cell of an integer column that is not such a whole number. */
long long pyrhonn_csv_format(const double *values, const unsigned char *show, size_t rows, size_t cols,
                             const unsigned char *integer, char sep, char *out, size_t cap)
{
    size_t at = 0, r, c;
    for (r = 0; r < rows; r++) {
        if (cap - at < (cols + 1) * (PYRHONN_CSV_CELL_MAX + 1)) {
            return -1;
        }
        for (c = 0; c < cols; c++) {
            const double x = values[r * cols + c];
            if (c) {
                out[at++] = sep;
            }
            if ((show != NULL && !show[r * cols + c]) || !(x - x == 0.0)) {
                continue;
            }
            if (integer != NULL && integer[c]) {
                char text[20];
                int n = 0;
                uint64_t v;
                if (!(x > -9007199254740992.0 && x < 9007199254740992.0) || x != (double)(int64_t)x) {
                    return -2 - (long long)(r * cols + c);
                }
                if (x < 0) {
                    out[at++] = '-';
                }
                v = (uint64_t)(x < 0 ? -(int64_t)x : (int64_t)x);
                do {
                    text[19 - n++] = (char)('0' + v % 10);
                    v /= 10;
                } while (v != 0);
                memcpy(out + at, text + 20 - n, (size_t)n);
                at += (size_t)n;
            } else {
                at += pyrhonn_write_double(x, out + at);
            }
        }
        out[at++] = '\n';
    }
    return (long long)at;
}

/* ---- reading -------------------------------------------------------------------------------- */

static const double pyrhonn_exact_pow10[23] = {
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11,
    1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
};

/* w * 10^q (w > 0, q in -342..308) as a double when decided exactly here:
 * 1, else 0 (the caller converts it otherwise). */
static int pyrhonn_decimal_to_double(uint64_t w, int32_t q, double *value)
{
    const uint64_t *p;
    pyrhonn_u128 low, high, h, r, half;
    uint64_t m, bits;
    int lz = 0, top, shift;
    int32_t e;
    if (w <= (1ull << 53) && q >= -22 && q <= 22) { /* both exact: one rounding (Clinger) */
        *value = q >= 0 ? (double)w * pyrhonn_exact_pow10[q] : (double)w / pyrhonn_exact_pow10[-q];
        return 1;
    }
    while (!(w >> 63)) {
        w <<= 1;
        lz++;
    }
    p = PYRHONN_POW5_128[q + 342];
    /* w * (P + d), 0 <= d < 1, lies in [F, F + 2^64) with F = w * P (192 bits);
     * divided by 2^64 it lies in [h, h + 2) with h = floor(F / 2^64). */
    low = (pyrhonn_u128)w * p[0];
    high = (pyrhonn_u128)w * p[1];
    h = high + (low >> 64);
    top = (int)(h >> 127); /* h >= 2^126 */
    shift = 126 + top - 52; /* the 53 bits kept */
    r = h & ((((pyrhonn_u128)1) << shift) - 1);
    half = ((pyrhonn_u128)1) << (shift - 1);
    if (r <= half && half <= r + 2) {
        return 0; /* a rounding boundary within reach: undecided here */
    }
    if ((r | 3) == ((((pyrhonn_u128)1) << shift) - 1)) {
        return 0; /* carries into the kept bits within reach */
    }
    m = (uint64_t)(h >> shift) + (r > half ? 1u : 0u);
    e = (int32_t)shift + 64 + q + PYRHONN_POW5_128_EXP[q + 342] - lz + 52; /* x = m * 2^(e - 52) */
    if (m == (1ull << 53)) {
        m >>= 1;
        e++;
    }
    if (e < -1022 || e > 1023) {
        return 0; /* subnormal or out of range */
    }
    bits = ((uint64_t)(e + 1023) << 52) | (m & ((1ull << 52) - 1));
    memcpy(value, &bits, sizeof bits);
    return 1;
}

static locale_t pyrhonn_c_locale;

/* The number in text[0..n) (its sign, digits, point and exponent already
 * checked), by strtod in the C locale. */
static double pyrhonn_strtod(const char *text, size_t n, int *ok)
{
    char buf[512];
    char *end;
    double x;
    locale_t c_locale;
    if (n >= sizeof buf) {
        *ok = 0;
        return 0.0;
    }
    c_locale = __atomic_load_n(&pyrhonn_c_locale, __ATOMIC_ACQUIRE);
    if (c_locale == (locale_t)0) { /* made once; a thread that loses the race frees its own */
        locale_t made = newlocale(LC_ALL_MASK, "C", (locale_t)0), none = (locale_t)0;
        if (made == (locale_t)0) {
            *ok = 0;
            return 0.0;
        }
        if (__atomic_compare_exchange_n(&pyrhonn_c_locale, &none, made, 0, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE)) {
            c_locale = made;
        } else {
            freelocale(made);
            c_locale = none;
        }
    }
    memcpy(buf, text, n);
    buf[n] = '\0';
    x = strtod_l(buf, &end, c_locale);
    *ok = end == buf + n;
    return x;
}

/* The digits at *at (up to e): the first 19 significant ones into *w, each
 * adding ``kept`` to the decimal exponent *q, the others counted and adding
 * ``dropped``. Returns whether there was a digit. */
static int pyrhonn_digit_run(const char **at, const char *e, uint64_t *w, int32_t *digits, int32_t *q, int32_t kept,
                             int32_t dropped)
{
    const char *s = *at, *first = *at;
    while (s < e && *s >= '0' && *s <= '9') {
        if (*digits < 19) {
            *w = *w * 10 + (uint64_t)(*s - '0');
            *digits += (*w != 0);
            *q += kept;
        } else {
            (*digits)++;
            *q += dropped;
        }
        s++;
    }
    *at = s;
    return s != first;
}

/* One cell [s, e) as a number: 1 and *value, 2 for an empty cell (spaces
 * only; *value NaN), 0 for anything else (not a plain decimal number, or out
 * of the float64 range). */
static int pyrhonn_cell(const char *s, const char *e, int tab_is_space, double *value)
{
    const char *start, *stop;
    uint64_t w = 0;
    int32_t q = 0, digits = 0, any = 0, exp10 = 0, exp_sign = 1;
    int negative = 0, ok = 1;
    while (s < e && (*s == ' ' || (tab_is_space && *s == '\t'))) s++;
    while (e > s && (e[-1] == ' ' || (tab_is_space && e[-1] == '\t'))) e--;
    if (s == e) {
        *value = __builtin_nan("");
        return 2;
    }
    start = s;
    if (*s == '+' || *s == '-') {
        negative = *s == '-';
        s++;
    }
    any = pyrhonn_digit_run(&s, e, &w, &digits, &q, 0, 1);
    if (s < e && *s == '.') {
        s++;
        any |= pyrhonn_digit_run(&s, e, &w, &digits, &q, -1, 0);
    }
    if (!any) {
        return 0;
    }
    if (s < e && (*s == 'e' || *s == 'E')) {
        int exp_digits = 0;
        s++;
        if (s < e && (*s == '+' || *s == '-')) {
            exp_sign = *s == '-' ? -1 : 1;
            s++;
        }
        while (s < e && *s >= '0' && *s <= '9') {
            if (exp10 < 100000) {
                exp10 = exp10 * 10 + (*s - '0');
            }
            exp_digits++;
            s++;
        }
        if (!exp_digits) {
            return 0;
        }
    }
    if (s != e) {
        return 0;
    }
    stop = e;
    q += exp_sign * exp10;
    if (w == 0) {
        *value = negative ? -0.0 : 0.0;
        return 1;
    }
    if (digits > 19 || q < -342 || q > 308 || !pyrhonn_decimal_to_double(w, q, value)) {
        *value = pyrhonn_strtod(start, (size_t)(stop - start), &ok);
        if (!ok || !(*value - *value == 0.0)) {
            return 0;
        }
        return 1;
    }
    if (negative) {
        *value = -*value;
    }
    return 1;
}

/* Parses the CSV lines of text[0..n) (no quotes; a line ends at '\n' or
 * "\r\n", the last one possibly at the end of the text; a lone '\r' is
 * refused), each of ``fields`` fields
 * separated by ``sep``. Field f's ``kind``: 0 ignored, 1 a number (into
 * column ``slot[f]`` of the row-major ``numbers``, ``n_numbers`` wide; an
 * empty cell NaN), 2 a flag (into column ``slot[f]`` of ``flags``,
 * ``n_flags`` wide: 0 or 1 for a bare "0" or "1", 2 for anything else). At
 * most ``max_rows`` lines. Returns the lines parsed; on a defect -1 - the
 * line (0-based) and *bad_field the first field that is not a number
 * (0-based), or -1 when the line is blank, holds a lone '\r', has too few
 * or too many fields, or is beyond ``max_rows``. */
long long pyrhonn_csv_parse(const char *text, size_t n, char sep, size_t fields, const unsigned char *kind,
                            const size_t *slot, double *numbers, size_t n_numbers, unsigned char *flags,
                            size_t n_flags, size_t max_rows, long long *bad_field)
{
    const char *p = text, *end = text + n;
    size_t row = 0;
    const int tab_is_space = sep != '\t';
    *bad_field = -1;
    while (p < end) {
        size_t f = 0;
        long long bad = -1; /* the first field that is not a number, named once the line is counted */
        const char *blank = p;
        if (row >= max_rows) {
            return -1 - (long long)row;
        }
        while (blank < end && (*blank == ' ' || *blank == '\t')) blank++;
        if (blank == end || *blank == '\n' || (*blank == '\r' && blank + 1 < end && blank[1] == '\n')) {
            return -1 - (long long)row; /* a blank line */
        }
        for (;;) {
            const char *cell = p, *cell_end;
            while (p < end && *p != sep && *p != '\n' && *p != '\r') p++;
            cell_end = p;
            if (p < end && *p == '\r') {
                if (p + 1 == end || p[1] != '\n') {
                    return -1 - (long long)row; /* a lone \r: a line end to some readers */
                }
                p++; /* the line ends by \r\n */
            }
            if (f >= fields) {
                return -1 - (long long)row;
            }
            if (kind[f] == 1) {
                if (bad < 0 && !pyrhonn_cell(cell, cell_end, tab_is_space, &numbers[row * n_numbers + slot[f]])) {
                    bad = (long long)f;
                }
            } else if (kind[f] == 2) {
                flags[row * n_flags + slot[f]] =
                    (unsigned char)(cell_end - cell == 1 && (*cell == '0' || *cell == '1') ? *cell - '0' : 2);
            }
            f++;
            if (p < end && *p == sep) {
                p++;
                continue;
            }
            break;
        }
        if (f != fields) {
            return -1 - (long long)row;
        }
        if (bad >= 0) {
            *bad_field = bad;
            return -1 - (long long)row;
        }
        if (p < end) {
            p++; /* the '\n' */
        }
        row++;
    }
    return (long long)row;
}
