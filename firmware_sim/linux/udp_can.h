/*
 * udp_can.h - python-can's udp_multicast wire format: one CAN (FD) message
 * per UDP datagram, as a msgpack map (can/interfaces/udp_multicast/utils.py,
 * pack_message / unpack_message):
 *
 *   {"timestamp": float, "arbitration_id": int, "is_extended_id": bool,
 *    "is_remote_frame": bool, "is_error_frame": bool, "channel": nil|str|int,
 *    "dlc": int, "data": bin, "is_fd": bool, "bitrate_switch": bool,
 *    "error_state_indicator": bool}
 *
 * ENCODER. udp_can_encode writes the map in pack_message's key order and
 * with msgpack's shortest forms (fixmap, fixstr keys, float64 timestamp,
 * positive fixint/uint8/16/32 identifier, bin8 data, channel nil), so for a
 * message without a channel its output is byte for byte what python-can
 * sends, and unpack_message(..., check=True) accepts it.
 *
 * DECODER. udp_can_decode accepts every encoding of that map a msgpack
 * writer may produce: fixmap/map16/map32; keys as fixstr/str8/str16/str32,
 * in any order; the timestamp as float64/float32 or any integer; integers as
 * positive/negative fixint, uint8..64 or int8..64 (then range-checked);
 * bools as true/false; channel nil, any integer or a UTF-8 str (skipped);
 * data as bin8/bin16/bin32 of at most 64 bytes. It is strict otherwise:
 * every one of the 11 keys exactly once and no other, each value of its
 * type, no byte after the map, and the message itself valid the way
 * python-can's Message(check=True) checks it (UDP_CAN_E_*: see below). A
 * rejected datagram leaves *msg untouched. Any byte string is safe to pass:
 * every read is bounds-checked, nothing is allocated, nothing recurses.
 *
 * Plain C99: no OS calls, no allocation, no stdio, no libm.
 */
#ifndef UDP_CAN_H
#define UDP_CAN_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define UDP_CAN_MAX_DATA 64u       /* CAN FD payload */
#define UDP_CAN_MAX_ENCODED 220u   /* longest udp_can_encode output (64 data bytes, 32-bit id) */

typedef enum {
    UDP_CAN_OK = 0,
    UDP_CAN_E_NULL = 1,         /* a required pointer argument is NULL */
    UDP_CAN_E_TRUNCATED = 2,    /* the datagram ends inside an item (or is empty) */
    UDP_CAN_E_NOT_MAP = 3,      /* the datagram is not a msgpack map */
    UDP_CAN_E_KEY = 4,          /* a key that is not a str, or not one of the 11 field names */
    UDP_CAN_E_DUPLICATE = 5,    /* a key given twice */
    UDP_CAN_E_MISSING = 6,      /* one of the 11 keys is absent */
    UDP_CAN_E_TYPE = 7,         /* a value of the wrong type for its key, or a str that is not UTF-8 */
    UDP_CAN_E_DATA_LENGTH = 8,  /* data longer than 64 bytes */
    UDP_CAN_E_DLC = 9,          /* dlc differs from the data length, or above 64 (8 for classic CAN) */
    UDP_CAN_E_ID = 10,          /* arbitration_id negative, or beyond 11 / 29 bits */
    UDP_CAN_E_FLAGS = 11,       /* remote and error, remote FD or with data, BRS/ESI without FD */
    UDP_CAN_E_TIMESTAMP = 12,   /* timestamp negative, infinite or NaN */
    UDP_CAN_E_TRAILING = 13,    /* bytes after the map */
    UDP_CAN_E_SPACE = 14        /* encoder: the output buffer is too small */
} udp_can_status;

#define UDP_CAN_N_STATUS 15

/* One message, the fields of python-can's can.Message that travel. */
typedef struct {
    double timestamp;               /* seconds */
    uint32_t arbitration_id;        /* without flags: < 0x800, or < 0x20000000 when extended */
    uint8_t is_extended_id;         /* 0 / 1 */
    uint8_t is_remote_frame;
    uint8_t is_error_frame;
    uint8_t is_fd;
    uint8_t bitrate_switch;
    uint8_t error_state_indicator;
    uint8_t dlc;                    /* python-can's dlc: the length in bytes, 0..64 (0..8 classic) */
    uint8_t len;                    /* bytes in data: dlc, except 0 for a remote frame */
    uint8_t data[UDP_CAN_MAX_DATA];
} udp_can_msg;

/* Encode msg into out[0..cap); *written (may be NULL) gets the length.
 * UDP_CAN_OK, UDP_CAN_E_NULL, UDP_CAN_E_SPACE, or the reason msg is not a
 * valid message (udp_can_check). Nothing is written on error. A buffer of
 * UDP_CAN_MAX_ENCODED bytes always suffices. */
udp_can_status udp_can_encode(const udp_can_msg *msg, uint8_t *out, size_t cap, size_t *written);

/* Decode the datagram buf[0..n) into *msg (untouched on error). buf may be
 * NULL only when n is 0 (then UDP_CAN_E_TRUNCATED). */
udp_can_status udp_can_decode(const uint8_t *buf, size_t n, udp_can_msg *msg);

/* python-can's Message._check on msg, plus len/dlc consistency:
 * UDP_CAN_OK or the first reason it fails. */
udp_can_status udp_can_check(const udp_can_msg *msg);

/* Short name of a status ("truncated", "trailing", ...); "?" when unknown. */
const char *udp_can_status_name(udp_can_status status);

#ifdef __cplusplus
}
#endif

#endif /* UDP_CAN_H */
