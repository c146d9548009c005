/*
 * fw_secoc.h - SecOC-style authentication of the command frames (Control,
 * WeightLoad), after AUTOSAR's Secure Onboard Communication on CAN.
 *
 * SECURED PDU. A secured frame is the Authentic PDU followed by a trailer:
 *
 *   | Authentic PDU (len - 12 bytes) | FV: 4 bytes | MAC: 8 bytes |
 *
 *   FV   the 32 least significant bits of the 64-bit freshness value,
 *        little-endian (the DBC's Intel u32 signal `Freshness`);
 *   MAC  the first 8 bytes of the AES-128-CMAC (RFC 4493), in the order
 *        CMAC produces them (the DBC's Intel u64 signal `Mac` reads them
 *        as a little-endian integer).
 *
 * The MAC covers (AUTOSAR's "DataToAuthenticator"):
 *
 *   DataId (2 bytes, big-endian) | Authentic PDU | full FV (8 bytes, big-endian)
 *
 * where DataId is the frame's 11-bit CAN identifier (0x110 Control, 0x120
 * WeightLoad), so a payload signed for one message is not valid for the other.
 *
 * FRESHNESS. Sender and receiver each keep the full 64-bit value. The sender
 * adds one per secured frame. The receiver rebuilds the full value from the
 * 32 bits it gets as AUTOSAR does: the received bits replace the low half of
 * the last accepted value, and the high half goes up by one when they are not
 * greater than the last low half. The rebuilt value must be newer than the
 * last accepted one by at most FW_SECOC_ACCEPTANCE_WINDOW; otherwise the frame
 * is a replay or stale (FW_E_FRESHNESS) and no MAC is computed. The last
 * accepted value moves only when the MAC verifies.
 */
#ifndef FW_SECOC_H
#define FW_SECOC_H

#include <stddef.h>
#include <stdint.h>

#include "fw_aes_cmac.h"
#include "fw_hal.h"

#ifdef __cplusplus
extern "C" {
#endif

#define FW_SECOC_FV_BYTES 4u                                   /* truncated freshness in the frame */
#define FW_SECOC_MAC_BYTES 8u                                  /* truncated authenticator in the frame */
#define FW_SECOC_TRAILER_BYTES (FW_SECOC_FV_BYTES + FW_SECOC_MAC_BYTES)
#define FW_SECOC_MAX_PDU 64u                                   /* a CAN FD payload */

/* How far ahead of the last accepted freshness value a frame may be: the
 * number of secured frames the receiver may miss in a row and still follow.
 * Anything further is refused as FW_E_FRESHNESS. Must be below 2^32, so a
 * frame repeating the last accepted low half is never taken as newer. */
#ifndef FW_SECOC_ACCEPTANCE_WINDOW
#define FW_SECOC_ACCEPTANCE_WINDOW 65536u
#endif

/* The truncated MAC over DataId | pdu[0..auth_len) | freshness. FW_E_NULL,
 * FW_E_LENGTH when auth_len exceeds FW_SECOC_MAX_PDU - FW_SECOC_TRAILER_BYTES. */
fw_status fw_secoc_mac(const fw_cmac_key *k, uint16_t data_id, const uint8_t *pdu, size_t auth_len,
                       uint64_t freshness, uint8_t mac[FW_SECOC_MAC_BYTES]);

/* The sender's side: write the trailer (low 32 bits of freshness, MAC) into
 * the last FW_SECOC_TRAILER_BYTES of pdu (len bytes in all). FW_E_NULL,
 * FW_E_LENGTH when len is below the trailer or above FW_SECOC_MAX_PDU. */
fw_status fw_secoc_protect(const fw_cmac_key *k, uint16_t data_id, uint8_t *pdu, size_t len, uint64_t freshness);

/* The receiver's side: rebuild the full freshness value against *latest
 * (the last accepted one), check it is within the acceptance window, verify
 * the MAC. FW_OK (and *latest becomes the frame's freshness),
 * FW_E_FRESHNESS (not newer than *latest, or beyond the window),
 * FW_E_AUTH (the MAC does not verify), FW_E_LENGTH, FW_E_NULL. *latest is
 * changed only on FW_OK. */
fw_status fw_secoc_verify(const fw_cmac_key *k, uint16_t data_id, const uint8_t *pdu, size_t len,
                          uint64_t *latest);

#ifdef __cplusplus
}
#endif

#endif /* FW_SECOC_H */
