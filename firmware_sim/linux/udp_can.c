/*
 * udp_can.c - python-can's udp_multicast msgpack map, encoded and decoded
 * without allocation (see udp_can.h for what is accepted and rejected).
 */
#include "udp_can.h"

#include <float.h>
#include <string.h>

/* IEEE 754 binary32 / binary64, as msgpack's float32 / float64 are. */
typedef char udp_can_float_is_32_bits[sizeof(float) == 4 ? 1 : -1];
typedef char udp_can_double_is_64_bits[sizeof(double) == 8 ? 1 : -1];

/* The keys, in pack_message's order (a dict keeps insertion order). */
enum {
    K_TIMESTAMP, K_ARBITRATION_ID, K_IS_EXTENDED_ID, K_IS_REMOTE_FRAME, K_IS_ERROR_FRAME, K_CHANNEL, K_DLC,
    K_DATA, K_IS_FD, K_BITRATE_SWITCH, K_ERROR_STATE_INDICATOR, N_KEYS
};

static const char *const KEY_NAMES[N_KEYS] = {
    "timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame", "channel", "dlc",
    "data", "is_fd", "bitrate_switch", "error_state_indicator"};

#define ALL_KEYS ((1u << N_KEYS) - 1u)

/* msgpack type bytes used here */
#define MP_NIL 0xc0u
#define MP_FALSE 0xc2u
#define MP_TRUE 0xc3u
#define MP_BIN8 0xc4u
#define MP_BIN16 0xc5u
#define MP_BIN32 0xc6u
#define MP_FLOAT32 0xcau
#define MP_FLOAT64 0xcbu
#define MP_UINT8 0xccu
#define MP_UINT16 0xcdu
#define MP_UINT32 0xceu
#define MP_UINT64 0xcfu
#define MP_INT8 0xd0u
#define MP_INT64 0xd3u
#define MP_STR8 0xd9u
#define MP_STR16 0xdau
#define MP_STR32 0xdbu
#define MP_MAP16 0xdeu
#define MP_MAP32 0xdfu

const char *udp_can_status_name(udp_can_status status)
{
    switch (status) {
    case UDP_CAN_OK: return "ok";
    case UDP_CAN_E_NULL: return "null";
    case UDP_CAN_E_TRUNCATED: return "truncated";
    case UDP_CAN_E_NOT_MAP: return "not_map";
    case UDP_CAN_E_KEY: return "key";
    case UDP_CAN_E_DUPLICATE: return "duplicate";
    case UDP_CAN_E_MISSING: return "missing";
    case UDP_CAN_E_TYPE: return "type";
    case UDP_CAN_E_DATA_LENGTH: return "data_length";
    case UDP_CAN_E_DLC: return "dlc";
    case UDP_CAN_E_ID: return "id";
    case UDP_CAN_E_FLAGS: return "flags";
    case UDP_CAN_E_TIMESTAMP: return "timestamp";
    case UDP_CAN_E_TRAILING: return "trailing";
    case UDP_CAN_E_SPACE: return "space";
    }
    return "?";
}

udp_can_status udp_can_check(const udp_can_msg *m)
{
    double ts;
    if (m == NULL) {
        return UDP_CAN_E_NULL;
    }
    ts = m->timestamp;
    if (ts != ts || ts < 0.0 || ts > DBL_MAX) { /* NaN, negative, +inf (-0.0 passes, as in python-can) */
        return UDP_CAN_E_TIMESTAMP;
    }
    if (m->is_extended_id > 1u || m->is_remote_frame > 1u || m->is_error_frame > 1u || m->is_fd > 1u ||
        m->bitrate_switch > 1u || m->error_state_indicator > 1u) {
        return UDP_CAN_E_FLAGS;
    }
    if (m->is_remote_frame && (m->is_error_frame || m->is_fd)) {
        return UDP_CAN_E_FLAGS;
    }
    if (m->arbitration_id >= (m->is_extended_id ? 0x20000000u : 0x800u)) {
        return UDP_CAN_E_ID;
    }
    if (m->dlc > (m->is_fd ? UDP_CAN_MAX_DATA : 8u)) {
        return UDP_CAN_E_DLC;
    }
    if (m->is_remote_frame) {
        if (m->len != 0u) {
            return UDP_CAN_E_FLAGS; /* remote frames carry no data */
        }
    } else if (m->len > UDP_CAN_MAX_DATA) {
        return UDP_CAN_E_DATA_LENGTH;
    } else if (m->dlc != m->len) {
        return UDP_CAN_E_DLC;
    }
    if (!m->is_fd && (m->bitrate_switch || m->error_state_indicator)) {
        return UDP_CAN_E_FLAGS;
    }
    return UDP_CAN_OK;
}

/* ------------------------------------------------------------- encoder */

typedef struct {
    uint8_t b[UDP_CAN_MAX_ENCODED];
    size_t n;
    int overflow;
} writer;

static void put(writer *w, uint8_t byte)
{
    if (w->n < sizeof w->b) {
        w->b[w->n++] = byte;
    } else {
        w->overflow = 1;
    }
}

static void put_be(writer *w, uint64_t v, unsigned bytes)
{
    while (bytes-- > 0u) {
        put(w, (uint8_t)(v >> (8u * bytes)));
    }
}

static void put_key(writer *w, unsigned k)
{
    const char *s = KEY_NAMES[k];
    size_t len = strlen(s);
    put(w, (uint8_t)(0xa0u | len)); /* fixstr: every name is shorter than 32 */
    while (*s != '\0') {
        put(w, (uint8_t)*s++);
    }
}

static void put_bool(writer *w, unsigned k, uint8_t v)
{
    put_key(w, k);
    put(w, v ? MP_TRUE : MP_FALSE);
}

static void put_uint(writer *w, unsigned k, uint32_t v)
{
    put_key(w, k);
    if (v < 0x80u) {
        put(w, (uint8_t)v);
    } else if (v <= 0xffu) {
        put(w, MP_UINT8);
        put_be(w, v, 1u);
    } else if (v <= 0xffffu) {
        put(w, MP_UINT16);
        put_be(w, v, 2u);
    } else {
        put(w, MP_UINT32);
        put_be(w, v, 4u);
    }
}

udp_can_status udp_can_encode(const udp_can_msg *msg, uint8_t *out, size_t cap, size_t *written)
{
    writer w;
    uint64_t bits;
    udp_can_status st;
    uint8_t i;

    if (msg == NULL || out == NULL) {
        return UDP_CAN_E_NULL;
    }
    st = udp_can_check(msg);
    if (st != UDP_CAN_OK) {
        return st;
    }
    w.n = 0;
    w.overflow = 0;
    put(&w, (uint8_t)(0x80u | N_KEYS)); /* fixmap of 11 */
    put_key(&w, K_TIMESTAMP);
    put(&w, MP_FLOAT64);
    memcpy(&bits, &msg->timestamp, sizeof bits);
    put_be(&w, bits, 8u);
    put_uint(&w, K_ARBITRATION_ID, msg->arbitration_id);
    put_bool(&w, K_IS_EXTENDED_ID, msg->is_extended_id);
    put_bool(&w, K_IS_REMOTE_FRAME, msg->is_remote_frame);
    put_bool(&w, K_IS_ERROR_FRAME, msg->is_error_frame);
    put_key(&w, K_CHANNEL);
    put(&w, MP_NIL);
    put_uint(&w, K_DLC, msg->dlc);
    put_key(&w, K_DATA);
    put(&w, MP_BIN8);
    put(&w, msg->len);
    for (i = 0; i < msg->len; ++i) {
        put(&w, msg->data[i]);
    }
    put_bool(&w, K_IS_FD, msg->is_fd);
    put_bool(&w, K_BITRATE_SWITCH, msg->bitrate_switch);
    put_bool(&w, K_ERROR_STATE_INDICATOR, msg->error_state_indicator);
    if (w.overflow || w.n > cap) {
        return w.overflow ? UDP_CAN_E_DATA_LENGTH : UDP_CAN_E_SPACE; /* overflow: unreachable after check */
    }
    memcpy(out, w.b, w.n);
    if (written != NULL) {
        *written = w.n;
    }
    return UDP_CAN_OK;
}

/* ------------------------------------------------------------- decoder */

typedef struct {
    const uint8_t *b;
    size_t n, pos;
} reader;

static int have(const reader *r, size_t k)
{
    return r->n - r->pos >= k;
}

/* Big-endian unsigned of `bytes` bytes at the cursor (caller checked have). */
static uint64_t take_be(reader *r, unsigned bytes)
{
    uint64_t v = 0;
    while (bytes-- > 0u) {
        v = (v << 8) | r->b[r->pos++];
    }
    return v;
}

/* Length of a str/bin/map whose type byte was just read: `bytes` bytes of
 * big-endian length follow. */
static udp_can_status take_length(reader *r, unsigned bytes, uint64_t *len)
{
    if (!have(r, bytes)) {
        return UDP_CAN_E_TRUNCATED;
    }
    *len = take_be(r, bytes);
    return UDP_CAN_OK;
}

/* Any msgpack integer. The value is neg ? -mag : mag. UDP_CAN_E_TYPE when
 * the item is not an integer (cursor unmoved). */
static udp_can_status take_int(reader *r, int *neg, uint64_t *mag)
{
    unsigned t, bytes;
    uint64_t v;
    if (!have(r, 1u)) {
        return UDP_CAN_E_TRUNCATED;
    }
    t = r->b[r->pos];
    if (t <= 0x7fu) {
        r->pos += 1u;
        *neg = 0;
        *mag = t;
        return UDP_CAN_OK;
    }
    if (t >= 0xe0u) { /* negative fixint, -32..-1 */
        r->pos += 1u;
        *neg = 1;
        *mag = 0x100u - t;
        return UDP_CAN_OK;
    }
    if (t >= MP_UINT8 && t <= MP_UINT64) {
        bytes = 1u << (t - MP_UINT8);
        if (!have(r, 1u + bytes)) {
            return UDP_CAN_E_TRUNCATED;
        }
        r->pos += 1u;
        *neg = 0;
        *mag = take_be(r, bytes);
        return UDP_CAN_OK;
    }
    if (t >= MP_INT8 && t <= MP_INT64) {
        bytes = 1u << (t - MP_INT8);
        if (!have(r, 1u + bytes)) {
            return UDP_CAN_E_TRUNCATED;
        }
        r->pos += 1u;
        v = take_be(r, bytes);
        if (bytes < 8u && (v >> (8u * bytes - 1u)) != 0u) { /* sign-extend */
            v |= ~(uint64_t)0 << (8u * bytes);
        }
        *neg = (v >> 63) != 0u;
        *mag = *neg ? (~v + 1u) : v; /* two's complement magnitude; INT64_MIN gives 2^63 */
        return UDP_CAN_OK;
    }
    return UDP_CAN_E_TYPE;
}

static udp_can_status take_bool(reader *r, uint8_t *v)
{
    if (!have(r, 1u)) {
        return UDP_CAN_E_TRUNCATED;
    }
    if (r->b[r->pos] != MP_TRUE && r->b[r->pos] != MP_FALSE) {
        return UDP_CAN_E_TYPE;
    }
    *v = r->b[r->pos++] == MP_TRUE;
    return UDP_CAN_OK;
}

/* A str header at the cursor: its length (cursor after the header), or
 * UDP_CAN_E_TYPE when the item is not a str (cursor unmoved). */
static udp_can_status take_str_header(reader *r, uint64_t *len)
{
    unsigned t;
    if (!have(r, 1u)) {
        return UDP_CAN_E_TRUNCATED;
    }
    t = r->b[r->pos];
    if (t >= 0xa0u && t <= 0xbfu) {
        r->pos += 1u;
        *len = t & 0x1fu;
        return UDP_CAN_OK;
    }
    if (t == MP_STR8 || t == MP_STR16 || t == MP_STR32) {
        udp_can_status st;
        size_t at = r->pos;
        r->pos += 1u;
        st = take_length(r, t == MP_STR8 ? 1u : t == MP_STR16 ? 2u : 4u, len);
        if (st != UDP_CAN_OK) {
            r->pos = at;
        }
        return st;
    }
    return UDP_CAN_E_TYPE;
}

/* Strict UTF-8, as Python's decoder: no overlong forms, no surrogates, at most U+10FFFF. */
static int utf8_valid(const uint8_t *s, size_t n)
{
    size_t i = 0;
    while (i < n) {
        unsigned c = s[i], lo = 0x80u, hi = 0xbfu;
        size_t more, j;
        if (c <= 0x7fu) {
            i += 1u;
            continue;
        }
        if (c >= 0xc2u && c <= 0xdfu) {
            more = 1u;
        } else if (c >= 0xe0u && c <= 0xefu) {
            more = 2u;
            lo = c == 0xe0u ? 0xa0u : 0x80u;
            hi = c == 0xedu ? 0x9fu : 0xbfu;
        } else if (c >= 0xf0u && c <= 0xf4u) {
            more = 3u;
            lo = c == 0xf0u ? 0x90u : 0x80u;
            hi = c == 0xf4u ? 0x8fu : 0xbfu;
        } else {
            return 0;
        }
        if (n - i - 1u < more) {
            return 0;
        }
        for (j = 1; j <= more; ++j) {
            unsigned d = s[i + j];
            if (d < (j == 1u ? lo : 0x80u) || d > (j == 1u ? hi : 0xbfu)) {
                return 0;
            }
        }
        i += 1u + more;
    }
    return 1;
}

/* The channel: nil, an integer or a UTF-8 str; its value is not kept. */
static udp_can_status skip_channel(reader *r)
{
    udp_can_status st;
    uint64_t len, mag;
    int neg;
    if (!have(r, 1u)) {
        return UDP_CAN_E_TRUNCATED;
    }
    if (r->b[r->pos] == MP_NIL) {
        r->pos += 1u;
        return UDP_CAN_OK;
    }
    st = take_int(r, &neg, &mag);
    if (st != UDP_CAN_E_TYPE) {
        return st;
    }
    st = take_str_header(r, &len);
    if (st != UDP_CAN_OK) {
        return st;
    }
    if (len > r->n - r->pos) {
        return UDP_CAN_E_TRUNCATED;
    }
    if (!utf8_valid(r->b + r->pos, (size_t)len)) {
        return UDP_CAN_E_TYPE;
    }
    r->pos += (size_t)len;
    return UDP_CAN_OK;
}

static udp_can_status take_timestamp(reader *r, double *ts)
{
    unsigned t;
    uint64_t mag;
    int neg;
    udp_can_status st;
    if (!have(r, 1u)) {
        return UDP_CAN_E_TRUNCATED;
    }
    t = r->b[r->pos];
    if (t == MP_FLOAT64) {
        uint64_t bits;
        if (!have(r, 9u)) {
            return UDP_CAN_E_TRUNCATED;
        }
        r->pos += 1u;
        bits = take_be(r, 8u);
        memcpy(ts, &bits, sizeof *ts);
        return UDP_CAN_OK;
    }
    if (t == MP_FLOAT32) {
        uint32_t bits;
        float f;
        if (!have(r, 5u)) {
            return UDP_CAN_E_TRUNCATED;
        }
        r->pos += 1u;
        bits = (uint32_t)take_be(r, 4u);
        memcpy(&f, &bits, sizeof f);
        *ts = (double)f;
        return UDP_CAN_OK;
    }
    st = take_int(r, &neg, &mag); /* an int timestamp: python-can takes it as it is */
    if (st == UDP_CAN_OK) {
        *ts = neg ? -(double)mag : (double)mag;
    }
    return st;
}

static udp_can_status take_data(reader *r, udp_can_msg *m)
{
    unsigned t;
    uint64_t len;
    udp_can_status st;
    if (!have(r, 1u)) {
        return UDP_CAN_E_TRUNCATED;
    }
    t = r->b[r->pos];
    if (t != MP_BIN8 && t != MP_BIN16 && t != MP_BIN32) {
        return UDP_CAN_E_TYPE;
    }
    r->pos += 1u;
    st = take_length(r, t == MP_BIN8 ? 1u : t == MP_BIN16 ? 2u : 4u, &len);
    if (st != UDP_CAN_OK) {
        return st;
    }
    if (len > UDP_CAN_MAX_DATA) {
        return UDP_CAN_E_DATA_LENGTH;
    }
    if (len > r->n - r->pos) {
        return UDP_CAN_E_TRUNCATED;
    }
    m->len = (uint8_t)len;
    memcpy(m->data, r->b + r->pos, (size_t)len);
    r->pos += (size_t)len;
    return UDP_CAN_OK;
}

/* The key at the cursor: its index in KEY_NAMES. */
static udp_can_status take_key(reader *r, unsigned *k)
{
    uint64_t len;
    unsigned i;
    udp_can_status st = take_str_header(r, &len);
    if (st == UDP_CAN_E_TYPE) {
        return UDP_CAN_E_KEY;
    }
    if (st != UDP_CAN_OK) {
        return st;
    }
    if (len > r->n - r->pos) {
        return UDP_CAN_E_TRUNCATED;
    }
    for (i = 0; i < N_KEYS; ++i) {
        if (strlen(KEY_NAMES[i]) == len && memcmp(KEY_NAMES[i], r->b + r->pos, (size_t)len) == 0) {
            r->pos += (size_t)len;
            *k = i;
            return UDP_CAN_OK;
        }
    }
    return UDP_CAN_E_KEY;
}

udp_can_status udp_can_decode(const uint8_t *buf, size_t n, udp_can_msg *msg)
{
    reader r;
    udp_can_msg m;
    uint64_t count, i, mag;
    unsigned t, seen = 0, k;
    int neg;
    udp_can_status st;
    uint8_t *flag;

    if (msg == NULL || (buf == NULL && n != 0u)) {
        return UDP_CAN_E_NULL;
    }
    r.b = buf;
    r.n = n;
    r.pos = 0;
    memset(&m, 0, sizeof m);
    if (!have(&r, 1u)) {
        return UDP_CAN_E_TRUNCATED;
    }
    t = r.b[r.pos++];
    if (t >= 0x80u && t <= 0x8fu) {
        count = t & 0x0fu;
    } else if (t == MP_MAP16 || t == MP_MAP32) {
        st = take_length(&r, t == MP_MAP16 ? 2u : 4u, &count);
        if (st != UDP_CAN_OK) {
            return st;
        }
    } else {
        return UDP_CAN_E_NOT_MAP;
    }
    /* every pair takes at least 2 bytes, so the loop ends with the buffer */
    for (i = 0; i < count; ++i) {
        st = take_key(&r, &k);
        if (st != UDP_CAN_OK) {
            return st;
        }
        if (seen & (1u << k)) {
            return UDP_CAN_E_DUPLICATE;
        }
        seen |= 1u << k;
        flag = NULL;
        switch (k) {
        case K_TIMESTAMP:
            st = take_timestamp(&r, &m.timestamp);
            break;
        case K_ARBITRATION_ID:
            st = take_int(&r, &neg, &mag);
            if (st == UDP_CAN_OK) {
                if (neg || mag > 0xffffffffu) {
                    return UDP_CAN_E_ID;
                }
                m.arbitration_id = (uint32_t)mag;
            }
            break;
        case K_DLC:
            st = take_int(&r, &neg, &mag);
            if (st == UDP_CAN_OK) {
                if (neg || mag > UDP_CAN_MAX_DATA) {
                    return UDP_CAN_E_DLC;
                }
                m.dlc = (uint8_t)mag;
            }
            break;
        case K_CHANNEL:
            st = skip_channel(&r);
            break;
        case K_DATA:
            st = take_data(&r, &m);
            break;
        case K_IS_EXTENDED_ID: flag = &m.is_extended_id; break;
        case K_IS_REMOTE_FRAME: flag = &m.is_remote_frame; break;
        case K_IS_ERROR_FRAME: flag = &m.is_error_frame; break;
        case K_IS_FD: flag = &m.is_fd; break;
        case K_BITRATE_SWITCH: flag = &m.bitrate_switch; break;
        default: flag = &m.error_state_indicator; break;
        }
        if (flag != NULL) {
            st = take_bool(&r, flag);
        }
        if (st != UDP_CAN_OK) {
            return st;
        }
    }
    if (seen != ALL_KEYS) {
        return UDP_CAN_E_MISSING;
    }
    if (r.pos != r.n) {
        return UDP_CAN_E_TRAILING;
    }
    st = udp_can_check(&m);
    if (st != UDP_CAN_OK) {
        return st;
    }
    *msg = m;
    return UDP_CAN_OK;
}
