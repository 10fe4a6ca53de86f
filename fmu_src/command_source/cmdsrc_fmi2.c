/*
 * FMI 2.0 co-simulation API of CommandSource over the version-independent instance
 * (cmdsrc.c).  Each function begins with the shared prologue BEGIN (fmu_src/fmi/fmi_layer.h),
 * which checks its allowed phases (FMI_MASK_<function>, generated from fmu_src/fmi/phase_rules.py);
 * a refused call logs why, returns fmi2Error and changes nothing.  What every native FMU's FMI 2.0
 * layer has the same (inquiry, callbacks, doStep and status, the functions none provides) is
 * fmu_src/fmi/fmi2_common.c.
 */
#include "cmdsrc.h"

#include <stdlib.h>

#include "fmi2Functions.h"

#define FMI_STATUS fmi2Status
#define FMI_INSTANCE fmi2Component
#include "fmi_layer.h"

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    fmi2CallbackFunctions *cb = fmi2_callbacks(functions);
    if (cb == NULL) return NULL;
    CsInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = fmi2_log};
    CsInstance *inst = NULL;
    char *resources = cs_path_from_uri(fmuResourceLocation);
    if (fmuType != fmi2CoSimulation)
        cs_refuse(&probe, "fmi2Instantiate", "this FMU supports co-simulation only");
    else if (resources == NULL)
        cs_refuse(&probe, "fmi2Instantiate", "fmuResourceLocation \"%s\" is not a file URI (the schedule is read "
                  "from resources/%s)", fmuResourceLocation ? fmuResourceLocation : "(NULL)", CS_SCHEDULE_FILE);
    else
        inst = cs_instantiate(instanceName, fmuGUID, resources, cb, fmi2_log, loggingOn == fmi2True, FMI2_PHASE_NAMES);
    free(resources);
    if (inst == NULL) free(cb);
    return inst;
}

FREE_INSTANCE(fmi2FreeInstance)

SET_DEBUG_LOGGING(fmi2SetDebugLogging, fmi2Boolean, fmi2String)

fmi2Status fmi2SetupExperiment(fmi2Component instance, fmi2Boolean toleranceDefined, fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BEGIN(fmi2SetupExperiment)
    (void)toleranceDefined, (void)tolerance;
    return (fmi2Status)cs_setup(inst, call, startTime, stopTimeDefined == fmi2True, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component instance) {
    BEGIN(fmi2EnterInitializationMode)
    return (fmi2Status)cs_enter_init(inst, call);
}

EXIT_INITIALIZATION_MODE(fmi2ExitInitializationMode)

TERMINATE(fmi2Terminate)

RESET(fmi2Reset)

fmi2Status fmi2GetReal(fmi2Component instance, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    BEGIN(fmi2GetReal)
    if (nvr > 0 && value == NULL) return (fmi2Status)cs_refuse(inst, call, "NULL value array with nvr = %zu", nvr);
    if (cs_check_get(inst, call, vr, nvr) != CS_OK) return fmi2Error;
    for (size_t i = 0; i < nvr; ++i) value[i] = cs_output(inst, vr[i]);
    return fmi2OK;
}

/* Types without variables, and setters (the FMU has no inputs or parameters): nothing is fine. */
#define NONE(fn, ctype, what)                                                                              \
    fmi2Status fn(fmi2Component instance, const fmi2ValueReference vr[], size_t nvr, ctype value[]) {  \
        BEGIN(fn)                                                                                      \
        (void)vr, (void)value;                                                                         \
        if (nvr == 0) return fmi2OK;                                                                   \
        REFUSE("this FMU has no %s", what);                                                            \
    }
NONE(fmi2GetInteger, fmi2Integer, "Integer variables")
NONE(fmi2GetBoolean, fmi2Boolean, "Boolean variables")
NONE(fmi2GetString, fmi2String, "String variables")
NONE(fmi2SetReal, const fmi2Real, "inputs or parameters: its outputs come from resources/schedule.csv")
NONE(fmi2SetInteger, const fmi2Integer, "Integer variables")
NONE(fmi2SetBoolean, const fmi2Boolean, "Boolean variables")
NONE(fmi2SetString, const fmi2String, "String variables")

/* Not provided (canGetAndSetFMUstate = false): refused in every phase; the functions no native FMU
 * provides are in fmi2_common.c. */
NOT_PROVIDED(fmi2GetFMUstate, fmi2FMUstate *s)
NOT_PROVIDED(fmi2SetFMUstate, fmi2FMUstate s)
NOT_PROVIDED(fmi2FreeFMUstate, fmi2FMUstate *s)
NOT_PROVIDED(fmi2SerializedFMUstateSize, fmi2FMUstate s, size_t *n)
NOT_PROVIDED(fmi2SerializeFMUstate, fmi2FMUstate s, fmi2Byte b[], size_t n)
NOT_PROVIDED(fmi2DeSerializeFMUstate, const fmi2Byte b[], size_t n, fmi2FMUstate *s)
