/*
 * A plain C FMI 3.0 co-simulation master for a loop of several FMUs (no Python anywhere),
 * for Linux and, cross-compiled with MinGW-w64, for Windows: fmi2_loop_host.c for FMI 3.0.
 *
 *   fmi3_loop_host SCRIPT
 *
 * SCRIPT is a text file of lines (FMUs are numbered in the order of their F lines):
 *   F LIBRARY TOKEN RESOURCE_PATH   load an FMU's library and instantiate it (a folder path ending in
 *                                   a separator, or - for none)
 *   P fmu R|I|B|S vr value          set a variable in initialization mode (S: a word)
 *   L src R|I|B vr dst vr           a connection: before dst steps, dst's vr = src's vr
 *   O fmu R|I|B vr                  print this variable after every step
 *   T h n                           n communication steps of h seconds (the last T line counts)
 * Each communication step steps the FMUs in their F order, each after its incoming connections
 * are copied (sequential, Gauss-Seidel: a later FMU sees this step's outputs of an earlier one).
 * After each step the O variables are printed on one line (%.17g, so doubles round-trip).
 * Timing goes to stderr: the wall and CPU (clock()) time of the loop, initialization excluded.
 */
#if !defined(_WIN32)
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#endif
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi3Functions.h"

#ifdef _WIN32
#include <windows.h>
typedef HMODULE Lib;
static Lib lib_open(const char *path) { return LoadLibraryA(path); }
static void *lib_sym(Lib lib, const char *name) { return (void *)GetProcAddress(lib, name); }
static double now_s(void) {
    LARGE_INTEGER f, t;
    QueryPerformanceFrequency(&f);
    QueryPerformanceCounter(&t);
    return (double)t.QuadPart / (double)f.QuadPart;
}
#else
#include <dlfcn.h>
#include <time.h>
typedef void *Lib;
static Lib lib_open(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *lib_sym(Lib lib, const char *name) { return dlsym(lib, name); }
static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}
#endif

#define MAX_FMUS 4
#define MAX_LINKS 64
#define MAX_OUT 64

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

typedef struct {
    int src, dst;
    char type;
    fmi3ValueReference src_vr, dst_vr;
} Link;

typedef struct {
    int fmu;
    char type;
    fmi3ValueReference vr;
} Out;

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

static int load(Fmu *f, const char *path, const char *guid, const char *resources, int index) {
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
    f->c = inst(names[index], guid, strcmp(resources, "-") ? resources : NULL, fmi3False, fmi3False, fmi3False,
                fmi3False, NULL, 0, names[index], logger, NULL);
    if (f->c == NULL) {
        fprintf(stderr, "fmi3InstantiateCoSimulation of %s returned NULL\n", path);
        return 4;
    }
    CHECK(f->enter(f->c, fmi3False, 0.0, 0.0, fmi3False, 0.0))
    return 0;
}

static int copy(const Fmu *fmus, const Link *l) {
    const Fmu *s = &fmus[l->src], *d = &fmus[l->dst];
    if (l->type == 'R') {
        fmi3Float64 v;
        CHECK(s->get_real(s->c, &l->src_vr, 1, &v, 1))
        CHECK(d->set_real(d->c, &l->dst_vr, 1, &v, 1))
    } else if (l->type == 'I') {
        fmi3Int32 v;
        CHECK(s->get_int(s->c, &l->src_vr, 1, &v, 1))
        CHECK(d->set_int(d->c, &l->dst_vr, 1, &v, 1))
    } else {
        fmi3Boolean v;
        CHECK(s->get_bool(s->c, &l->src_vr, 1, &v, 1))
        CHECK(d->set_bool(d->c, &l->dst_vr, 1, &v, 1))
    }
    return 0;
}

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: fmi3_loop_host SCRIPT\n");
        return 1;
    }
    FILE *script = fopen(argv[1], "r");
    if (script == NULL) {
        fprintf(stderr, "cannot open %s\n", argv[1]);
        return 1;
    }
    static Fmu fmus[MAX_FMUS];
    static Link links[MAX_LINKS];
    static Out outs[MAX_OUT];
    int n_fmus = 0, n_links = 0, n_outs = 0, rc;
    long n_steps = 0;
    double h = 0.0;
    char kind[4], path[4096], guid[256], uri[4096 + 16], type[4], word[256];
    while (fscanf(script, "%3s", kind) == 1) {
        if (kind[0] == 'F' && n_fmus < MAX_FMUS) {
            if (fscanf(script, "%4095s %255s %4111s", path, guid, uri) != 3) return 1;
            if ((rc = load(&fmus[n_fmus], path, guid, uri, n_fmus)) != 0) return rc;
            n_fmus++;
        } else if (kind[0] == 'P') {
            int i;
            unsigned vr;
            if (fscanf(script, "%d %3s %u", &i, type, &vr) != 3 || i < 0 || i >= n_fmus) return 1;
            Fmu *f = &fmus[i];
            fmi3ValueReference r = vr;
            if (type[0] == 'S') {
                if (fscanf(script, "%255s", word) != 1) return 1;
                fmi3String s = word;
                CHECK(f->set_string(f->c, &r, 1, &s, 1))
            } else {
                double value;
                if (fscanf(script, "%lf", &value) != 1) return 1;
                fmi3Int32 iv = (fmi3Int32)value;
                fmi3Boolean bv = value != 0.0;
                if (type[0] == 'R') CHECK(f->set_real(f->c, &r, 1, &value, 1))
                if (type[0] == 'I') CHECK(f->set_int(f->c, &r, 1, &iv, 1))
                if (type[0] == 'B') CHECK(f->set_bool(f->c, &r, 1, &bv, 1))
            }
        } else if (kind[0] == 'L' && n_links < MAX_LINKS) {
            Link *l = &links[n_links++];
            unsigned a, b;
            if (fscanf(script, "%d %3s %u %d %u", &l->src, type, &a, &l->dst, &b) != 5) return 1;
            l->type = type[0];
            l->src_vr = a;
            l->dst_vr = b;
            if (l->src < 0 || l->src >= n_fmus || l->dst < 0 || l->dst >= n_fmus) return 1;
        } else if (kind[0] == 'O' && n_outs < MAX_OUT) {
            Out *o = &outs[n_outs++];
            unsigned vr;
            if (fscanf(script, "%d %3s %u", &o->fmu, type, &vr) != 3) return 1;
            o->type = type[0];
            o->vr = vr;
        } else if (kind[0] == 'T') {
            if (fscanf(script, "%lf %ld", &h, &n_steps) != 2) return 1;
        } else {
            fprintf(stderr, "bad script line starting with %s\n", kind);
            return 1;
        }
    }
    fclose(script);
    for (int i = 0; i < n_fmus; i++) CHECK(fmus[i].exit_init(fmus[i].c))
    double t = 0.0, t0 = now_s();
    clock_t c0 = clock();
    for (long k = 0; k < n_steps; k++) {
        for (int i = 0; i < n_fmus; i++) {
            for (int j = 0; j < n_links; j++)
                if (links[j].dst == i && (rc = copy(fmus, &links[j])) != 0) return rc;
            fmi3Boolean event, terminate, early;
            fmi3Float64 last;
            CHECK(fmus[i].do_step(fmus[i].c, t, h, fmi3True, &event, &terminate, &early, &last))
        }
        t = (double)(k + 1) * h;
        for (int j = 0; j < n_outs; j++) {
            const Fmu *f = &fmus[outs[j].fmu];
            double v;
            if (outs[j].type == 'R') {
                CHECK(f->get_real(f->c, &outs[j].vr, 1, &v, 1))
            } else if (outs[j].type == 'I') {
                fmi3Int32 iv;
                CHECK(f->get_int(f->c, &outs[j].vr, 1, &iv, 1))
                v = iv;
            } else {
                fmi3Boolean bv;
                CHECK(f->get_bool(f->c, &outs[j].vr, 1, &bv, 1))
                v = bv;
            }
            printf(j ? " %.17g" : "%.17g", v);
        }
        printf("\n");
    }
    fprintf(stderr, "loop wall time %.6f s cpu time %.6f s for %ld steps\n", now_s() - t0,
            (double)(clock() - c0) / CLOCKS_PER_SEC, n_steps);
    for (int i = 0; i < n_fmus; i++) {
        CHECK(fmus[i].terminate(fmus[i].c))
        fmus[i].free_instance(fmus[i].c);
    }
    return 0;
}
