/*
 * FMI 2.0 co-simulation API of the native CassiePlant FMU: a thin layer over the
 * version-independent instance (cp_instance.c).  Every function starts with the one prologue
 * BEGIN (fmu_src/fmi/fmi_layer.h), which refuses a call outside the phases of its
 * FMI_MASK_<function> (fmi_phase_rules.h, generated from fmu_src/fmi/phase_rules.py); the
 * shapes every native FMU shares are written once in fmi_layer.h, and the inquiry functions,
 * doStep, the status functions and the functions no native FMU provides in fmi2_common.c.
 */
#include "cp_instance.h" /* first: the floating-point contract */

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define FMI_STATUS fmi2Status
#define FMI_INSTANCE fmi2Component
#include "fmi_layer.h"

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
    fmi2CallbackFunctions *cb = fmi2_callbacks(functions);
    if (cb == NULL) return NULL;
    CpInstance probe = {.name = (char *)(instanceName ? instanceName : ""), .env = cb, .log = fmi2_log,
                        .phase_names = FMI2_PHASE_NAMES};
    CpInstance *inst = NULL;
    char *resources = uri_path(fmuResourceLocation);
    if (fmuType != fmi2CoSimulation)
        cp_refuse(&probe, "fmi2Instantiate", "this FMU supports co-simulation only");
    else if (resources == NULL)
        cp_refuse(&probe, "fmi2Instantiate", "fmuResourceLocation %s is not a file URI; the FMU needs its resources",
                  fmuResourceLocation ? fmuResourceLocation : "(null)");
    else
        inst = cp_instantiate(instanceName, fmuGUID, resources, cb, fmi2_log, loggingOn == fmi2True, FMI2_PHASE_NAMES);
    free(resources);
    if (inst == NULL) free(cb);
    return inst;
}

FREE_INSTANCE(fmi2FreeInstance)

SET_DEBUG_LOGGING(fmi2SetDebugLogging, fmi2Boolean, fmi2String)

fmi2Status fmi2SetupExperiment(fmi2Component instance, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BEGIN(fmi2SetupExperiment)
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    return (fmi2Status)cp_setup(inst, call, startTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component instance) {
    BEGIN(fmi2EnterInitializationMode)
    inst->phase = CP_INIT_MODE;
    return fmi2OK;
}

EXIT_INITIALIZATION_MODE(fmi2ExitInitializationMode)
TERMINATE(fmi2Terminate)
RESET(fmi2Reset)

/* ---- variables (FMI2_GETTER, FMI2_SETTER: fmi_layer.h) --------------------------------------- */
#define FROM_BOOL(x) ((x) != fmi2False ? 1.0 : 0.0) /* any nonzero fmi2Boolean is true */
FMI2_NUMERIC_VARIABLES(CP_REAL, CP_INTEGER, CP_BOOLEAN, FROM_BOOL)

/* Strings: cassie_model and terrain_field_file (cp_set_strings, cp_get_string). */
fmi2Status fmi2GetString(fmi2Component instance, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    BEGIN(fmi2GetString)
    if (nvr > 0 && value == NULL) REFUSE("NULL value array with nvr = %zu", nvr);
    if (cp_check_get(inst, call, vr, nvr, CP_STRING) != CP_OK) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = cp_get_string(inst, vr[i]);
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component instance, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    BEGIN(fmi2SetString)
    return (fmi2Status)cp_set_strings(inst, call, vr, value, nvr);
}

/* ---- FMU state (cp_instance.c, through FMUSTATE_FUNCTIONS of fmi_layer.h) --------------------- */
FMUSTATE_FUNCTIONS(fmi2FMUstate, fmi2Byte, fmi2GetFMUstate, fmi2SetFMUstate, fmi2FreeFMUstate,
                   fmi2SerializedFMUstateSize, fmi2SerializeFMUstate, fmi2DeSerializeFMUstate)
