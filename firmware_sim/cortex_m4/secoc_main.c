/* The command authentication on the Cortex-M4F under QEMU: checks AES-CMAC
 * against RFC 4493's four examples on the target, then counts the
 * instructions of fw_secoc_verify on a secured Control (16 bytes, one AES
 * block) and a secured WeightLoad (64 bytes, four blocks) with SysTick under
 * `qemu -icount shift=0`, as vector_main.c counts rhonn_step. Prints
 * `cmac_rfc4493 ok`, `instructions_per_control_verify N` and
 * `instructions_per_weight_load_verify N` (run_m4.py reads them). */
#include <stdio.h>
#include <string.h>

#include "fw_aes_cmac.h"
#include "fw_secoc.h"

#define N_FRAMES 64u

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)

static void systick_start(void)
{
    SYST_RVR = 0x00FFFFFFu;
    SYST_CVR = 0u;
    SYST_CSR = 5u; /* enable, processor clock, no interrupt */
}

static uint32_t systick_now(void)
{
    return SYST_CVR;
}

/* SysTick ticks per instruction under -icount (two instructions per loop). */
static double ticks_per_instruction(void)
{
    const uint32_t n = 200000u;
    uint32_t t0, t1, count = n;
    systick_start();
    t0 = systick_now();
    __asm__ volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(count) : : "cc");
    t1 = systick_now();
    return (double)((t0 - t1) & 0x00FFFFFFu) / (2.0 * (double)n);
}

static const uint8_t RFC_KEY[16] = {0x2b, 0x7e, 0x15, 0x16, 0x28, 0xae, 0xd2, 0xa6,
                                    0xab, 0xf7, 0x15, 0x88, 0x09, 0xcf, 0x4f, 0x3c};
static const uint8_t RFC_MSG[64] = {
    0x6b, 0xc1, 0xbe, 0xe2, 0x2e, 0x40, 0x9f, 0x96, 0xe9, 0x3d, 0x7e, 0x11, 0x73, 0x93, 0x17, 0x2a,
    0xae, 0x2d, 0x8a, 0x57, 0x1e, 0x03, 0xac, 0x9c, 0x9e, 0xb7, 0x6f, 0xac, 0x45, 0xaf, 0x8e, 0x51,
    0x30, 0xc8, 0x1c, 0x46, 0xa3, 0x5c, 0xe4, 0x11, 0xe5, 0xfb, 0xc1, 0x19, 0x1a, 0x0a, 0x52, 0xef,
    0xf6, 0x9f, 0x24, 0x45, 0xdf, 0x4f, 0x9b, 0x17, 0xad, 0x2b, 0x41, 0x7b, 0xe6, 0x6c, 0x37, 0x10};
static const size_t RFC_LEN[4] = {0, 16, 40, 64};
static const uint8_t RFC_TAG[4][16] = {
    {0xbb, 0x1d, 0x69, 0x29, 0xe9, 0x59, 0x37, 0x28, 0x7f, 0xa3, 0x7d, 0x12, 0x9b, 0x75, 0x67, 0x46},
    {0x07, 0x0a, 0x16, 0xb4, 0x6b, 0x4d, 0x41, 0x44, 0xf7, 0x9b, 0xdd, 0x9d, 0xd0, 0x4a, 0x28, 0x7c},
    {0xdf, 0xa6, 0x67, 0x47, 0xde, 0x9a, 0xe6, 0x30, 0x30, 0xca, 0x32, 0x61, 0x14, 0x97, 0xc8, 0x27},
    {0x51, 0xf0, 0xbe, 0xbf, 0x7e, 0x3b, 0x9d, 0x92, 0xfc, 0x49, 0x74, 0x17, 0x79, 0x36, 0x3c, 0xfe}};

static uint8_t control[N_FRAMES][16];
static uint8_t weights[N_FRAMES][64];

/* Verify every frame of one kind; the instructions per frame. */
static double count_verify(const fw_cmac_key *k, uint16_t data_id, uint8_t *frames, size_t len, double tpi,
                           int *all_ok)
{
    uint64_t latest = 0;
    uint32_t t0, t1, i;
    int ok = 1;
    systick_start();
    t0 = systick_now();
    for (i = 0; i < N_FRAMES; ++i) {
        ok &= fw_secoc_verify(k, data_id, &frames[i * len], len, &latest) == FW_OK;
    }
    t1 = systick_now();
    *all_ok &= ok;
    return (double)((t0 - t1) & 0x00FFFFFFu) / tpi / (double)N_FRAMES;
}

int main(void)
{
    static const uint8_t key[16] = {'p', 'y', 'r', 'h', 'o', 'n', 'n', '-', 'T', 'E', 'S', 'T', '-', 'k', 'e', 'y'};
    fw_cmac_key k;
    uint8_t tag[16];
    double tpi, per_control, per_weights;
    uint32_t i;
    int ok = 1;

    for (i = 0; i < 4u; ++i) {
        (void)fw_aes128_cmac(RFC_KEY, RFC_MSG, RFC_LEN[i], tag);
        ok &= memcmp(tag, RFC_TAG[i], 16) == 0;
    }
    printf("cmac_rfc4493 %s\n", ok ? "ok" : "FAILED");
    (void)fw_cmac_init(&k, key);
    for (i = 0; i < N_FRAMES; ++i) {
        memset(control[i], 0, sizeof control[i]);
        control[i][0] = 3u;
        (void)fw_secoc_protect(&k, 0x110u, control[i], sizeof control[i], (uint64_t)i + 1u);
        memset(weights[i], 0, sizeof weights[i]);
        weights[i][2] = 12u;
        (void)fw_secoc_protect(&k, 0x120u, weights[i], sizeof weights[i], (uint64_t)i + 1u);
    }
    tpi = ticks_per_instruction();
    per_control = count_verify(&k, 0x110u, &control[0][0], 16u, tpi, &ok);
    per_weights = count_verify(&k, 0x120u, &weights[0][0], 64u, tpi, &ok);
    printf("ticks_per_instruction %.6f\n", tpi);
    printf("instructions_per_control_verify %.1f\n", per_control);
    printf("instructions_per_weight_load_verify %.1f\n", per_weights);
    printf("verified %s\n", ok ? "ok" : "FAILED");
    return ok ? 0 : 1;
}
