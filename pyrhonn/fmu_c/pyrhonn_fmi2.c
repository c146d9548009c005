/*
 * pyrhonn_fmi2.c - the FMI 2.0 co-simulation interface of an exported
 * identifier (the model: pyrhonn_fmu_model.c). Every function of the
 * standard is exported; those of model exchange, FMU states, derivatives
 * and asynchronous steps, which the FMU does not provide (its
 * modelDescription.xml says so), return fmi2Error with a message.
 */
#include "fmi2Functions.h"

static void fmu_emit(const fmu_model *m, fmu_result result, const char *message)
{
    fmi2CallbackLogger log = NULL;
    fmi2Status status = result == FMU_RESULT_OK ? fmi2OK : result == FMU_RESULT_WARNING ? fmi2Warning : fmi2Error;
    if (m->log_fn == NULL || (result == FMU_RESULT_OK && !m->log_on)) {
        return;
    }
    memcpy(&log, &m->log_fn, sizeof log);
    log((fmi2ComponentEnvironment)m->log_env, m->name, status,
        result == FMU_RESULT_OK ? "logEvents" : result == FMU_RESULT_WARNING ? "logStatusWarning" : "logStatusError",
        "%s", message);
}

static fmi2Status fmu_status(fmu_result result)
{
    return result == FMU_RESULT_ERROR ? fmi2Error : result == FMU_RESULT_WARNING ? fmi2Warning : fmi2OK;
}

#define FMU_INSTANCE                                                  \
    fmu_model *m = (fmu_model *)c;                                    \
    if (m == NULL) {                                                  \
        return fmi2Error;                                             \
    }

/* The arrays of a getter or setter: given whenever there are values. */
#define FMU_ARRAYS(call)                                                                   \
    if (nvr > 0 && (vr == NULL || value == NULL)) {                                        \
        fmu_logf(m, FMU_RESULT_ERROR, "%s: vr or value is NULL", call);                    \
        return fmi2Error;                                                                  \
    }

#define FMU_NOT_PROVIDED(call)                                        \
    if (c != NULL) {                                                  \
        fmu_logf((const fmu_model *)c, FMU_RESULT_ERROR,              \
                 "%s: not provided by this FMU (co-simulation only)", call); \
    }                                                                 \
    return fmi2Error;

const char *fmi2GetTypesPlatform(void)
{
    return fmi2TypesPlatform;
}

const char *fmi2GetVersion(void)
{
    return fmi2Version;
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    FMU_INSTANCE
    (void)nCategories;
    (void)categories;
    m->log_on = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    void *log_fn = NULL;
    fmi2CallbackLogger logger = functions != NULL ? functions->logger : NULL;
    fmi2ComponentEnvironment env = functions != NULL ? functions->componentEnvironment : NULL;
    fmu_model *m;
    (void)fmuResourceLocation; (void)visible;
    if (fmuType != fmi2CoSimulation) {
        if (logger != NULL) {
            logger(env, instanceName, fmi2Error, "logStatusError", "fmuType: this FMU is for co-simulation only");
        }
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, FMU_TOKEN) != 0) {
        if (logger != NULL) {
            logger(env, instanceName, fmi2Error, "logStatusError", "fmuGUID: not this FMU's (%s): its "
                   "modelDescription.xml does not belong to this binary", FMU_TOKEN);
        }
        return NULL;
    }
    if (logger != NULL) {
        memcpy(&log_fn, &logger, sizeof log_fn);
    }
    m = fmu_new(instanceName, env, log_fn, loggingOn ? 1 : 0);
    if (m == NULL && logger != NULL) {
        logger(env, instanceName, fmi2Error, "logStatusError", "fmi2Instantiate: out of memory or configuration "
               "refused");
    }
    return (fmi2Component)m;
}

void fmi2FreeInstance(fmi2Component c)
{
    free(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    FMU_INSTANCE
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (m->phase != FMU_INSTANTIATED) {
        fmu_logf(m, FMU_RESULT_ERROR, "fmi2SetupExperiment: only after instantiation or reset");
        return fmi2Error;
    }
    if (!isfinite(startTime)) {
        fmu_logf(m, FMU_RESULT_ERROR, "startTime: not a finite number");
        return fmi2Error;
    }
    m->start_time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    FMU_INSTANCE
    return fmu_status(fmu_enter_initialization(m, m->start_time));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    FMU_INSTANCE
    return fmu_status(fmu_exit_initialization(m));
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    FMU_INSTANCE
    m->phase = FMU_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    FMU_INSTANCE
    return fmu_status(fmu_start(m));
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    size_t k;
    FMU_INSTANCE
    FMU_ARRAYS("fmi2GetReal")
    for (k = 0; k < nvr; ++k) {
        if (fmu_get_real(m, vr[k], &value[k], 0) != FMU_RESULT_OK) {
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    size_t k;
    FMU_INSTANCE
    FMU_ARRAYS("fmi2GetInteger")
    for (k = 0; k < nvr; ++k) {
        int v = 0;
        if (fmu_get_int(m, vr[k], &v) != FMU_RESULT_OK) {
            return fmi2Error;
        }
        value[k] = (fmi2Integer)v;
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    size_t k;
    FMU_INSTANCE
    FMU_ARRAYS("fmi2GetBoolean")
    for (k = 0; k < nvr; ++k) {
        int v = 0;
        if (fmu_get_bool(m, vr[k], &v) != FMU_RESULT_OK) {
            return fmi2Error;
        }
        value[k] = v ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    (void)vr; (void)value;
    if (nvr == 0) {
        return fmi2OK;
    }
    FMU_NOT_PROVIDED("fmi2GetString (the FMU has no String variables)")
}

/* Inputs and parameters are set in every phase but after termination. */
#define FMU_SETTABLE(call)                                                                 \
    if (m->phase == FMU_TERMINATED) {                                                      \
        fmu_logf(m, FMU_RESULT_ERROR, "%s: the instance is terminated", call);             \
        return fmi2Error;                                                                  \
    }

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    size_t k;
    FMU_INSTANCE
    FMU_SETTABLE("fmi2SetReal")
    FMU_ARRAYS("fmi2SetReal")
    for (k = 0; k < nvr; ++k) {
        if (fmu_set_real(m, vr[k], value[k]) != FMU_RESULT_OK) {
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    size_t k;
    FMU_INSTANCE
    FMU_SETTABLE("fmi2SetInteger")
    FMU_ARRAYS("fmi2SetInteger")
    for (k = 0; k < nvr; ++k) {
        if (fmu_set_int(m, vr[k], (int)value[k]) != FMU_RESULT_OK) {
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    size_t k;
    FMU_INSTANCE
    FMU_SETTABLE("fmi2SetBoolean")
    FMU_ARRAYS("fmi2SetBoolean")
    for (k = 0; k < nvr; ++k) {
        if (fmu_set_bool(m, vr[k], value[k] ? 1 : 0) != FMU_RESULT_OK) {
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    (void)vr; (void)value;
    if (nvr == 0) {
        return fmi2OK;
    }
    FMU_NOT_PROVIDED("fmi2SetString (the FMU has no String variables)")
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    (void)FMUstate;
    FMU_NOT_PROVIDED("fmi2GetFMUstate (canGetAndSetFMUstate=\"false\")")
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    (void)FMUstate;
    FMU_NOT_PROVIDED("fmi2SetFMUstate (canGetAndSetFMUstate=\"false\")")
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    (void)FMUstate;
    FMU_NOT_PROVIDED("fmi2FreeFMUstate (canGetAndSetFMUstate=\"false\")")
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    (void)FMUstate; (void)size;
    FMU_NOT_PROVIDED("fmi2SerializedFMUstateSize")
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    (void)FMUstate; (void)serializedState; (void)size;
    FMU_NOT_PROVIDED("fmi2SerializeFMUstate")
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    (void)serializedState; (void)size; (void)FMUstate;
    FMU_NOT_PROVIDED("fmi2DeSerializeFMUstate")
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    FMU_NOT_PROVIDED("fmi2GetDirectionalDerivative")
}

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    FMU_NOT_PROVIDED("fmi2EnterEventMode")
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    (void)eventInfo;
    FMU_NOT_PROVIDED("fmi2NewDiscreteStates")
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    FMU_NOT_PROVIDED("fmi2EnterContinuousTimeMode")
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    FMU_NOT_PROVIDED("fmi2CompletedIntegratorStep")
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    (void)time;
    FMU_NOT_PROVIDED("fmi2SetTime")
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    (void)x; (void)nx;
    FMU_NOT_PROVIDED("fmi2SetContinuousStates")
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    (void)derivatives; (void)nx;
    FMU_NOT_PROVIDED("fmi2GetDerivatives")
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    (void)eventIndicators; (void)ni;
    FMU_NOT_PROVIDED("fmi2GetEventIndicators")
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    (void)x; (void)nx;
    FMU_NOT_PROVIDED("fmi2GetContinuousStates")
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    (void)x_nominal; (void)nx;
    FMU_NOT_PROVIDED("fmi2GetNominalsOfContinuousStates")
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    FMU_NOT_PROVIDED("fmi2SetRealInputDerivatives (canInterpolateInputs=\"false\")")
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    FMU_NOT_PROVIDED("fmi2GetRealOutputDerivatives (maxOutputDerivativeOrder=\"0\")")
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    FMU_INSTANCE
    (void)noSetFMUStatePriorToCurrentPoint;
    return fmu_status(fmu_do_step(m, currentCommunicationPoint, communicationStepSize));
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    FMU_NOT_PROVIDED("fmi2CancelStep (steps are not asynchronous)")
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s; (void)value;
    FMU_NOT_PROVIDED("fmi2GetStatus (steps are not asynchronous)")
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    FMU_INSTANCE
    if (s == fmi2LastSuccessfulTime && value != NULL) {
        *value = m->time;
        return fmi2OK;
    }
    FMU_NOT_PROVIDED("fmi2GetRealStatus (only fmi2LastSuccessfulTime)")
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s; (void)value;
    FMU_NOT_PROVIDED("fmi2GetIntegerStatus")
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    (void)s; (void)value;
    FMU_NOT_PROVIDED("fmi2GetBooleanStatus")
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s; (void)value;
    FMU_NOT_PROVIDED("fmi2GetStringStatus")
}
