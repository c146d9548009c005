/*
 * fw_aes_cmac.h - AES-128 (FIPS-197, encryption only) and AES-CMAC
 * (RFC 4493 / NIST SP 800-38B), the MAC of the SecOC-style authentication
 * of command frames (fw_secoc.h).
 *
 * Caller-owned key schedules, no allocation, no stdio, no libm; C99.
 *
 * SIDE CHANNELS. No branch and no loop bound depends on the key or the
 * message content: GF(2^8) doubling and the CMAC subkey shift use masks,
 * and fw_mac_equal compares in constant time. The S-box is a 256-byte table
 * indexed by secret bytes, so its timing is constant only where memory
 * access time does not depend on the address: true on a Cortex-M4 without
 * a data cache (flash wait states are address-independent), not on a host
 * CPU with caches, where cache-timing attacks on table AES are known. The
 * host builds are simulations; a production target with a cache should use
 * its crypto peripheral (or a bitsliced AES) behind the same functions.
 */
#ifndef FW_AES_CMAC_H
#define FW_AES_CMAC_H

#include <stddef.h>
#include <stdint.h>

#include "fw_hal.h"

#ifdef __cplusplus
extern "C" {
#endif

#define FW_AES_BLOCK 16u        /* bytes in an AES block, and in a full CMAC tag */
#define FW_AES128_KEY 16u       /* bytes in an AES-128 key */
#define FW_AES128_ROUNDS 10u

/* The expanded AES-128 key: 11 round keys (FIPS-197 section 5.2). */
typedef struct {
    uint8_t rk[(FW_AES128_ROUNDS + 1u) * FW_AES_BLOCK];
} fw_aes128_key;

/* A CMAC key: the cipher's schedule and the subkeys K1, K2 (RFC 4493
 * section 2.3), derived once so that each tag costs only the blocks of the
 * message. */
typedef struct {
    fw_aes128_key aes;
    uint8_t k1[FW_AES_BLOCK];
    uint8_t k2[FW_AES_BLOCK];
} fw_cmac_key;

/* Expand a 16-byte key. FW_E_NULL. */
fw_status fw_aes128_expand(fw_aes128_key *ks, const uint8_t key[FW_AES128_KEY]);

/* Encrypt one block (in and out may be the same buffer). FW_E_NULL. */
fw_status fw_aes128_encrypt(const fw_aes128_key *ks, const uint8_t in[FW_AES_BLOCK], uint8_t out[FW_AES_BLOCK]);

/* Derive the CMAC key (schedule, K1, K2) from a 16-byte AES key. FW_E_NULL. */
fw_status fw_cmac_init(fw_cmac_key *k, const uint8_t key[FW_AES128_KEY]);

/* The full 16-byte AES-CMAC tag of msg (len bytes; msg may be NULL when len
 * is 0). FW_E_NULL. */
fw_status fw_cmac(const fw_cmac_key *k, const uint8_t *msg, size_t len, uint8_t tag[FW_AES_BLOCK]);

/* One-shot AES-CMAC with a raw key (tests, the Python cross-check). */
fw_status fw_aes128_cmac(const uint8_t key[FW_AES128_KEY], const uint8_t *msg, size_t len,
                         uint8_t tag[FW_AES_BLOCK]);

/* 1 when the n bytes of a and b are equal, else 0, in time independent of
 * where they differ. */
int fw_mac_equal(const uint8_t *a, const uint8_t *b, size_t n);

#ifdef __cplusplus
}
#endif

#endif /* FW_AES_CMAC_H */
