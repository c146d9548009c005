/* The core compiled with RHONN_CALIBRATE=0 (rhonn.h): the trace ceilings and
 * gates are the configuration's. The setters accept exactly those values
 * (and still refuse a bad one with RHONN_E_VALUE), refuse any other with
 * RHONN_E_CONFIG, and leave the identifier as it was. */
#include <math.h>
#include <string.h>

#include "check.h"
#include "rhonn.h"

static rhonn_t net, before;

static void the_setters_take_only_the_configurations_values(void)
{
    rhonn_config c;
    rhonn_real v;
    memset(&c, 0, sizeof c);
    c.n_states = 2;
    c.n_inputs = 0;
    c.neurons[0].n_terms = c.neurons[1].n_terms = 1;
    c.neurons[0].beta = c.neurons[1].beta = 1;
    c.neurons[0].eta = c.neurons[1].eta = 1;
    c.neurons[0].r = c.neurons[1].r = (rhonn_real)0.1;
    c.neurons[0].p0[0] = c.neurons[1].p0[0] = 10;
    c.neurons[0].terms[0].n_factors = c.neurons[1].terms[0].n_factors = 1;
    c.neurons[0].terms[0].factors[0].kind = c.neurons[1].terms[0].factors[0].kind = (uint8_t)RHONN_FACTOR_ONE;
    c.neurons[0].terms[0].factors[0].power = c.neurons[1].terms[0].factors[0].power = 1;
    c.neurons[0].gate = 9;
    c.neurons[1].p_trace_max = 20;
    CHECK_STATUS(rhonn_init(&net, &c, NULL), RHONN_OK);
    memcpy(&before, &net, sizeof net);
    CHECK_STATUS(rhonn_set_gate(&net, 0, 9), RHONN_OK);
    CHECK_STATUS(rhonn_set_gate(&net, 1, 0), RHONN_OK);
    CHECK_STATUS(rhonn_set_trace_ceiling(&net, 1, 20), RHONN_OK);
    CHECK_STATUS(rhonn_set_gate(&net, 0, 4), RHONN_E_CONFIG);
    CHECK_STATUS(rhonn_set_gate(&net, 1, 4), RHONN_E_CONFIG);
    CHECK_STATUS(rhonn_set_trace_ceiling(&net, 1, 30), RHONN_E_CONFIG);
    CHECK_STATUS(rhonn_set_trace_ceiling(&net, 0, 30), RHONN_E_CONFIG);
    CHECK_STATUS(rhonn_set_gate(&net, 0, (rhonn_real)NAN), RHONN_E_VALUE);
    CHECK_STATUS(rhonn_set_trace_ceiling(&net, 1, 5), RHONN_E_VALUE); /* below trace P(0) */
    CHECK_STATUS(rhonn_check_gate(&net, 0, 9), RHONN_OK); /* the checks alone say the same */
    CHECK_STATUS(rhonn_check_gate(&net, 0, 4), RHONN_E_CONFIG);
    CHECK_STATUS(rhonn_check_trace_ceiling(&net, 1, 30), RHONN_E_CONFIG);
    CHECK_STATUS(rhonn_check_trace_ceiling(&net, 1, 5), RHONN_E_VALUE);
    CHECK(memcmp(&before, &net, sizeof net) == 0);
    CHECK_STATUS(rhonn_get_gate(&net, 0, &v), RHONN_OK);
    CHECK(v == 9);
    CHECK_STATUS(rhonn_get_trace_ceiling(&net, 1, &v), RHONN_OK);
    CHECK(v == 20);
}

int main(void)
{
    RUN(the_setters_take_only_the_configurations_values);
    return CHECK_SUMMARY();
}
