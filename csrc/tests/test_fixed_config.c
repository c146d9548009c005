/* The core compiled for one configuration (RHONN_FIXED_CONFIG=LIM_IDENTIFIER)
 * accepts that configuration, from any copy, and refuses every other one
 * with RHONN_E_CONFIG naming the first field that differs, leaving the
 * identifier as it was. */
#include <string.h>

#include "check.h"
#include "lim_identifier.h"
#include "rhonn.h"

static rhonn_t net;

static void accepts_its_configuration_from_a_copy(void)
{
    rhonn_config copy = LIM_IDENTIFIER;
    rhonn_config_error where;
    rhonn_real x[6] = {0}, u[2] = {0}, xhat[6];
    CHECK_STATUS(rhonn_init(&net, &copy, &where), RHONN_OK);
    CHECK(where.field == RHONN_FIELD_NONE);
    CHECK_STATUS(rhonn_step(&net, x, u, NULL, xhat), RHONN_OK);
}

/* cfg differs from LIM_IDENTIFIER in one field: refused with that field
 * named, and net (initialised and stepped before) unchanged byte for byte. */
static void refused(const rhonn_config *cfg, rhonn_field field, uint8_t neuron, uint8_t term, uint8_t factor)
{
    static rhonn_t before;
    rhonn_config_error where;
    memcpy(&before, &net, sizeof net);
    CHECK_STATUS(rhonn_init(&net, cfg, &where), RHONN_E_CONFIG);
    CHECK(where.field == (uint8_t)field);
    CHECK(where.neuron == neuron && where.term == term && where.factor == factor);
    CHECK(memcmp(&before, &net, sizeof net) == 0);
}

static void refuses_any_other_configuration_naming_the_field(void)
{
    rhonn_config c;
    rhonn_real x[6] = {0}, u[2] = {0}, xhat[6];
    CHECK_STATUS(rhonn_init(&net, &LIM_IDENTIFIER, NULL), RHONN_OK);
    CHECK_STATUS(rhonn_step(&net, x, u, NULL, xhat), RHONN_OK);

    c = LIM_IDENTIFIER; c.n_inputs = 3; refused(&c, RHONN_FIELD_N_INPUTS, 0, 0, 0);
    c = LIM_IDENTIFIER; c.x0[2] = (rhonn_real)0.5; refused(&c, RHONN_FIELD_X0, 2, 0, 2);
    c = LIM_IDENTIFIER; c.x0[2] = -c.x0[2]; refused(&c, RHONN_FIELD_X0, 2, 0, 2); /* -0 is not 0 */
    c = LIM_IDENTIFIER; c.neurons[1].beta = (rhonn_real)2.0; refused(&c, RHONN_FIELD_BETA, 1, 0, 0);
    c = LIM_IDENTIFIER; c.neurons[2].eta = (rhonn_real)0.5; refused(&c, RHONN_FIELD_ETA, 2, 0, 0);
    c = LIM_IDENTIFIER; c.neurons[3].r = (rhonn_real)0.2; refused(&c, RHONN_FIELD_R, 3, 0, 0);
    c = LIM_IDENTIFIER; c.neurons[4].q[3] = (rhonn_real)0.5; refused(&c, RHONN_FIELD_Q, 4, 3, 3);
    c = LIM_IDENTIFIER; c.neurons[5].w0[1] = (rhonn_real)1.0; refused(&c, RHONN_FIELD_W0, 5, 1, 1);
    c = LIM_IDENTIFIER; c.neurons[5].p0[6] = (rhonn_real)7.0; refused(&c, RHONN_FIELD_P0, 5, 1, 6);
    c = LIM_IDENTIFIER; c.neurons[2].terms[3].factors[1].index = 3;
    refused(&c, RHONN_FIELD_FACTOR_INDEX, 2, 3, 1);
    c = LIM_IDENTIFIER; c.neurons[1].terms[1].factors[1].delay = 0;
    refused(&c, RHONN_FIELD_FACTOR_DELAY, 1, 1, 1);
    c = LIM_IDENTIFIER; c.neurons[0].terms[0].factors[0].power = 2;
    refused(&c, RHONN_FIELD_FACTOR_POWER, 0, 0, 0);
    c = LIM_IDENTIFIER; c.neurons[0].terms[1].factors[0].kind = RHONN_FACTOR_S;
    refused(&c, RHONN_FIELD_FACTOR_KIND, 0, 1, 0);
    c = LIM_IDENTIFIER; c.neurons[3].covariance = RHONN_COV_UD; refused(&c, RHONN_FIELD_COVARIANCE, 3, 0, 0);
    c = LIM_IDENTIFIER; c.neurons[3].forgetting = (rhonn_real)0.99; refused(&c, RHONN_FIELD_FORGETTING, 3, 0, 0);
    c = LIM_IDENTIFIER; c.neurons[3].p_trace_max = (rhonn_real)1e6; refused(&c, RHONN_FIELD_P_TRACE_MAX, 3, 0, 0);
    c = LIM_IDENTIFIER; c.neurons[4].reset_after = 3; refused(&c, RHONN_FIELD_RESET_AFTER, 4, 0, 0);
    c = LIM_IDENTIFIER; c.neurons[5].gate = (rhonn_real)9.0; refused(&c, RHONN_FIELD_GATE, 5, 0, 0);
    /* an invalid configuration is reported as such first */
    c = LIM_IDENTIFIER; c.neurons[4].r = (rhonn_real)-1.0; refused(&c, RHONN_FIELD_R, 4, 0, 0);
    CHECK_STATUS(rhonn_init(&net, NULL, NULL), RHONN_E_NULL);
}

int main(void)
{
    RUN(accepts_its_configuration_from_a_copy);
    RUN(refuses_any_other_configuration_naming_the_field);
    return CHECK_SUMMARY();
}
