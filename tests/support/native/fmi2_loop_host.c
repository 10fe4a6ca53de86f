/*
 * A plain C FMI 2.0 co-simulation master for a loop of several FMUs (no Python anywhere),
 * for Linux and, cross-compiled with MinGW-w64, for Windows: the FMI 2.0 calls behind the
 * loop of loop_host.h (its header says the script's lines).
 *
 *   fmi2_loop_host SCRIPT
 */
#if !defined(_WIN32)
#define _POSIX_C_SOURCE 200809L /* clock_gettime, dlopen */
#endif
#include <stdio.h>
#include <stdlib.h>

#include "fmi2Functions.h"
#include "host_common.h"

#define HOST_NAME "fmi2_loop_host"

typedef struct {
    fmi2Component c;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2SetRealTYPE *set_real;
    fmi2SetIntegerTYPE *set_int;
    fmi2SetBooleanTYPE *set_bool;
    fmi2SetStringTYPE *set_string;
    fmi2GetRealTYPE *get_real;
    fmi2GetIntegerTYPE *get_int;
    fmi2GetBooleanTYPE *get_bool;
    fmi2DoStepTYPE *do_step;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;
} Fmu;

#define SYM(f, field, name)                                               \
    if (((f)->field = lib_sym(lib, name)) == NULL) {                      \
        fprintf(stderr, "missing %s\n", name);                            \
        return 2;                                                         \
    }
#define CHECK(call)                                                       \
    if ((call) != fmi2OK) {                                               \
        fprintf(stderr, "%s failed\n", #call);                            \
        return 3;                                                         \
    }

static fmi2CallbackFunctions callbacks = {host_fmi2_logger, calloc, free, NULL, NULL};

static int fmu_load(Fmu *f, const char *path, const char *guid, const char *resources, int index) {
    Lib lib = lib_open(path);
    if (lib == NULL) {
        fprintf(stderr, "cannot load %s\n", path);
        return 2;
    }
    fmi2InstantiateTYPE *inst = (fmi2InstantiateTYPE *)lib_sym(lib, "fmi2Instantiate");
    if (inst == NULL) return 2;
    SYM(f, setup, "fmi2SetupExperiment") SYM(f, enter, "fmi2EnterInitializationMode")
    SYM(f, exit_init, "fmi2ExitInitializationMode") SYM(f, set_real, "fmi2SetReal")
    SYM(f, set_int, "fmi2SetInteger") SYM(f, set_bool, "fmi2SetBoolean") SYM(f, set_string, "fmi2SetString")
    SYM(f, get_real, "fmi2GetReal") SYM(f, get_int, "fmi2GetInteger") SYM(f, get_bool, "fmi2GetBoolean")
    SYM(f, do_step, "fmi2DoStep") SYM(f, terminate, "fmi2Terminate") SYM(f, free_instance, "fmi2FreeInstance")
    char name[32];
    snprintf(name, sizeof name, "fmu%d", index);
    f->c = inst(name, fmi2CoSimulation, guid, resources, &callbacks, fmi2False, fmi2False);
    if (f->c == NULL) {
        fprintf(stderr, "fmi2Instantiate of %s returned NULL\n", path);
        return 4;
    }
    CHECK(f->setup(f->c, fmi2False, 0.0, 0.0, fmi2False, 0.0))
    CHECK(f->enter(f->c))
    return 0;
}

static int fmu_set(Fmu *f, char type, unsigned vr, double value) {
    const fmi2ValueReference r = vr;
    const fmi2Integer iv = (fmi2Integer)value;
    const fmi2Boolean bv = value != 0.0;
    if (type == 'R') CHECK(f->set_real(f->c, &r, 1, &value))
    if (type == 'I') CHECK(f->set_int(f->c, &r, 1, &iv))
    if (type == 'B') CHECK(f->set_bool(f->c, &r, 1, &bv))
    return 0;
}

static int fmu_set_string(Fmu *f, unsigned vr, const char *word) {
    const fmi2ValueReference r = vr;
    const fmi2String s = word;
    CHECK(f->set_string(f->c, &r, 1, &s))
    return 0;
}

static int fmu_get(const Fmu *f, char type, unsigned vr, double *value) {
    const fmi2ValueReference r = vr;
    if (type == 'R') {
        CHECK(f->get_real(f->c, &r, 1, value))
    } else if (type == 'I') {
        fmi2Integer iv;
        CHECK(f->get_int(f->c, &r, 1, &iv))
        *value = iv;
    } else {
        fmi2Boolean bv;
        CHECK(f->get_bool(f->c, &r, 1, &bv))
        *value = bv;
    }
    return 0;
}

static int fmu_exit_init(Fmu *f) {
    CHECK(f->exit_init(f->c))
    return 0;
}

static int fmu_do_step(Fmu *f, double t, double h) {
    CHECK(f->do_step(f->c, t, h, fmi2True))
    return 0;
}

static int fmu_end(Fmu *f) {
    CHECK(f->terminate(f->c))
    f->free_instance(f->c);
    return 0;
}

#include "loop_host.h"
