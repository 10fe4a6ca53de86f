/*
 * FMI 2.0 co-simulation API of the native CassiePlant FMU: a thin layer over the
 * version-independent instance (cp_instance.c).  Every function starts with the one prologue
 * BEGIN, which refuses a call outside the phases of its mask (FMI 2.0.4 section 4.2.4), as
 * fmu_src/regulator_fmu/native/fmi2_api.c does for the regulator.
 */
#include "cp_instance.h" /* first: the floating-point contract */

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static const char *const PHASE_NAMES[] = {"instantiated", "initializationMode", "stepComplete", "terminated"};

#define BEGIN(fn, mask)                                                          \
    static const char *const call = #fn;                                         \
    CpInstance *inst = (CpInstance *)c;                                          \
    if (inst == NULL) return fmi2Error;                                          \
    if (cp_allowed(inst, call, (mask)) != CP_OK) return fmi2Error
#define NOT_PROVIDED(fn, why)                                                    \
    do {                                                                         \
        CpInstance *inst_ = (CpInstance *)c;                                     \
        if (inst_ == NULL) return fmi2Error;                                     \
        return (fmi2Status)cp_refuse(inst_, #fn, "not provided by this FMU (%s)", why); \
    } while (0)

static void log_fmi2(const CpInstance *inst, CpStatus status, const char *category, const char *message) {
    const fmi2CallbackFunctions *cb = (const fmi2CallbackFunctions *)inst->env;
    if (cb != NULL && cb->logger != NULL) /* the message as an argument, never as the format */
        cb->logger(cb->componentEnvironment, inst->name, (fmi2Status)status, category, "%s", message);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

/* The folder a file URI names (file:///path, file:/path, file://localhost/path), %XX decoded. */
static char *uri_path(const char *uri) {
    if (uri == NULL) return NULL;
    const char *p;
    if (!strncmp(uri, "file://localhost/", 17)) p = uri + 16;
    else if (!strncmp(uri, "file:///", 8)) p = uri + 7;
    else if (!strncmp(uri, "file:/", 6)) p = uri + 5;
    else return NULL;
#ifdef _WIN32
    if (p[0] == '/' && p[1] && p[2] == ':') p++; /* file:///C:/... */
#endif
    char *out = malloc(strlen(p) + 1), *o = out;
    if (out == NULL) return NULL;
    for (; *p; p++) {
        unsigned hi, lo;
        if (*p == '%' && sscanf(p + 1, "%1x%1x", &hi, &lo) == 2) {
            *o++ = (char)(hi * 16 + lo);
            p += 2;
        } else {
            *o++ = *p;
        }
    }
    *o = 0;
    size_t n = strlen(out);
    while (n > 1 && (out[n - 1] == '/' || out[n - 1] == '\\')) out[--n] = 0;
    return out;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    if (functions == NULL) return NULL;
    fmi2CallbackFunctions *cb = malloc(sizeof *cb);
    if (cb == NULL) return NULL;
    *cb = *functions;
    CpInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = log_fmi2,
                        .phase_names = PHASE_NAMES};
    CpInstance *inst = NULL;
    char *resources = uri_path(fmuResourceLocation);
    if (fmuType != fmi2CoSimulation)
        cp_refuse(&probe, "fmi2Instantiate", "this FMU supports co-simulation only");
    else if (resources == NULL)
        cp_refuse(&probe, "fmi2Instantiate", "fmuResourceLocation %s is not a file URI; the FMU needs its resources",
                  fmuResourceLocation ? fmuResourceLocation : "(null)");
    else
        inst = cp_instantiate(instanceName, fmuGUID, resources, cb, log_fmi2, loggingOn == fmi2True, PHASE_NAMES);
    free(resources);
    if (inst == NULL) free(cb);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    CpInstance *inst = (CpInstance *)c;
    if (inst == NULL) return;
    void *cb = inst->env;
    cp_free_instance(inst);
    free(cb);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]) {
    BEGIN(fmi2SetDebugLogging, CP_ANY_PHASE);
    if (cp_check_categories(inst, call, n, categories) != CP_OK) return fmi2Error;
    inst->logging_on = loggingOn == fmi2True;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    BEGIN(fmi2SetupExperiment, CP_INSTANTIATED);
    return (fmi2Status)cp_setup(inst, call, startTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    BEGIN(fmi2EnterInitializationMode, CP_INSTANTIATED);
    inst->phase = CP_INIT_MODE;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    BEGIN(fmi2ExitInitializationMode, CP_INIT_MODE);
    return (fmi2Status)cp_exit_init(inst, call);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    BEGIN(fmi2Terminate, CP_STEP_MODE);
    inst->phase = CP_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    BEGIN(fmi2Reset, CP_ANY_PHASE);
    cp_reset(inst);
    return fmi2OK;
}

/* ---- variables ------------------------------------------------------------------------------ */
#define GET(fn, T, cptype, conv)                                                                  \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t n, T value[]) {          \
        BEGIN(fn, CP_GET_PHASES);                                                                 \
        if (cp_check_get(inst, call, vr, n, cptype) != CP_OK) return fmi2Error;                   \
        if (n > 0 && value == NULL) return (fmi2Status)cp_refuse(inst, call, "value is NULL");    \
        for (size_t i = 0; i < n; i++) value[i] = conv(inst->values[vr[i]]);                      \
        return fmi2OK;                                                                            \
    }
#define AS_REAL(x) (x)
#define AS_INT(x) ((fmi2Integer)(x))
#define AS_BOOL(x) ((x) != 0.0 ? fmi2True : fmi2False)
#define AS_MODEL(x) (CP_MODEL_NAMES[(int)(x)])
GET(fmi2GetReal, fmi2Real, CP_REAL, AS_REAL)
GET(fmi2GetInteger, fmi2Integer, CP_INTEGER, AS_INT)
GET(fmi2GetBoolean, fmi2Boolean, CP_BOOLEAN, AS_BOOL)
GET(fmi2GetString, fmi2String, CP_STRING, AS_MODEL)

/* All or nothing: every value is checked before any is stored. */
#define SET(fn, T, cptype, conv)                                                                       \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t n, const T value[]) {         \
        BEGIN(fn, CP_SET_PHASES);                                                                      \
        if (n > 0 && (vr == NULL || value == NULL)) return (fmi2Status)cp_refuse(inst, call, "NULL array"); \
        for (size_t i = 0; i < n; i++)                                                                 \
            if (cp_check_set(inst, call, vr[i], cptype, conv(value[i])) != CP_OK) return fmi2Error;    \
        for (size_t i = 0; i < n; i++) inst->values[vr[i]] = conv(value[i]);                           \
        return fmi2OK;                                                                                 \
    }
#define FROM_BOOL(x) ((x) != fmi2False ? 1.0 : 0.0)
#define FROM_NUM(x) ((double)(x))
SET(fmi2SetReal, fmi2Real, CP_REAL, FROM_NUM)
SET(fmi2SetInteger, fmi2Integer, CP_INTEGER, FROM_NUM)
SET(fmi2SetBoolean, fmi2Boolean, CP_BOOLEAN, FROM_BOOL)

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[]) {
    BEGIN(fmi2SetString, CP_SET_PHASES);
    if (n > 0 && (vr == NULL || value == NULL)) return (fmi2Status)cp_refuse(inst, call, "NULL array");
    double index[CP_N_VARS];
    if (n > CP_N_VARS) return (fmi2Status)cp_refuse(inst, call, "%zu values: more than the variables", n);
    for (size_t i = 0; i < n; i++)
        if (cp_check_set(inst, call, vr[i], CP_STRING, 0.0) != CP_OK ||
            cp_model_index(inst, call, value[i], &index[i]) != CP_OK)
            return fmi2Error;
    for (size_t i = 0; i < n; i++) inst->values[vr[i]] = index[i];
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    BEGIN(fmi2DoStep, CP_STEP_MODE);
    return (fmi2Status)cp_do_step(inst, call, t, h);
}

/* ---- FMU state ------------------------------------------------------------------------------ */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    BEGIN(fmi2GetFMUstate, CP_ANY_PHASE);
    return (fmi2Status)cp_fmustate_get(inst, call, (void **)state);
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    BEGIN(fmi2SetFMUstate, CP_ANY_PHASE);
    return (fmi2Status)cp_fmustate_set(inst, call, state);
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    BEGIN(fmi2FreeFMUstate, CP_ANY_PHASE);
    cp_fmustate_free((void **)state);
    return fmi2OK;
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    BEGIN(fmi2SerializedFMUstateSize, CP_ANY_PHASE);
    return (fmi2Status)cp_fmustate_size(inst, call, state, size);
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    BEGIN(fmi2SerializeFMUstate, CP_ANY_PHASE);
    return (fmi2Status)cp_fmustate_serialize(inst, call, state, (unsigned char *)bytes, size);
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    BEGIN(fmi2DeSerializeFMUstate, CP_ANY_PHASE);
    return (fmi2Status)cp_fmustate_deserialize(inst, call, (const unsigned char *)bytes, size, (void **)state);
}

/* ---- not provided ------------------------------------------------------------------------- */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    NOT_PROVIDED(fmi2GetDirectionalDerivative, "providesDirectionalDerivative = false");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr, (void)n, (void)order, (void)value;
    NOT_PROVIDED(fmi2SetRealInputDerivatives, "canInterpolateInputs = false");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr, (void)n, (void)order, (void)value;
    NOT_PROVIDED(fmi2GetRealOutputDerivatives, "maxOutputDerivativeOrder = 0");
}
fmi2Status fmi2CancelStep(fmi2Component c) { NOT_PROVIDED(fmi2CancelStep, "canRunAsynchronuously = false"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)s, (void)v;
    NOT_PROVIDED(fmi2GetStatus, "doStep never returns fmi2Pending");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)s, (void)v;
    NOT_PROVIDED(fmi2GetRealStatus, "no such status");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)s, (void)v;
    NOT_PROVIDED(fmi2GetIntegerStatus, "no such status");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)s, (void)v;
    NOT_PROVIDED(fmi2GetBooleanStatus, "no such status");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)s, (void)v;
    NOT_PROVIDED(fmi2GetStringStatus, "no such status");
}
