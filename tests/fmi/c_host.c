/*
 * A minimal C co-simulation host for the AdaptiveVelocityRegulator FMU (FMI 2.0 CS).
 *
 *   c_host UNZIPPED_FMU_DIR GUID N_STEPS
 *
 * Loads binaries/linux64/AdaptiveVelocityRegulator.so, runs N_STEPS steps of 5 ms with
 * the deterministic inputs below and prints every output (%.17g) per step.  Used by
 * tests/test_fmu_c_host.py to show what a non-Python host needs.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env; (void)category;
    va_list args;
    va_start(args, message);
    fprintf(stderr, "[%s status %d] ", name, (int)status);
    vfprintf(stderr, message, args);
    fprintf(stderr, "\n");
    va_end(args);
}

#define LOAD(fn)                                                         \
    fn##TYPE *fn = (fn##TYPE *)dlsym(lib, #fn);                          \
    if (fn == NULL) { fprintf(stderr, "missing %s\n", #fn); return 2; }

#define CHECK(call)                                                      \
    if ((call) != fmi2OK) { fprintf(stderr, "%s failed\n", #call); return 3; }

int main(int argc, char **argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: c_host UNZIPPED_FMU_DIR GUID N_STEPS\n");
        return 1;
    }
    char path[4096], resources[4200];
    snprintf(path, sizeof path, "%s/binaries/linux64/AdaptiveVelocityRegulator.so", argv[1]);
    snprintf(resources, sizeof resources, "file://%s/resources", argv[1]);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
        return 2;
    }
    LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationMode) LOAD(fmi2SetReal) LOAD(fmi2SetInteger) LOAD(fmi2GetReal)
    LOAD(fmi2DoStep) LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("c_host", fmi2CoSimulation, argv[2], resources, &callbacks, fmi2False,
                                      fmi2False);
    if (c == NULL) {
        fprintf(stderr, "fmi2Instantiate returned NULL\n");
        return 4;
    }
    /* value references: the host reads them from modelDescription.xml; here via the environment */
    const char *vr_env = getenv("AVR_VRS");  /* "vx,vx_des,pitch,step_index,out0,out1,..." */
    if (vr_env == NULL) { fprintf(stderr, "set AVR_VRS\n"); return 1; }
    fmi2ValueReference vrs[64];
    int n = 0;
    char *list = strdup(vr_env);
    for (char *tok = strtok(list, ","); tok && n < 64; tok = strtok(NULL, ",")) vrs[n++] = (fmi2ValueReference)atoi(tok);
    free(list);
    int n_out = n - 4;
    CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0))
    CHECK(fmi2EnterInitializationMode(c))
    CHECK(fmi2ExitInitializationMode(c))
    const double h = 0.005;
    int steps = atoi(argv[3]);
    for (int k = 0; k < steps; ++k) {
        fmi2Real in[3] = {0.5 + 0.3 * sin(0.05 * k), 0.5, 0.02 * cos(0.1 * k)}; /* vx, vx_des, pitch */
        fmi2Integer step_index = k / 70;
        CHECK(fmi2SetReal(c, vrs, 3, in))
        CHECK(fmi2SetInteger(c, vrs + 3, 1, &step_index))
        CHECK(fmi2DoStep(c, k * h, h, fmi2True))
        fmi2Real out[60];
        CHECK(fmi2GetReal(c, vrs + 4, (size_t)n_out, out))
        for (int i = 0; i < n_out; ++i) printf(i ? " %.17g" : "%.17g", out[i]);
        printf("\n");
    }
    CHECK(fmi2Terminate(c))
    fmi2FreeInstance(c);
    return 0;
}
