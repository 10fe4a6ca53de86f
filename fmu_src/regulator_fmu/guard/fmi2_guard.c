/*
 * FMI 2.0 co-simulation guard for the AdaptiveVelocityRegulator FMU.
 *
 * This is the library a host loads (binaries/linux64/<modelIdentifier>.so).  It keeps
 * the FMI 2.0 co-simulation state machine (FMI 2.0.x section 4.2.4) per instance,
 * checks every call, pointer, string and value against the standard and the model
 * description, and only then forwards to pythonfmu's library
 * (<modelIdentifier>_pythonfmu.so, beside this one), which runs the Python slave.
 *
 * Why: pythonfmu 0.7.0 enforces no state machine, reports a refusal from Python only as
 * fmi2Fatal, dereferences NULL strings, crashes on resource locations it cannot load,
 * and after a Python exception releases the slave's objects once when failing and again
 * in fmi2FreeInstance (a double free).  Here:
 *
 *  - a refused call returns fmi2Error, is logged naming the variable, value and allowed
 *    range (or the reason), and has no effect: the instance stays usable and keeps what
 *    it has learned;
 *  - strings (instanceName, GUID, resource URI, log categories, String values) must be
 *    non-NULL, valid UTF-8 and of bounded length; the resource URI may be any local
 *    form FMI 2.0 allows (file:///p, file:/p, file://localhost/p, percent-escapes) and is
 *    handed to pythonfmu as the canonical path of a folder that holds this FMU's slave;
 *  - FMU states are checked completely in C (guard_state.c) before Python sees them;
 *  - after a Fatal from the inner library every call but fmi2FreeInstance returns
 *    fmi2Fatal without reaching Python, and fmi2FreeInstance then releases only the
 *    guard's own memory (pythonfmu's instance is deliberately leaked: freeing it would
 *    release its Python objects a second time).
 *
 * A Python slave cannot answer fmi2Error itself (pythonfmu turns an exception into
 * fmi2Fatal): a call after which pythonfmu reports fmi2OK but the slave logged a message
 * with status fmi2Error is answered with fmi2Error (the slave logs the reason and changes
 * nothing).  For that pythonfmu is instantiated with loggingOn and keeps logging; its
 * messages reach the host if they are warnings or worse, or while the host has logging on.
 *
 * The same sources guard a second FMU (CassiePlant) built with its own table; its
 * avr_guard_vars.h may define AVR_STEP_QUANTUM: communication steps must then be whole
 * multiples of it, and AVR_MAX_STEP: the longest communication step (one that long must
 * finish in bounded time; a longer one is refused before it reaches the slave).
 *
 * The variable table (AVR_VARS, the fixed parameters, the log categories) is generated
 * by build.py from the model description into avr_guard_vars.h.  Each FMI function's
 * allowed phases are its FMI_MASK_<function> in fmi_phase_rules.h (generated from
 * fmu_src/fmi/phase_rules.py), checked by the one PROLOGUE macro (guard.h).
 */
#define _GNU_SOURCE
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "guard.h"

/* Relative tolerance on "doStep starts where the last step ended" (t0 + k*h vs t + h differ by ulps). */
#define TIME_MATCH_RTOL 1e-9
#ifdef AVR_STEP_QUANTUM
/* "A whole multiple of AVR_STEP_QUANTUM": within 1e-6 of a whole number >= 1 of quanta. */
#define STEP_QUANTUM_TOL 1e-6
#endif

/* pythonfmu's messages reach the host through here: pythonfmu passes its text as the format
 * string and a NULL category when it has none; the host gets "%s" and a declared category. */
static void inner_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                         fmi2String message, ...) {
    (void)name;
    Guard *g = (Guard *)env;
    if (g == NULL) return;
    if (status == fmi2Error) g->inner_logged_error = 1;
    if (g->host.logger == NULL || (status == fmi2OK && !g->logging_on)) return;
    if (category == NULL || string_problem(category, MAX_CATEGORY_BYTES) != NULL) category = "logAll";
    if (message == NULL || string_problem(message, MAX_INNER_MESSAGE_BYTES) != NULL) message = "(unprintable message)";
    g->host.logger(g->host.componentEnvironment, g->name, status, category, "%s", message);
}

/* ---- inquiry and life cycle ------------------------------------------------------------ */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

/* Why fmi2Instantiate cannot proceed (written to why[]), or NULL; *path gets the resources folder. */
static const char *instantiate_problem(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                       fmi2String fmuResourceLocation, char **path, char *why, size_t n) {
    const char *p = string_problem(instanceName, MAX_NAME_BYTES);
    if (p != NULL || instanceName[0] == '\0') {
        snprintf(why, n, "instanceName %s", p ? p : "is empty");
        return why;
    }
    if (fmuType != fmi2CoSimulation) return "this FMU supports co-simulation only (fmuType must be fmi2CoSimulation)";
    if ((p = string_problem(fmuGUID, MAX_GUID_BYTES)) != NULL) {
        snprintf(why, n, "fmuGUID %s", p);
        return why;
    }
    if (strcmp(fmuGUID, AVR_GUID) != 0) {
        snprintf(why, n, "GUID %s does not match this FMU's %s", fmuGUID, AVR_GUID);
        return why;
    }
    char reason[600];
    if ((*path = resource_path(fmuResourceLocation, reason, sizeof reason)) == NULL) {
        snprintf(why, n, "fmuResourceLocation: %s", reason);
        return why;
    }
    return inner_load_problem();
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    /* allocateMemory/freeMemory may be NULL: canNotUseMemoryManagementFunctions is true */
    if (functions == NULL || functions->logger == NULL) return NULL;  /* nowhere to say why */
    const char *name = string_problem(instanceName, MAX_NAME_BYTES) == NULL ? instanceName : "(invalid instanceName)";
    char why[1024], *path = NULL;
    const char *problem = instantiate_problem(instanceName, fmuType, fmuGUID, fmuResourceLocation, &path, why,
                                              sizeof why);
    Guard *g = problem ? NULL : calloc(1, sizeof *g);
    char *copy = g ? strdup(instanceName) : NULL;
    if (problem == NULL && copy == NULL) problem = "out of memory";
    if (problem != NULL) {
        Guard probe = {.host = *functions, .name = (char *)name};
        guard_log(&probe, fmi2Error, "fmi2Instantiate failed: %s", problem);
        free(g);
        free(path);
        return NULL;
    }
    g->tag = GUARD_TAG;
    g->host = *functions;
    g->to_inner = *functions;
    g->to_inner.logger = inner_logger;
    g->to_inner.componentEnvironment = g;
    g->name = copy;
    g->phase = INSTANTIATED;
    g->logging_on = loggingOn;
    fixed_defaults(g->fixed);
    g->inner = inner.fmi2Instantiate(instanceName, fmuType, fmuGUID, path, &g->to_inner, visible, fmi2True);
    free(path);
    if (g->inner == NULL) {
        guard_log(g, fmi2Error, "fmi2Instantiate failed: pythonfmu could not create the Python slave (its reason "
                  "is logged above)");
        g->tag = 0;
        free(copy);
        free(g);
        return NULL;
    }
    return g;
}

void fmi2FreeInstance(fmi2Component c) {
    Guard *g = (Guard *)c;
    if (g == NULL || g->tag != GUARD_TAG) return;
    /* After a Fatal pythonfmu has already released the slave's Python objects once; its
     * fmi2FreeInstance would release them again (heap corruption).  Leak it instead. */
    if (g->phase != FATAL) inner.fmi2FreeInstance(g->inner);
    g->tag = 0;
    free(g->name);
    free(g);
}

static int is_log_category(const char *s) {
    for (unsigned i = 0; i < AVR_N_LOG_CATEGORIES; ++i)
        if (strcmp(s, AVR_LOG_CATEGORIES[i]) == 0) return 1;
    return 0;
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    PROLOGUE(fmi2SetDebugLogging);
    if (nCategories > 0 && categories == NULL) return refuse(g, call, "categories is NULL (nCategories = %zu)", nCategories);
    for (size_t i = 0; i < nCategories; ++i) {
        const char *p = string_problem(categories[i], MAX_CATEGORY_BYTES);
        if (p != NULL) return refuse(g, call, "categories[%zu] %s", i, p);
        if (!is_log_category(categories[i])) {
            char known[400] = "";
            for (unsigned k = 0; k < AVR_N_LOG_CATEGORIES; ++k) {
                size_t used = strlen(known);
                snprintf(known + used, sizeof known - used, "%s%s", k ? ", " : "", AVR_LOG_CATEGORIES[k]);
            }
            return refuse(g, call, "categories[%zu] = \"%.100s\" is not a log category of this FMU (known: %s)", i,
                          categories[i], known);
        }
    }
    g->logging_on = loggingOn;  /* pythonfmu keeps logging: its errors must reach track() */
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    PROLOGUE(fmi2SetupExperiment);
    if (!isfinite(startTime)) return refuse(g, call, "startTime = %g: must be finite", startTime);
    if (stopTimeDefined && !(stopTime >= startTime))
        return refuse(g, call, "stopTime = %g: must be >= startTime = %g", stopTime, startTime);
    fmi2Status s = track(g, inner.fmi2SetupExperiment(g->inner, toleranceDefined, tolerance, startTime,
                                                      stopTimeDefined, stopTime));
    if (s == fmi2OK) g->time = startTime;
    return s;
}

/* What the inner library answered a phase transition (see track); on fmi2OK the instance is in `next`. */
static fmi2Status moved_to(Guard *g, fmi2Status answer, enum Phase next) {
    const fmi2Status s = track(g, answer);
    if (s == fmi2OK) g->phase = next;
    return s;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    PROLOGUE(fmi2EnterInitializationMode);
    return moved_to(g, inner.fmi2EnterInitializationMode(g->inner), INIT_MODE);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    PROLOGUE(fmi2ExitInitializationMode);
    return moved_to(g, inner.fmi2ExitInitializationMode(g->inner), STEP_COMPLETE);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    PROLOGUE(fmi2Terminate);
    return moved_to(g, inner.fmi2Terminate(g->inner), TERMINATED);
}

fmi2Status fmi2Reset(fmi2Component c) {
    PROLOGUE(fmi2Reset);
    const fmi2Status s = moved_to(g, inner.fmi2Reset(g->inner), INSTANTIATED);
    if (s == fmi2OK) {
        g->time = 0.0;
        fixed_defaults(g->fixed);
    }
    return s;
}

/* ---- stepping -------------------------------------------------------------------------------- */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    PROLOGUE(fmi2DoStep);
    if (!(isfinite(communicationStepSize) && communicationStepSize > 0.0))
        return refuse(g, call, "communicationStepSize = %g: must be a finite number > 0", communicationStepSize);
    double tolerance = TIME_MATCH_RTOL * (fabs(g->time) > 1.0 ? fabs(g->time) : 1.0);
    if (!(isfinite(currentCommunicationPoint) && fabs(currentCommunicationPoint - g->time) <= tolerance))
        return refuse(g, call, "currentCommunicationPoint = %.17g: must equal the end of the last step (%.17g)",
                      currentCommunicationPoint, g->time);
    if (!isfinite(currentCommunicationPoint + communicationStepSize))
        return refuse(g, call, "currentCommunicationPoint + communicationStepSize overflows");
#ifdef AVR_MAX_STEP
    if (!(communicationStepSize <= AVR_MAX_STEP))
        return refuse(g, call, "communicationStepSize = %.17g s: exceeds the maximum communication step %g s of this "
                      "FMU (take several steps)", communicationStepSize, AVR_MAX_STEP);
#endif
#ifdef AVR_STEP_QUANTUM
    const double quanta = communicationStepSize / AVR_STEP_QUANTUM;
    if (!(quanta >= 1.0 - STEP_QUANTUM_TOL && fabs(quanta - nearbyint(quanta)) <= STEP_QUANTUM_TOL))
        return refuse(g, call, "communicationStepSize = %.17g s: must be a whole multiple of the plant step %g s",
                      communicationStepSize, AVR_STEP_QUANTUM);
#endif
    fmi2Status s = track(g, inner.fmi2DoStep(g->inner, currentCommunicationPoint, communicationStepSize,
                                             noSetFMUStatePriorToCurrentPoint));
    if (s == fmi2OK) {
        g->time = currentCommunicationPoint + communicationStepSize;
    } else if (s == fmi2Discard || s == fmi2Error) {
        g->phase = STEP_FAILED;
    }
    return s;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    PROLOGUE(fmi2GetRealStatus);
    if (s != fmi2LastSuccessfulTime || value == NULL)
        return refuse(g, call, "only fmi2LastSuccessfulTime is supported, with a non-NULL value pointer");
    *value = g->time;
    return fmi2OK;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    PROLOGUE(fmi2GetBooleanStatus);
    if (s != fmi2Terminated || value == NULL)
        return refuse(g, call, "only fmi2Terminated is supported, with a non-NULL value pointer");
    *value = fmi2False; /* the regulator never asks to end the simulation */
    return fmi2OK;
}

/* ---- not supported by this FMU (capability flags say so) ----------------------------------- */
#define UNSUPPORTED(fn, why)                  \
    PROLOGUE_MASK(fn, FMI_ANY_PHASE);         \
    return refuse(g, call, "not supported (%s)", why)

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    UNSUPPORTED(fmi2GetDirectionalDerivative, "providesDirectionalDerivative=false");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    UNSUPPORTED(fmi2SetRealInputDerivatives, "canInterpolateInputs=false");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    UNSUPPORTED(fmi2GetRealOutputDerivatives, "maxOutputDerivativeOrder=0");
}
fmi2Status fmi2CancelStep(fmi2Component c) { UNSUPPORTED(fmi2CancelStep, "canRunAsynchronuously=false"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    UNSUPPORTED(fmi2GetStatus, "this FMU never returns fmi2Pending");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    UNSUPPORTED(fmi2GetIntegerStatus, "no integer status");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    UNSUPPORTED(fmi2GetStringStatus, "no string status");
}
