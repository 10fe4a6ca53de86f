/*
 * The fmi2Get and fmi2Set functions: every value reference, type, causality, variability, range and
 * string is checked against the generated table (AVR_VARS) before pythonfmu sees the call;
 * the first problem is refused with fmi2Error naming the variable and its allowed range,
 * and a refused call sets nothing.  The guard also keeps the current values of the fixed
 * parameters, which FMU states must match (guard_state.c).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "guard.h"

static const AvrVar *lookup(Guard *g, const char *call, fmi2ValueReference vr, char type) {
    if (vr >= AVR_N_VARS) {
        refuse(g, call, "valueReference %u does not exist (0..%u)", (unsigned)vr, (unsigned)AVR_N_VARS - 1);
        return NULL;
    }
    const AvrVar *v = &AVR_VARS[vr];
    if (v->type != type) {
        refuse(g, call, "%s (valueReference %u) is not of this type", v->name, (unsigned)vr);
        return NULL;
    }
    return v;
}

static fmi2Status check_get(Guard *g, const char *call, const fmi2ValueReference vr[], size_t nvr, char type,
                            const void *values) {
    if (nvr > 0 && (vr == NULL || values == NULL)) return refuse(g, call, "NULL vr[] or value[] with nvr = %zu", nvr);
    for (size_t i = 0; i < nvr; ++i)
        if (lookup(g, call, vr[i], type) == NULL) return fmi2Error;
    return fmi2OK;
}

static void range_text(const AvrVar *v, char *out, size_t n) {
    char lo[32] = "-inf", hi[32] = "inf";
    if (v->has_min) format_double(v->min, lo, sizeof lo);
    if (v->has_max) format_double(v->max, hi, sizeof hi);
    snprintf(out, n, "[%s, %s]", lo, hi);
}

/* May variable v be set in the current phase? */
static fmi2Status check_settable(Guard *g, const char *call, const AvrVar *v) {
    if (v->causality == 'o') return refuse(g, call, "%s is an output and cannot be set", v->name);
    if (g->phase == STEP_COMPLETE && v->causality == 'p' && v->variability == 'f')
        return refuse(g, call, "%s is a fixed parameter: set it before fmi2ExitInitializationMode", v->name);
    return fmi2OK;
}

/* Is values[i] (of the variable's type) acceptable? */
static fmi2Status check_value(Guard *g, const char *call, const AvrVar *v, const void *values, size_t i) {
    char range[80], text[32];
    range_text(v, range, sizeof range);
    if (v->type == 'R' || v->type == 'I') {
        double x = v->type == 'R' ? ((const fmi2Real *)values)[i] : (double)((const fmi2Integer *)values)[i];
        format_double(x, text, sizeof text);
        if (!isfinite(x)) return refuse(g, call, "%s = %s: must be a finite number in %s", v->name, text, range);
        if ((v->has_min && x < v->min) || (v->has_max && x > v->max))
            return refuse(g, call, "%s = %s: out of range %s", v->name, text, range);
    } else if (v->type == 'B') {
        fmi2Boolean b = ((const fmi2Boolean *)values)[i];
        if (b != fmi2True && b != fmi2False)
            return refuse(g, call, "%s = %d: an fmi2Boolean must be fmi2True (1) or fmi2False (0)", v->name, (int)b);
    } else {
        const char *problem = string_problem(((const fmi2String *)values)[i], MAX_STRING_BYTES);
        if (problem != NULL) return refuse(g, call, "%s: the string %s", v->name, problem);
    }
    return fmi2OK;
}

static fmi2Status check_set(Guard *g, const char *call, const fmi2ValueReference vr[], size_t nvr, char type,
                            const void *values) {
    if (nvr > 0 && (vr == NULL || values == NULL)) return refuse(g, call, "NULL vr[] or value[] with nvr = %zu", nvr);
    for (size_t i = 0; i < nvr; ++i) {
        const AvrVar *v = lookup(g, call, vr[i], type);
        if (v == NULL || check_settable(g, call, v) != fmi2OK || check_value(g, call, v, values, i) != fmi2OK)
            return fmi2Error;
    }
    return fmi2OK;
}

/* After the inner library accepted a set: remember the fixed parameters' new values. */
static void note_fixed(Guard *g, const fmi2ValueReference vr[], size_t nvr, char type, const void *values) {
    for (size_t i = 0; i < nvr; ++i) {
        int k = fixed_index(vr[i]);
        if (k < 0) continue;
        if (type == 'R') g->fixed[k] = ((const fmi2Real *)values)[i];
        else if (type == 'I') g->fixed[k] = (double)((const fmi2Integer *)values)[i];
        else if (type == 'B') g->fixed[k] = ((const fmi2Boolean *)values)[i] ? 1.0 : 0.0;
    }
}

#define GETTER(fn, ctype, code)                                                                  \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, ctype value[]) {   \
        PROLOGUE(fn);                                                                            \
        fmi2Status s = check_get(g, call, vr, nvr, code, value);                                 \
        if (s != fmi2OK || nvr == 0) return s;                                                   \
        return track(g, inner.fn(g->inner, vr, nvr, value));                                     \
    }
GETTER(fmi2GetReal, fmi2Real, 'R')
GETTER(fmi2GetInteger, fmi2Integer, 'I')
GETTER(fmi2GetBoolean, fmi2Boolean, 'B')
GETTER(fmi2GetString, fmi2String, 'S')

#define SETTER(fn, ctype, code)                                                                       \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const ctype value[]) {  \
        PROLOGUE(fn);                                                                                 \
        fmi2Status s = check_set(g, call, vr, nvr, code, value);                                      \
        if (s != fmi2OK || nvr == 0) return s;                                                        \
        s = track(g, inner.fn(g->inner, vr, nvr, value));                                             \
        if (s == fmi2OK) note_fixed(g, vr, nvr, code, value);                                         \
        return s;                                                                                     \
    }
SETTER(fmi2SetReal, fmi2Real, 'R')
SETTER(fmi2SetInteger, fmi2Integer, 'I')
SETTER(fmi2SetBoolean, fmi2Boolean, 'B')
SETTER(fmi2SetString, fmi2String, 'S')
