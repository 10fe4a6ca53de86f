/*
 * FMI 3.0 co-simulation API of CommandSource over the version-independent instance
 * (cmdsrc.c), the same as the FMI 2.0 layer (cmdsrc_fmi2.c) behind FMI 3.0's names and
 * types.  Six Float64 outputs (value references 0..5, as in FMI 2.0) and the independent
 * variable `time` (value reference 6).  Each function begins with the shared prologue BEGIN
 * (fmu_src/fmi/fmi_layer.h), which checks its allowed phases (FMI_MASK_<function>, generated from
 * fmu_src/fmi/phase_rules.py: FMI 3.0 section 4.3, co-simulation without event mode); a refused
 * call logs why, returns fmi3Error and changes nothing.  No event mode, no intermediate update, no
 * clocks, no FMU state, no derivatives, no Model Exchange or Scheduled Execution: those
 * functions exist (every host resolves every symbol) and refuse in every phase.
 */
#include "cmdsrc.h"

#include <stdlib.h>

#include "fmi3Functions.h"

#define FMI_STATUS fmi3Status
#define FMI_INSTANCE fmi3Instance
#include "fmi_layer.h"

#define TIME_VR ((fmi3ValueReference)CS_N_OUTPUTS)

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
    FmiCallbacks3 *cb = fmi3_callbacks(instanceEnvironment, logMessage);
    if (cb == NULL) return NULL;
    CsInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = fmi3_log};
    CsInstance *inst = NULL;
    static const char call[] = "fmi3InstantiateCoSimulation";
    const char *problem = fmi3_cosim_problem(eventModeUsed, nRequiredIntermediateVariables);
    if (problem != NULL)
        cs_refuse(&probe, call, "%s", problem);
    else if (resourcePath == NULL || resourcePath[0] == '\0')
        cs_refuse(&probe, call, "no resourcePath: the schedule is read from resources/%s", CS_SCHEDULE_FILE);
    else /* FMI 3.0: resourcePath is a native path (with a trailing separator), not a URI */
        inst = cs_instantiate(instanceName, instantiationToken, resourcePath, cb, fmi3_log, loggingOn != fmi3False,
                              FMI3_PHASE_NAMES);
    if (inst == NULL) free(cb);
    return inst;
}

FREE_INSTANCE(fmi3FreeInstance)

SET_DEBUG_LOGGING(fmi3SetDebugLogging, fmi3Boolean, fmi3String)

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    BEGIN(fmi3EnterInitializationMode)
    (void)toleranceDefined, (void)tolerance;
    if (cs_setup(inst, call, startTime, stopTimeDefined != fmi3False, stopTime) != CS_OK) return fmi3Error;
    return (fmi3Status)cs_enter_init(inst, call);
}

EXIT_INITIALIZATION_MODE(fmi3ExitInitializationMode)

TERMINATE(fmi3Terminate)

RESET(fmi3Reset)

/* ---- variables ---------------------------------------------------------------------------------- */
fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues) {
    BEGIN(fmi3GetFloat64)
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
    BEGIN(fmi3SetFloat64)
    (void)valueReferences, (void)values, (void)nValues;
    if (nValueReferences == 0) return fmi3OK;
    return (fmi3Status)cs_refuse(inst, call, "this FMU has no inputs or parameters (its outputs come from "
                                 "resources/%s; time is the independent variable)", CS_SCHEDULE_FILE);
}

/* Types without variables (NO_GET_SET, fmi_layer.h; the types no native FMU has are in fmi3_common.c). */
NO_GET_SET(Int32)
NO_GET_SET(Boolean)

/* ---- not provided (canGetAndSetFMUState = false): refused in every phase; what no native FMU
 *      provides is in fmi3_common.c -------------------------------------------------------------- */
NOT_PROVIDED(fmi3GetFMUState, fmi3FMUState *state)
NOT_PROVIDED(fmi3SetFMUState, fmi3FMUState state)
NOT_PROVIDED(fmi3FreeFMUState, fmi3FMUState *state)
NOT_PROVIDED(fmi3SerializedFMUStateSize, fmi3FMUState state, size_t *size)
NOT_PROVIDED(fmi3SerializeFMUState, fmi3FMUState state, fmi3Byte serializedState[], size_t size)
NOT_PROVIDED(fmi3DeserializeFMUState, const fmi3Byte serializedState[], size_t size, fmi3FMUState *state)
