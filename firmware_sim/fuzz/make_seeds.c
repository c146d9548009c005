/* Writes a seed corpus for fuzz_on_frame into the folder given as argv[1]:
 * a run of valid Measurement frames, each control command (secured by the
 * harness: selector 0xE0), a weight transfer (0xE1 chunks), an unsecured
 * command, and frames with wrong lengths, so that the fuzzer starts from
 * inputs that reach every branch of the protocol. Packs with the code
 * cantools generated from rhonn_id.dbc. */
#include <stdio.h>
#include <string.h>

#include "rhonn_id.h"

static size_t put_frame(uint8_t *buf, size_t pos, uint8_t sel, const uint8_t *payload, size_t len)
{
    buf[pos++] = sel;
    buf[pos++] = (uint8_t)len;
    memcpy(&buf[pos], payload, len);
    return pos + len;
}

static size_t measurement(uint8_t *buf, size_t pos, uint16_t seq, int valid)
{
    struct rhonn_id_measurement_t m;
    uint8_t payload[64];
    memset(&m, 0, sizeof m);
    m.seq = seq;
    m.valid_qm = m.valid_v = m.valid_lambda_a = m.valid_lambda_b = m.valid_ia = (uint8_t)valid;
    m.valid_ib = 1u;
    m.qm = rhonn_id_measurement_qm_encode(0.01 * seq);
    m.v = rhonn_id_measurement_v_encode(0.2);
    m.ia = rhonn_id_measurement_ia_encode(3.0);
    m.ua = rhonn_id_measurement_ua_encode(100.0);
    (void)rhonn_id_measurement_pack(payload, &m, sizeof payload);
    return put_frame(buf, pos, 0u, payload, RHONN_ID_MEASUREMENT_LENGTH);
}

static int write_seed(const char *dir, const char *name, const uint8_t *buf, size_t len)
{
    char path[512];
    FILE *f;
    snprintf(path, sizeof path, "%s/%s", dir, name);
    f = fopen(path, "wb");
    if (f == NULL || fwrite(buf, 1, len, f) != len) {
        perror(path);
        return 1;
    }
    fclose(f);
    return 0;
}

int main(int argc, char **argv)
{
    uint8_t buf[4096];
    size_t pos = 0;
    uint16_t k;
    int rc = 0;
    uint8_t cmd;

    if (argc != 2) {
        fprintf(stderr, "usage: make_seeds DIR\n");
        return 2;
    }
    for (k = 0; k < 20; ++k) {
        pos = measurement(buf, pos, k, k % 5 != 3);
    }
    rc |= write_seed(argv[1], "measurements", buf, pos);
    for (cmd = 0; cmd < 8; ++cmd) {
        struct rhonn_id_control_t c;
        uint8_t payload[64];
        memset(&c, 0, sizeof c);
        c.command = cmd;
        (void)rhonn_id_control_pack(payload, &c, sizeof payload);
        pos = measurement(buf, 0, 1, 1);
        pos = put_frame(buf, pos, 0xE0u, payload, 4u); /* the harness secures it */
        pos = measurement(buf, pos, 2, 1);
        {
            char name[32];
            snprintf(name, sizeof name, "control_%u", (unsigned)cmd);
            rc |= write_seed(argv[1], name, buf, pos);
        }
    }
    {
        struct rhonn_id_control_t c;
        struct rhonn_id_weight_load_t w;
        uint8_t payload[64];
        uint8_t neuron;
        memset(&c, 0, sizeof c);
        c.command = RHONN_ID_CONTROL_COMMAND_WEIGHTS_BEGIN_CHOICE;
        (void)rhonn_id_control_pack(payload, &c, sizeof payload);
        pos = put_frame(buf, 0, 0xE0u, payload, 4u);
        for (neuron = 0; neuron < 6u; ++neuron) {
            memset(&w, 0, sizeof w);
            w.neuron = neuron;
            w.count = 2;
            w.w00 = 0.5f;
            w.w01 = -0.25f;
            (void)rhonn_id_weight_load_pack(payload, &w, sizeof payload);
            pos = put_frame(buf, pos, 0xE1u, payload, RHONN_ID_WEIGHT_LOAD_LENGTH - 12u);
        }
        c.command = RHONN_ID_CONTROL_COMMAND_WEIGHTS_COMMIT_CHOICE;
        (void)rhonn_id_control_pack(payload, &c, sizeof payload);
        pos = put_frame(buf, pos, 0xE0u, payload, 4u);
        pos = put_frame(buf, pos, 3u, payload, RHONN_ID_CONTROL_LENGTH); /* the same, unsecured */
        rc |= write_seed(argv[1], "weights", buf, pos);
    }
    {
        uint8_t payload[64];
        memset(payload, 0, sizeof payload);
        pos = put_frame(buf, 0, 0u, payload, 19u);  /* short measurement */
        pos = put_frame(buf, pos, 4u, payload, 64u); /* weight chunk without a transfer */
        pos = put_frame(buf, pos, 0xF0u, payload, 8u);
        rc |= write_seed(argv[1], "malformed", buf, pos);
    }
    return rc;
}
