/*
 * One FMU instance, independent of the FMI version: the variable values, the FMI phase,
 * the networks and the learned state, and every check the FMI layers share (variable
 * legality and ranges, step arguments, FMU state blobs).  fmi2_api.c and fmi3_api.c
 * are thin layers over this (through fmi_model.h and the shared fmu_src/fmi/fmi_layer.h, whose
 * prologue checks each function's generated FMI_MASK_<function>), converting their types to and
 * from the doubles kept here.
 *
 * Every refused call logs a message naming the call, the variable and its allowed range,
 * returns AVR_ERROR and changes nothing.
 */
#ifndef AVR_INSTANCE_H
#define AVR_INSTANCE_H

#include "avr_model.h" /* first: see avr_types.h */

#include <stddef.h>
#include <stdint.h>

#include "fmi_phase_rules.h"

typedef enum { AVR_OK = 0, AVR_WARNING = 1, AVR_DISCARD = 2, AVR_ERROR = 3, AVR_FATAL = 4 } AvrStatus;

/* Phases as the bits of fmi_phase_rules.h, so that a function's allowed phases are one mask
 * (its FMI_MASK_<function>).  The bit is stored in FMU-state blobs.  No stepFailed: a refused
 * doStep changes nothing. */
typedef enum {
    AVR_INSTANTIATED = FMI_INSTANTIATED,
    AVR_INIT_MODE = FMI_INIT_MODE,
    AVR_STEP_MODE = FMI_STEP_MODE, /* FMI 2.0 stepComplete, FMI 3.0 Step Mode */
    AVR_TERMINATED = FMI_TERMINATED,
} AvrPhase;
#define AVR_N_PHASES 4 /* the bits above: 0 .. 3 */

/* Relative tolerance on "doStep starts where the last step ended" (t0 + k h vs t + h differ by ulps). */
#define AVR_TIME_MATCH_RTOL 1e-9

struct AvrInstance;
typedef void AvrLogFn(const struct AvrInstance *inst, AvrStatus status, const char *category, const char *message);

typedef struct AvrInstance {
    char *name;
    void *env;              /* the FMI layer's callback context */
    AvrLogFn *log;          /* the FMI layer's logger adapter (may do nothing) */
    int logging_on;
    const char *const *phase_names; /* indexed by bit number, in the FMI version's words */
    AvrPhase phase;
    double time;
    double values[AVR_N_VARS];
    AvrNetworks *net; /* built by avr_exit_init (or restored with a state); NULL before */
    AvrCore core;
} AvrInstance;

/* The FMU state as one self-checking blob (see avr_instance.c for its layout). */
typedef struct {
    size_t size;
    unsigned char bytes[];
} AvrBlob;

AvrInstance *avr_instantiate(const char *name, const char *token, void *env, AvrLogFn *log, int logging_on,
                             const char *const *phase_names);
void avr_free_instance(AvrInstance *inst);
AvrStatus avr_refuse(const AvrInstance *inst, const char *call, const char *fmt, ...)
#if defined(__MINGW32__)
    __attribute__((format(gnu_printf, 3, 4))) /* with __USE_MINGW_ANSI_STDIO */
#elif defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
AvrStatus avr_allowed(const AvrInstance *inst, const char *call, unsigned mask);

AvrStatus avr_setup(AvrInstance *inst, const char *call, double start_time, int stop_defined, double stop_time);
AvrStatus avr_exit_init(AvrInstance *inst, const char *call);
void avr_reset(AvrInstance *inst);

/* Checks vr[0..n-1] are variables of `type` (and, for set, settable now); value(i) as a double. */
AvrStatus avr_check_get(const AvrInstance *inst, const char *call, const uint32_t vr[], size_t n, AvrType type);
AvrStatus avr_check_set(const AvrInstance *inst, const char *call, uint32_t vr, AvrType type, double value);

AvrStatus avr_do_step(AvrInstance *inst, const char *call, double t, double h);

/* The longest log category accepted (a longer or unterminated one is refused). */
#define AVR_MAX_CATEGORY_BYTES 256u
/* fmi*SetDebugLogging's categories: AVR_OK if each is non-NULL, valid UTF-8 and one the model
 * description declares (AVR_LOG_CATEGORIES, generated with the variable table), else a refusal
 * naming the index (and the declared categories); the same rule as the pythonfmu FMU's guard. */
AvrStatus avr_check_categories(const AvrInstance *inst, const char *call, size_t n, const char *const categories[]);

/* Shared by avr_instance.c and avr_state.c. */
void avr_fmt_double(char *out, size_t size, double x);
int avr_value_problem(const AvrVar *v, double x, char *out, size_t size);
/* Why the parameter values values[] (with x in place of values[vr]; vr = AVR_N_VARS: none) break
 * AVR_REQUIRES (writes every broken rule, returns 1), or 0 (avr_specs.requires_problems). */
int avr_requires_problem(const double *values, uint32_t vr, double x, char *out, size_t size);
AvrStatus avr_prepare_networks(AvrInstance *inst, const char *call, int n, uint32_t seed, AvrNetworks **net,
                               AvrCore *core);
void avr_adopt(AvrInstance *inst, AvrNetworks *net, AvrCore *core);

AvrStatus avr_state_check(const AvrInstance *inst, const char *call, const unsigned char *bytes, size_t size);

/* The FMI FMUstate functions of both versions (an FMUstate is an AvrBlob *). */
AvrStatus avr_fmustate_get(AvrInstance *inst, const char *call, void **state);
AvrStatus avr_fmustate_set(AvrInstance *inst, const char *call, const void *state);
void avr_fmustate_free(void **state);
AvrStatus avr_fmustate_size(const AvrInstance *inst, const char *call, const void *state, size_t *size);
AvrStatus avr_fmustate_serialize(const AvrInstance *inst, const char *call, const void *state, unsigned char *bytes,
                                 size_t size);
AvrStatus avr_fmustate_deserialize(const AvrInstance *inst, const char *call, const unsigned char *bytes, size_t size,
                                   void **state);

#endif
