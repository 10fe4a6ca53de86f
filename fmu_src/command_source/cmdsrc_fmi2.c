/*
 * FMI 2.0 co-simulation API of CommandSource over the version-independent instance
 * (cmdsrc.c).  Each function first checks its allowed phases (its MASK, FMI 2.0.4
 * section 4.2.4); a refused call logs why, returns fmi2Error and changes nothing.
 */
#include "cmdsrc.h"

#include <stdlib.h>

#include "fmi2Functions.h"

#define INIT_STEP_TERM (CS_INIT_MODE | CS_STEP_MODE | CS_TERMINATED)
#define SET_PHASES (CS_INSTANTIATED | CS_INIT_MODE | CS_STEP_MODE)

#define BEGIN(fn, mask)                                                 \
    CsInstance *inst = (CsInstance *)c;                                 \
    static const char call[] = #fn;                                     \
    if (cs_allowed(inst, call, (mask)) != CS_OK) return fmi2Error;

static const char *const PHASE_NAMES[] = {"instantiated", "initializationMode", "stepComplete", "terminated"};

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
        inst = cs_instantiate(instanceName, fmuGUID, resources, cb, log_fmi2, loggingOn == fmi2True, PHASE_NAMES);
    free(resources);
    if (inst == NULL) free(cb);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    CsInstance *inst = (CsInstance *)c;
    if (inst == NULL) return;
    void *cb = inst->env;
    cs_free(inst);
    free(cb);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    BEGIN(fmi2SetDebugLogging, CS_ANY_PHASE)
    if (nCategories > 0 && categories == NULL)
        return (fmi2Status)cs_refuse(inst, call, "categories is NULL with nCategories = %zu", nCategories);
    inst->logging_on = loggingOn == fmi2True;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BEGIN(fmi2SetupExperiment, CS_INSTANTIATED)
    (void)toleranceDefined, (void)tolerance;
    return (fmi2Status)cs_setup(inst, call, startTime, stopTimeDefined == fmi2True, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    BEGIN(fmi2EnterInitializationMode, CS_INSTANTIATED)
    return (fmi2Status)cs_enter_init(inst, call);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    BEGIN(fmi2ExitInitializationMode, CS_INIT_MODE)
    inst->phase = CS_STEP_MODE;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    BEGIN(fmi2Terminate, CS_STEP_MODE)
    inst->phase = CS_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    BEGIN(fmi2Reset, CS_ANY_PHASE)
    cs_reset(inst);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    BEGIN(fmi2GetReal, INIT_STEP_TERM)
    if (nvr > 0 && value == NULL) return (fmi2Status)cs_refuse(inst, call, "NULL value array with nvr = %zu", nvr);
    if (cs_check_get(inst, call, vr, nvr) != CS_OK) return fmi2Error;
    for (size_t i = 0; i < nvr; ++i) value[i] = cs_output(inst, vr[i]);
    return fmi2OK;
}

/* Types without variables, and setters (the FMU has no inputs or parameters): nothing is fine. */
#define NONE(fn, mask, ctype, what)                                                                    \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, ctype value[]) {         \
        BEGIN(fn, mask)                                                                                \
        (void)vr, (void)value;                                                                         \
        return nvr == 0 ? fmi2OK : (fmi2Status)cs_refuse(inst, call, "this FMU has no %s", what);      \
    }
NONE(fmi2GetInteger, INIT_STEP_TERM, fmi2Integer, "Integer variables")
NONE(fmi2GetBoolean, INIT_STEP_TERM, fmi2Boolean, "Boolean variables")
NONE(fmi2GetString, INIT_STEP_TERM, fmi2String, "String variables")
NONE(fmi2SetReal, SET_PHASES, const fmi2Real, "inputs or parameters: its outputs come from resources/schedule.csv")
NONE(fmi2SetInteger, SET_PHASES, const fmi2Integer, "Integer variables")
NONE(fmi2SetBoolean, SET_PHASES, const fmi2Boolean, "Boolean variables")
NONE(fmi2SetString, SET_PHASES, const fmi2String, "String variables")

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    BEGIN(fmi2DoStep, CS_STEP_MODE)
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)cs_do_step(inst, call, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    BEGIN(fmi2GetRealStatus, CS_STEP_MODE | CS_TERMINATED)
    if (s != fmi2LastSuccessfulTime || value == NULL)
        return (fmi2Status)cs_refuse(inst, call, "only fmi2LastSuccessfulTime is provided");
    *value = inst->time;
    return fmi2OK;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    BEGIN(fmi2GetBooleanStatus, CS_STEP_MODE | CS_TERMINATED)
    if (s != fmi2Terminated || value == NULL) return (fmi2Status)cs_refuse(inst, call, "only fmi2Terminated is provided");
    *value = fmi2False;
    return fmi2OK;
}

/* Not provided (canGetAndSetFMUstate, canInterpolateInputs, maxOutputDerivativeOrder = 0,
 * canRunAsynchronuously, providesDirectionalDerivative all false): refused in every phase. */
#define NOT_PROVIDED(fn, ...)                                  \
    fmi2Status fn(fmi2Component c, __VA_ARGS__) {              \
        BEGIN(fn, 0u)                                          \
        return fmi2Error;                                      \
    }
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-parameter"
#endif
NOT_PROVIDED(fmi2GetFMUstate, fmi2FMUstate *s)
NOT_PROVIDED(fmi2SetFMUstate, fmi2FMUstate s)
NOT_PROVIDED(fmi2FreeFMUstate, fmi2FMUstate *s)
NOT_PROVIDED(fmi2SerializedFMUstateSize, fmi2FMUstate s, size_t *n)
NOT_PROVIDED(fmi2SerializeFMUstate, fmi2FMUstate s, fmi2Byte b[], size_t n)
NOT_PROVIDED(fmi2DeSerializeFMUstate, const fmi2Byte b[], size_t n, fmi2FMUstate *s)
NOT_PROVIDED(fmi2GetDirectionalDerivative, const fmi2ValueReference u[], size_t nu, const fmi2ValueReference k[],
             size_t nk, const fmi2Real dk[], fmi2Real du[])
NOT_PROVIDED(fmi2SetRealInputDerivatives, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[],
             const fmi2Real value[])
NOT_PROVIDED(fmi2GetRealOutputDerivatives, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[],
             fmi2Real value[])
NOT_PROVIDED(fmi2GetStatus, const fmi2StatusKind s, fmi2Status *value)
NOT_PROVIDED(fmi2GetIntegerStatus, const fmi2StatusKind s, fmi2Integer *value)
NOT_PROVIDED(fmi2GetStringStatus, const fmi2StatusKind s, fmi2String *value)
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

fmi2Status fmi2CancelStep(fmi2Component c) {
    BEGIN(fmi2CancelStep, 0u)
    return fmi2Error;
}
