/*
 * What every translation unit of the FMI guard uses (guard.h): logging to the host, refusing a
 * call, the phase check of the PROLOGUE, what the inner library's answer means, and the fixed
 * parameters' defaults.  It calls nothing of fmi2_guard.c, guard_state.c or guard_values.c:
 * they call it.
 */
#define _GNU_SOURCE
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "guard.h"

const char *const PHASE_NAMES[N_PHASES] = {"instantiated", "initializationMode", "stepComplete",
                                           "stepFailed", "terminated", "fatal"};

/* ---- logging -------------------------------------------------------------------- */
static void vlog_to(const fmi2CallbackFunctions *cb, const char *name, fmi2Status status, const char *fmt,
                    va_list args) {
    char message[1024];
    vsnprintf(message, sizeof message, fmt, args);
    if (cb == NULL || cb->logger == NULL) return;
    const char *category = status == fmi2Error ? "logStatusError" : status == fmi2Fatal ? "logStatusFatal" : "logAll";
    /* the message is passed as an argument, never as the format string */
    cb->logger(cb->componentEnvironment, name, status, category, "%s", message);
}

void guard_log(const Guard *g, fmi2Status status, const char *fmt, ...) {
    if (g == NULL) return;
    va_list args;
    va_start(args, fmt);
    vlog_to(&g->host, g->name, status, fmt, args);
    va_end(args);
}

fmi2Status refuse(Guard *g, const char *call, const char *fmt, ...) {
    char message[900];
    va_list args;
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    guard_log(g, fmi2Error, "%s refused: %s", call, message);
    return fmi2Error;
}

/* The state's bit in the FMI_MASK_<function> masks of fmi_phase_rules.h (FATAL: none). */
static unsigned phase_bit(enum Phase phase) {
    static const unsigned bits[N_PHASES] = {
        [INSTANTIATED] = FMI_INSTANTIATED, [INIT_MODE] = FMI_INIT_MODE, [STEP_COMPLETE] = FMI_STEP_MODE,
        [STEP_FAILED] = FMI_STEP_FAILED, [TERMINATED] = FMI_TERMINATED, [FATAL] = 0u};
    return bits[phase];
}

fmi2Status check_phase(Guard *g, const char *call, unsigned allowed) {
    if (g == NULL || g->tag != GUARD_TAG) return fmi2Error;  /* not an instance: nothing to log to */
    keep_python_thread_state();
    if (g->phase == FATAL) {
        guard_log(g, fmi2Fatal, "%s refused: the instance had a fatal error; only fmi2FreeInstance is allowed", call);
        return fmi2Fatal;
    }
    if (allowed & phase_bit(g->phase)) return fmi2OK;
    char list[256] = "";
    for (int p = INSTANTIATED; p <= TERMINATED; ++p) {
        if (!(allowed & phase_bit((enum Phase)p))) continue;
        size_t used = strlen(list);
        snprintf(list + used, sizeof list - used, "%s%s", used ? ", " : "", PHASE_NAMES[p]);
    }
    return refuse(g, call, "not allowed in state %s (allowed in: %s)", PHASE_NAMES[g->phase], list);
}

/* Records what the inner library answered: fmi2OK after the slave logged an fmi2Error is an
 * fmi2Error (the slave's way to refuse); a Fatal makes the instance unusable for good. */
fmi2Status track(Guard *g, fmi2Status status) {
    if (status == fmi2OK && g->inner_logged_error) status = fmi2Error;
    g->inner_logged_error = 0;
    if (status == fmi2Fatal && g->phase != FATAL) {
        g->phase = FATAL;
        guard_log(g, fmi2Fatal, "the Python slave failed (pythonfmu answered fmi2Fatal, its reason is logged above); "
                  "only fmi2FreeInstance is allowed now");
    }
    return status;
}

/* ---- fixed parameters ---------------------------------------------------------------- */
void fixed_defaults(double fixed[AVR_N_FIXED]) {
    for (unsigned i = 0; i < AVR_N_FIXED; ++i) fixed[i] = AVR_VARS[AVR_FIXED_VRS[i]].start;
}

int fixed_index(fmi2ValueReference vr) {
    for (unsigned i = 0; i < AVR_N_FIXED; ++i)
        if (AVR_FIXED_VRS[i] == vr) return (int)i;
    return -1;
}

