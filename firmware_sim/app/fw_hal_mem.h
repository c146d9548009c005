/*
 * fw_hal_mem.h - an fw_hal over memory: frames the application sends go
 * into an outbox, frames it receives come from an inbox, and the clock is a
 * number the caller sets (advanced by tick_ns at every read, so step times
 * are deterministic). Used by the host unit tests, by the Python extension
 * pyrhonn._fwapp (which swaps in the host's monotonic clock) and by fuzzing.
 * Plain C99, no OS calls.
 */
#ifndef FW_HAL_MEM_H
#define FW_HAL_MEM_H

#include <stdint.h>

#include "fw_hal.h"

#ifdef __cplusplus
extern "C" {
#endif

#define FW_MEM_HAL_DEPTH 16u

typedef struct {
    fw_frame frames[FW_MEM_HAL_DEPTH];
    uint32_t head;   /* oldest frame */
    uint32_t count;
} fw_mem_queue;

typedef struct {
    fw_mem_queue outbox;    /* filled by send */
    fw_mem_queue inbox;     /* drained by receive */
    uint64_t now_ns;        /* the clock: now() first adds tick_ns, then returns it */
    uint64_t tick_ns;
    uint8_t fail_send;      /* nonzero: send returns FW_E_HAL (tests) */
    uint8_t fail_clock;     /* nonzero: now returns FW_E_HAL (tests) */
    uint32_t dropped;       /* frames refused because the outbox was full */
} fw_mem_hal;

/* Empty queues, clock 0, and hal bound to the three functions below. */
fw_status fw_mem_hal_init(fw_mem_hal *m, fw_hal *hal);

fw_status fw_mem_hal_send(void *ctx, const fw_frame *frame);   /* to the outbox; FW_E_HAL when full */
fw_status fw_mem_hal_receive(void *ctx, fw_frame *frame);      /* from the inbox; FW_E_EMPTY */
fw_status fw_mem_hal_now(void *ctx, uint64_t *ns);

/* The test side: put a frame into the inbox, take one from the outbox. */
fw_status fw_mem_hal_push(fw_mem_hal *m, const fw_frame *frame);   /* FW_E_HAL when full */
fw_status fw_mem_hal_pop(fw_mem_hal *m, fw_frame *frame);          /* FW_E_EMPTY */

#ifdef __cplusplus
}
#endif

#endif /* FW_HAL_MEM_H */
