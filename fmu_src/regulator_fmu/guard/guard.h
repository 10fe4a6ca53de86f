/*
 * Declarations shared by the FMI guard's translation units (guard_base.c: logging, refusals,
 * the phase check and the fixed parameters' defaults, used by the others; fmi2_guard.c: the FMI
 * functions; guard_inner.c: pythonfmu's library and Python thread states; guard_state.c:
 * FMU states and their serialized form; guard_text.c: strings, URIs and number formatting).  The library is compiled with
 * -fvisibility=hidden: only the fmi2* functions (FMI2_Export) are exported.
 */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "fmi2Functions.h"
#include "avr_guard_vars.h"
#include "fmi_phase_rules.h"

/* FMI 2.0 co-simulation states (section 4.2.4) plus FATAL: after a Fatal only
 * fmi2FreeInstance (and freeing FMU states) is allowed, and nothing reaches pythonfmu. */
enum Phase { INSTANTIATED, INIT_MODE, STEP_COMPLETE, STEP_FAILED, TERMINATED, FATAL, N_PHASES };

/* Bounds on strings the host hands us: a longer (or unterminated) one is refused. */
#define MAX_NAME_BYTES 4096u     /* instanceName */
#define MAX_GUID_BYTES 64u       /* fmuGUID */
#define MAX_CATEGORY_BYTES 256u  /* a log category */
#define MAX_URI_BYTES 16384u     /* fmuResourceLocation */
#define MAX_STRING_BYTES 65536u  /* a String value */
#define MAX_INNER_MESSAGE_BYTES (1u << 20)  /* a message pythonfmu logs: a longer one is replaced */

#define GUARD_TAG 0x41565247u  /* "AVRG": marks a live Guard */
#define STATE_TAG 0x41565253u  /* "AVRS": marks a live GuardState */

typedef struct {
    uint32_t tag;
    fmi2Component inner;               /* pythonfmu's instance; never called again after a Fatal */
    enum Phase phase;
    double time;                       /* end of the last successful step */
    double fixed[AVR_N_FIXED];         /* current values of the fixed parameters (AVR_FIXED_VRS order) */
    fmi2CallbackFunctions host;        /* the host's callbacks (a copy) */
    fmi2CallbackFunctions to_inner;    /* what pythonfmu gets: our logger, environment = this Guard */
    int inner_logged_error;            /* pythonfmu logged an fmi2Error during the current call */
    fmi2Boolean logging_on;            /* the host's choice; pythonfmu itself always logs (see track) */
    char *name;
} Guard;

typedef struct {
    uint32_t tag;
    fmi2FMUstate inner;                /* pythonfmu's state (a Python bytes object) */
    enum Phase phase;
    double time;
    double fixed[AVR_N_FIXED];         /* the fixed parameters' values when it was saved */
} GuardState;

/* ---- guard_base.c ---- */
extern const char *const PHASE_NAMES[N_PHASES];
void guard_log(const Guard *g, fmi2Status status, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
fmi2Status refuse(Guard *g, const char *call, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
fmi2Status check_phase(Guard *g, const char *call, unsigned allowed);
fmi2Status track(Guard *g, fmi2Status status);

/* The inner (pythonfmu) library's functions, resolved by load_inner(). */
#define INNER_FUNCTIONS(X) \
    X(fmi2Instantiate) X(fmi2FreeInstance) X(fmi2SetDebugLogging) X(fmi2SetupExperiment) \
    X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode) X(fmi2Terminate) X(fmi2Reset) \
    X(fmi2GetReal) X(fmi2GetInteger) X(fmi2GetBoolean) X(fmi2GetString) \
    X(fmi2SetReal) X(fmi2SetInteger) X(fmi2SetBoolean) X(fmi2SetString) \
    X(fmi2GetFMUstate) X(fmi2SetFMUstate) X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize) \
    X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate) X(fmi2DoStep)
typedef struct {
#define DECLARE_INNER(fn) fn##TYPE *fn;
    INNER_FUNCTIONS(DECLARE_INNER)
#undef DECLARE_INNER
} InnerApi;
extern InnerApi inner;

/* ---- guard_inner.c ---- */
/* Loads the inner library (once); NULL if it is loaded, else why it cannot be. */
const char *inner_load_problem(void);
/* Gives a host thread Python did not create one Python thread state, kept until exit. */
void keep_python_thread_state(void);

/* ---- guard_text.c ---- */
/* 1 if s is a NUL-terminated, valid UTF-8 string of at most max_bytes bytes (no overlongs,
 * no surrogates, nothing above U+10FFFF); *len gets its length.  Never reads past the
 * terminating NUL, nor more than max_bytes + 4 bytes of an unterminated buffer. */
int utf8_valid(const char *s, size_t max_bytes, size_t *len);
/* Why a string argument is unacceptable ("is NULL", "is not valid UTF-8", ...), or NULL if it is fine. */
const char *string_problem(const char *s, size_t max_bytes);
/* Resolves an FMI 2.0 resource-location URI to the canonical path of this FMU's resources folder.
 * Returns a malloc'd path, or NULL with the reason in why[]. */
char *resource_path(const char *uri, char *why, size_t why_size);
/* Shortest decimal text that reads back as exactly x (e.g. "0.1", "1e+308", "nan"). */
void format_double(double x, char *out, size_t size);

/* ---- guard_base.c: the fixed parameters ---- */
void fixed_defaults(double fixed[AVR_N_FIXED]);
/* Index of vr in AVR_FIXED_VRS, or -1 if it is not a fixed parameter. */
int fixed_index(fmi2ValueReference vr);

/* The prologue of every FMI function that takes an instance: `g` and `call` are defined,
 * and the function returns at once unless c is a live instance in a phase where fn is allowed
 * (FMI_MASK_<fn>, fmi_phase_rules.h, generated from fmu_src/fmi/phase_rules.py).  PROLOGUE_MASK:
 * the same with another mask (a function this FMU does not provide: FMI_ANY_PHASE, then refused). */
#define PROLOGUE(fn) PROLOGUE_MASK(fn, FMI_MASK_##fn)
#define PROLOGUE_MASK(fn, mask)                                         \
    Guard *const g = (Guard *)c;                                        \
    static const char call[] = #fn;                                     \
    do {                                                                \
        const fmi2Status allowed_ = check_phase(g, call, (mask));       \
        if (allowed_ != fmi2OK) return allowed_;                        \
    } while (0)
