/*
 * FMI 2.0 co-simulation API of the native AdaptiveVelocityRegulator FMU: a thin layer
 * over the version-independent instance (avr_instance.c).  Every function starts with
 * the one prologue BEGIN (fmu_src/fmi/fmi_layer.h), which refuses a call outside the phases
 * of its FMI_MASK_<function> (fmi_phase_rules.h, generated from fmu_src/fmi/phase_rules.py);
 * the shapes every native FMU shares are written once in fmi_layer.h, the functions no native
 * FMU provides in fmi2_common.c.
 */
#include "avr_instance.h" /* first: see avr_types.h */

#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define FMI_STATUS fmi2Status
#define FMI_INSTANCE fmi2Component
#include "fmi_layer.h"

/* ---- creation, life cycle (the inquiry functions: fmi2_common.c) ------------------------------ */

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuResourceLocation; /* the FMU needs no resources */
    (void)visible;
    fmi2CallbackFunctions *cb = fmi2_callbacks(functions);
    if (cb == NULL) return NULL;
    AvrInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = fmi2_log};
    AvrInstance *inst = NULL;
    if (fmuType != fmi2CoSimulation)
        avr_refuse(&probe, "fmi2Instantiate", "this FMU supports co-simulation only");
    else
        inst = avr_instantiate(instanceName, fmuGUID, cb, fmi2_log, loggingOn == fmi2True, FMI2_PHASE_NAMES);
    if (inst == NULL) free(cb);
    return inst;
}

FREE_INSTANCE(fmi2FreeInstance)

SET_DEBUG_LOGGING(fmi2SetDebugLogging, fmi2Boolean, fmi2String)

fmi2Status fmi2SetupExperiment(fmi2Component instance, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BEGIN(fmi2SetupExperiment)
    (void)toleranceDefined; /* a discrete-time regulator: no tolerance to honour */
    (void)tolerance;
    return (fmi2Status)avr_setup(inst, call, startTime, stopTimeDefined == fmi2True, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component instance) {
    BEGIN(fmi2EnterInitializationMode)
    inst->phase = AVR_INIT_MODE;
    return fmi2OK;
}

EXIT_INITIALIZATION_MODE(fmi2ExitInitializationMode)
TERMINATE(fmi2Terminate)
RESET(fmi2Reset)

/* ---- variables ------------------------------------------------------------------------------- */
/* a Boolean other than 0/1 is refused by its range check */
FMI2_NUMERIC_VARIABLES(AVR_REAL, AVR_INTEGER, AVR_BOOLEAN, FMI_TO_DOUBLE)

fmi2Status fmi2GetString(fmi2Component instance, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    BEGIN(fmi2GetString)
    (void)vr, (void)value;
    if (nvr > 0) REFUSE("this FMU has no String variables");
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component instance, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    BEGIN(fmi2SetString)
    (void)vr, (void)value;
    if (nvr > 0) REFUSE("this FMU has no String variables");
    return fmi2OK;
}

/* ---- FMU state (avr_state.c, through FMUSTATE_FUNCTIONS of fmi_layer.h) ---------------------- */
FMUSTATE_FUNCTIONS(fmi2FMUstate, fmi2Byte, fmi2GetFMUstate, fmi2SetFMUstate, fmi2FreeFMUstate,
                   fmi2SerializedFMUstateSize, fmi2SerializeFMUstate, fmi2DeSerializeFMUstate)
