/*
 * One CassiePlantNative instance, independent of the FMI version: the variable values, the
 * FMI phase, the walker, and every check both FMI layers share (phases, variables and their
 * ranges, step arguments, FMU states).  fmi2_plant.c and fmi3_plant.c are thin layers over it
 * (through fmi_model.h and the shared fmu_src/fmi/fmi_layer.h, as the regulator's avr_instance.c):
 * each converts its types to and from the doubles kept here.
 *
 * Every refused call logs a message naming the call, the variable and its allowed range,
 * returns CP_ERROR and changes nothing.
 */
#ifndef CP_INSTANCE_H
#define CP_INSTANCE_H

#include "cassie_plant.h" /* first: the floating-point contract */

#include <stddef.h>
#include <stdint.h>

#include "fmi_phase_rules.h"

typedef enum { CP_OK = 0, CP_WARNING = 1, CP_DISCARD = 2, CP_ERROR = 3, CP_FATAL = 4 } CpStatus;

/* Phases as the bits of fmi_phase_rules.h (generated from fmu_src/fmi/phase_rules.py), so that
 * a function's allowed phases are one mask, its FMI_MASK_<function>.  The bit is stored in
 * FMU-state blobs.  No stepFailed: a refused doStep changes nothing. */
typedef enum {
    CP_INSTANTIATED = FMI_INSTANTIATED,
    CP_INIT_MODE = FMI_INIT_MODE,
    CP_STEP_MODE = FMI_STEP_MODE, /* FMI 2.0 stepComplete, FMI 3.0 Step Mode */
    CP_TERMINATED = FMI_TERMINATED,
} CpPhase;
#define CP_N_PHASES 4 /* the bits above: 0 .. 3 */
/* Relative tolerance on "doStep starts where the last step ended" (fmu_src/fmi/avr_slavebase.py). */
#define CP_TIME_MATCH_RTOL 1e-9

struct CpInstance;
typedef void CpLogFn(const struct CpInstance *inst, CpStatus status, const char *category, const char *message);

typedef struct CpInstance {
    char *name;
    void *env;        /* the FMI layer's callback context */
    CpLogFn *log;     /* the FMI layer's logger adapter */
    int logging_on;
    const char *const *phase_names; /* by bit number, in the FMI version's words */
    CpPhase phase;
    double time;
    double values[CP_N_VARS];
    char *resources; /* the resources folder (a file system path) */
    char *terrain_field; /* terrain_field_file's text (malloc'd); NULL: "" (its start value) */
    CpWalker walker;
    int has_walker;
} CpInstance;

/* An FMU state: one self-checking blob (layout in cp_instance.c). */
typedef struct {
    size_t size;
    unsigned char bytes[];
} CpBlob;

CpInstance *cp_instantiate(const char *name, const char *token, const char *resources, void *env, CpLogFn *log,
                           int logging_on, const char *const *phase_names);
void cp_free_instance(CpInstance *inst);
CpStatus cp_refuse(const CpInstance *inst, const char *call, const char *fmt, ...)
#if defined(__MINGW32__)
    __attribute__((format(gnu_printf, 3, 4)))
#elif defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
void cp_debug(const CpInstance *inst, const char *fmt, ...)
#if defined(__MINGW32__)
    __attribute__((format(gnu_printf, 2, 3)))
#elif defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
CpStatus cp_allowed(const CpInstance *inst, const char *call, unsigned mask);
CpStatus cp_check_categories(const CpInstance *inst, const char *call, size_t n, const char *const categories[]);

CpStatus cp_setup(CpInstance *inst, const char *call, double start_time);
CpStatus cp_exit_init(CpInstance *inst, const char *call);
void cp_reset(CpInstance *inst);

/* vr[0..n-1] are variables of `type` (get: any; set: settable now, `value` legal). */
CpStatus cp_check_get(const CpInstance *inst, const char *call, const uint32_t vr[], size_t n, CpType type);
CpStatus cp_check_set(const CpInstance *inst, const char *call, uint32_t vr, CpType type, double value);
/* The String variables: cassie_model (kept in values[] as its index in CP_MODEL_NAMES) and
 * terrain_field_file (a path of at most CP_MAX_TEXT_BYTES bytes, kept as text).  Set: all or
 * nothing, every vr settable now and every text legal before any is stored. */
#define CP_MAX_TEXT_BYTES 4095
CpStatus cp_set_strings(CpInstance *inst, const char *call, const uint32_t vr[], const char *const text[], size_t n);
/* The text of String variable vr (checked by cp_check_get). */
const char *cp_get_string(const CpInstance *inst, uint32_t vr);

CpStatus cp_do_step(CpInstance *inst, const char *call, double t, double h);

/* The FMU state functions of both versions (an FMU state is a CpBlob *). */
CpStatus cp_fmustate_get(CpInstance *inst, const char *call, void **state);
CpStatus cp_fmustate_set(CpInstance *inst, const char *call, const void *state);
void cp_fmustate_free(void **state);
CpStatus cp_fmustate_size(const CpInstance *inst, const char *call, const void *state, size_t *size);
CpStatus cp_fmustate_serialize(const CpInstance *inst, const char *call, const void *state, unsigned char *bytes,
                               size_t size);
CpStatus cp_fmustate_deserialize(const CpInstance *inst, const char *call, const unsigned char *bytes, size_t size,
                                 void **state);

#endif
