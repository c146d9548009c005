/*
 * fw_aes_cmac.c - AES-128 encryption (FIPS-197) and AES-CMAC (RFC 4493).
 * See fw_aes_cmac.h for the side-channel notes.
 */
#include "fw_aes_cmac.h"

#include <string.h>

/* FIPS-197 Figure 7. Indexed by secret bytes: constant time only where
 * memory access time does not depend on the address (fw_aes_cmac.h). */
static const uint8_t SBOX[256] = {
    0x63, 0x7c, 0x77, 0x7b, 0xf2, 0x6b, 0x6f, 0xc5, 0x30, 0x01, 0x67, 0x2b, 0xfe, 0xd7, 0xab, 0x76,
    0xca, 0x82, 0xc9, 0x7d, 0xfa, 0x59, 0x47, 0xf0, 0xad, 0xd4, 0xa2, 0xaf, 0x9c, 0xa4, 0x72, 0xc0,
    0xb7, 0xfd, 0x93, 0x26, 0x36, 0x3f, 0xf7, 0xcc, 0x34, 0xa5, 0xe5, 0xf1, 0x71, 0xd8, 0x31, 0x15,
    0x04, 0xc7, 0x23, 0xc3, 0x18, 0x96, 0x05, 0x9a, 0x07, 0x12, 0x80, 0xe2, 0xeb, 0x27, 0xb2, 0x75,
    0x09, 0x83, 0x2c, 0x1a, 0x1b, 0x6e, 0x5a, 0xa0, 0x52, 0x3b, 0xd6, 0xb3, 0x29, 0xe3, 0x2f, 0x84,
    0x53, 0xd1, 0x00, 0xed, 0x20, 0xfc, 0xb1, 0x5b, 0x6a, 0xcb, 0xbe, 0x39, 0x4a, 0x4c, 0x58, 0xcf,
    0xd0, 0xef, 0xaa, 0xfb, 0x43, 0x4d, 0x33, 0x85, 0x45, 0xf9, 0x02, 0x7f, 0x50, 0x3c, 0x9f, 0xa8,
    0x51, 0xa3, 0x40, 0x8f, 0x92, 0x9d, 0x38, 0xf5, 0xbc, 0xb6, 0xda, 0x21, 0x10, 0xff, 0xf3, 0xd2,
    0xcd, 0x0c, 0x13, 0xec, 0x5f, 0x97, 0x44, 0x17, 0xc4, 0xa7, 0x7e, 0x3d, 0x64, 0x5d, 0x19, 0x73,
    0x60, 0x81, 0x4f, 0xdc, 0x22, 0x2a, 0x90, 0x88, 0x46, 0xee, 0xb8, 0x14, 0xde, 0x5e, 0x0b, 0xdb,
    0xe0, 0x32, 0x3a, 0x0a, 0x49, 0x06, 0x24, 0x5c, 0xc2, 0xd3, 0xac, 0x62, 0x91, 0x95, 0xe4, 0x79,
    0xe7, 0xc8, 0x37, 0x6d, 0x8d, 0xd5, 0x4e, 0xa9, 0x6c, 0x56, 0xf4, 0xea, 0x65, 0x7a, 0xae, 0x08,
    0xba, 0x78, 0x25, 0x2e, 0x1c, 0xa6, 0xb4, 0xc6, 0xe8, 0xdd, 0x74, 0x1f, 0x4b, 0xbd, 0x8b, 0x8a,
    0x70, 0x3e, 0xb5, 0x66, 0x48, 0x03, 0xf6, 0x0e, 0x61, 0x35, 0x57, 0xb9, 0x86, 0xc1, 0x1d, 0x9e,
    0xe1, 0xf8, 0x98, 0x11, 0x69, 0xd9, 0x8e, 0x94, 0x9b, 0x1e, 0x87, 0xe9, 0xce, 0x55, 0x28, 0xdf,
    0x8c, 0xa1, 0x89, 0x0d, 0xbf, 0xe6, 0x42, 0x68, 0x41, 0x99, 0x2d, 0x0f, 0xb0, 0x54, 0xbb, 0x16,
};

/* Multiplication by x in GF(2^8) mod x^8 + x^4 + x^3 + x + 1 (FIPS-197
 * section 4.2.1, xtime), without a branch on the secret high bit. */
static uint8_t xtime(uint8_t b)
{
    return (uint8_t)((uint8_t)(b << 1) ^ (0x1Bu & (uint8_t)(0u - (unsigned)(b >> 7))));
}

fw_status fw_aes128_expand(fw_aes128_key *ks, const uint8_t key[FW_AES128_KEY])
{
    /* FIPS-197 section 5.2: w[i] = w[i-4] ^ SubWord(RotWord(w[i-1])) ^ Rcon
     * every fourth word, w[i-4] ^ w[i-1] otherwise. */
    uint8_t rcon = 0x01u;
    unsigned i;

    if (ks == NULL || key == NULL) {
        return FW_E_NULL;
    }
    memcpy(ks->rk, key, FW_AES128_KEY);
    for (i = 4u; i < 4u * (FW_AES128_ROUNDS + 1u); ++i) {
        uint8_t t[4];
        unsigned j;
        memcpy(t, &ks->rk[4u * (i - 1u)], 4u);
        if (i % 4u == 0u) { /* the schedule's shape is public: this branch is on i only */
            uint8_t first = t[0];
            t[0] = (uint8_t)(SBOX[t[1]] ^ rcon);
            t[1] = SBOX[t[2]];
            t[2] = SBOX[t[3]];
            t[3] = SBOX[first];
            rcon = xtime(rcon);
        }
        for (j = 0; j < 4u; ++j) {
            ks->rk[4u * i + j] = (uint8_t)(ks->rk[4u * (i - 4u) + j] ^ t[j]);
        }
    }
    return FW_OK;
}

static void add_round_key(uint8_t s[FW_AES_BLOCK], const uint8_t *rk)
{
    unsigned i;
    for (i = 0; i < FW_AES_BLOCK; ++i) {
        s[i] = (uint8_t)(s[i] ^ rk[i]);
    }
}

/* SubBytes and ShiftRows together (FIPS-197 sections 5.1.1-5.1.2). The
 * state is column-major: s[r + 4c]; row r moves left by r columns. */
static void sub_shift(uint8_t s[FW_AES_BLOCK])
{
    uint8_t t[FW_AES_BLOCK];
    unsigned r, c;
    for (c = 0; c < 4u; ++c) {
        for (r = 0; r < 4u; ++r) {
            t[r + 4u * c] = SBOX[s[r + 4u * ((c + r) % 4u)]];
        }
    }
    memcpy(s, t, FW_AES_BLOCK);
}

/* MixColumns (FIPS-197 section 5.1.3), each column times {03}x^3 + {01}x^2
 * + {01}x + {02}, written with xtime as in section 4.2.1. */
static void mix_columns(uint8_t s[FW_AES_BLOCK])
{
    unsigned c;
    for (c = 0; c < 4u; ++c) {
        uint8_t *col = &s[4u * c];
        uint8_t a0 = col[0], a1 = col[1], a2 = col[2], a3 = col[3];
        uint8_t all = (uint8_t)(a0 ^ a1 ^ a2 ^ a3);
        col[0] = (uint8_t)(a0 ^ all ^ xtime((uint8_t)(a0 ^ a1)));
        col[1] = (uint8_t)(a1 ^ all ^ xtime((uint8_t)(a1 ^ a2)));
        col[2] = (uint8_t)(a2 ^ all ^ xtime((uint8_t)(a2 ^ a3)));
        col[3] = (uint8_t)(a3 ^ all ^ xtime((uint8_t)(a3 ^ a0)));
    }
}

fw_status fw_aes128_encrypt(const fw_aes128_key *ks, const uint8_t in[FW_AES_BLOCK], uint8_t out[FW_AES_BLOCK])
{
    uint8_t s[FW_AES_BLOCK];
    unsigned round;

    if (ks == NULL || in == NULL || out == NULL) {
        return FW_E_NULL;
    }
    memcpy(s, in, FW_AES_BLOCK);
    add_round_key(s, ks->rk);
    for (round = 1u; round < FW_AES128_ROUNDS; ++round) {
        sub_shift(s);
        mix_columns(s);
        add_round_key(s, &ks->rk[FW_AES_BLOCK * round]);
    }
    sub_shift(s);
    add_round_key(s, &ks->rk[FW_AES_BLOCK * FW_AES128_ROUNDS]);
    memcpy(out, s, FW_AES_BLOCK);
    return FW_OK;
}

/* One left shift of a 128-bit big-endian string, and the conditional XOR
 * of R_128 = 0x87 when the shifted-out bit was 1 (RFC 4493 section 2.3),
 * by mask. */
static void double_block(const uint8_t in[FW_AES_BLOCK], uint8_t out[FW_AES_BLOCK])
{
    uint8_t carry = (uint8_t)(in[0] >> 7);
    unsigned i;
    for (i = 0; i + 1u < FW_AES_BLOCK; ++i) {
        out[i] = (uint8_t)((uint8_t)(in[i] << 1) | (in[i + 1u] >> 7));
    }
    out[FW_AES_BLOCK - 1u] = (uint8_t)((uint8_t)(in[FW_AES_BLOCK - 1u] << 1) ^ (0x87u & (uint8_t)(0u - carry)));
}

fw_status fw_cmac_init(fw_cmac_key *k, const uint8_t key[FW_AES128_KEY])
{
    uint8_t l[FW_AES_BLOCK];

    if (k == NULL || key == NULL) {
        return FW_E_NULL;
    }
    (void)fw_aes128_expand(&k->aes, key);
    memset(l, 0, sizeof l);
    (void)fw_aes128_encrypt(&k->aes, l, l); /* L = AES-128(K, 0^128) */
    double_block(l, k->k1);
    double_block(k->k1, k->k2);
    return FW_OK;
}

fw_status fw_cmac(const fw_cmac_key *k, const uint8_t *msg, size_t len, uint8_t tag[FW_AES_BLOCK])
{
    /* RFC 4493 section 2.4: CBC over the blocks; the last block is XORed
     * with K1 when complete, else padded with 10..0 and XORed with K2. The
     * empty message is one padded block. Only the public length steers. */
    uint8_t x[FW_AES_BLOCK];
    size_t n_full, pos = 0, rest, i;

    if (k == NULL || tag == NULL || (msg == NULL && len != 0u)) {
        return FW_E_NULL;
    }
    memset(x, 0, sizeof x);
    n_full = len == 0u ? 0u : (len - 1u) / FW_AES_BLOCK; /* blocks before the last one */
    for (i = 0; i < n_full; ++i, pos += FW_AES_BLOCK) {
        size_t j;
        for (j = 0; j < FW_AES_BLOCK; ++j) {
            x[j] = (uint8_t)(x[j] ^ msg[pos + j]);
        }
        (void)fw_aes128_encrypt(&k->aes, x, x);
    }
    rest = len - pos; /* 0..16: 16 only for a complete last block */
    for (i = 0; i < FW_AES_BLOCK; ++i) {
        uint8_t m;
        if (i < rest) {
            m = (uint8_t)(msg[pos + i] ^ (rest == FW_AES_BLOCK ? k->k1[i] : k->k2[i]));
        } else {
            m = (uint8_t)((i == rest ? 0x80u : 0x00u) ^ k->k2[i]);
        }
        x[i] = (uint8_t)(x[i] ^ m);
    }
    (void)fw_aes128_encrypt(&k->aes, x, tag);
    return FW_OK;
}

fw_status fw_aes128_cmac(const uint8_t key[FW_AES128_KEY], const uint8_t *msg, size_t len,
                         uint8_t tag[FW_AES_BLOCK])
{
    fw_cmac_key k;
    fw_status st;

    if (key == NULL) {
        return FW_E_NULL;
    }
    (void)fw_cmac_init(&k, key);
    st = fw_cmac(&k, msg, len, tag);
    return st;
}

int fw_mac_equal(const uint8_t *a, const uint8_t *b, size_t n)
{
    uint8_t diff = 0;
    size_t i;
    for (i = 0; i < n; ++i) {
        diff = (uint8_t)(diff | (a[i] ^ b[i]));
    }
    return diff == 0u;
}
