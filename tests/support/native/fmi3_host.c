/*
 * A plain C FMI 3.0 co-simulation host (no Python anywhere), for Linux x86-64 and,
 * cross-compiled, for Linux aarch64 (run under qemu-aarch64 in the tests).
 *
 *   fmi3_host LIBRARY INSTANTIATION_TOKEN SCRIPT
 *
 * SCRIPT has the lines of tests/support/native/fmi2_host.c's scripts:
 *   P vr F|R|I|B value    set a parameter before initialization (Float64, Int32, Boolean)
 *   I vr1 .. vr8 vr9      value references of the 8 Float64 inputs and the Int32 step_index
 *   O n vr1 .. vrn        value references of the Float64 outputs to print
 *   S x1 .. x8 k          one communication step of 5 ms with these inputs
 * Every step's outputs are printed (%.17g, which reads back as the same double).
 */
#define _POSIX_C_SOURCE 200809L /* dlopen */
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"
#include "host_common.h"

#define MAX_STEPS 200000
#define MAX_OUT 64

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)env;
    fprintf(stderr, "[status %d %s] %s\n", (int)status, category ? category : "", message ? message : "");
}

#define LOAD(fn)                                                          \
    fn##TYPE *fn = (fn##TYPE *)lib_sym(lib, #fn);                         \
    if (fn == NULL) { fprintf(stderr, "missing %s\n", #fn); return 2; }
#define CHECK(call)                                                       \
    if ((call) != fmi3OK) { fprintf(stderr, "%s failed\n", #call); return 3; }

static double inputs[MAX_STEPS][9];

int main(int argc, char **argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: fmi3_host LIBRARY INSTANTIATION_TOKEN SCRIPT\n");
        return 1;
    }
    Lib lib = lib_open(argv[1]);
    if (lib == NULL) { fprintf(stderr, "cannot load %s: %s\n", argv[1], dlerror()); return 2; }
    LOAD(fmi3InstantiateCoSimulation) LOAD(fmi3EnterInitializationMode) LOAD(fmi3ExitInitializationMode)
    LOAD(fmi3SetFloat64) LOAD(fmi3SetInt32) LOAD(fmi3SetBoolean) LOAD(fmi3GetFloat64) LOAD(fmi3DoStep)
    LOAD(fmi3Terminate) LOAD(fmi3FreeInstance)
    fmi3Instance c = fmi3InstantiateCoSimulation("fmi3_host", argv[2], NULL, fmi3False, fmi3False, fmi3False,
                                                 fmi3False, NULL, 0, NULL, logger, NULL);
    if (c == NULL) { fprintf(stderr, "fmi3InstantiateCoSimulation returned NULL\n"); return 4; }
    FILE *script = fopen(argv[3], "r");
    if (script == NULL) { fprintf(stderr, "cannot open %s\n", argv[3]); return 1; }
    fmi3ValueReference in_vr[9], out_vr[MAX_OUT];
    int n_out = 0, n_steps = 0;
    char kind[4];
    while (fscanf(script, "%3s", kind) == 1) {
        if (kind[0] == 'P') {
            unsigned vr;
            char type[4];
            double value;
            if (fscanf(script, "%u %3s %lf", &vr, type, &value) != 3) return 1;
            fmi3ValueReference r = vr;
            fmi3Int32 i = (fmi3Int32)value;
            fmi3Boolean b = value != 0.0;
            if (type[0] == 'F' || type[0] == 'R') CHECK(fmi3SetFloat64(c, &r, 1, &value, 1))
            if (type[0] == 'I') CHECK(fmi3SetInt32(c, &r, 1, &i, 1))
            if (type[0] == 'B') CHECK(fmi3SetBoolean(c, &r, 1, &b, 1))
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
    CHECK(fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0))
    CHECK(fmi3ExitInitializationMode(c))
    const double h = 0.005;
    fmi3Float64 out[MAX_OUT];
    for (int s = 0; s < n_steps; ++s) {
        fmi3Int32 step_index = (fmi3Int32)inputs[s][8];
        fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
        fmi3Float64 last = 0.0;
        CHECK(fmi3SetFloat64(c, in_vr, 8, inputs[s], 8))
        CHECK(fmi3SetInt32(c, in_vr + 8, 1, &step_index, 1))
        CHECK(fmi3DoStep(c, (double)s * h, h, fmi3True, &event, &terminate, &early, &last))
        CHECK(fmi3GetFloat64(c, out_vr, (size_t)n_out, out, (size_t)n_out))
        for (int j = 0; j < n_out; ++j) printf(j ? " %.17g" : "%.17g", out[j]);
        printf("\n");
    }
    CHECK(fmi3Terminate(c))
    fmi3FreeInstance(c);
    return 0;
}
