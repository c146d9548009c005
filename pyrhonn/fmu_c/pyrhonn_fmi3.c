/*
 * pyrhonn_fmi3.c - the FMI 3.0 co-simulation interface of an exported
 * identifier (the model: pyrhonn_fmu_model.c). Every function of the
 * standard is exported; those of model exchange, scheduled execution,
 * clocks, FMU states and derivatives, which the FMU does not provide
 * (its modelDescription.xml says so), return fmi3Error with a message.
 */
#include "fmi3Functions.h"

static void fmu_emit(const fmu_model *m, fmu_result result, const char *message)
{
    fmi3LogMessageCallback log = NULL;
    fmi3Status status = result == FMU_RESULT_OK ? fmi3OK : result == FMU_RESULT_WARNING ? fmi3Warning : fmi3Error;
    if (m->log_fn == NULL || (result == FMU_RESULT_OK && !m->log_on)) {
        return;
    }
    memcpy(&log, &m->log_fn, sizeof log);
    log((fmi3InstanceEnvironment)m->log_env, status,
        result == FMU_RESULT_OK ? "logEvents" : result == FMU_RESULT_WARNING ? "logStatusWarning" : "logStatusError",
        message);
}

static fmi3Status fmu_status(fmu_model *m, fmu_result result)
{
    if (result == FMU_RESULT_ERROR) {
        return fmi3Error;
    }
    (void)m;
    return result == FMU_RESULT_WARNING ? fmi3Warning : fmi3OK;
}

#define FMU_INSTANCE(call)                                            \
    fmu_model *m = (fmu_model *)instance;                             \
    if (m == NULL) {                                                  \
        return fmi3Error;                                             \
    }

#define FMU_NOT_PROVIDED(call)                                        \
    if (instance != NULL) {                                           \
        fmu_logf((const fmu_model *)instance, FMU_RESULT_ERROR,       \
                 "%s: not provided by this FMU (co-simulation only)", call); \
    }                                                                 \
    return fmi3Error;

const char *fmi3GetVersion(void)
{
    return fmi3Version;
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    FMU_INSTANCE("fmi3SetDebugLogging")
    (void)nCategories;
    (void)categories;
    m->log_on = loggingOn ? 1 : 0;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateModelExchange: this FMU is for co-simulation only");
    }
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    void *log_fn = NULL;
    fmu_model *m;
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (instantiationToken == NULL || strcmp(instantiationToken, FMU_TOKEN) != 0) {
        if (logMessage != NULL) {
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "instantiationToken: not this FMU's (" FMU_TOKEN "): its modelDescription.xml does not "
                       "belong to this binary");
        }
        return NULL;
    }
    if (eventModeUsed) {
        if (logMessage != NULL) {
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "eventModeUsed: this FMU has no event mode (hasEventMode=\"false\")");
        }
        return NULL;
    }
    if (logMessage != NULL) {
        memcpy(&log_fn, &logMessage, sizeof log_fn);
    }
    m = fmu_new(instanceName, instanceEnvironment, log_fn, loggingOn ? 1 : 0);
    if (m == NULL && logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: out of memory or "
                   "configuration refused");
    }
    return (fmi3Instance)m;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU is for co-simulation only");
    }
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    FMU_INSTANCE("fmi3EnterInitializationMode")
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    return fmu_status(m, fmu_enter_initialization(m, startTime));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    FMU_INSTANCE("fmi3ExitInitializationMode")
    return fmu_status(m, fmu_exit_initialization(m));
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    FMU_NOT_PROVIDED("fmi3EnterEventMode")
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    FMU_INSTANCE("fmi3Terminate")
    m->phase = FMU_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    fmu_model *m = (fmu_model *)instance;
    if (m == NULL) {
        return fmi3Error;
    }
    return fmu_status(m, fmu_start(m));
}

/* Getters and setters: one value per value reference (every variable is a scalar). */
#define FMU_COUNT_CHECK(call)                                                              \
    if (nValues != nValueReferences) {                                                     \
        fmu_logf(m, FMU_RESULT_ERROR, "%s: nValues %lu for %lu scalar variables", call,      \
                 (unsigned long)nValues, (unsigned long)nValueReferences);                 \
        return fmi3Error;                                                                  \
    }                                                                                      \
    if (nValueReferences > 0 && (valueReferences == NULL || values == NULL)) {             \
        fmu_logf(m, FMU_RESULT_ERROR, "%s: valueReferences or values is NULL", call);      \
        return fmi3Error;                                                                  \
    }

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    size_t k;
    FMU_INSTANCE("fmi3GetFloat64")
    FMU_COUNT_CHECK("fmi3GetFloat64")
    for (k = 0; k < nValueReferences; ++k) {
        if (fmu_get_real(m, valueReferences[k], &values[k], 1) != FMU_RESULT_OK) {
            return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues)
{
    size_t k;
    FMU_INSTANCE("fmi3GetInt32")
    FMU_COUNT_CHECK("fmi3GetInt32")
    for (k = 0; k < nValueReferences; ++k) {
        int v = 0;
        if (fmu_get_int(m, valueReferences[k], &v) != FMU_RESULT_OK) {
            return fmi3Error;
        }
        values[k] = (fmi3Int32)v;
    }
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues)
{
    size_t k;
    FMU_INSTANCE("fmi3GetBoolean")
    FMU_COUNT_CHECK("fmi3GetBoolean")
    for (k = 0; k < nValueReferences; ++k) {
        int v = 0;
        if (fmu_get_bool(m, valueReferences[k], &v) != FMU_RESULT_OK) {
            return fmi3Error;
        }
        values[k] = v != 0;
    }
    return fmi3OK;
}

/* Inputs and parameters are set in every phase but after termination. */
#define FMU_SETTABLE(call)                                                                 \
    if (m->phase == FMU_TERMINATED) {                                                      \
        fmu_logf(m, FMU_RESULT_ERROR, "%s: the instance is terminated", call);             \
        return fmi3Error;                                                                  \
    }

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    size_t k;
    FMU_INSTANCE("fmi3SetFloat64")
    FMU_COUNT_CHECK("fmi3SetFloat64")
    FMU_SETTABLE("fmi3SetFloat64")
    for (k = 0; k < nValueReferences; ++k) {
        if (fmu_set_real(m, valueReferences[k], values[k]) != FMU_RESULT_OK) {
            return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues)
{
    size_t k;
    FMU_INSTANCE("fmi3SetInt32")
    FMU_COUNT_CHECK("fmi3SetInt32")
    FMU_SETTABLE("fmi3SetInt32")
    for (k = 0; k < nValueReferences; ++k) {
        if (fmu_set_int(m, valueReferences[k], (int)values[k]) != FMU_RESULT_OK) {
            return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[], size_t nValues)
{
    size_t k;
    FMU_INSTANCE("fmi3SetBoolean")
    FMU_COUNT_CHECK("fmi3SetBoolean")
    FMU_SETTABLE("fmi3SetBoolean")
    for (k = 0; k < nValueReferences; ++k) {
        if (fmu_set_bool(m, valueReferences[k], values[k] ? 1 : 0) != FMU_RESULT_OK) {
            return fmi3Error;
        }
    }
    return fmi3OK;
}

/* The types this FMU has no variables of. */
#define FMU_NO_VARIABLES(name, type, constness)                                            \
    fmi3Status name(fmi3Instance instance, const fmi3ValueReference valueReferences[],      \
                    size_t nValueReferences, constness type values[], size_t nValues)      \
    {                                                                                      \
        (void)valueReferences; (void)values; (void)nValues;                                \
        if (nValueReferences == 0) {                                                       \
            return fmi3OK;                                                                 \
        }                                                                                  \
        FMU_NOT_PROVIDED(#name " (the FMU has no variables of this type)")                 \
    }

FMU_NO_VARIABLES(fmi3GetFloat32, fmi3Float32, )
FMU_NO_VARIABLES(fmi3GetInt8, fmi3Int8, )
FMU_NO_VARIABLES(fmi3GetUInt8, fmi3UInt8, )
FMU_NO_VARIABLES(fmi3GetInt16, fmi3Int16, )
FMU_NO_VARIABLES(fmi3GetUInt16, fmi3UInt16, )
FMU_NO_VARIABLES(fmi3GetUInt32, fmi3UInt32, )
FMU_NO_VARIABLES(fmi3GetInt64, fmi3Int64, )
FMU_NO_VARIABLES(fmi3GetUInt64, fmi3UInt64, )
FMU_NO_VARIABLES(fmi3GetString, fmi3String, )
FMU_NO_VARIABLES(fmi3SetFloat32, fmi3Float32, const)
FMU_NO_VARIABLES(fmi3SetInt8, fmi3Int8, const)
FMU_NO_VARIABLES(fmi3SetUInt8, fmi3UInt8, const)
FMU_NO_VARIABLES(fmi3SetInt16, fmi3Int16, const)
FMU_NO_VARIABLES(fmi3SetUInt16, fmi3UInt16, const)
FMU_NO_VARIABLES(fmi3SetUInt32, fmi3UInt32, const)
FMU_NO_VARIABLES(fmi3SetInt64, fmi3Int64, const)
FMU_NO_VARIABLES(fmi3SetUInt64, fmi3UInt64, const)
FMU_NO_VARIABLES(fmi3SetString, fmi3String, const)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueReferences; (void)nValueReferences; (void)valueSizes; (void)values; (void)nValues;
    FMU_NOT_PROVIDED("fmi3GetBinary (the FMU has no Binary variables)")
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)valueReferences; (void)nValueReferences; (void)valueSizes; (void)values; (void)nValues;
    FMU_NOT_PROVIDED("fmi3SetBinary (the FMU has no Binary variables)")
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[])
{
    (void)valueReferences; (void)nValueReferences; (void)values;
    FMU_NOT_PROVIDED("fmi3GetClock")
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[])
{
    (void)valueReferences; (void)nValueReferences; (void)values;
    FMU_NOT_PROVIDED("fmi3SetClock")
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference; (void)nDependencies;
    FMU_NOT_PROVIDED("fmi3GetNumberOfVariableDependencies")
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    FMU_NOT_PROVIDED("fmi3GetVariableDependencies")
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    (void)FMUState;
    FMU_NOT_PROVIDED("fmi3GetFMUState (canGetAndSetFMUState=\"false\")")
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    (void)FMUState;
    FMU_NOT_PROVIDED("fmi3SetFMUState (canGetAndSetFMUState=\"false\")")
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    (void)FMUState;
    FMU_NOT_PROVIDED("fmi3FreeFMUState (canGetAndSetFMUState=\"false\")")
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    (void)FMUState; (void)size;
    FMU_NOT_PROVIDED("fmi3SerializedFMUStateSize")
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    (void)FMUState; (void)serializedState; (void)size;
    FMU_NOT_PROVIDED("fmi3SerializeFMUState")
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    (void)serializedState; (void)size; (void)FMUState;
    FMU_NOT_PROVIDED("fmi3DeserializeFMUState")
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                        size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    FMU_NOT_PROVIDED("fmi3GetDirectionalDerivative")
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    FMU_NOT_PROVIDED("fmi3GetAdjointDerivative")
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    FMU_NOT_PROVIDED("fmi3EnterConfigurationMode (the FMU has no structural parameters)")
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    FMU_NOT_PROVIDED("fmi3ExitConfigurationMode (the FMU has no structural parameters)")
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers;
    FMU_NOT_PROVIDED("fmi3GetIntervalDecimal")
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions; (void)qualifiers;
    FMU_NOT_PROVIDED("fmi3GetIntervalFraction")
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    FMU_NOT_PROVIDED("fmi3GetShiftDecimal")
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    FMU_NOT_PROVIDED("fmi3GetShiftFraction")
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals;
    FMU_NOT_PROVIDED("fmi3SetIntervalDecimal")
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    FMU_NOT_PROVIDED("fmi3SetIntervalFraction")
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    FMU_NOT_PROVIDED("fmi3SetShiftDecimal")
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    FMU_NOT_PROVIDED("fmi3SetShiftFraction")
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    FMU_NOT_PROVIDED("fmi3EvaluateDiscreteStates")
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    (void)discreteStatesNeedUpdate; (void)terminateSimulation; (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged; (void)nextEventTimeDefined; (void)nextEventTime;
    FMU_NOT_PROVIDED("fmi3UpdateDiscreteStates (the FMU has no event mode)")
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    FMU_NOT_PROVIDED("fmi3EnterContinuousTimeMode")
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    FMU_NOT_PROVIDED("fmi3CompletedIntegratorStep")
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    (void)time;
    FMU_NOT_PROVIDED("fmi3SetTime")
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates; (void)nContinuousStates;
    FMU_NOT_PROVIDED("fmi3SetContinuousStates")
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    (void)derivatives; (void)nContinuousStates;
    FMU_NOT_PROVIDED("fmi3GetContinuousStateDerivatives")
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    (void)eventIndicators; (void)nEventIndicators;
    FMU_NOT_PROVIDED("fmi3GetEventIndicators")
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    (void)continuousStates; (void)nContinuousStates;
    FMU_NOT_PROVIDED("fmi3GetContinuousStates")
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates)
{
    (void)nominals; (void)nContinuousStates;
    FMU_NOT_PROVIDED("fmi3GetNominalsOfContinuousStates")
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    (void)nEventIndicators;
    FMU_NOT_PROVIDED("fmi3GetNumberOfEventIndicators")
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    (void)nContinuousStates;
    FMU_NOT_PROVIDED("fmi3GetNumberOfContinuousStates")
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    FMU_NOT_PROVIDED("fmi3EnterStepMode (the FMU has no event mode)")
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    FMU_NOT_PROVIDED("fmi3GetOutputDerivatives (maxOutputDerivativeOrder=\"0\")")
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    fmu_result r;
    FMU_INSTANCE("fmi3DoStep")
    (void)noSetFMUStatePriorToCurrentPoint;
    r = fmu_do_step(m, currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded != NULL) {
        *eventHandlingNeeded = fmi3False;
    }
    if (terminateSimulation != NULL) {
        *terminateSimulation = fmi3False;
    }
    if (earlyReturn != NULL) {
        *earlyReturn = fmi3False;
    }
    if (lastSuccessfulTime != NULL) {
        *lastSuccessfulTime = m->time;
    }
    return fmu_status(m, r);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    FMU_NOT_PROVIDED("fmi3ActivateModelPartition")
}
