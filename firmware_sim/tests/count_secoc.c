/*
 * count_secoc.c - the cost of the command authentication, for an instruction
 * counter (valgrind --tool=callgrind; not a test, no timing):
 *
 *   count_secoc N   handles N authenticated Control frames (LearningOn, each
 *                   with the next freshness value) through fw_app_on_frame,
 *                   then runs fw_secoc_verify alone N times.
 *
 * CMake builds it twice, count_secoc (FW_SECOC=1) and count_secoc_plain
 * (FW_SECOC=0): compare callgrind's inclusive counts of fw_app_on_frame;
 * fw_secoc_verify's count is the MAC check itself (docs/firmware-protocol.md,
 * Authentication).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fw_app.h"
#include "fw_hal_mem.h"
#include "fw_secoc_key.h"
#include "lim_identifier.h"
#include "rhonn_id.h"

static fw_app app;
static fw_mem_hal mem;

int main(int argc, char **argv)
{
    static const uint8_t key[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
    fw_hal hal;
    fw_app_config cfg;
    fw_cmac_key k;
    fw_frame out;
    uint8_t c[RHONN_ID_CONTROL_LENGTH];
    uint64_t latest = 0;
    long n, i, accepted = 0;

    n = argc > 1 ? strtol(argv[1], NULL, 10) : 1000;
    cfg.identifier = &LIM_IDENTIFIER;
    cfg.deadline_ns = 0;
    cfg.diag_period = 0;
    if (fw_mem_hal_init(&mem, &hal) != FW_OK || fw_app_init(&app, &cfg, &hal) != FW_OK
        || fw_cmac_init(&k, key) != FW_OK) {
        return 1;
    }
    for (i = 1; i <= n; ++i) {
        memset(c, 0, sizeof c);
        c[0] = RHONN_ID_CONTROL_COMMAND_LEARNING_ON_CHOICE;
        (void)fw_secoc_protect(&k, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, (uint64_t)i);
        accepted += fw_app_on_frame(&app, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, 0) == FW_OK;
        while (fw_mem_hal_pop(&mem, &out) == FW_OK) {
        }
    }
    for (i = 1; i <= n; ++i) {
        (void)fw_secoc_protect(&k, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, (uint64_t)i);
        accepted += fw_secoc_verify(&k, RHONN_ID_CONTROL_FRAME_ID, c, sizeof c, &latest) == FW_OK;
    }
    printf("FW_SECOC=%d: %ld of %ld frames accepted\n", FW_SECOC, accepted, 2 * n);
    return accepted == 2 * n ? 0 : 1;
}
