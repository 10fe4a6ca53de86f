/*
 * FMI 2.0 co-simulation API of CommandSource over the version-independent instance
 * (cmdsrc.c).  Each function begins with the shared prologue BEGIN (fmu_src/fmi/fmi_layer.h),
 * which checks its allowed phases (FMI_MASK_<function>, generated from fmu_src/fmi/phase_rules.py);
 * a refused call logs why, returns fmi2Error and changes nothing.
 */
#include "cmdsrc.h"

#include <stdlib.h>

#include "fmi2Functions.h"

#define FMI_STATUS fmi2Status
#define FMI_INSTANCE fmi2Component
#include "fmi_layer.h"

static void log_fmi2(const CsInstance *inst, CsStatus status, const char *category, const char *message) {
    const fmi2CallbackFunctions *cb = (const fmi2CallbackFunctions *)inst->env;
    if (cb != NULL && cb->logger != NULL)
        cb->logger(cb->componentEnvironment, inst->name, (fmi2Status)status, category, "%s", message);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    if (functions == NULL) return NULL;
    fmi2CallbackFunctions *cb = malloc(sizeof *cb);
    if (cb == NULL) return NULL;
    *cb = *functions;
    CsInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = log_fmi2};
    CsInstance *inst = NULL;
    char *resources = cs_path_from_uri(fmuResourceLocation);
    if (fmuType != fmi2CoSimulation)
        cs_refuse(&probe, "fmi2Instantiate", "this FMU supports co-simulation only");
    else if (resources == NULL)
        cs_refuse(&probe, "fmi2Instantiate", "fmuResourceLocation \"%s\" is not a file URI (the schedule is read "
                  "from resources/%s)", fmuResourceLocation ? fmuResourceLocation : "(NULL)", CS_SCHEDULE_FILE);
    else
        inst = cs_instantiate(instanceName, fmuGUID, resources, cb, log_fmi2, loggingOn == fmi2True, FMI2_PHASE_NAMES);
    free(resources);
    if (inst == NULL) free(cb);
    return inst;
}

FREE_INSTANCE(fmi2FreeInstance)

fmi2Status fmi2SetDebugLogging(fmi2Component instance, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    BEGIN(fmi2SetDebugLogging)
    if (nCategories > 0 && categories == NULL)
        return (fmi2Status)cs_refuse(inst, call, "categories is NULL with nCategories = %zu", nCategories);
    inst->logging_on = loggingOn == fmi2True;
    return fmi2OK;
}

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

fmi2Status fmi2ExitInitializationMode(fmi2Component instance) {
    BEGIN(fmi2ExitInitializationMode)
    inst->phase = CS_STEP_MODE;
    return fmi2OK;
}

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

fmi2Status fmi2DoStep(fmi2Component instance, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    BEGIN(fmi2DoStep)
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)cs_do_step(inst, call, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2GetRealStatus(fmi2Component instance, const fmi2StatusKind s, fmi2Real *value) {
    BEGIN(fmi2GetRealStatus)
    if (s != fmi2LastSuccessfulTime || value == NULL)
        return (fmi2Status)cs_refuse(inst, call, "only fmi2LastSuccessfulTime is provided");
    *value = inst->time;
    return fmi2OK;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component instance, const fmi2StatusKind s, fmi2Boolean *value) {
    BEGIN(fmi2GetBooleanStatus)
    if (s != fmi2Terminated || value == NULL) return (fmi2Status)cs_refuse(inst, call, "only fmi2Terminated is provided");
    *value = fmi2False;
    return fmi2OK;
}

/* Not provided (canGetAndSetFMUstate = false): refused in every phase; the functions no native FMU
 * provides are in fmi2_refused.c. */
NOT_PROVIDED(fmi2GetFMUstate, fmi2FMUstate *s)
NOT_PROVIDED(fmi2SetFMUstate, fmi2FMUstate s)
NOT_PROVIDED(fmi2FreeFMUstate, fmi2FMUstate *s)
NOT_PROVIDED(fmi2SerializedFMUstateSize, fmi2FMUstate s, size_t *n)
NOT_PROVIDED(fmi2SerializeFMUstate, fmi2FMUstate s, fmi2Byte b[], size_t n)
NOT_PROVIDED(fmi2DeSerializeFMUstate, const fmi2Byte b[], size_t n, fmi2FMUstate *s)
