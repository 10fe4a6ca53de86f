/*
 * FMI 2.0 co-simulation API of the native AdaptiveVelocityRegulator FMU: a thin layer
 * over the version-independent instance (avr_instance.c).  Every function starts with
 * the one prologue BEGIN, which refuses a call outside the phases of its mask below.
 */
#include "avr_instance.h" /* first: see avr_types.h */

#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

/* ---- allowed phases per function (FMI 2.0.4 section 4.2.4; stepFailed/stepCanceled never
 *      occur: a refused doStep changes nothing, and steps are never asynchronous) ---------- */
#define ANY AVR_ANY_PHASE
#define MASK_fmi2SetDebugLogging ANY
#define MASK_fmi2SetupExperiment AVR_INSTANTIATED
#define MASK_fmi2EnterInitializationMode AVR_INSTANTIATED
#define MASK_fmi2ExitInitializationMode AVR_INIT_MODE
#define MASK_fmi2Terminate AVR_STEP_MODE
#define MASK_fmi2Reset ANY
#define MASK_fmi2GetReal (AVR_INIT_MODE | AVR_STEP_MODE | AVR_TERMINATED)
#define MASK_fmi2GetInteger MASK_fmi2GetReal
#define MASK_fmi2GetBoolean MASK_fmi2GetReal
#define MASK_fmi2GetString MASK_fmi2GetReal
#define MASK_fmi2SetReal (AVR_INSTANTIATED | AVR_INIT_MODE | AVR_STEP_MODE)
#define MASK_fmi2SetInteger MASK_fmi2SetReal
#define MASK_fmi2SetBoolean MASK_fmi2SetReal
#define MASK_fmi2SetString MASK_fmi2SetReal
#define MASK_fmi2GetFMUstate ANY
#define MASK_fmi2SetFMUstate ANY
#define MASK_fmi2FreeFMUstate ANY
#define MASK_fmi2SerializedFMUstateSize ANY
#define MASK_fmi2SerializeFMUstate ANY
#define MASK_fmi2DeSerializeFMUstate ANY
#define MASK_fmi2GetDirectionalDerivative 0u /* not provided */
#define MASK_fmi2SetRealInputDerivatives 0u  /* canInterpolateInputs = false */
#define MASK_fmi2GetRealOutputDerivatives 0u /* maxOutputDerivativeOrder = 0 */
#define MASK_fmi2DoStep AVR_STEP_MODE
#define MASK_fmi2CancelStep 0u /* canRunAsynchronuously = false */
#define MASK_fmi2GetStatus 0u  /* never fmi2Pending */
#define MASK_fmi2GetRealStatus (AVR_STEP_MODE | AVR_TERMINATED)
#define MASK_fmi2GetIntegerStatus 0u
#define MASK_fmi2GetBooleanStatus (AVR_STEP_MODE | AVR_TERMINATED)
#define MASK_fmi2GetStringStatus 0u

/* The one prologue: the instance, the call's name, and its phase check. */
#define BEGIN(fn)                                                           \
    AvrInstance *inst = (AvrInstance *)c;                                   \
    static const char call[] = #fn;                                         \
    if (avr_allowed(inst, call, MASK_##fn) != AVR_OK) return fmi2Error;

#define REFUSE(...) return (fmi2Status)avr_refuse(inst, call, __VA_ARGS__)

static const char *const PHASE_NAMES[] = {"instantiated", "initializationMode", "stepComplete", "terminated"};

static void log_fmi2(const AvrInstance *inst, AvrStatus status, const char *category, const char *message) {
    const fmi2CallbackFunctions *cb = (const fmi2CallbackFunctions *)inst->env;
    /* the message goes as an argument, never as the format string */
    if (cb != NULL && cb->logger != NULL)
        cb->logger(cb->componentEnvironment, inst->name, (fmi2Status)status, category, "%s", message);
}

/* ---- inquiry, creation, life cycle ---------------------------------------------------------- */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuResourceLocation; /* the FMU needs no resources */
    (void)visible;
    if (functions == NULL) return NULL;
    fmi2CallbackFunctions *cb = malloc(sizeof *cb);
    if (cb == NULL) return NULL;
    *cb = *functions;
    AvrInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = log_fmi2};
    AvrInstance *inst = NULL;
    if (fmuType != fmi2CoSimulation)
        avr_refuse(&probe, "fmi2Instantiate", "this FMU supports co-simulation only");
    else
        inst = avr_instantiate(instanceName, fmuGUID, cb, log_fmi2, loggingOn == fmi2True, PHASE_NAMES);
    if (inst == NULL) free(cb);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    AvrInstance *inst = (AvrInstance *)c;
    if (inst == NULL) return;
    void *cb = inst->env;
    avr_free_instance(inst);
    free(cb);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    BEGIN(fmi2SetDebugLogging)
    if (nCategories > 0 && categories == NULL) REFUSE("categories is NULL with nCategories = %zu", nCategories);
    inst->logging_on = loggingOn == fmi2True;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BEGIN(fmi2SetupExperiment)
    (void)toleranceDefined; /* a discrete-time regulator: no tolerance to honour */
    (void)tolerance;
    return (fmi2Status)avr_setup(inst, call, startTime, stopTimeDefined == fmi2True, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    BEGIN(fmi2EnterInitializationMode)
    inst->phase = AVR_INIT_MODE;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    BEGIN(fmi2ExitInitializationMode)
    return (fmi2Status)avr_exit_init(inst, call);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    BEGIN(fmi2Terminate)
    inst->phase = AVR_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    BEGIN(fmi2Reset)
    avr_reset(inst);
    return fmi2OK;
}

/* ---- variables ------------------------------------------------------------------------------- */
#define GETTER(fn, ctype, type, FROM_DOUBLE)                                                          \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, ctype value[]) {        \
        BEGIN(fn)                                                                                     \
        if (nvr > 0 && value == NULL) REFUSE("NULL value array with nvr = %zu", nvr);                 \
        if (avr_check_get(inst, call, vr, nvr, type) != AVR_OK) return fmi2Error;                     \
        for (size_t i = 0; i < nvr; ++i) value[i] = FROM_DOUBLE(inst->values[vr[i]]);                 \
        return fmi2OK;                                                                                \
    }
#define SETTER(fn, ctype, type)                                                                        \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const ctype value[]) {   \
        BEGIN(fn)                                                                                      \
        if (nvr > 0 && (vr == NULL || value == NULL)) REFUSE("NULL vr or value array with nvr = %zu", nvr); \
        for (size_t i = 0; i < nvr; ++i) /* all checked before any is applied */                      \
            if (avr_check_set(inst, call, vr[i], type, (double)value[i]) != AVR_OK) return fmi2Error;  \
        for (size_t i = 0; i < nvr; ++i) inst->values[vr[i]] = (double)value[i];                       \
        return fmi2OK;                                                                                 \
    }
#define AS_REAL(x) (x)
#define AS_INTEGER(x) ((fmi2Integer)(x))
#define AS_BOOLEAN(x) ((x) != 0.0 ? fmi2True : fmi2False)
GETTER(fmi2GetReal, fmi2Real, AVR_REAL, AS_REAL)
GETTER(fmi2GetInteger, fmi2Integer, AVR_INTEGER, AS_INTEGER)
GETTER(fmi2GetBoolean, fmi2Boolean, AVR_BOOLEAN, AS_BOOLEAN)
SETTER(fmi2SetReal, fmi2Real, AVR_REAL)
SETTER(fmi2SetInteger, fmi2Integer, AVR_INTEGER)
SETTER(fmi2SetBoolean, fmi2Boolean, AVR_BOOLEAN)

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    BEGIN(fmi2GetString)
    (void)vr, (void)value;
    if (nvr > 0) REFUSE("this FMU has no String variables");
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    BEGIN(fmi2SetString)
    (void)vr, (void)value;
    if (nvr > 0) REFUSE("this FMU has no String variables");
    return fmi2OK;
}

/* ---- FMU state (avr_state.c) --------------------------------------------------------------------- */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    BEGIN(fmi2GetFMUstate)
    return (fmi2Status)avr_fmustate_get(inst, call, state);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    BEGIN(fmi2SetFMUstate)
    return (fmi2Status)avr_fmustate_set(inst, call, state);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    BEGIN(fmi2FreeFMUstate)
    avr_fmustate_free(state);
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    BEGIN(fmi2SerializedFMUstateSize)
    return (fmi2Status)avr_fmustate_size(inst, call, state, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[], size_t size) {
    BEGIN(fmi2SerializeFMUstate)
    return (fmi2Status)avr_fmustate_serialize(inst, call, state, (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *state) {
    BEGIN(fmi2DeSerializeFMUstate)
    return (fmi2Status)avr_fmustate_deserialize(inst, call, (const unsigned char *)serializedState, size, state);
}

/* ---- not provided (the model description says so) ------------------------------------------------ */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    BEGIN(fmi2GetDirectionalDerivative)
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    BEGIN(fmi2SetRealInputDerivatives)
    (void)vr, (void)nvr, (void)order, (void)value;
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    BEGIN(fmi2GetRealOutputDerivatives)
    (void)vr, (void)nvr, (void)order, (void)value;
    return fmi2Error;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    BEGIN(fmi2CancelStep)
    return fmi2Error;
}

/* ---- stepping and status ----------------------------------------------------------------------- */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    BEGIN(fmi2DoStep)
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)avr_do_step(inst, call, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    BEGIN(fmi2GetStatus)
    (void)s, (void)value;
    return fmi2Error;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    BEGIN(fmi2GetRealStatus)
    if (s != fmi2LastSuccessfulTime || value == NULL) REFUSE("only fmi2LastSuccessfulTime is provided");
    *value = inst->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    BEGIN(fmi2GetIntegerStatus)
    (void)s, (void)value;
    return fmi2Error;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    BEGIN(fmi2GetBooleanStatus)
    if (s != fmi2Terminated || value == NULL) REFUSE("only fmi2Terminated is provided");
    *value = fmi2False; /* the regulator never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    BEGIN(fmi2GetStringStatus)
    (void)s, (void)value;
    return fmi2Error;
}
