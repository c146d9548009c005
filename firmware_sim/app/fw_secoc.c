/*
 * fw_secoc.c - SecOC-style secured PDUs: truncated freshness value and
 * truncated AES-128-CMAC. See fw_secoc.h.
 */
#include "fw_secoc.h"

#include <string.h>

/* DataId (2) + the longest Authentic PDU + the full freshness value (8). */
#define FW_SECOC_MAX_INPUT (2u + (FW_SECOC_MAX_PDU - FW_SECOC_TRAILER_BYTES) + 8u)

typedef char fw_secoc_window_fits[(FW_SECOC_ACCEPTANCE_WINDOW) >= 1u
                                  && (uint64_t)(FW_SECOC_ACCEPTANCE_WINDOW) < 0x100000000ull ? 1 : -1];

fw_status fw_secoc_mac(const fw_cmac_key *k, uint16_t data_id, const uint8_t *pdu, size_t auth_len,
                       uint64_t freshness, uint8_t mac[FW_SECOC_MAC_BYTES])
{
    uint8_t in[FW_SECOC_MAX_INPUT];
    uint8_t tag[FW_AES_BLOCK];
    size_t n = 0;
    unsigned i;

    if (k == NULL || mac == NULL || (pdu == NULL && auth_len != 0u)) {
        return FW_E_NULL;
    }
    if (auth_len > FW_SECOC_MAX_PDU - FW_SECOC_TRAILER_BYTES) {
        return FW_E_LENGTH;
    }
    in[n++] = (uint8_t)(data_id >> 8);
    in[n++] = (uint8_t)data_id;
    if (auth_len != 0u) {
        memcpy(&in[n], pdu, auth_len);
        n += auth_len;
    }
    for (i = 0; i < 8u; ++i) {
        in[n++] = (uint8_t)(freshness >> (56u - 8u * i));
    }
    (void)fw_cmac(k, in, n, tag);
    memcpy(mac, tag, FW_SECOC_MAC_BYTES); /* truncation keeps the leading bytes */
    return FW_OK;
}

fw_status fw_secoc_protect(const fw_cmac_key *k, uint16_t data_id, uint8_t *pdu, size_t len, uint64_t freshness)
{
    size_t auth_len;
    unsigned i;

    if (k == NULL || pdu == NULL) {
        return FW_E_NULL;
    }
    if (len < FW_SECOC_TRAILER_BYTES || len > FW_SECOC_MAX_PDU) {
        return FW_E_LENGTH;
    }
    auth_len = len - FW_SECOC_TRAILER_BYTES;
    for (i = 0; i < FW_SECOC_FV_BYTES; ++i) {
        pdu[auth_len + i] = (uint8_t)(freshness >> (8u * i));
    }
    return fw_secoc_mac(k, data_id, pdu, auth_len, freshness, &pdu[auth_len + FW_SECOC_FV_BYTES]);
}

fw_status fw_secoc_verify(const fw_cmac_key *k, uint16_t data_id, const uint8_t *pdu, size_t len,
                          uint64_t *latest)
{
    uint8_t mac[FW_SECOC_MAC_BYTES];
    uint64_t fv;
    uint32_t low = 0;
    size_t auth_len;
    unsigned i;

    if (k == NULL || pdu == NULL || latest == NULL) {
        return FW_E_NULL;
    }
    if (len < FW_SECOC_TRAILER_BYTES || len > FW_SECOC_MAX_PDU) {
        return FW_E_LENGTH;
    }
    auth_len = len - FW_SECOC_TRAILER_BYTES;
    for (i = 0; i < FW_SECOC_FV_BYTES; ++i) {
        low |= (uint32_t)pdu[auth_len + i] << (8u * i);
    }
    /* AUTOSAR's reconstruction: the received bits replace the low half; the
     * high half goes up by one when they are not above the last low half. */
    fv = (*latest & 0xFFFFFFFF00000000ull) | low;
    if (low <= (uint32_t)*latest) {
        if ((*latest >> 32) == 0xFFFFFFFFull) {
            return FW_E_FRESHNESS; /* the counter is spent: nothing is newer */
        }
        fv += 0x100000000ull;
    }
    /* fv > *latest here; a repeat of the last low half lands 2^32 ahead,
     * beyond the window. The freshness value is public: no secret timing. */
    if (fv - *latest > (uint64_t)(FW_SECOC_ACCEPTANCE_WINDOW)) {
        return FW_E_FRESHNESS;
    }
    (void)fw_secoc_mac(k, data_id, pdu, auth_len, fv, mac);
    if (!fw_mac_equal(mac, &pdu[auth_len + FW_SECOC_FV_BYTES], FW_SECOC_MAC_BYTES)) {
        return FW_E_AUTH;
    }
    *latest = fv;
    return FW_OK;
}
