/*
 * FMI 3.0 co-simulation API of the native CassiePlant FMU: a thin layer over the
 * version-independent instance (cp_instance.c), the same source as the FMI 2.0 layer
 * (fmi2_plant.c).  Co-simulation without event mode or intermediate update; the variables
 * are Float64, Int32, Boolean and String scalars, plus the independent variable time
 * (valueReference CP_N_VARS); the functions of other types or interfaces are refused.
 */
#include "cp_instance.h" /* first: the floating-point contract */

#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define TIME_VR ((fmi3ValueReference)CP_N_VARS)

static const char *const PHASE_NAMES[] = {"Instantiated", "InitializationMode", "StepMode", "Terminated"};

typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Callbacks;

#define BEGIN(fn, mask)                                                          \
    static const char *const call = #fn;                                         \
    CpInstance *inst = (CpInstance *)instance;                                   \
    if (inst == NULL) return fmi3Error;                                          \
    if (cp_allowed(inst, call, (mask)) != CP_OK) return fmi3Error
#define REFUSE(...) return (fmi3Status)cp_refuse(inst, call, __VA_ARGS__)

#if defined(__GNUC__)
#define UNUSED_BEGIN _Pragma("GCC diagnostic push") _Pragma("GCC diagnostic ignored \"-Wunused-parameter\"")
#define UNUSED_END _Pragma("GCC diagnostic pop")
#else
#define UNUSED_BEGIN
#define UNUSED_END
#endif
/* Refused in every phase, the reason logged. */
#define NOT_PROVIDED(fn, ...)                                                    \
    UNUSED_BEGIN                                                                 \
    fmi3Status fn(fmi3Instance instance, __VA_ARGS__) {                          \
        CpInstance *inst = (CpInstance *)instance;                               \
        if (inst == NULL) return fmi3Error;                                      \
        return (fmi3Status)cp_refuse(inst, #fn, "not provided by this FMU (co-simulation without event mode)"); \
    }                                                                            \
    UNUSED_END
#define NOT_PROVIDED0(fn)                                                        \
    fmi3Status fn(fmi3Instance instance) {                                       \
        CpInstance *inst = (CpInstance *)instance;                               \
        if (inst == NULL) return fmi3Error;                                      \
        return (fmi3Status)cp_refuse(inst, #fn, "not provided by this FMU (co-simulation without event mode)"); \
    }

typedef char fmi3Boolean_is_one_byte[sizeof(fmi3Boolean) == 1 ? 1 : -1];

static void log_fmi3(const CpInstance *inst, CpStatus status, const char *category, const char *message) {
    const Callbacks *cb = (const Callbacks *)inst->env;
    if (cb != NULL && cb->log != NULL) cb->log(cb->env, (fmi3Status)status, category, message);
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)visible, (void)earlyReturnAllowed, (void)requiredIntermediateVariables, (void)intermediateUpdate;
    Callbacks *cb = malloc(sizeof *cb);
    if (cb == NULL) return NULL;
    cb->env = instanceEnvironment;
    cb->log = logMessage;
    CpInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = log_fmi3,
                        .phase_names = PHASE_NAMES};
    CpInstance *inst = NULL;
    char *resources = NULL;
    if (resourcePath != NULL) { /* a path ending in a separator: without it */
        size_t n = strlen(resourcePath);
        resources = malloc(n + 1);
        if (resources) {
            strcpy(resources, resourcePath);
            while (n > 1 && (resources[n - 1] == '/' || resources[n - 1] == '\\')) resources[--n] = 0;
        }
    }
    if (eventModeUsed)
        cp_refuse(&probe, "fmi3InstantiateCoSimulation", "eventModeUsed: this FMU has no event mode");
    else if (nRequiredIntermediateVariables > 0)
        cp_refuse(&probe, "fmi3InstantiateCoSimulation", "this FMU provides no intermediate variables");
    else
        inst = cp_instantiate(instanceName, instantiationToken, resources, cb, log_fmi3, loggingOn, PHASE_NAMES);
    free(resources);
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
    CpInstance *inst = (CpInstance *)instance;
    if (inst == NULL) return;
    void *cb = inst->env;
    cp_free_instance(inst);
    free(cb);
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    BEGIN(fmi3SetDebugLogging, CP_ANY_PHASE);
    if (cp_check_categories(inst, call, nCategories, categories) != CP_OK) return fmi3Error;
    inst->logging_on = loggingOn;
    return fmi3OK;
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    BEGIN(fmi3EnterInitializationMode, CP_INSTANTIATED);
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    if (cp_setup(inst, call, startTime) != CP_OK) return fmi3Error;
    inst->phase = CP_INIT_MODE;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    BEGIN(fmi3ExitInitializationMode, CP_INIT_MODE);
    return (fmi3Status)cp_exit_init(inst, call);
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    BEGIN(fmi3Terminate, CP_STEP_MODE);
    inst->phase = CP_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    BEGIN(fmi3Reset, CP_ANY_PHASE);
    cp_reset(inst);
    return fmi3OK;
}

/* ---- variables --------------------------------------------------------------------------------- */
static fmi3Status check_counts(CpInstance *inst, const char *call, const fmi3ValueReference vr[], size_t nvr,
                               const void *values, size_t nValues) {
    if (nvr > 0 && (vr == NULL || values == NULL)) REFUSE("NULL valueReferences or values with %zu references", nvr);
    if (nValues != nvr) REFUSE("nValues = %zu, but %zu scalar variables were given", nValues, nvr);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    BEGIN(fmi3GetFloat64, CP_GET_PHASES);
    if (check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != fmi3OK) return fmi3Error;
    for (size_t i = 0; i < nValueReferences; ++i)
        if (valueReferences[i] != TIME_VR && cp_check_get(inst, call, &valueReferences[i], 1, CP_REAL) != CP_OK)
            return fmi3Error;
    for (size_t i = 0; i < nValueReferences; ++i)
        values[i] = valueReferences[i] == TIME_VR ? inst->time : inst->values[valueReferences[i]];
    return fmi3OK;
}

#define GETTER(fn, ctype, type, FROM_DOUBLE)                                                                   \
    fmi3Status fn(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                  ctype values[], size_t nValues) {                                                           \
        BEGIN(fn, CP_GET_PHASES);                                                                             \
        if (check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != fmi3OK ||        \
            cp_check_get(inst, call, valueReferences, nValueReferences, type) != CP_OK)                       \
            return fmi3Error;                                                                                 \
        for (size_t i = 0; i < nValueReferences; ++i) values[i] = FROM_DOUBLE(inst->values[valueReferences[i]]); \
        return fmi3OK;                                                                                        \
    }
#define SETTER(fn, ctype, type, READ)                                                                           \
    fmi3Status fn(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,   \
                  const ctype values[], size_t nValues) {                                                       \
        BEGIN(fn, CP_SET_PHASES);                                                                               \
        if (check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != fmi3OK) return fmi3Error; \
        for (size_t i = 0; i < nValueReferences; ++i) {                                                         \
            if (valueReferences[i] == TIME_VR) REFUSE("time is the independent variable and cannot be set");   \
            if (cp_check_set(inst, call, valueReferences[i], type, READ(values, i)) != CP_OK) return fmi3Error; \
        }                                                                                                       \
        for (size_t i = 0; i < nValueReferences; ++i) inst->values[valueReferences[i]] = READ(values, i);      \
        return fmi3OK;                                                                                          \
    }
#define AS_INT32(x) ((fmi3Int32)(x))
#define AS_BOOLEAN(x) ((x) != 0.0)
#define AS_MODEL(x) (CP_MODEL_NAMES[(int)(x)])
#define READ_NUMBER(values, i) ((double)(values)[i])
#define READ_BYTE(values, i) ((double)((const unsigned char *)(values))[i])
GETTER(fmi3GetInt32, fmi3Int32, CP_INTEGER, AS_INT32)
GETTER(fmi3GetBoolean, fmi3Boolean, CP_BOOLEAN, AS_BOOLEAN)
GETTER(fmi3GetString, fmi3String, CP_STRING, AS_MODEL)
SETTER(fmi3SetFloat64, fmi3Float64, CP_REAL, READ_NUMBER)
SETTER(fmi3SetInt32, fmi3Int32, CP_INTEGER, READ_NUMBER)
SETTER(fmi3SetBoolean, fmi3Boolean, CP_BOOLEAN, READ_BYTE)

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const fmi3String values[], size_t nValues) {
    BEGIN(fmi3SetString, CP_SET_PHASES);
    if (check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != fmi3OK) return fmi3Error;
    if (nValueReferences > CP_N_VARS) REFUSE("%zu values: more than the variables", nValueReferences);
    double index[CP_N_VARS];
    for (size_t i = 0; i < nValueReferences; ++i) {
        if (valueReferences[i] == TIME_VR) REFUSE("time is the independent variable and cannot be set");
        if (cp_check_set(inst, call, valueReferences[i], CP_STRING, 0.0) != CP_OK ||
            cp_model_index(inst, call, values[i], &index[i]) != CP_OK)
            return fmi3Error;
    }
    for (size_t i = 0; i < nValueReferences; ++i) inst->values[valueReferences[i]] = index[i];
    return fmi3OK;
}

/* ---- FMU state ----------------------------------------------------------------------------------- */
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *state) {
    BEGIN(fmi3GetFMUState, CP_ANY_PHASE);
    return (fmi3Status)cp_fmustate_get(inst, call, (void **)state);
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state) {
    BEGIN(fmi3SetFMUState, CP_ANY_PHASE);
    return (fmi3Status)cp_fmustate_set(inst, call, state);
}
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *state) {
    BEGIN(fmi3FreeFMUState, CP_ANY_PHASE);
    cp_fmustate_free((void **)state);
    return fmi3OK;
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state, size_t *size) {
    BEGIN(fmi3SerializedFMUStateSize, CP_ANY_PHASE);
    return (fmi3Status)cp_fmustate_size(inst, call, state, size);
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state, fmi3Byte bytes[], size_t size) {
    BEGIN(fmi3SerializeFMUState, CP_ANY_PHASE);
    return (fmi3Status)cp_fmustate_serialize(inst, call, state, bytes, size);
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte bytes[], size_t size, fmi3FMUState *state) {
    BEGIN(fmi3DeserializeFMUState, CP_ANY_PHASE);
    return (fmi3Status)cp_fmustate_deserialize(inst, call, bytes, size, (void **)state);
}

/* ---- stepping ------------------------------------------------------------------------------------ */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    BEGIN(fmi3DoStep, CP_STEP_MODE);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (eventHandlingNeeded == NULL || terminateSimulation == NULL || earlyReturn == NULL || lastSuccessfulTime == NULL)
        REFUSE("NULL output argument");
    if (cp_do_step(inst, call, currentCommunicationPoint, communicationStepSize) != CP_OK) return fmi3Error;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = inst->time;
    return fmi3OK;
}

/* ---- types this FMU has no variables of, and other interfaces: refused ------------------------------ */
#define NO_VARIABLES(fn, mask, ctype, type_name)                                                               \
    fmi3Status fn(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,  \
                  ctype values[], size_t nValues) {                                                            \
        BEGIN(fn, mask);                                                                                       \
        (void)valueReferences, (void)values, (void)nValues;                                                    \
        if (nValueReferences == 0) return fmi3OK;                                                              \
        REFUSE("this FMU has no %s variables", type_name);                                                     \
    }
#define NO_GET_SET(T)                                                             \
    NO_VARIABLES(fmi3Get##T, CP_GET_PHASES, fmi3##T, #T)                          \
    NO_VARIABLES(fmi3Set##T, CP_SET_PHASES, const fmi3##T, #T)
NO_GET_SET(Float32)
NO_GET_SET(Int8)
NO_GET_SET(UInt8)
NO_GET_SET(Int16)
NO_GET_SET(UInt16)
NO_GET_SET(UInt32)
NO_GET_SET(Int64)
NO_GET_SET(UInt64)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    BEGIN(fmi3GetBinary, CP_GET_PHASES);
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    if (nValueReferences == 0) return fmi3OK;
    REFUSE("this FMU has no Binary variables");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    BEGIN(fmi3SetBinary, CP_SET_PHASES);
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    if (nValueReferences == 0) return fmi3OK;
    REFUSE("this FMU has no Binary variables");
}

NOT_PROVIDED0(fmi3EnterEventMode)
NOT_PROVIDED0(fmi3EnterConfigurationMode)
NOT_PROVIDED0(fmi3ExitConfigurationMode)
NOT_PROVIDED0(fmi3EvaluateDiscreteStates)
NOT_PROVIDED0(fmi3EnterContinuousTimeMode)
NOT_PROVIDED0(fmi3EnterStepMode)
NOT_PROVIDED(fmi3GetClock, const fmi3ValueReference vr[], size_t n, fmi3Clock values[])
NOT_PROVIDED(fmi3SetClock, const fmi3ValueReference vr[], size_t n, const fmi3Clock values[])
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
