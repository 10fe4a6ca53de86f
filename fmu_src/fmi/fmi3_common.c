/*
 * What the FMI 3.0 layer of every native FMU of this project has the same: the version, the
 * host's callbacks and the logger over them, the co-simulation options none supports, doStep
 * over the model's instance (fmi_model.h), and the
 * functions none provides (variable types neither model has variables of, event mode, clocks,
 * configuration mode, Model Exchange, Scheduled Execution, derivatives).  Each of those exists
 * so that every host resolves every symbol; each refuses with fmi3Error and a log message,
 * through the same prologue as the model's layer.
 */
#include "fmi_model.h" /* first: the model's own headers may set feature macros */

#include <stdlib.h>

#include "fmi3Functions.h"

#define FMI_STATUS fmi3Status
#define FMI_INSTANCE fmi3Instance
#include "fmi_layer.h"

const char *fmi3GetVersion(void) { return fmi3Version; }

FmiCallbacks3 *fmi3_callbacks(fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    FmiCallbacks3 *cb = malloc(sizeof *cb);
    if (cb != NULL) *cb = (FmiCallbacks3){.env = env, .log = log};
    return cb;
}

void fmi3_log(const FmiModelInstance *inst, FmiModelStatus status, const char *category, const char *message) {
    const FmiCallbacks3 *cb = (const FmiCallbacks3 *)inst->env;
    if (cb != NULL && cb->log != NULL) cb->log(cb->env, (fmi3Status)status, category, message);
}

const char *fmi3_cosim_problem(fmi3Boolean eventModeUsed, size_t nRequiredIntermediateVariables) {
    if (eventModeUsed) return "eventModeUsed: this FMU has no event mode";
    if (nRequiredIntermediateVariables > 0) return "this FMU provides no intermediate variables";
    return NULL;
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

fmi3Status fmi3_check_counts(FmiModelInstance *inst, const char *call, const fmi3ValueReference vr[], size_t nvr,
                             const void *values, size_t nValues) {
    if (nvr > 0 && (vr == NULL || values == NULL)) REFUSE("NULL valueReferences or values with %zu references", nvr);
    if (nValues != nvr) REFUSE("nValues = %zu, but %zu scalar variables were given", nValues, nvr);
    return fmi3OK;
}

/* ---- stepping (the model steps: fmi_model_do_step) --------------------------------------------- */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    BEGIN(fmi3DoStep)
    (void)noSetFMUStatePriorToCurrentPoint;
    if (eventHandlingNeeded == NULL || terminateSimulation == NULL || earlyReturn == NULL || lastSuccessfulTime == NULL)
        REFUSE("NULL output argument");
    if (fmi_model_do_step(inst, call, currentCommunicationPoint, communicationStepSize) != 0) return fmi3Error;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = inst->time;
    return fmi3OK;
}

/* Getters and setters of types without variables (NO_GET_SET, fmi_layer.h). */
NO_GET_SET(Float32)
NO_GET_SET(Int8)
NO_GET_SET(UInt8)
NO_GET_SET(Int16)
NO_GET_SET(UInt16)
NO_GET_SET(UInt32)
NO_GET_SET(Int64)
NO_GET_SET(UInt64)
#ifndef FMI_MODEL_HAS_STRINGS /* fmi_model.h: the model's layer gets and sets its String variables */
NO_GET_SET(String)
#endif

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    BEGIN(fmi3GetBinary)
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    if (nValueReferences == 0) return fmi3OK;
    REFUSE("this FMU has no Binary variables");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    BEGIN(fmi3SetBinary)
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    if (nValueReferences == 0) return fmi3OK;
    REFUSE("this FMU has no Binary variables");
}

/* Not provided at all: refused in every phase (NOT_PROVIDED, fmi_layer.h). */
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
