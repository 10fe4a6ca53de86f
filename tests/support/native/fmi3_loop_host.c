/*
 * A plain C FMI 3.0 co-simulation master for a loop of several FMUs (no Python anywhere),
 * for Linux and, cross-compiled with MinGW-w64, for Windows: the FMI 3.0 calls behind the
 * loop of loop_host.h (its header says the script's lines).
 *
 *   fmi3_loop_host SCRIPT
 */
#if !defined(_WIN32)
#define _POSIX_C_SOURCE 200809L /* clock_gettime, dlopen */
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "host_common.h"

#define HOST_NAME "fmi3_loop_host"

typedef struct {
    fmi3Instance c;
    fmi3EnterInitializationModeTYPE *enter;
    fmi3ExitInitializationModeTYPE *exit_init;
    fmi3SetFloat64TYPE *set_real;
    fmi3SetInt32TYPE *set_int;
    fmi3SetBooleanTYPE *set_bool;
    fmi3SetStringTYPE *set_string;
    fmi3GetFloat64TYPE *get_real;
    fmi3GetInt32TYPE *get_int;
    fmi3GetBooleanTYPE *get_bool;
    fmi3DoStepTYPE *do_step;
    fmi3TerminateTYPE *terminate;
    fmi3FreeInstanceTYPE *free_instance;
} Fmu;

/* FMI 3.0 logger: the instance environment is the instance's name. */
static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)category;
    fprintf(stderr, "[%s status %d] %s\n", (const char *)env, (int)status, message);
}

#define SYM(f, field, name)                                               \
    if (((f)->field = lib_sym(lib, name)) == NULL) {                      \
        fprintf(stderr, "missing %s\n", name);                            \
        return 2;                                                         \
    }
#define CHECK(call)                                                       \
    if ((call) != fmi3OK) {                                               \
        fprintf(stderr, "%s failed\n", #call);                            \
        return 3;                                                         \
    }

static char names[4][32];

static int fmu_load(Fmu *f, const char *path, const char *token, const char *resources, int index) {
    Lib lib = lib_open(path);
    if (lib == NULL) {
        fprintf(stderr, "cannot load %s\n", path);
        return 2;
    }
    fmi3InstantiateCoSimulationTYPE *inst = (fmi3InstantiateCoSimulationTYPE *)lib_sym(lib, "fmi3InstantiateCoSimulation");
    if (inst == NULL) return 2;
    SYM(f, enter, "fmi3EnterInitializationMode")
    SYM(f, exit_init, "fmi3ExitInitializationMode") SYM(f, set_real, "fmi3SetFloat64")
    SYM(f, set_int, "fmi3SetInt32") SYM(f, set_bool, "fmi3SetBoolean") SYM(f, set_string, "fmi3SetString")
    SYM(f, get_real, "fmi3GetFloat64") SYM(f, get_int, "fmi3GetInt32") SYM(f, get_bool, "fmi3GetBoolean")
    SYM(f, do_step, "fmi3DoStep") SYM(f, terminate, "fmi3Terminate") SYM(f, free_instance, "fmi3FreeInstance")
    snprintf(names[index], sizeof names[index], "fmu%d", index);
    f->c = inst(names[index], token, strcmp(resources, "-") ? resources : NULL, fmi3False, fmi3False, fmi3False,
                fmi3False, NULL, 0, names[index], logger, NULL);
    if (f->c == NULL) {
        fprintf(stderr, "fmi3InstantiateCoSimulation of %s returned NULL\n", path);
        return 4;
    }
    CHECK(f->enter(f->c, fmi3False, 0.0, 0.0, fmi3False, 0.0))
    return 0;
}

static int fmu_set(Fmu *f, char type, unsigned vr, double value) {
    const fmi3ValueReference r = vr;
    const fmi3Int32 iv = (fmi3Int32)value;
    const fmi3Boolean bv = value != 0.0;
    if (type == 'R') CHECK(f->set_real(f->c, &r, 1, &value, 1))
    if (type == 'I') CHECK(f->set_int(f->c, &r, 1, &iv, 1))
    if (type == 'B') CHECK(f->set_bool(f->c, &r, 1, &bv, 1))
    return 0;
}

static int fmu_set_string(Fmu *f, unsigned vr, const char *word) {
    const fmi3ValueReference r = vr;
    const fmi3String s = word;
    CHECK(f->set_string(f->c, &r, 1, &s, 1))
    return 0;
}

static int fmu_get(const Fmu *f, char type, unsigned vr, double *value) {
    const fmi3ValueReference r = vr;
    if (type == 'R') {
        CHECK(f->get_real(f->c, &r, 1, value, 1))
    } else if (type == 'I') {
        fmi3Int32 iv;
        CHECK(f->get_int(f->c, &r, 1, &iv, 1))
        *value = iv;
    } else {
        fmi3Boolean bv;
        CHECK(f->get_bool(f->c, &r, 1, &bv, 1))
        *value = bv;
    }
    return 0;
}

static int fmu_exit_init(Fmu *f) {
    CHECK(f->exit_init(f->c))
    return 0;
}

static int fmu_do_step(Fmu *f, double t, double h) {
    fmi3Boolean event, terminate, early;
    fmi3Float64 last;
    CHECK(f->do_step(f->c, t, h, fmi3True, &event, &terminate, &early, &last))
    return 0;
}

static int fmu_end(Fmu *f) {
    CHECK(f->terminate(f->c))
    f->free_instance(f->c);
    return 0;
}

#include "loop_host.h"
