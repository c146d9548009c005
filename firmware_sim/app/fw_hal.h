/*
 * fw_hal.h - what the identifier application needs from its platform: send a
 * CAN (FD) frame, receive one, read a monotonic clock. A platform fills an
 * fw_hal with three function pointers and a context pointer and hands it to
 * fw_app_init; the application never calls anything else.
 *
 *   host tests, Python, fuzzing   fw_hal_mem.h (frames in memory, settable clock)
 *   Linux runner                  SocketCAN raw socket + clock_gettime(CLOCK_MONOTONIC)
 *   Cortex-M4                     the CAN FD peripheral driver + SysTick/DWT
 *
 * Frame identifiers follow SocketCAN's can_id convention, so a Linux runner
 * passes struct canfd_frame's can_id through unchanged: 11-bit identifiers
 * as they are, 29-bit ones with FW_CAN_EFF_FLAG set. The protocol uses 11-bit
 * identifiers only; any flagged identifier is unknown to it.
 *
 * Plain C99: no OS calls, no allocation, no stdio.
 */
#ifndef FW_HAL_H
#define FW_HAL_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Status of every firmware_sim function. The numbers are part of the
 * protocol (ControlAck.Result and Diagnostics.LastReject in rhonn_id.dbc;
 * fw_app.c checks they agree at compile time). */
typedef enum {
    FW_OK = 0,
    FW_E_NULL = 1,          /* a required pointer argument is NULL */
    FW_E_NOT_INIT = 2,      /* the fw_app was not set up by fw_app_init */
    FW_E_CONFIG = 3,        /* configuration rejected (identifier, sizes, HAL) */
    FW_E_UNKNOWN_ID = 4,    /* frame identifier not received by this node */
    FW_E_LENGTH = 5,        /* frame length differs from the DBC's */
    FW_E_RANGE = 6,         /* a signal outside its DBC range, or a weight index/value out of range */
    FW_E_SEQ_REPEAT = 7,    /* measurement repeats the last sequence counter */
    FW_E_SEQ_JUMP = 8,      /* measurement's sequence counter is not last + 1 */
    FW_E_STATE = 9,         /* command or weight frame not valid now (no transfer open) */
    FW_E_WEIGHTS = 10,      /* weight commit refused: weights missing, or rejected by the core */
    FW_E_STEP = 11,         /* measurement accepted but rhonn_step failed; filter unchanged */
    FW_E_HAL = 12,          /* the platform failed to send a frame or read the clock */
    FW_E_EMPTY = 13,        /* HAL receive: no frame pending (not an error) */
    FW_E_AUTH = 14,         /* command frame whose authenticator (MAC) does not verify */
    FW_E_FRESHNESS = 15     /* command frame replayed or stale: freshness not newer, or too far ahead */
} fw_status;

#define FW_CAN_EFF_FLAG 0x80000000u /* 29-bit identifier (SocketCAN CAN_EFF_FLAG) */
#define FW_CAN_RTR_FLAG 0x40000000u /* remote request (SocketCAN CAN_RTR_FLAG) */
#define FW_CAN_ERR_FLAG 0x20000000u /* error frame (SocketCAN CAN_ERR_FLAG) */

#define FW_FRAME_FD 0x01u           /* CAN FD frame (else classic CAN) */
#define FW_FRAME_BRS 0x02u          /* bit-rate switch in the data phase */

#define FW_MAX_FRAME_LEN 64u        /* largest CAN FD payload */

typedef struct {
    uint32_t id;                    /* can_id: identifier plus FW_CAN_*_FLAG bits */
    uint8_t len;                    /* payload bytes, 0..64 */
    uint8_t flags;                  /* FW_FRAME_FD | FW_FRAME_BRS */
    uint8_t data[FW_MAX_FRAME_LEN];
} fw_frame;

typedef struct {
    void *ctx;  /* handed back to every call */
    /* Queue one frame for transmission. FW_OK or FW_E_HAL. Required. */
    fw_status (*send)(void *ctx, const fw_frame *frame);
    /* Take one received frame: FW_OK, FW_E_EMPTY when none is pending, or
     * FW_E_HAL. May be NULL when the platform calls fw_app_on_frame itself. */
    fw_status (*receive)(void *ctx, fw_frame *frame);
    /* Monotonic time in nanoseconds. FW_OK or FW_E_HAL. Required. */
    fw_status (*now)(void *ctx, uint64_t *ns);
} fw_hal;

#ifdef __cplusplus
}
#endif

#endif /* FW_HAL_H */
