/*
 * CommandSource: a co-simulation FMU with no inputs that plays a schedule of the
 * walking command and the pelvis push from its resources (resources/schedule.csv).
 * This header is the FMI-version-independent instance; cmdsrc_fmi2.c and
 * cmdsrc_fmi3.c are the thin FMI 2.0 and FMI 3.0 layers over it.
 *
 * Semantics: at every time t the outputs hold the row with the largest time <= t
 * (piecewise constant, right-continuous: a row at t switches the value at t, the
 * master hands it to its inputs for the step [t, t + h)).  A push of duration d from t0
 * is two rows, the force at t0 and its removal at t0 + d.  "<=" has a relative
 * tolerance of CS_TIME_RTOL, so a master's t = k h computed as k * h, as a sum of
 * steps or from integer nanoseconds switches at the same communication point.
 */
#ifndef CMDSRC_H
#define CMDSRC_H

#include <stddef.h>

#include "fmi_phase_rules.h"

#define CS_N_OUTPUTS 6
#define CS_TIME_RTOL 1e-9
#define CS_MAX_ROWS 100000
#define CS_SCHEDULE_FILE "schedule.csv"

typedef enum { CS_OK = 0, CS_WARNING = 1, CS_DISCARD = 2, CS_ERROR = 3, CS_FATAL = 4 } CsStatus;

/* Phases as the bits of fmi_phase_rules.h: a function's allowed phases are its FMI_MASK_<function>. */
typedef enum {
    CS_INSTANTIATED = FMI_INSTANTIATED,
    CS_INIT_MODE = FMI_INIT_MODE,
    CS_STEP_MODE = FMI_STEP_MODE,
    CS_TERMINATED = FMI_TERMINATED,
} CsPhase;
#define CS_N_PHASES 4 /* the bits above: 0 .. 3 */

/* The output names in value-reference order (0..5), the schedule's columns after `time`. */
extern const char *const CS_OUTPUT_NAMES[CS_N_OUTPUTS];

struct CsInstance;
typedef void CsLogFn(const struct CsInstance *inst, CsStatus status, const char *category, const char *message);

typedef struct CsInstance {
    char *name;
    void *env;
    CsLogFn *log;
    int logging_on;
    const char *const *phase_names;
    CsPhase phase;
    double start_time;
    double time;
    size_t n_rows;
    double *times;  /* n_rows, strictly increasing */
    double *values; /* n_rows x CS_N_OUTPUTS */
    size_t row;     /* the row in force at `time` */
} CsInstance;

/* resources: the folder holding schedule.csv, a native path (with or without a trailing separator). */
CsInstance *cs_instantiate(const char *name, const char *token, const char *resources, void *env, CsLogFn *log,
                           int logging_on, const char *const *phase_names);
void cs_free(CsInstance *inst);
CsStatus cs_refuse(const CsInstance *inst, const char *call, const char *fmt, ...)
#if defined(__MINGW32__)
    __attribute__((format(gnu_printf, 3, 4)))
#elif defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
CsStatus cs_allowed(const CsInstance *inst, const char *call, unsigned mask);
/* fmi*SetDebugLogging's categories: CS_OK unless n > 0 and the array is NULL. */
CsStatus cs_check_categories(const CsInstance *inst, const char *call, size_t n, const char *const categories[]);
CsStatus cs_setup(CsInstance *inst, const char *call, double start_time, int stop_defined, double stop_time);
CsStatus cs_enter_init(CsInstance *inst, const char *call);
CsStatus cs_exit_init(CsInstance *inst, const char *call);
void cs_reset(CsInstance *inst);
CsStatus cs_check_get(const CsInstance *inst, const char *call, const unsigned vr[], size_t n);
CsStatus cs_do_step(CsInstance *inst, const char *call, double t, double h);
double cs_output(const CsInstance *inst, unsigned vr);

/* A file URI (file:///C:/x, file:/x, file://localhost/x, %-escapes) as a native path; NULL if it is none. */
char *cs_path_from_uri(const char *uri);

#endif
