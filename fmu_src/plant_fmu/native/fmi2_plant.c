/*
 * FMI 2.0 co-simulation API of the native CassiePlant FMU: the variable table of
 * fmu_src/plant_fmu/fmu_core.py (generated into cp_vars.h), the FMI 2.0 state machine, and
 * the same refusals as the pythonfmu CassiePlant (a refused call logs a message naming the
 * call, the variable and its range, returns fmi2Error and changes nothing) over the C walker
 * (cassie_plant.c).  Phase masks per function as in fmu_src/native/fmi2_api.c (Reference-FMUs
 * style: one prologue per function).
 */
#include "cassie_plant.h" /* first: the floating-point contract */

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

typedef enum { INSTANTIATED = 1, INIT_MODE = 2, STEP_MODE = 4, TERMINATED = 8 } Phase;
#define ANY (INSTANTIATED | INIT_MODE | STEP_MODE | TERMINATED)
static const char *const PHASE_NAMES[] = {"instantiated", "initializationMode", "stepComplete", "terminated"};
static const char *const TYPE_NAMES[] = {"Real", "Integer", "Boolean", "String"};
/* Relative tolerance on "doStep starts where the last step ended" (fmu_src/fmi/avr_slavebase.py). */
#define TIME_MATCH_RTOL 1e-9

typedef struct {
    char *name;
    fmi2CallbackFunctions cb;
    int logging_on;
    Phase phase;
    double time;
    double values[CP_N_VARS];
    char *resources; /* the resources folder, a file system path */
    CpWalker walker;
    int has_walker;
} Instance;

static void vlog(const Instance *inst, fmi2Status status, const char *category, const char *fmt, va_list ap) {
    if (!inst->cb.logger) return;
    if (status == fmi2OK && !inst->logging_on) return;
    char msg[1200];
    vsnprintf(msg, sizeof msg, fmt, ap);
    inst->cb.logger(inst->cb.componentEnvironment, inst->name, status, category, "%s", msg);
}

#if defined(__GNUC__)
#define PRINTF_LIKE(f, a) __attribute__((format(printf, f, a)))
#else
#define PRINTF_LIKE(f, a)
#endif
static void logf_(const Instance *inst, fmi2Status status, const char *category, const char *fmt, ...)
    PRINTF_LIKE(4, 5);
static void logf_(const Instance *inst, fmi2Status status, const char *category, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog(inst, status, category, fmt, ap);
    va_end(ap);
}

/* Log the refusal (category logStatusError, always) and answer fmi2Error. */
static fmi2Status refuse(const Instance *inst, const char *fmt, ...) PRINTF_LIKE(2, 3);
static fmi2Status refuse(const Instance *inst, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog(inst, fmi2Error, "logStatusError", fmt, ap);
    va_end(ap);
    return fmi2Error;
}
#define REFUSE refuse

static const char *phase_name(Phase p) {
    for (int i = 0; i < 4; i++)
        if (p == (Phase)(1 << i)) return PHASE_NAMES[i];
    return "?";
}

static fmi2Status allowed(const Instance *inst, const char *call, unsigned mask) {
    if (inst->phase & mask) return fmi2OK;
    char list[200] = "";
    for (int i = 0; i < 4; i++)
        if (mask & (1u << i)) {
            if (list[0]) strncat(list, ", ", sizeof list - strlen(list) - 1);
            strncat(list, PHASE_NAMES[i], sizeof list - strlen(list) - 1);
        }
    return REFUSE(inst, "%s is not allowed in state %s (allowed in: %s)", call, phase_name(inst->phase), list);
}

#define BEGIN(call, mask)                                              \
    Instance *inst = (Instance *)c;                                    \
    if (inst == NULL) return fmi2Error;                                \
    if (allowed(inst, call, (mask)) != fmi2OK) return fmi2Error

/* ---- inquiry, creation, life cycle ------------------------------------------------------- */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

static char *resource_path(const char *uri) {
    if (uri == NULL) return NULL;
    const char *p = uri;
    if (!strncmp(p, "file://", 7)) {
        p += 7;
        if (!strncmp(p, "localhost/", 10)) p += 9;
    } else if (!strncmp(p, "file:", 5)) {
        p += 5;
    } else {
        return NULL;
    }
#ifdef _WIN32
    if (p[0] == '/' && p[1] && p[2] == ':') p++; /* file:///C:/... */
#endif
    char *out = malloc(strlen(p) + 1), *o = out;
    if (!out) return NULL;
    for (; *p; p++) {
        if (*p == '%' && p[1] && p[2]) {
            char hex[3] = {p[1], p[2], 0};
            *o++ = (char)strtol(hex, NULL, 16);
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

static void defaults(Instance *inst) {
    for (int i = 0; i < CP_N_VARS; i++) inst->values[i] = CP_VARS[i].start;
    inst->time = 0.0;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    if (functions == NULL) return NULL;
    Instance probe = {.name = (char *)(instanceName ? instanceName : ""), .cb = *functions};
    if (fmuType != fmi2CoSimulation) {
        REFUSE(&probe, "fmi2Instantiate: this FMU supports co-simulation only");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, CP_GUID) != 0) {
        REFUSE(&probe, "fmi2Instantiate: GUID %s is not this FMU's (%s)", fmuGUID ? fmuGUID : "(null)", CP_GUID);
        return NULL;
    }
    char *resources = resource_path(fmuResourceLocation);
    if (resources == NULL) {
        REFUSE(&probe, "fmi2Instantiate: fmuResourceLocation %s is not a file URI; the FMU needs its resources "
               "(the Cassie models)", fmuResourceLocation ? fmuResourceLocation : "(null)");
        return NULL;
    }
    Instance *inst = calloc(1, sizeof *inst);
    if (inst == NULL) {
        free(resources);
        return NULL;
    }
    inst->name = malloc(strlen(probe.name) + 1);
    if (inst->name == NULL) {
        free(resources);
        free(inst);
        return NULL;
    }
    strcpy(inst->name, probe.name);
    inst->cb = *functions;
    inst->logging_on = loggingOn == fmi2True;
    inst->phase = INSTANTIATED;
    inst->resources = resources;
    defaults(inst);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return;
    if (inst->has_walker) cp_free(&inst->walker);
    free(inst->resources);
    free(inst->name);
    free(inst);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]) {
    BEGIN("fmi2SetDebugLogging", ANY);
    if (n > 0 && categories == NULL) return REFUSE(inst, "fmi2SetDebugLogging: categories is NULL with n = %zu", n);
    for (size_t i = 0; i < n; i++) {
        int known = 0;
        for (int k = 0; k < CP_N_LOG_CATEGORIES && categories[i]; k++)
            known |= !strcmp(categories[i], CP_LOG_CATEGORIES[k]);
        if (!known)
            return REFUSE(inst, "fmi2SetDebugLogging: category %zu is not one the model description declares "
                          "(logStatusError, logAll)", i);
    }
    inst->logging_on = loggingOn == fmi2True;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    BEGIN("fmi2SetupExperiment", INSTANTIATED);
    if (!isfinite(startTime)) return REFUSE(inst, "fmi2SetupExperiment: startTime = %.17g: must be finite", startTime);
    inst->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    BEGIN("fmi2EnterInitializationMode", INSTANTIATED);
    inst->phase = INIT_MODE;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    BEGIN("fmi2ExitInitializationMode", INIT_MODE);
    if (!(inst->values[CP_VR_torso_mass_kg] > 0.0))
        return REFUSE(inst, "fmi2ExitInitializationMode refused: torso_mass_kg = %.17g kg: must be in (0, %g] kg",
                      inst->values[CP_VR_torso_mass_kg], CP_VARS[CP_VR_torso_mass_kg].max);
    char models[4200], err[1200];
    snprintf(models, sizeof models, "%s/models", inst->resources);
    if (cp_start(&inst->walker, models, inst->values, err, sizeof err))
        return REFUSE(inst, "fmi2ExitInitializationMode refused: %s", err);
    inst->has_walker = 1;
    cp_outputs(&inst->walker, inst->values);
    inst->phase = STEP_MODE;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    BEGIN("fmi2Terminate", STEP_MODE);
    inst->phase = TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    BEGIN("fmi2Reset", ANY);
    if (inst->has_walker) cp_free(&inst->walker);
    inst->has_walker = 0;
    defaults(inst);
    inst->phase = INSTANTIATED;
    return fmi2OK;
}

/* ---- variables --------------------------------------------------------------------------- */
static const CpVar *lookup(const Instance *inst, const char *call, fmi2ValueReference vr, CpType type) {
    if (vr >= CP_N_VARS) {
        REFUSE(inst, "%s: valueReference %u does not exist (0..%u)", call, (unsigned)vr, (unsigned)CP_N_VARS - 1);
        return NULL;
    }
    const CpVar *v = &CP_VARS[vr];
    if (v->type != type) {
        REFUSE(inst, "%s: %s (valueReference %u) is a %s variable", call, v->name, (unsigned)vr, TYPE_NAMES[v->type]);
        return NULL;
    }
    return v;
}

static fmi2Status check_get(const Instance *inst, const char *call, const fmi2ValueReference vr[], size_t n, CpType type) {
    if (n > 0 && vr == NULL) return REFUSE(inst, "%s: vr is NULL with nvr = %zu", call, n);
    for (size_t i = 0; i < n; i++)
        if (!lookup(inst, call, vr[i], type)) return fmi2Error;
    return fmi2OK;
}

static fmi2Status check_set(const Instance *inst, const char *call, fmi2ValueReference vr, CpType type, double x) {
    const CpVar *v = lookup(inst, call, vr, type);
    if (!v) return fmi2Error;
    if (v->causality == CP_OUTPUT) return REFUSE(inst, "%s: %s is an output and cannot be set", call, v->name);
    if (inst->phase == STEP_MODE && v->causality == CP_PARAMETER)
        return REFUSE(inst, "%s: %s is a fixed parameter: set it before fmi2ExitInitializationMode", call, v->name);
    if (type == CP_BOOLEAN) return fmi2OK;
    if (!isfinite(x) || (type == CP_INTEGER && x != floor(x)) || (v->has_min && x < v->min) || (v->has_max && x > v->max))
        return REFUSE(inst, "%s: %s = %.17g: out of range [%.17g, %.17g]%s", call, v->name, x, v->min, v->max,
                      *v->unit ? v->unit : "");
    return fmi2OK;
}

#define SET_PHASES (INSTANTIATED | INIT_MODE | STEP_MODE)
#define GET_PHASES (INIT_MODE | STEP_MODE | TERMINATED)

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    BEGIN("fmi2GetReal", GET_PHASES);
    if (check_get(inst, "fmi2GetReal", vr, n, CP_REAL)) return fmi2Error;
    for (size_t i = 0; i < n; i++) value[i] = inst->values[vr[i]];
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]) {
    BEGIN("fmi2GetInteger", GET_PHASES);
    if (check_get(inst, "fmi2GetInteger", vr, n, CP_INTEGER)) return fmi2Error;
    for (size_t i = 0; i < n; i++) value[i] = (fmi2Integer)inst->values[vr[i]];
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean value[]) {
    BEGIN("fmi2GetBoolean", GET_PHASES);
    if (check_get(inst, "fmi2GetBoolean", vr, n, CP_BOOLEAN)) return fmi2Error;
    for (size_t i = 0; i < n; i++) value[i] = inst->values[vr[i]] != 0.0 ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String value[]) {
    BEGIN("fmi2GetString", GET_PHASES);
    if (check_get(inst, "fmi2GetString", vr, n, CP_STRING)) return fmi2Error;
    for (size_t i = 0; i < n; i++) value[i] = CP_MODEL_NAMES[(int)inst->values[vr[i]]];
    return fmi2OK;
}

#define SET_BODY(call, type, conv)                                                    \
    BEGIN(call, SET_PHASES);                                                          \
    if (n > 0 && (vr == NULL || value == NULL)) return REFUSE(inst, "%s: NULL array with nvr = %zu", call, n); \
    for (size_t i = 0; i < n; i++)                                                    \
        if (check_set(inst, call, vr[i], type, conv(value[i]))) return fmi2Error;     \
    for (size_t i = 0; i < n; i++) inst->values[vr[i]] = conv(value[i]);              \
    return fmi2OK

#define AS_DOUBLE(x) ((double)(x))
#define AS_BOOL(x) ((x) != fmi2False ? 1.0 : 0.0)

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    SET_BODY("fmi2SetReal", CP_REAL, AS_DOUBLE);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]) {
    SET_BODY("fmi2SetInteger", CP_INTEGER, AS_DOUBLE);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean value[]) {
    SET_BODY("fmi2SetBoolean", CP_BOOLEAN, AS_BOOL);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[]) {
    BEGIN("fmi2SetString", SET_PHASES);
    if (n > 0 && (vr == NULL || value == NULL)) return REFUSE(inst, "fmi2SetString: NULL array with nvr = %zu", n);
    int index[64];
    if (n > 64) return REFUSE(inst, "fmi2SetString: at most 64 values per call");
    for (size_t i = 0; i < n; i++) {
        if (check_set(inst, "fmi2SetString", vr[i], CP_STRING, 0.0)) return fmi2Error;
        index[i] = -1;
        for (int k = 0; k < CP_N_MODELS && value[i]; k++)
            if (!strcmp(value[i], CP_MODEL_NAMES[k])) index[i] = k;
        if (index[i] < 0)
            return REFUSE(inst, "fmi2SetString: cassie_model = '%s': must be one of 'menagerie', 'osu'",
                          value[i] ? value[i] : "(null)");
    }
    for (size_t i = 0; i < n; i++) inst->values[vr[i]] = index[i];
    return fmi2OK;
}

/* ---- stepping ---------------------------------------------------------------------------- */
/* fmu_core.plant_steps: the step as a whole number of plant steps, or -1. */
static long plant_steps(double h) {
    double n = h / CP_PLANT_STEP_S;
    if (!(isfinite(n) && n >= 1.0 - CP_STEPS_TOL && fabs(n - nearbyint(n)) <= CP_STEPS_TOL && h <= CP_MAX_STEP_S))
        return -1;
    return (long)nearbyint(n);
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    BEGIN("fmi2DoStep", STEP_MODE);
    if (!(isfinite(h) && h > 0.0))
        return REFUSE(inst, "fmi2DoStep refused: communicationStepSize = %.17g: must be a finite number > 0", h);
    double tol = TIME_MATCH_RTOL * (fabs(inst->time) > 1.0 ? fabs(inst->time) : 1.0);
    if (!(isfinite(t) && fabs(t - inst->time) <= tol))
        return REFUSE(inst, "fmi2DoStep refused: currentCommunicationPoint = %.17g: must equal the end of the last "
                      "step (%.17g) to within %g s", t, inst->time, tol);
    if (!(h <= CP_MAX_STEP_S))
        return REFUSE(inst, "fmi2DoStep refused: communicationStepSize = %.17g s: exceeds the maximum communication "
                      "step %g s of this FMU (take several steps)", h, CP_MAX_STEP_S);
    long n = plant_steps(h);
    if (n < 0)
        return REFUSE(inst, "fmi2DoStep refused: communicationStepSize = %.17g s: must be a whole multiple of the "
                      "plant step %g s", h, CP_PLANT_STEP_S);
    int fell = inst->values[CP_VR_fell] != 0.0;
    cp_advance(&inst->walker, inst->values, n);
    cp_outputs(&inst->walker, inst->values);
    if (inst->values[CP_VR_fell] != 0.0 && !fell)
        logf_(inst, fmi2OK, "logAll", "CassiePlant fell at t = %.4f s: %s", inst->values[CP_VR_plant_time],
              inst->walker.fall_reason);
    inst->time = t + h;
    return fmi2OK;
}

/* ---- not provided ------------------------------------------------------------------------- */
#define NOT_PROVIDED(call, why)                                         \
    do {                                                                \
        Instance *inst_ = (Instance *)c;                                \
        if (inst_ == NULL) return fmi2Error;                            \
        return REFUSE(inst_, "%s is not provided by this FMU (%s)", call, why); \
    } while (0)

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)s;
    NOT_PROVIDED("fmi2GetFMUstate", "canGetAndSetFMUstate = false");
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    (void)s;
    NOT_PROVIDED("fmi2SetFMUstate", "canGetAndSetFMUstate = false");
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)s;
    NOT_PROVIDED("fmi2FreeFMUstate", "canGetAndSetFMUstate = false");
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)s, (void)n;
    NOT_PROVIDED("fmi2SerializedFMUstateSize", "canSerializeFMUstate = false");
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)s, (void)b, (void)n;
    NOT_PROVIDED("fmi2SerializeFMUstate", "canSerializeFMUstate = false");
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)s, (void)b, (void)n;
    NOT_PROVIDED("fmi2DeSerializeFMUstate", "canSerializeFMUstate = false");
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    NOT_PROVIDED("fmi2GetDirectionalDerivative", "providesDirectionalDerivative = false");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr, (void)n, (void)order, (void)value;
    NOT_PROVIDED("fmi2SetRealInputDerivatives", "canInterpolateInputs = false");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr, (void)n, (void)order, (void)value;
    NOT_PROVIDED("fmi2GetRealOutputDerivatives", "maxOutputDerivativeOrder = 0");
}
fmi2Status fmi2CancelStep(fmi2Component c) { NOT_PROVIDED("fmi2CancelStep", "canRunAsynchronuously = false"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)s, (void)v;
    NOT_PROVIDED("fmi2GetStatus", "doStep never returns fmi2Pending");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)s, (void)v;
    NOT_PROVIDED("fmi2GetRealStatus", "no such status");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)s, (void)v;
    NOT_PROVIDED("fmi2GetIntegerStatus", "no such status");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)s, (void)v;
    NOT_PROVIDED("fmi2GetBooleanStatus", "no such status");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)s, (void)v;
    NOT_PROVIDED("fmi2GetStringStatus", "no such status");
}
