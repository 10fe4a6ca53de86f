/*
 * FMI 3.0 co-simulation API of the native AdaptiveVelocityRegulator FMU: the same
 * version-independent instance (avr_instance.c) as the FMI 2.0 layer, behind FMI 3.0's
 * names and types.  Float64/Int32/Boolean variables; the independent variable `time`
 * has the value reference after the last variable of the table (so every other value
 * reference equals the FMI 2.0 FMU's).  No event mode, no intermediate update, no
 * clocks, no Model Exchange or Scheduled Execution: those functions refuse.
 */
#include "avr_instance.h" /* first: see avr_types.h */

#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define FMI_STATUS fmi3Status
#define FMI_INSTANCE fmi3Instance
#include "fmi_layer.h"

#define TIME_VR ((fmi3ValueReference)AVR_N_VARS)

typedef char fmi3Boolean_is_one_byte[sizeof(fmi3Boolean) == 1 ? 1 : -1];

/* ---- creation, life cycle (the version, ME and SE instantiation: fmi3_common.c) --------------- */
fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)resourcePath, (void)visible, (void)earlyReturnAllowed, (void)requiredIntermediateVariables;
    (void)intermediateUpdate; /* never called: no intermediate update */
    FmiCallbacks3 *cb = fmi3_callbacks(instanceEnvironment, logMessage);
    if (cb == NULL) return NULL;
    AvrInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = fmi3_log};
    AvrInstance *inst = NULL;
    const char *problem = fmi3_cosim_problem(eventModeUsed, nRequiredIntermediateVariables);
    if (problem != NULL)
        avr_refuse(&probe, "fmi3InstantiateCoSimulation", "%s", problem);
    else
        inst = avr_instantiate(instanceName, instantiationToken, cb, fmi3_log, loggingOn, FMI3_PHASE_NAMES);
    if (inst == NULL) free(cb);
    return inst;
}

FREE_INSTANCE(fmi3FreeInstance)

SET_DEBUG_LOGGING(fmi3SetDebugLogging, fmi3Boolean, fmi3String)

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    BEGIN(fmi3EnterInitializationMode)
    (void)toleranceDefined, (void)tolerance;
    if (avr_setup(inst, call, startTime, stopTimeDefined, stopTime) != AVR_OK) return fmi3Error;
    inst->phase = AVR_INIT_MODE;
    return fmi3OK;
}

EXIT_INITIALIZATION_MODE(fmi3ExitInitializationMode)
TERMINATE(fmi3Terminate)
RESET(fmi3Reset)

/* ---- variables of this FMU's types (FMI3_GETTER, FMI3_SETTER: fmi_layer.h) ---------------------- */
FMI3_NUMERIC_VARIABLES(AVR_REAL, AVR_INTEGER, AVR_BOOLEAN, TIME_VR)

/* ---- FMU state (avr_state.c, through FMUSTATE_FUNCTIONS of fmi_layer.h) ---------------------- */
FMUSTATE_FUNCTIONS(fmi3FMUState, fmi3Byte, fmi3GetFMUState, fmi3SetFMUState, fmi3FreeFMUState,
                   fmi3SerializedFMUStateSize, fmi3SerializeFMUState, fmi3DeserializeFMUState)
