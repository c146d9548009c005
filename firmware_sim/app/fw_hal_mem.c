/*
 * fw_hal_mem.c - the in-memory fw_hal. See fw_hal_mem.h.
 */
#include "fw_hal_mem.h"

#include <string.h>

static fw_status queue_put(fw_mem_queue *q, const fw_frame *frame)
{
    if (q->count >= FW_MEM_HAL_DEPTH) {
        return FW_E_HAL;
    }
    q->frames[(q->head + q->count) % FW_MEM_HAL_DEPTH] = *frame;
    ++q->count;
    return FW_OK;
}

static fw_status queue_take(fw_mem_queue *q, fw_frame *frame)
{
    if (q->count == 0u) {
        return FW_E_EMPTY;
    }
    *frame = q->frames[q->head];
    q->head = (q->head + 1u) % FW_MEM_HAL_DEPTH;
    --q->count;
    return FW_OK;
}

fw_status fw_mem_hal_init(fw_mem_hal *m, fw_hal *hal)
{
    if (m == NULL || hal == NULL) {
        return FW_E_NULL;
    }
    memset(m, 0, sizeof *m);
    hal->ctx = m;
    hal->send = fw_mem_hal_send;
    hal->receive = fw_mem_hal_receive;
    hal->now = fw_mem_hal_now;
    return FW_OK;
}

fw_status fw_mem_hal_send(void *ctx, const fw_frame *frame)
{
    fw_mem_hal *m = (fw_mem_hal *)ctx;

    if (m == NULL || frame == NULL) {
        return FW_E_NULL;
    }
    if (m->fail_send || frame->len > FW_MAX_FRAME_LEN) {
        return FW_E_HAL;
    }
    if (queue_put(&m->outbox, frame) != FW_OK) {
        ++m->dropped;
        return FW_E_HAL;
    }
    return FW_OK;
}

fw_status fw_mem_hal_receive(void *ctx, fw_frame *frame)
{
    fw_mem_hal *m = (fw_mem_hal *)ctx;

    if (m == NULL || frame == NULL) {
        return FW_E_NULL;
    }
    return queue_take(&m->inbox, frame);
}

fw_status fw_mem_hal_now(void *ctx, uint64_t *ns)
{
    fw_mem_hal *m = (fw_mem_hal *)ctx;

    if (m == NULL || ns == NULL) {
        return FW_E_NULL;
    }
    if (m->fail_clock) {
        return FW_E_HAL;
    }
    m->now_ns += m->tick_ns;
    *ns = m->now_ns;
    return FW_OK;
}

fw_status fw_mem_hal_push(fw_mem_hal *m, const fw_frame *frame)
{
    if (m == NULL || frame == NULL) {
        return FW_E_NULL;
    }
    return queue_put(&m->inbox, frame);
}

fw_status fw_mem_hal_pop(fw_mem_hal *m, fw_frame *frame)
{
    if (m == NULL || frame == NULL) {
        return FW_E_NULL;
    }
    return queue_take(&m->outbox, frame);
}
