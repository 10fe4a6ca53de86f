/*
 * FMI 3.0 co-simulation API of the native CassiePlant FMU: the same version-independent
 * instance (cp_instance.c) as the FMI 2.0 layer (fmi2_plant.c), behind FMI 3.0's names and
 * types, over the shared layer (fmu_src/fmi/fmi_layer.h: the prologue BEGIN with each
 * function's generated FMI_MASK_<function>).  Co-simulation without event mode or intermediate
 * update; the variables are Float64, Int32, Boolean and String scalars, plus the independent
 * variable time (valueReference CP_N_VARS).  The version, doStep, the getters and setters of
 * other types and the functions of other interfaces (refused) are fmi3_common.c's.
 */
#include "cp_instance.h" /* first: the floating-point contract */

#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define FMI_STATUS fmi3Status
#define FMI_INSTANCE fmi3Instance
#include "fmi_layer.h"

#define TIME_VR ((fmi3ValueReference)CP_N_VARS)

typedef char fmi3Boolean_is_one_byte[sizeof(fmi3Boolean) == 1 ? 1 : -1];

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
    CpInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = fmi3_log,
                        .phase_names = FMI3_PHASE_NAMES};
    CpInstance *inst = NULL;
    char *resources = NULL;
    if (resourcePath != NULL) { /* FMI 3.0: a native path ending in a separator; kept without it */
        size_t n = strlen(resourcePath);
        resources = malloc(n + 1);
        if (resources) {
            strcpy(resources, resourcePath);
            while (n > 1 && (resources[n - 1] == '/' || resources[n - 1] == '\\')) resources[--n] = 0;
        }
    }
    const char *problem = fmi3_cosim_problem(eventModeUsed, nRequiredIntermediateVariables);
    if (problem != NULL)
        cp_refuse(&probe, "fmi3InstantiateCoSimulation", "%s", problem);
    else
        inst = cp_instantiate(instanceName, instantiationToken, resources, cb, fmi3_log, loggingOn, FMI3_PHASE_NAMES);
    free(resources);
    if (inst == NULL) free(cb);
    return inst;
}

FREE_INSTANCE(fmi3FreeInstance)

SET_DEBUG_LOGGING(fmi3SetDebugLogging, fmi3Boolean, fmi3String)

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    BEGIN(fmi3EnterInitializationMode)
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    if (cp_setup(inst, call, startTime) != CP_OK) return fmi3Error;
    inst->phase = CP_INIT_MODE;
    return fmi3OK;
}

EXIT_INITIALIZATION_MODE(fmi3ExitInitializationMode)
TERMINATE(fmi3Terminate)
RESET(fmi3Reset)

/* ---- variables (FMI3_GETTER, FMI3_SETTER: fmi_layer.h) --------------------------------------- */
FMI3_NUMERIC_VARIABLES(CP_REAL, CP_INTEGER, CP_BOOLEAN, TIME_VR)

/* Strings: cassie_model and terrain_field_file (cp_set_strings, cp_get_string). */
fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         fmi3String values[], size_t nValues) {
    BEGIN(fmi3GetString)
    if (fmi3_check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != fmi3OK ||
        cp_check_get(inst, call, valueReferences, nValueReferences, CP_STRING) != CP_OK)
        return fmi3Error;
    for (size_t i = 0; i < nValueReferences; ++i) values[i] = cp_get_string(inst, valueReferences[i]);
    return fmi3OK;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const fmi3String values[], size_t nValues) {
    BEGIN(fmi3SetString)
    if (fmi3_check_counts(inst, call, valueReferences, nValueReferences, values, nValues) != fmi3OK) return fmi3Error;
    for (size_t i = 0; i < nValueReferences; ++i)
        if (valueReferences[i] == TIME_VR) REFUSE("time is the independent variable and cannot be set");
    return (fmi3Status)cp_set_strings(inst, call, valueReferences, values, nValueReferences);
}

/* ---- FMU state (cp_instance.c, through FMUSTATE_FUNCTIONS of fmi_layer.h) --------------------- */
FMUSTATE_FUNCTIONS(fmi3FMUState, fmi3Byte, fmi3GetFMUState, fmi3SetFMUState, fmi3FreeFMUState,
                   fmi3SerializedFMUStateSize, fmi3SerializeFMUState, fmi3DeserializeFMUState)
