/*
 * FMI 3.0 co-simulation API of CommandSource over the version-independent instance
 * (cmdsrc.c), the same as the FMI 2.0 layer (cmdsrc_fmi2.c) behind FMI 3.0's names and
 * types.  Six Float64 outputs (value references 0..5, as in FMI 2.0) and the independent
 * variable `time` (value reference 6).  Each function first checks its allowed phases
 * (FMI 3.0 section 4.3, co-simulation without event mode); a refused call logs why,
 * returns fmi3Error and changes nothing.  No event mode, no intermediate update, no
 * clocks, no FMU state, no derivatives, no Model Exchange or Scheduled Execution: those
 * functions exist (every host resolves every symbol) and refuse in every phase.
 */
#include "cmdsrc.h"

#include <stdlib.h>

#include "fmi3Functions.h"

#define TIME_VR ((fmi3ValueReference)CS_N_OUTPUTS)
#define GET_PHASES (CS_INIT_MODE | CS_STEP_MODE | CS_TERMINATED)
#define SET_PHASES (CS_INSTANTIATED | CS_INIT_MODE | CS_STEP_MODE)

#define BEGIN(fn, mask)                                                 \
    CsInstance *inst = (CsInstance *)instance;                          \
    static const char call[] = #fn;                                     \
    if (cs_allowed(inst, call, (mask)) != CS_OK) return fmi3Error;

static const char *const PHASE_NAMES[] = {"Instantiated", "InitializationMode", "StepMode", "Terminated"};

typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Callbacks;

static void log_fmi3(const CsInstance *inst, CsStatus status, const char *category, const char *message) {
    const Callbacks *cb = (const Callbacks *)inst->env;
    if (cb != NULL && cb->log != NULL) cb->log(cb->env, (fmi3Status)status, category, message);
}

/* ---- inquiry, creation, life cycle ------------------------------------------------------------ */
const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)visible, (void)earlyReturnAllowed, (void)requiredIntermediateVariables;
    (void)intermediateUpdate; /* never called: no intermediate update */
    Callbacks *cb = malloc(sizeof *cb);
    if (cb == NULL) return NULL;
    cb->env = instanceEnvironment;
    cb->log = logMessage;
    CsInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = log_fmi3};
    CsInstance *inst = NULL;
    static const char call[] = "fmi3InstantiateCoSimulation";
    if (eventModeUsed)
        cs_refuse(&probe, call, "eventModeUsed: this FMU has no event mode");
    else if (nRequiredIntermediateVariables > 0)
        cs_refuse(&probe, call, "this FMU provides no intermediate variables");
    else if (resourcePath == NULL || resourcePath[0] == '\0')
        cs_refuse(&probe, call, "no resourcePath: the schedule is read from resources/%s", CS_SCHEDULE_FILE);
    else /* FMI 3.0: resourcePath is a native path (with a trailing separator), not a URI */
        inst = cs_instantiate(instanceName, instantiationToken, resourcePath, cb, log_fmi3, loggingOn != fmi3False,
                              PHASE_NAMES);
    if (inst == NULL) free(cb);
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    if (logMessage != NULL)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError", "this FMU supports co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    return fmi3InstantiateModelExchange(instanceName, instantiationToken, resourcePath, visible, loggingOn,
                                        instanceEnvironment, logMessage);
}

void fmi3FreeInstance(fmi3Instance instance) {
    CsInstance *inst = (CsInstance *)instance;
    if (inst == NULL) return;
    void *cb = inst->env;
    cs_free(inst);
    free(cb);
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    BEGIN(fmi3SetDebugLogging, CS_ANY_PHASE)
    if (nCategories > 0 && categories == NULL)
        return (fmi3Status)cs_refuse(inst, call, "categories is NULL with nCategories = %zu", nCategories);
    inst->logging_on = loggingOn != fmi3False;
    return fmi3OK;
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    BEGIN(fmi3EnterInitializationMode, CS_INSTANTIATED)
    (void)toleranceDefined, (void)tolerance;
    if (cs_setup(inst, call, startTime, stopTimeDefined != fmi3False, stopTime) != CS_OK) return fmi3Error;
    return (fmi3Status)cs_enter_init(inst, call);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    BEGIN(fmi3ExitInitializationMode, CS_INIT_MODE)
    inst->phase = CS_STEP_MODE;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    BEGIN(fmi3Terminate, CS_STEP_MODE)
    inst->phase = CS_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    BEGIN(fmi3Reset, CS_ANY_PHASE)
    cs_reset(inst);
    return fmi3OK;
}

/* ---- variables ---------------------------------------------------------------------------------- */
fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues) {
    BEGIN(fmi3GetFloat64, GET_PHASES)
    if (nValueReferences > 0 && (valueReferences == NULL || values == NULL))
        return (fmi3Status)cs_refuse(inst, call, "NULL valueReferences or values with %zu references", nValueReferences);
    if (nValues != nValueReferences)
        return (fmi3Status)cs_refuse(inst, call, "nValues = %zu, but %zu scalar variables were given", nValues,
                                     nValueReferences);
    for (size_t i = 0; i < nValueReferences; ++i)
        if (valueReferences[i] != TIME_VR && cs_check_get(inst, call, &valueReferences[i], 1) != CS_OK)
            return fmi3Error;
    for (size_t i = 0; i < nValueReferences; ++i)
        values[i] = valueReferences[i] == TIME_VR ? inst->time : cs_output(inst, valueReferences[i]);
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues) {
    BEGIN(fmi3SetFloat64, SET_PHASES)
    (void)valueReferences, (void)values, (void)nValues;
    if (nValueReferences == 0) return fmi3OK;
    return (fmi3Status)cs_refuse(inst, call, "this FMU has no inputs or parameters (its outputs come from "
                                 "resources/%s; time is the independent variable)", CS_SCHEDULE_FILE);
}

/* Types without variables: nothing to get or set is fine, anything else refused. */
#define NO_VARIABLES(fn, mask, ctype, type_name)                                                               \
    fmi3Status fn(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,  \
                  ctype values[], size_t nValues) {                                                            \
        BEGIN(fn, mask)                                                                                        \
        (void)valueReferences, (void)values, (void)nValues;                                                    \
        if (nValueReferences == 0) return fmi3OK;                                                              \
        return (fmi3Status)cs_refuse(inst, call, "this FMU has no %s variables", type_name);                  \
    }
#define NO_GET_SET(T)                                                 \
    NO_VARIABLES(fmi3Get##T, GET_PHASES, fmi3##T, #T)                 \
    NO_VARIABLES(fmi3Set##T, SET_PHASES, const fmi3##T, #T)
NO_GET_SET(Float32)
NO_GET_SET(Int8)
NO_GET_SET(UInt8)
NO_GET_SET(Int16)
NO_GET_SET(UInt16)
NO_GET_SET(Int32)
NO_GET_SET(UInt32)
NO_GET_SET(Int64)
NO_GET_SET(UInt64)
NO_GET_SET(Boolean)
NO_GET_SET(String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    BEGIN(fmi3GetBinary, GET_PHASES)
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    return nValueReferences == 0 ? fmi3OK : (fmi3Status)cs_refuse(inst, call, "this FMU has no Binary variables");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    BEGIN(fmi3SetBinary, SET_PHASES)
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    return nValueReferences == 0 ? fmi3OK : (fmi3Status)cs_refuse(inst, call, "this FMU has no Binary variables");
}

/* ---- stepping ------------------------------------------------------------------------------------ */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    BEGIN(fmi3DoStep, CS_STEP_MODE)
    (void)noSetFMUStatePriorToCurrentPoint;
    if (eventHandlingNeeded == NULL || terminateSimulation == NULL || earlyReturn == NULL || lastSuccessfulTime == NULL)
        return (fmi3Status)cs_refuse(inst, call, "NULL output argument");
    if (cs_do_step(inst, call, currentCommunicationPoint, communicationStepSize) != CS_OK) return fmi3Error;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = inst->time;
    return fmi3OK;
}

/* ---- not provided (see the model description): refused in every phase ------------------------- */
#define NOT_PROVIDED(fn, ...)                                  \
    fmi3Status fn(fmi3Instance instance, __VA_ARGS__) {        \
        BEGIN(fn, 0u)                                          \
        return fmi3Error;                                      \
    }
#define NOT_PROVIDED0(fn)                                      \
    fmi3Status fn(fmi3Instance instance) {                     \
        BEGIN(fn, 0u)                                          \
        return fmi3Error;                                      \
    }
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-parameter"
#endif
NOT_PROVIDED0(fmi3EnterEventMode)
NOT_PROVIDED0(fmi3EnterConfigurationMode)
NOT_PROVIDED0(fmi3ExitConfigurationMode)
NOT_PROVIDED0(fmi3EvaluateDiscreteStates)
NOT_PROVIDED0(fmi3EnterContinuousTimeMode)
NOT_PROVIDED0(fmi3EnterStepMode)
NOT_PROVIDED(fmi3GetClock, const fmi3ValueReference vr[], size_t n, fmi3Clock values[])
NOT_PROVIDED(fmi3SetClock, const fmi3ValueReference vr[], size_t n, const fmi3Clock values[])
NOT_PROVIDED(fmi3GetFMUState, fmi3FMUState *state)
NOT_PROVIDED(fmi3SetFMUState, fmi3FMUState state)
NOT_PROVIDED(fmi3FreeFMUState, fmi3FMUState *state)
NOT_PROVIDED(fmi3SerializedFMUStateSize, fmi3FMUState state, size_t *size)
NOT_PROVIDED(fmi3SerializeFMUState, fmi3FMUState state, fmi3Byte serializedState[], size_t size)
NOT_PROVIDED(fmi3DeserializeFMUState, const fmi3Byte serializedState[], size_t size, fmi3FMUState *state)
NOT_PROVIDED(fmi3GetNumberOfVariableDependencies, fmi3ValueReference vr, size_t *n)
NOT_PROVIDED(fmi3GetVariableDependencies, fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
             fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
             fmi3DependencyKind dependencyKinds[], size_t nDependencies)
NOT_PROVIDED(fmi3GetDirectionalDerivative, const fmi3ValueReference unknowns[], size_t nUnknowns,
             const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
             fmi3Float64 sensitivity[], size_t nSensitivity)
NOT_PROVIDED(fmi3GetAdjointDerivative, const fmi3ValueReference unknowns[], size_t nUnknowns,
             const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
             fmi3Float64 sensitivity[], size_t nSensitivity)
NOT_PROVIDED(fmi3GetIntervalDecimal, const fmi3ValueReference vr[], size_t n, fmi3Float64 intervals[],
             fmi3IntervalQualifier qualifiers[])
NOT_PROVIDED(fmi3GetIntervalFraction, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
             fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
NOT_PROVIDED(fmi3GetShiftDecimal, const fmi3ValueReference vr[], size_t n, fmi3Float64 shifts[])
NOT_PROVIDED(fmi3GetShiftFraction, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
             fmi3UInt64 resolutions[])
NOT_PROVIDED(fmi3SetIntervalDecimal, const fmi3ValueReference vr[], size_t n, const fmi3Float64 intervals[])
NOT_PROVIDED(fmi3SetIntervalFraction, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
             const fmi3UInt64 resolutions[])
NOT_PROVIDED(fmi3SetShiftDecimal, const fmi3ValueReference vr[], size_t n, const fmi3Float64 shifts[])
NOT_PROVIDED(fmi3SetShiftFraction, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
             const fmi3UInt64 resolutions[])
NOT_PROVIDED(fmi3UpdateDiscreteStates, fmi3Boolean *discreteStatesNeedUpdate, fmi3Boolean *terminateSimulation,
             fmi3Boolean *nominalsOfContinuousStatesChanged, fmi3Boolean *valuesOfContinuousStatesChanged,
             fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
NOT_PROVIDED(fmi3CompletedIntegratorStep, fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *enterEventMode,
             fmi3Boolean *terminateSimulation)
NOT_PROVIDED(fmi3SetTime, fmi3Float64 time)
NOT_PROVIDED(fmi3SetContinuousStates, const fmi3Float64 continuousStates[], size_t nContinuousStates)
NOT_PROVIDED(fmi3GetContinuousStateDerivatives, fmi3Float64 derivatives[], size_t nContinuousStates)
NOT_PROVIDED(fmi3GetEventIndicators, fmi3Float64 eventIndicators[], size_t nEventIndicators)
NOT_PROVIDED(fmi3GetContinuousStates, fmi3Float64 continuousStates[], size_t nContinuousStates)
NOT_PROVIDED(fmi3GetNominalsOfContinuousStates, fmi3Float64 nominals[], size_t nContinuousStates)
NOT_PROVIDED(fmi3GetNumberOfEventIndicators, size_t *nEventIndicators)
NOT_PROVIDED(fmi3GetNumberOfContinuousStates, size_t *nContinuousStates)
NOT_PROVIDED(fmi3GetOutputDerivatives, const fmi3ValueReference vr[], size_t n, const fmi3Int32 orders[],
             fmi3Float64 values[], size_t nValues)
NOT_PROVIDED(fmi3ActivateModelPartition, fmi3ValueReference clockReference, fmi3Float64 activationTime)
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
