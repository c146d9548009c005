/* Generated from rhonn_id.dbc by firmware_sim/tools/generate_protocol.py: do not edit. */
/* The identifier's states and inputs in the Measurement and Estimate frames, in the
 * identifier's order: the states are the signals with a Valid flag, the inputs the
 * other value signals. fw_protocol.c defines FW_IN_RANGE, FW_DECODE and FW_QUANTISE. */
#ifndef RHONN_ID_LAYOUT_H
#define RHONN_ID_LAYOUT_H

#define FW_N_STATES 6u /* Qm, V, LambdaA, LambdaB, Ia, Ib */
#define FW_N_INPUTS 2u /* Ua, Ub */

/* Every signal of the unpacked Measurement f within its DBC range (a state flagged not
 * valid is not range-checked). */
#define FW_MEASUREMENT_IN_RANGE(f) \
    (FW_IN_RANGE((f).seq, RHONN_ID_MEASUREMENT_SEQ) && \
    FW_IN_RANGE((f).valid_qm, RHONN_ID_MEASUREMENT_VALID_QM) && \
    FW_IN_RANGE((f).valid_v, RHONN_ID_MEASUREMENT_VALID_V) && \
    FW_IN_RANGE((f).valid_lambda_a, RHONN_ID_MEASUREMENT_VALID_LAMBDA_A) && \
    FW_IN_RANGE((f).valid_lambda_b, RHONN_ID_MEASUREMENT_VALID_LAMBDA_B) && \
    FW_IN_RANGE((f).valid_ia, RHONN_ID_MEASUREMENT_VALID_IA) && \
    FW_IN_RANGE((f).valid_ib, RHONN_ID_MEASUREMENT_VALID_IB) && \
    (!(f).valid_qm || FW_IN_RANGE((f).qm, RHONN_ID_MEASUREMENT_QM)) && \
    (!(f).valid_v || FW_IN_RANGE((f).v, RHONN_ID_MEASUREMENT_V)) && \
    (!(f).valid_lambda_a || FW_IN_RANGE((f).lambda_a, RHONN_ID_MEASUREMENT_LAMBDA_A)) && \
    (!(f).valid_lambda_b || FW_IN_RANGE((f).lambda_b, RHONN_ID_MEASUREMENT_LAMBDA_B)) && \
    (!(f).valid_ia || FW_IN_RANGE((f).ia, RHONN_ID_MEASUREMENT_IA)) && \
    (!(f).valid_ib || FW_IN_RANGE((f).ib, RHONN_ID_MEASUREMENT_IB)) && \
    FW_IN_RANGE((f).ua, RHONN_ID_MEASUREMENT_UA) && \
    FW_IN_RANGE((f).ub, RHONN_ID_MEASUREMENT_UB))

/* The flags and physical values of the unpacked Measurement f into the fw_measurement out. */
#define FW_MEASUREMENT_FILL(out, f) \
    do { \
    (out).valid[0] = (f).valid_qm; \
    (out).valid[1] = (f).valid_v; \
    (out).valid[2] = (f).valid_lambda_a; \
    (out).valid[3] = (f).valid_lambda_b; \
    (out).valid[4] = (f).valid_ia; \
    (out).valid[5] = (f).valid_ib; \
    (out).x[0] = FW_DECODE(rhonn_id_measurement_qm_decode, (f).qm, RHONN_ID_MEASUREMENT_QM); \
    (out).x[1] = FW_DECODE(rhonn_id_measurement_v_decode, (f).v, RHONN_ID_MEASUREMENT_V); \
    (out).x[2] = FW_DECODE(rhonn_id_measurement_lambda_a_decode, (f).lambda_a, RHONN_ID_MEASUREMENT_LAMBDA_A); \
    (out).x[3] = FW_DECODE(rhonn_id_measurement_lambda_b_decode, (f).lambda_b, RHONN_ID_MEASUREMENT_LAMBDA_B); \
    (out).x[4] = FW_DECODE(rhonn_id_measurement_ia_decode, (f).ia, RHONN_ID_MEASUREMENT_IA); \
    (out).x[5] = FW_DECODE(rhonn_id_measurement_ib_decode, (f).ib, RHONN_ID_MEASUREMENT_IB); \
    (out).u[0] = FW_DECODE(rhonn_id_measurement_ua_decode, (f).ua, RHONN_ID_MEASUREMENT_UA); \
    (out).u[1] = FW_DECODE(rhonn_id_measurement_ub_decode, (f).ub, RHONN_ID_MEASUREMENT_UB); \
    } while (0)

/* Every state of the unpacked Measurement f marked valid. */
#define FW_MEASUREMENT_ALL_VALID(f) \
    do { \
    (f).valid_qm = 1u; \
    (f).valid_v = 1u; \
    (f).valid_lambda_a = 1u; \
    (f).valid_lambda_b = 1u; \
    (f).valid_ia = 1u; \
    (f).valid_ib = 1u; \
    } while (0)

/* The estimates of the fw_estimate *e into the Estimate struct f, collecting saturation. */
#define FW_ESTIMATE_FILL(f, e) \
    do { \
    FW_QUANTISE((f).qm_hat, int32_t, (e)->xhat[0], RHONN_ID_ESTIMATE_QM_HAT); \
    FW_QUANTISE((f).v_hat, int16_t, (e)->xhat[1], RHONN_ID_ESTIMATE_V_HAT); \
    FW_QUANTISE((f).lambda_a_hat, int16_t, (e)->xhat[2], RHONN_ID_ESTIMATE_LAMBDA_A_HAT); \
    FW_QUANTISE((f).lambda_b_hat, int16_t, (e)->xhat[3], RHONN_ID_ESTIMATE_LAMBDA_B_HAT); \
    FW_QUANTISE((f).ia_hat, int16_t, (e)->xhat[4], RHONN_ID_ESTIMATE_IA_HAT); \
    FW_QUANTISE((f).ib_hat, int16_t, (e)->xhat[5], RHONN_ID_ESTIMATE_IB_HAT); \
    } while (0)

#endif /* RHONN_ID_LAYOUT_H */
