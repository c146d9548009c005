/*
 * test_udp_can.c - host unit tests of the udp_multicast msgpack codec
 * (CTest; also under AddressSanitizer + UBSan in the sanitize build).
 *
 *   - the encoder writes exactly python-can's pack_message bytes;
 *   - encode -> decode is the identity, up to the longest frame;
 *   - other valid encodings (map16, str8 keys, float32, wide ints, keys in
 *     any order, str/int channels) decode to the same message;
 *   - every malformed datagram is rejected with its reason and leaves the
 *     output untouched: each truncation, trailing bytes, data of 65 bytes,
 *     dlc mismatches, bad keys, duplicates, wrong types, invalid messages;
 *   - random and bit-flipped datagrams never crash the decoder.
 */
#include <stdlib.h>
#include <string.h>

#include "../../csrc/tests/check.h"
#include "udp_can.h"

#define CHECK_UDP(expr, want)                                                                 \
    do {                                                                                      \
        udp_can_status got_ = (expr);                                                         \
        ++check_count;                                                                        \
        if (got_ != (want)) {                                                                 \
            ++check_failures;                                                                 \
            fprintf(stderr, "%s:%d: %s returned %s, expected %s\n", __FILE__, __LINE__, #expr, \
                    udp_can_status_name(got_), udp_can_status_name(want));                    \
        }                                                                                     \
    } while (0)

/* python-can 4.x: pack_message(Message(timestamp=1.5, arbitration_id=0x101,
 * is_extended_id=False, is_fd=True, bitrate_switch=True, data=bytes(range(16)))) */
static const char PYTHON_CAN_BYTES[] =
    "\x8b"
    "\xa9" "timestamp" "\xcb\x3f\xf8\x00\x00\x00\x00\x00\x00"
    "\xae" "arbitration_id" "\xcd\x01\x01"
    "\xae" "is_extended_id" "\xc2"
    "\xaf" "is_remote_frame" "\xc2"
    "\xae" "is_error_frame" "\xc2"
    "\xa7" "channel" "\xc0"
    "\xa3" "dlc" "\x10"
    "\xa4" "data" "\xc4\x10"
    "\x00\x01\x02\x03\x04\x05\x06\x07\x08\x09\x0a\x0b\x0c\x0d\x0e\x0f"
    "\xa5" "is_fd" "\xc3"
    "\xae" "bitrate_switch" "\xc3"
    "\xb5" "error_state_indicator" "\xc2";
#define PYTHON_CAN_LEN (sizeof PYTHON_CAN_BYTES - 1u)

static udp_can_msg sample(void)
{
    udp_can_msg m;
    uint8_t i;
    memset(&m, 0, sizeof m);
    m.timestamp = 1.5;
    m.arbitration_id = 0x101;
    m.is_fd = 1;
    m.bitrate_switch = 1;
    m.dlc = m.len = 16;
    for (i = 0; i < 16; ++i) {
        m.data[i] = i;
    }
    return m;
}

static int same_msg(const udp_can_msg *a, const udp_can_msg *b)
{
    return a->timestamp == b->timestamp && a->arbitration_id == b->arbitration_id &&
           a->is_extended_id == b->is_extended_id && a->is_remote_frame == b->is_remote_frame &&
           a->is_error_frame == b->is_error_frame && a->is_fd == b->is_fd && a->bitrate_switch == b->bitrate_switch &&
           a->error_state_indicator == b->error_state_indicator && a->dlc == b->dlc && a->len == b->len &&
           memcmp(a->data, b->data, a->len) == 0;
}

static const uint8_t *U(const char *s)
{
    return (const uint8_t *)s;
}

static void test_encoder_writes_python_cans_bytes(void)
{
    udp_can_msg m = sample();
    uint8_t out[UDP_CAN_MAX_ENCODED];
    size_t n = 0;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, &n), UDP_CAN_OK);
    CHECK(n == PYTHON_CAN_LEN && memcmp(out, PYTHON_CAN_BYTES, n) == 0);
    /* too small a buffer: refused, nothing written */
    memset(out, 0xee, sizeof out);
    CHECK_UDP(udp_can_encode(&m, out, n - 1u, &n), UDP_CAN_E_SPACE);
    CHECK(out[0] == 0xee);
    CHECK_UDP(udp_can_encode(NULL, out, sizeof out, NULL), UDP_CAN_E_NULL);
    CHECK_UDP(udp_can_encode(&m, NULL, sizeof out, NULL), UDP_CAN_E_NULL);
}

static void test_decoder_reads_python_cans_bytes(void)
{
    udp_can_msg want = sample(), got;
    memset(&got, 0, sizeof got);
    CHECK_UDP(udp_can_decode(U(PYTHON_CAN_BYTES), PYTHON_CAN_LEN, &got), UDP_CAN_OK);
    CHECK(same_msg(&got, &want));
    CHECK_UDP(udp_can_decode(U(PYTHON_CAN_BYTES), PYTHON_CAN_LEN, NULL), UDP_CAN_E_NULL);
    CHECK_UDP(udp_can_decode(NULL, 3, &got), UDP_CAN_E_NULL);
    CHECK_UDP(udp_can_decode(NULL, 0, &got), UDP_CAN_E_TRUNCATED);
}

static void test_round_trip_up_to_the_longest_frame(void)
{
    static const uint32_t ids[] = {0, 0x7f, 0x80, 0xff, 0x100, 0x7ff, 0xffff, 0x10000, 0x1fffffff};
    uint8_t out[UDP_CAN_MAX_ENCODED];
    size_t n, k, longest = 0;
    uint8_t len;
    for (k = 0; k < sizeof ids / sizeof ids[0]; ++k) {
        for (len = 0; len <= 64; ++len) {
            udp_can_msg m, back;
            uint8_t i;
            memset(&m, 0, sizeof m);
            m.timestamp = 1234567.125 + (double)len;
            m.arbitration_id = ids[k];
            m.is_extended_id = ids[k] > 0x7ffu;
            m.is_fd = len > 8u || (k & 1u);
            m.bitrate_switch = m.is_fd && (len & 1u);
            m.error_state_indicator = m.is_fd && (len & 2u);
            m.dlc = m.len = len;
            for (i = 0; i < len; ++i) {
                m.data[i] = (uint8_t)(i * 37u + k);
            }
            CHECK_UDP(udp_can_encode(&m, out, sizeof out, &n), UDP_CAN_OK);
            CHECK_UDP(udp_can_decode(out, n, &back), UDP_CAN_OK);
            CHECK(same_msg(&m, &back));
            longest = n > longest ? n : longest;
        }
    }
    CHECK(longest == UDP_CAN_MAX_ENCODED);
    {   /* remote and error frames */
        udp_can_msg m, back;
        memset(&m, 0, sizeof m);
        m.is_remote_frame = 1;
        m.dlc = 8;
        m.arbitration_id = 0x123;
        CHECK_UDP(udp_can_encode(&m, out, sizeof out, &n), UDP_CAN_OK);
        CHECK_UDP(udp_can_decode(out, n, &back), UDP_CAN_OK);
        CHECK(same_msg(&m, &back));
        memset(&m, 0, sizeof m);
        m.is_error_frame = 1;
        m.dlc = m.len = 8;
        CHECK_UDP(udp_can_encode(&m, out, sizeof out, &n), UDP_CAN_OK);
        CHECK_UDP(udp_can_decode(out, n, &back), UDP_CAN_OK);
        CHECK(same_msg(&m, &back));
    }
}

/* Offset of the value of `key` (a fixstr key) in the python-can sample. */
static size_t key_end(const char *key)
{
    size_t k = strlen(key), at;
    for (at = 1; at + k < PYTHON_CAN_LEN; ++at) {
        if ((uint8_t)PYTHON_CAN_BYTES[at - 1u] == (0xa0u | k) && memcmp(PYTHON_CAN_BYTES + at, key, k) == 0) {
            return at + k;
        }
    }
    return 0; /* not reached for the keys used here */
}

/* The sample written another valid way: map16, str8 keys, keys reordered,
 * float32 timestamp, uint64 id, int8 dlc, bin16 data, a str channel. */
static void test_other_valid_encodings_decode_to_the_same_message(void)
{
    static const char other[] =
        "\xde\x00\x0b"
        "\xd9\x04" "data" "\xc5\x00\x10"
        "\x00\x01\x02\x03\x04\x05\x06\x07\x08\x09\x0a\x0b\x0c\x0d\x0e\x0f"
        "\xa5" "is_fd" "\xc3"
        "\xa9" "timestamp" "\xca\x3f\xc0\x00\x00"
        "\xae" "arbitration_id" "\xcf\x00\x00\x00\x00\x00\x00\x01\x01"
        "\xae" "is_extended_id" "\xc2"
        "\xa7" "channel" "\xa6" "vcan\xc3\xa9"
        "\xaf" "is_remote_frame" "\xc2"
        "\xae" "is_error_frame" "\xc2"
        "\xa3" "dlc" "\xd0\x10"
        "\xae" "bitrate_switch" "\xc3"
        "\xda\x00\x15" "error_state_indicator" "\xc2";
    static const char channels[][4] = {"\xc0", "\x05", "\xff", "\xd0\x80", "\xa0"};
    udp_can_msg want = sample(), got;
    uint8_t buf[256];
    size_t c, at = key_end("channel");
    CHECK_UDP(udp_can_decode(U(other), sizeof other - 1u, &got), UDP_CAN_OK);
    CHECK(same_msg(&got, &want));
    /* the channel as nil, positive and negative integers, an empty str */
    for (c = 0; c < sizeof channels / sizeof channels[0]; ++c) {
        size_t cl = strlen(channels[c]);
        memcpy(buf, PYTHON_CAN_BYTES, at);
        memcpy(buf + at, channels[c], cl);
        memcpy(buf + at + cl, PYTHON_CAN_BYTES + at + 1, PYTHON_CAN_LEN - at - 1u);
        memset(&got, 0, sizeof got);
        CHECK_UDP(udp_can_decode(buf, PYTHON_CAN_LEN + cl - 1u, &got), UDP_CAN_OK);
        CHECK(same_msg(&got, &want));
    }
}

/* Replace the value of `key` in the python-can sample by `value` (len bytes). */
static size_t with_value(uint8_t *buf, const char *key, const char *value, size_t len)
{
    size_t at = key_end(key), old, n;
    switch ((uint8_t)PYTHON_CAN_BYTES[at]) {
    case 0xcb: old = 9; break;
    case 0xcd: old = 3; break;
    case 0xc4: old = 2u + 16u; break;
    default: old = 1; break;
    }
    memcpy(buf, PYTHON_CAN_BYTES, at);
    memcpy(buf + at, value, len);
    n = PYTHON_CAN_LEN - at - old;
    memcpy(buf + at + len, PYTHON_CAN_BYTES + at + old, n);
    return at + len + n;
}

static void test_malformed_datagrams_are_rejected_with_their_reason(void)
{
    uint8_t buf[512], data65[2 + 65];
    udp_can_msg got, untouched;
    size_t n, cut;

    memset(&got, 0x5a, sizeof got);
    untouched = got;
    /* every truncation */
    for (cut = 0; cut < PYTHON_CAN_LEN; ++cut) {
        CHECK_UDP(udp_can_decode(U(PYTHON_CAN_BYTES), cut, &got), UDP_CAN_E_TRUNCATED);
    }
    /* trailing garbage */
    memcpy(buf, PYTHON_CAN_BYTES, PYTHON_CAN_LEN);
    buf[PYTHON_CAN_LEN] = 0xc0;
    CHECK_UDP(udp_can_decode(buf, PYTHON_CAN_LEN + 1u, &got), UDP_CAN_E_TRAILING);
    /* not a map */
    CHECK_UDP(udp_can_decode(U("\x91\xc0"), 2, &got), UDP_CAN_E_NOT_MAP);
    CHECK_UDP(udp_can_decode(U("\xc4\x00"), 2, &got), UDP_CAN_E_NOT_MAP);
    CHECK_UDP(udp_can_decode(U("\xde\x00"), 2, &got), UDP_CAN_E_TRUNCATED);
    /* a map missing a key, and one with a key too many (a duplicate) */
    buf[0] = 0x8a;
    CHECK_UDP(udp_can_decode(buf, PYTHON_CAN_LEN - 23u, &got), UDP_CAN_E_MISSING);
    buf[0] = 0x8c;
    memcpy(buf + PYTHON_CAN_LEN, "\xa3" "dlc" "\x10", 5);
    CHECK_UDP(udp_can_decode(buf, PYTHON_CAN_LEN + 5u, &got), UDP_CAN_E_DUPLICATE);
    /* an unknown key, and keys that are not str */
    memcpy(buf + PYTHON_CAN_LEN, "\xa5" "is_rx" "\xc3", 7);
    CHECK_UDP(udp_can_decode(buf, PYTHON_CAN_LEN + 7u, &got), UDP_CAN_E_KEY);
    memcpy(buf + PYTHON_CAN_LEN, "\x01\xc3", 2);
    CHECK_UDP(udp_can_decode(buf, PYTHON_CAN_LEN + 2u, &got), UDP_CAN_E_KEY);
    memcpy(buf + PYTHON_CAN_LEN, "\xc4\x03" "dlc" "\x10", 6);
    CHECK_UDP(udp_can_decode(buf, PYTHON_CAN_LEN + 6u, &got), UDP_CAN_E_KEY);
    /* data of 65 bytes, and a dlc that says 65 */
    data65[0] = 0xc4;
    data65[1] = 65;
    memset(data65 + 2, 7, 65);
    n = with_value(buf, "data", (const char *)data65, sizeof data65);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_DATA_LENGTH);
    n = with_value(buf, "data", "\xc6\xff\xff\xff\xff", 5); /* and one that claims 4 GB */
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_DATA_LENGTH);
    n = with_value(buf, "dlc", "\x41", 1);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_DLC);
    /* dlc and data disagree, or dlc negative */
    n = with_value(buf, "dlc", "\x0f", 1);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_DLC);
    n = with_value(buf, "dlc", "\xff", 1);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_DLC);
    /* classic CAN with 16 bytes */
    n = with_value(buf, "is_fd", "\xc2", 1);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_DLC);
    /* identifiers: 11 bits, negative, beyond 32 bits */
    n = with_value(buf, "arbitration_id", "\xcd\x08\x00", 3);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_ID);
    n = with_value(buf, "arbitration_id", "\xff", 1);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_ID);
    n = with_value(buf, "arbitration_id", "\xcf\x00\x00\x00\x01\x00\x00\x01\x01", 9);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_ID);
    /* wrong types */
    n = with_value(buf, "arbitration_id", "\xcb\x40\x70\x10\x00\x00\x00\x00\x00", 9);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TYPE);
    n = with_value(buf, "is_fd", "\x01", 1);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TYPE);
    n = with_value(buf, "timestamp", "\xc0", 1);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TYPE);
    n = with_value(buf, "channel", "\xcb\x00\x00\x00\x00\x00\x00\x00\x00", 9);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TYPE);
    n = with_value(buf, "channel", "\xa2\xc3\x28", 3); /* not UTF-8 */
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TYPE);
    n = with_value(buf, "channel", "\xa3\xed\xa0\x80", 4); /* a surrogate */
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TYPE);
    n = with_value(buf, "channel", "\xdb\xff\xff\xff\xff", 5);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TRUNCATED);
    n = with_value(buf, "data", "\xa2\x00\x01", 3); /* data as str */
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TYPE);
    /* timestamps python-can refuses */
    n = with_value(buf, "timestamp", "\xcb\xbf\xf0\x00\x00\x00\x00\x00\x00", 9);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TIMESTAMP);
    n = with_value(buf, "timestamp", "\xcb\x7f\xf8\x00\x00\x00\x00\x00\x00", 9);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TIMESTAMP);
    n = with_value(buf, "timestamp", "\xca\x7f\x80\x00\x00", 5);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TIMESTAMP);
    n = with_value(buf, "timestamp", "\xd0\xff", 2);
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_TIMESTAMP);
    /* flag combinations python-can refuses */
    n = with_value(buf, "is_remote_frame", "\xc3", 1); /* remote FD frame (with data) */
    CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_FLAGS);
    {   /* a classic 8-byte frame with BRS */
        udp_can_msg m = sample();
        size_t at;
        m.is_fd = m.bitrate_switch = 0;
        m.dlc = m.len = 8;
        CHECK_UDP(udp_can_encode(&m, buf, sizeof buf, &n), UDP_CAN_OK);
        for (at = 1; at + 14u < n && memcmp(buf + at, "bitrate_switch", 14) != 0; ++at) {
        }
        buf[at + 14u] = 0xc3;
        CHECK_UDP(udp_can_decode(buf, n, &got), UDP_CAN_E_FLAGS);
    }
    CHECK(memcmp(&got, &untouched, sizeof got) == 0);
}

static void test_invalid_messages_are_not_encoded(void)
{
    uint8_t out[UDP_CAN_MAX_ENCODED];
    volatile double zero = 0.0;
    udp_can_msg m;
    m = sample(); m.len = 65; m.dlc = 65;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_DLC);
    m = sample(); m.dlc = 15;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_DLC);
    m = sample(); m.is_fd = 0;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_DLC);
    m = sample(); m.arbitration_id = 0x800;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_ID);
    m = sample(); m.is_extended_id = 1; m.arbitration_id = 0x20000000u;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_ID);
    m = sample(); m.is_remote_frame = 1;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_FLAGS);
    m = sample(); m.is_fd = 0; m.dlc = m.len = 8;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_FLAGS); /* BRS without FD */
    m = sample(); m.is_error_frame = 2;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_FLAGS);
    m = sample(); m.timestamp = -1.0;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_TIMESTAMP);
    m = sample(); m.timestamp = zero / zero;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_TIMESTAMP);
    m = sample(); m.timestamp = 1.0 / zero;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_E_TIMESTAMP);
    m = sample(); m.timestamp = -0.0;
    CHECK_UDP(udp_can_encode(&m, out, sizeof out, NULL), UDP_CAN_OK);
    CHECK_UDP(udp_can_check(NULL), UDP_CAN_E_NULL);
    CHECK(strcmp(udp_can_status_name(UDP_CAN_E_TRAILING), "trailing") == 0);
    CHECK(strcmp(udp_can_status_name((udp_can_status)99), "?") == 0);
}

/* xorshift32: a deterministic stream for the smoke tests */
static uint32_t rng_state = 0x2545f491u;
static uint32_t rnd(void)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 17;
    rng_state ^= rng_state << 5;
    return rng_state;
}

static void test_random_and_bit_flipped_datagrams_never_crash(void)
{
    uint8_t buf[300];
    udp_can_msg got, out_msg;
    uint8_t out[UDP_CAN_MAX_ENCODED];
    size_t n, i, ok = 0, trials;
    memset(buf, 0, sizeof buf);
    for (trials = 0; trials < 200000u; ++trials) {
        udp_can_status st;
        if (trials & 1u) { /* a valid datagram with 1-3 bytes changed, maybe cut or extended */
            memcpy(buf, PYTHON_CAN_BYTES, PYTHON_CAN_LEN);
            n = PYTHON_CAN_LEN;
            for (i = 0; i < 1u + rnd() % 3u; ++i) {
                buf[rnd() % n] = (uint8_t)rnd();
            }
            if (rnd() % 4u == 0u) {
                n = rnd() % (sizeof buf);
            }
        } else {
            n = rnd() % (sizeof buf);
            for (i = 0; i < n; ++i) {
                buf[i] = (uint8_t)rnd();
            }
        }
        st = udp_can_decode(buf, n, &got);
        CHECK(st < UDP_CAN_N_STATUS && st != UDP_CAN_E_NULL && st != UDP_CAN_E_SPACE);
        if (st == UDP_CAN_OK) { /* whatever is accepted is a valid message and encodes again */
            ++ok;
            CHECK_UDP(udp_can_check(&got), UDP_CAN_OK);
            CHECK_UDP(udp_can_encode(&got, out, sizeof out, &n), UDP_CAN_OK);
            CHECK_UDP(udp_can_decode(out, n, &out_msg), UDP_CAN_OK);
            CHECK(same_msg(&got, &out_msg));
        }
    }
    CHECK(ok > 100u); /* the flips that hit data bytes */
}

int main(void)
{
    RUN(test_encoder_writes_python_cans_bytes);
    RUN(test_decoder_reads_python_cans_bytes);
    RUN(test_round_trip_up_to_the_longest_frame);
    RUN(test_other_valid_encodings_decode_to_the_same_message);
    RUN(test_malformed_datagrams_are_rejected_with_their_reason);
    RUN(test_invalid_messages_are_not_encoded);
    RUN(test_random_and_bit_flipped_datagrams_never_crash);
    return CHECK_SUMMARY();
}
