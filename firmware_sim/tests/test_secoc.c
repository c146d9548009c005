/*
 * test_secoc.c - host unit tests (CTest) of the command authentication:
 *
 *   - AES-128 against FIPS-197's examples (Appendix B and C.1);
 *   - AES-CMAC against RFC 4493's subkeys and its four examples (0, 16, 40
 *     and 64 bytes);
 *   - the secured PDU of fw_secoc.h: trailer layout, freshness rebuilt
 *     across the 32-bit wrap, replays, stale and too-far-ahead values,
 *     the MAC bound to the DataId and to every byte of the frame.
 */
#include <string.h>

#include "../../csrc/tests/check.h"
#include "fw_aes_cmac.h"
#include "fw_secoc.h"

static void hex(const char *s, uint8_t *out, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        unsigned v = 0, k;
        for (k = 0; k < 2u; ++k) {
            char c = s[2u * i + k];
            v = v * 16u + (unsigned)(c >= 'a' ? c - 'a' + 10 : c - '0');
        }
        out[i] = (uint8_t)v;
    }
}

static int same_hex(const uint8_t *got, const char *want, size_t n)
{
    uint8_t w[64];
    hex(want, w, n);
    return memcmp(got, w, n) == 0;
}

static void test_aes128_matches_fips197_examples(void)
{
    fw_aes128_key ks;
    uint8_t key[16], in[16], out[16];

    hex("000102030405060708090a0b0c0d0e0f", key, 16); /* Appendix C.1 */
    hex("00112233445566778899aabbccddeeff", in, 16);
    CHECK(fw_aes128_expand(&ks, key) == FW_OK);
    CHECK(fw_aes128_encrypt(&ks, in, out) == FW_OK);
    CHECK(same_hex(out, "69c4e0d86a7b0430d8cdb78070b4c55a", 16));
    CHECK(same_hex(&ks.rk[160], "13111d7fe3944a17f307a78b4d2b30c5", 16)); /* last round key */

    hex("2b7e151628aed2a6abf7158809cf4f3c", key, 16); /* Appendix B, in place */
    hex("3243f6a8885a308d313198a2e0370734", in, 16);
    CHECK(fw_aes128_expand(&ks, key) == FW_OK);
    CHECK(fw_aes128_encrypt(&ks, in, in) == FW_OK);
    CHECK(same_hex(in, "3925841d02dc09fbdc118597196a0b32", 16));
    CHECK(same_hex(&ks.rk[160], "d014f9a8c9ee2589e13f0cc8b6630ca6", 16));

    CHECK(fw_aes128_expand(NULL, key) == FW_E_NULL);
    CHECK(fw_aes128_encrypt(&ks, NULL, out) == FW_E_NULL);
}

static void test_cmac_matches_rfc4493_examples(void)
{
    static const char *msg_hex = "6bc1bee22e409f96e93d7e117393172aae2d8a571e03ac9c9eb76fac45af8e51"
                                 "30c81c46a35ce411e5fbc1191a0a52eff69f2445df4f9b17ad2b417be66c3710";
    static const struct {
        size_t len;
        const char *tag;
    } ex[4] = {
        {0, "bb1d6929e95937287fa37d129b756746"},
        {16, "070a16b46b4d4144f79bdd9dd04a287c"},
        {40, "dfa66747de9ae63030ca32611497c827"},
        {64, "51f0bebf7e3b9d92fc49741779363cfe"},
    };
    uint8_t key[16], msg[64], tag[16];
    fw_cmac_key k;
    size_t i;

    hex("2b7e151628aed2a6abf7158809cf4f3c", key, 16);
    hex(msg_hex, msg, 64);
    CHECK(fw_cmac_init(&k, key) == FW_OK);
    CHECK(same_hex(k.k1, "fbeed618357133667c85e08f7236a8de", 16)); /* RFC 4493 section 4, subkeys */
    CHECK(same_hex(k.k2, "f7ddac306ae266ccf90bc11ee46d513b", 16));
    for (i = 0; i < 4u; ++i) {
        memset(tag, 0, sizeof tag);
        CHECK(fw_cmac(&k, ex[i].len ? msg : NULL, ex[i].len, tag) == FW_OK);
        CHECK(same_hex(tag, ex[i].tag, 16));
        memset(tag, 0, sizeof tag);
        CHECK(fw_aes128_cmac(key, msg, ex[i].len, tag) == FW_OK);
        CHECK(same_hex(tag, ex[i].tag, 16));
    }
    CHECK(fw_cmac(&k, NULL, 1, tag) == FW_E_NULL);
    CHECK(fw_mac_equal(tag, tag, 16) == 1);
    {
        uint8_t other[16];
        memcpy(other, tag, 16);
        other[15] ^= 0x01u;
        CHECK(fw_mac_equal(tag, other, 16) == 0);
        CHECK(fw_mac_equal(tag, other, 15) == 1);
    }
}

static const uint8_t TEST_KEY[16] = {'p', 'y', 'r', 'h', 'o', 'n', 'n', '-', 'T', 'E', 'S', 'T', '-', 'k', 'e', 'y'};

static void test_secured_pdu_layout_and_mac_input(void)
{
    fw_cmac_key k;
    uint8_t pdu[16], in[14], tag[16];
    uint64_t fv = 0x0123456789ABCDEFull;

    CHECK(fw_cmac_init(&k, TEST_KEY) == FW_OK);
    memset(pdu, 0xEE, sizeof pdu);
    pdu[0] = 1;
    pdu[1] = 42;
    pdu[2] = pdu[3] = 0;
    CHECK(fw_secoc_protect(&k, 0x110, pdu, sizeof pdu, fv) == FW_OK);
    /* bytes 4-7: the low 32 bits, little-endian; bytes 8-15: CMAC's first
     * 8 bytes over 0x01 0x10 | bytes 0-3 | the 64 bits big-endian */
    CHECK(pdu[4] == 0xEF && pdu[5] == 0xCD && pdu[6] == 0xAB && pdu[7] == 0x89);
    in[0] = 0x01;
    in[1] = 0x10;
    memcpy(&in[2], pdu, 4);
    hex("0123456789abcdef", &in[6], 8);
    CHECK(fw_aes128_cmac(TEST_KEY, in, sizeof in, tag) == FW_OK);
    CHECK(memcmp(&pdu[8], tag, 8) == 0);
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 11, fv) == FW_E_LENGTH);
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 65, fv) == FW_E_LENGTH);
}

static void test_freshness_is_rebuilt_across_the_wrap_and_replays_are_refused(void)
{
    fw_cmac_key k;
    uint8_t pdu[16], copy[16];
    uint64_t latest = 0xFFFFFFF0ull, before;
    unsigned i;

    CHECK(fw_cmac_init(&k, TEST_KEY) == FW_OK);
    memset(pdu, 0, sizeof pdu);
    pdu[0] = 3;
    /* across the 32-bit wrap: 0x1_0000_0005 is rebuilt from 0x00000005 */
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 16, 0x100000005ull) == FW_OK);
    memcpy(copy, pdu, sizeof pdu);
    CHECK(fw_secoc_verify(&k, 0x110, pdu, 16, &latest) == FW_OK);
    CHECK(latest == 0x100000005ull);
    /* the same frame again: a replay */
    CHECK(fw_secoc_verify(&k, 0x110, copy, 16, &latest) == FW_E_FRESHNESS);
    CHECK(latest == 0x100000005ull);
    /* an older one: stale */
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 16, 0x100000004ull) == FW_OK);
    CHECK(fw_secoc_verify(&k, 0x110, pdu, 16, &latest) == FW_E_FRESHNESS);
    /* the window: exactly its size ahead is accepted, one more is not */
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 16, latest + FW_SECOC_ACCEPTANCE_WINDOW + 1u) == FW_OK);
    CHECK(fw_secoc_verify(&k, 0x110, pdu, 16, &latest) == FW_E_FRESHNESS);
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 16, latest + FW_SECOC_ACCEPTANCE_WINDOW) == FW_OK);
    before = latest;
    CHECK(fw_secoc_verify(&k, 0x110, pdu, 16, &latest) == FW_OK);
    CHECK(latest == before + FW_SECOC_ACCEPTANCE_WINDOW);
    /* every flipped bit of the frame, and another DataId, fail the MAC
     * (bits of the freshness field may fail the window first) */
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 16, latest + 1u) == FW_OK);
    before = latest;
    for (i = 0; i < 16u * 8u; ++i) {
        fw_status st;
        memcpy(copy, pdu, sizeof pdu);
        copy[i / 8u] ^= (uint8_t)(1u << (i % 8u));
        st = fw_secoc_verify(&k, 0x110, copy, 16, &latest);
        CHECK(st == FW_E_AUTH || (st == FW_E_FRESHNESS && i / 8u >= 4u && i / 8u < 8u));
        CHECK(latest == before);
    }
    CHECK(fw_secoc_verify(&k, 0x120, pdu, 16, &latest) == FW_E_AUTH);
    CHECK(fw_secoc_verify(&k, 0x110, pdu, 16, &latest) == FW_OK);
    /* a spent counter accepts nothing newer */
    latest = 0xFFFFFFFFFFFFFFF0ull;
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 16, 0xFFFFFFFFFFFFFFF1ull) == FW_OK);
    CHECK(fw_secoc_verify(&k, 0x110, pdu, 16, &latest) == FW_OK);
    CHECK(fw_secoc_protect(&k, 0x110, pdu, 16, 0x10ull) == FW_OK);
    CHECK(fw_secoc_verify(&k, 0x110, pdu, 16, &latest) == FW_E_FRESHNESS);
    CHECK(fw_secoc_verify(&k, 0x110, pdu, 11, &latest) == FW_E_LENGTH);
    CHECK(fw_secoc_verify(&k, 0x110, NULL, 16, &latest) == FW_E_NULL);
}

int main(void)
{
    RUN(test_aes128_matches_fips197_examples);
    RUN(test_cmac_matches_rfc4493_examples);
    RUN(test_secured_pdu_layout_and_mac_input);
    RUN(test_freshness_is_rebuilt_across_the_wrap_and_replays_are_refused);
    return CHECK_SUMMARY();
}
