/*
 * The loop of the plain C FMI co-simulation masters fmi2_loop_host.c and fmi3_loop_host.c (no
 * Python anywhere; Linux and, cross-compiled with MinGW-w64, Windows): the script, the
 * connections, the steps and the printed outputs, the same for both FMI versions.
 *
 *   fmiN_loop_host SCRIPT
 *
 * SCRIPT is a text file of lines (FMUs are numbered in the order of their F lines):
 *   F LIBRARY TOKEN RESOURCES       load an FMU's library and instantiate it (FMI 2.0: the GUID
 *                                   and the resource URI; FMI 3.0: the instantiation token and a
 *                                   folder path ending in a separator, or - for none)
 *   P fmu R|I|B|S vr value          set a variable in initialization mode (S: a word)
 *   L src R|I|B vr dst vr           a connection: before dst steps, dst's vr = src's vr
 *   O fmu R|I|B vr                  print this variable after every step
 *   T h n                           n communication steps of h seconds (the last T line counts)
 * Each communication step steps the FMUs in their F order, each after its incoming connections
 * are copied (sequential, Gauss-Seidel: a later FMU sees this step's outputs of an earlier one).
 * After each step the O variables are printed on one line (%.17g, so doubles round-trip).
 * Timing goes to stderr: the wall and CPU (clock()) time of the loop, initialization excluded.
 *
 * The FMI version's part is defined before including this file, each function answering 0 or
 * the host's exit status (2: a library or symbol is missing, 3: a call failed, 4: no instance):
 *   Fmu                                           one loaded FMU instance
 *   HOST_NAME                                     the program's name (usage message)
 *   fmu_load(f, path, token, resources, index)    load, instantiate, enter initialization mode
 *   fmu_set(f, type, vr, value)                   set an R, I or B variable (value as a double)
 *   fmu_set_string(f, vr, word)                   set a String variable
 *   fmu_get(f, type, vr, &value)                  get an R, I or B variable as a double
 *   fmu_exit_init(f), fmu_do_step(f, t, h), fmu_end(f) (terminate and free)
 * Integer and Boolean values go through doubles exactly (32-bit integers, 0 and 1).
 */
#ifndef LOOP_HOST_H
#define LOOP_HOST_H

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#define MAX_FMUS 4
#define MAX_LINKS 64
#define MAX_OUT 64

typedef struct {
    int src, dst;
    char type;
    unsigned src_vr, dst_vr;
} Link;

typedef struct {
    int fmu;
    char type;
    unsigned vr;
} Out;

#define LOOP_TRY(call)                                                    \
    if ((rc = (call)) != 0) return rc;

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: %s SCRIPT\n", HOST_NAME);
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
    char kind[4], path[4096], token[256], resources[4096 + 16], type[4], word[256];
    while (fscanf(script, "%3s", kind) == 1) {
        if (kind[0] == 'F' && n_fmus < MAX_FMUS) {
            if (fscanf(script, "%4095s %255s %4111s", path, token, resources) != 3) return 1;
            LOOP_TRY(fmu_load(&fmus[n_fmus], path, token, resources, n_fmus))
            n_fmus++;
        } else if (kind[0] == 'P') {
            int i;
            unsigned vr;
            if (fscanf(script, "%d %3s %u", &i, type, &vr) != 3 || i < 0 || i >= n_fmus) return 1;
            if (type[0] == 'S') {
                if (fscanf(script, "%255s", word) != 1) return 1;
                LOOP_TRY(fmu_set_string(&fmus[i], vr, word))
            } else {
                double value;
                if (fscanf(script, "%lf", &value) != 1) return 1;
                LOOP_TRY(fmu_set(&fmus[i], type[0], vr, value))
            }
        } else if (kind[0] == 'L' && n_links < MAX_LINKS) {
            Link *l = &links[n_links++];
            if (fscanf(script, "%d %3s %u %d %u", &l->src, type, &l->src_vr, &l->dst, &l->dst_vr) != 5) return 1;
            l->type = type[0];
            if (l->src < 0 || l->src >= n_fmus || l->dst < 0 || l->dst >= n_fmus) return 1;
        } else if (kind[0] == 'O' && n_outs < MAX_OUT) {
            Out *o = &outs[n_outs++];
            if (fscanf(script, "%d %3s %u", &o->fmu, type, &o->vr) != 3 || o->fmu < 0 || o->fmu >= n_fmus) return 1;
            o->type = type[0];
        } else if (kind[0] == 'T') {
            if (fscanf(script, "%lf %ld", &h, &n_steps) != 2) return 1;
        } else {
            fprintf(stderr, "bad script line starting with %s\n", kind);
            return 1;
        }
    }
    fclose(script);
    for (int i = 0; i < n_fmus; i++) LOOP_TRY(fmu_exit_init(&fmus[i]))
    double t = 0.0, t0 = now_s();
    clock_t c0 = clock();
    for (long k = 0; k < n_steps; k++) {
        for (int i = 0; i < n_fmus; i++) {
            for (int j = 0; j < n_links; j++) {
                const Link *l = &links[j];
                if (l->dst != i) continue;
                double v;
                LOOP_TRY(fmu_get(&fmus[l->src], l->type, l->src_vr, &v))
                LOOP_TRY(fmu_set(&fmus[l->dst], l->type, l->dst_vr, v))
            }
            LOOP_TRY(fmu_do_step(&fmus[i], t, h))
        }
        t = (double)(k + 1) * h;
        for (int j = 0; j < n_outs; j++) {
            double v;
            LOOP_TRY(fmu_get(&fmus[outs[j].fmu], outs[j].type, outs[j].vr, &v))
            printf(j ? " %.17g" : "%.17g", v);
        }
        printf("\n");
    }
    fprintf(stderr, "loop wall time %.6f s cpu time %.6f s for %ld steps\n", now_s() - t0,
            (double)(clock() - c0) / CLOCKS_PER_SEC, n_steps);
    for (int i = 0; i < n_fmus; i++) LOOP_TRY(fmu_end(&fmus[i]))
    return 0;
}

#endif
