/*
 * fuzz_udp_can.c - libFuzzer target of the udp_multicast codec: any datagram
 * is decoded without a crash or a sanitizer report, and whatever is
 * accepted is a valid message that encodes and decodes back to itself.
 *
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined -std=c99 \
 *       firmware_sim/linux/fuzz_udp_can.c firmware_sim/linux/udp_can.c -o fuzz_udp_can
 *   ./fuzz_udp_can -max_total_time=60 CORPUS_DIR
 */
#include <stdlib.h>
#include <string.h>

#include "udp_can.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    udp_can_msg m, back;
    uint8_t out[UDP_CAN_MAX_ENCODED];
    size_t n = 0;
    if (udp_can_decode(data, size, &m) != UDP_CAN_OK) {
        return 0;
    }
    if (udp_can_check(&m) != UDP_CAN_OK || udp_can_encode(&m, out, sizeof out, &n) != UDP_CAN_OK ||
        udp_can_decode(out, n, &back) != UDP_CAN_OK || back.arbitration_id != m.arbitration_id ||
        back.dlc != m.dlc || back.len != m.len || memcmp(back.data, m.data, m.len) != 0) {
        abort();
    }
    return 0;
}
