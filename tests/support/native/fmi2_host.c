/*
 * A plain C FMI 2.0 co-simulation host (no Python anywhere), for Linux and, cross-compiled
 * with MinGW-w64, for Windows (run under Wine in the tests).
 *
 *   fmi2_host LIBRARY GUID SCRIPT [REPEATS]
 *
 * SCRIPT is a text file of lines:
 *   P vr R|I|B value      set a parameter before initialization
 *   I vr1 .. vr8 vr9      value references of the 8 Real inputs and the Integer step_index
 *   O vr1 .. vrN          value references of the outputs to print
 *   S x1 .. x8 k          one communication step of 5 ms with these inputs
 * Without REPEATS every step's outputs are printed (%.17g).  With REPEATS the S lines are
 * run REPEATS times over (time continuing) and only timing is printed: the median and
 * mean wall time of one set+doStep+get, in microseconds.
 *
 * The environment variable FMI2_HOST_RESOURCES, if set, is the fmuResourceLocation URI
 * passed to fmi2Instantiate (a pythonfmu FMU needs its resources folder; the native FMU
 * needs none: "file:///" by default).
 */
#if !defined(_WIN32)
#define _POSIX_C_SOURCE 200809L /* clock_gettime, dlopen */
#endif
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#include "host_common.h"

#define MAX_STEPS 200000
#define MAX_OUT 64

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

#define LOAD(fn)                                                          \
    fn##TYPE *fn = (fn##TYPE *)lib_sym(lib, #fn);                         \
    if (fn == NULL) { fprintf(stderr, "missing %s\n", #fn); return 2; }
#define CHECK(call)                                                       \
    if ((call) != fmi2OK) { fprintf(stderr, "%s failed\n", #call); return 3; }

static double inputs[MAX_STEPS][9];
static double durations[MAX_STEPS];

int main(int argc, char **argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: fmi2_host LIBRARY GUID SCRIPT [REPEATS]\n");
        return 1;
    }
    int repeats = argc > 4 ? atoi(argv[4]) : 0;
    Lib lib = lib_open(argv[1]);
    if (lib == NULL) { fprintf(stderr, "cannot load %s\n", argv[1]); return 2; }
    LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationMode) LOAD(fmi2SetReal) LOAD(fmi2SetInteger) LOAD(fmi2SetBoolean)
    LOAD(fmi2GetReal) LOAD(fmi2DoStep) LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)
    fmi2CallbackFunctions callbacks = {host_fmi2_logger, calloc, free, NULL, NULL};
    const char *resources = getenv("FMI2_HOST_RESOURCES");
    fmi2Component c = fmi2Instantiate("fmi2_host", fmi2CoSimulation, argv[2], resources ? resources : "file:///",
                                      &callbacks, fmi2False, fmi2False);
    if (c == NULL) { fprintf(stderr, "fmi2Instantiate returned NULL\n"); return 4; }
    FILE *script = fopen(argv[3], "r");
    if (script == NULL) { fprintf(stderr, "cannot open %s\n", argv[3]); return 1; }
    fmi2ValueReference in_vr[9], out_vr[MAX_OUT];
    int n_out = 0, n_steps = 0;
    char kind[4];
    while (fscanf(script, "%3s", kind) == 1) {
        if (kind[0] == 'P') {
            unsigned vr;
            char type[4];
            double value;
            if (fscanf(script, "%u %3s %lf", &vr, type, &value) != 3) return 1;
            fmi2ValueReference r = vr;
            fmi2Integer i = (fmi2Integer)value;
            fmi2Boolean b = value != 0.0;
            if (type[0] == 'R') CHECK(fmi2SetReal(c, &r, 1, &value))
            if (type[0] == 'I') CHECK(fmi2SetInteger(c, &r, 1, &i))
            if (type[0] == 'B') CHECK(fmi2SetBoolean(c, &r, 1, &b))
        } else if (kind[0] == 'I') {
            for (int j = 0; j < 9; ++j)
                if (fscanf(script, "%u", &in_vr[j]) != 1) return 1;
        } else if (kind[0] == 'O') {
            if (fscanf(script, "%d", &n_out) != 1 || n_out > MAX_OUT) return 1;
            for (int j = 0; j < n_out; ++j)
                if (fscanf(script, "%u", &out_vr[j]) != 1) return 1;
        } else if (kind[0] == 'S' && n_steps < MAX_STEPS) {
            for (int j = 0; j < 9; ++j)
                if (fscanf(script, "%lf", &inputs[n_steps][j]) != 1) return 1;
            ++n_steps;
        }
    }
    fclose(script);
    CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0))
    CHECK(fmi2EnterInitializationMode(c))
    CHECK(fmi2ExitInitializationMode(c))
    const double h = 0.005;
    long k = 0;
    fmi2Real out[MAX_OUT];
    for (int rep = 0; rep < (repeats > 0 ? repeats : 1); ++rep) {
        for (int s = 0; s < n_steps; ++s, ++k) {
            fmi2Integer step_index = (fmi2Integer)inputs[s][8];
            double t0 = 1e6 * now_s();
            CHECK(fmi2SetReal(c, in_vr, 8, inputs[s]))
            CHECK(fmi2SetInteger(c, in_vr + 8, 1, &step_index))
            CHECK(fmi2DoStep(c, (double)k * h, h, fmi2True))
            CHECK(fmi2GetReal(c, out_vr, (size_t)n_out, out))
            durations[s] = 1e6 * now_s() - t0;
            if (repeats > 0) continue;
            for (int j = 0; j < n_out; ++j) printf(j ? " %.17g" : "%.17g", out[j]);
            printf("\n");
        }
    }
    if (repeats > 0) { /* the last repetition's per-step times */
        double mean = 0.0;
        for (int s = 0; s < n_steps; ++s) mean += durations[s] / n_steps;
        qsort(durations, (size_t)n_steps, sizeof durations[0], cmp_double);
        printf("median_us %.3f mean_us %.3f steps %d\n", durations[n_steps / 2], mean, n_steps);
    }
    CHECK(fmi2Terminate(c))
    fmi2FreeInstance(c);
    return 0;
}
