/*
 * FMI-version-independent instance behaviour (see avr_instance.h).
 *
 * The FMU state blob is written and checked in avr_state.c.
 */
#include "avr_instance.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "avr_guid.h"

/* ---- logging and refusals ------------------------------------------------------------ */
/* Shortest of %.15g/%.16g/%.17g that reads back exactly; nan/inf spelled the same everywhere. */
void avr_fmt_double(char *out, size_t size, double x) {
    if (isnan(x)) {
        snprintf(out, size, "nan");
        return;
    }
    if (isinf(x)) {
        snprintf(out, size, x > 0 ? "inf" : "-inf");
        return;
    }
    for (int digits = 15; digits <= 17; ++digits) {
        snprintf(out, size, "%.*g", digits, x);
        if (strtod(out, NULL) == x) return;
    }
}

static void vlog(const AvrInstance *inst, AvrStatus status, const char *category, const char *fmt, va_list args) {
    char message[1024];
    vsnprintf(message, sizeof message, fmt, args);
    if (inst != NULL && inst->log != NULL) inst->log(inst, status, category, message);
}

AvrStatus avr_refuse(const AvrInstance *inst, const char *call, const char *fmt, ...) {
    char reason[900];
    va_list args;
    va_start(args, fmt);
    vsnprintf(reason, sizeof reason, fmt, args);
    va_end(args);
    if (inst != NULL && inst->log != NULL) {
        char message[1024];
        snprintf(message, sizeof message, "%s refused: %s", call, reason);
        inst->log(inst, AVR_ERROR, "logStatusError", message);
    }
    return AVR_ERROR;
}

static void debug(const AvrInstance *inst, const char *fmt, ...) {
    if (!inst->logging_on) return;
    va_list args;
    va_start(args, fmt);
    vlog(inst, AVR_OK, "logAll", fmt, args);
    va_end(args);
}

static int phase_bit(AvrPhase phase) {
    int bit = 0;
    while (bit < AVR_N_PHASES - 1 && !((unsigned)phase & (1u << bit))) ++bit;
    return bit;
}

AvrStatus avr_allowed(const AvrInstance *inst, const char *call, unsigned mask) {
    if (inst == NULL) return AVR_ERROR;
    if ((unsigned)inst->phase & mask) return AVR_OK;
    if (mask == 0u) return avr_refuse(inst, call, "not provided by this FMU (see its modelDescription.xml)");
    char list[256] = "";
    for (int bit = 0; bit < AVR_N_PHASES; ++bit) {
        if (!(mask & (1u << bit))) continue;
        size_t used = strlen(list);
        snprintf(list + used, sizeof list - used, "%s%s", used ? ", " : "", inst->phase_names[bit]);
    }
    return avr_refuse(inst, call, "not allowed in state %s (allowed in: %s)", inst->phase_names[phase_bit(inst->phase)],
                      list[0] ? list : "none");
}

/* ---- life cycle ---------------------------------------------------------------------- */
static void set_start_values(AvrInstance *inst) {
    for (int vr = 0; vr < AVR_N_VARS; ++vr) inst->values[vr] = AVR_VARS[vr].start;
}

AvrInstance *avr_instantiate(const char *name, const char *token, void *env, AvrLogFn *log, int logging_on,
                             const char *const *phase_names) {
    AvrInstance probe = {.name = (char *)(name ? name : ""), .env = env, .log = log, .phase_names = phase_names};
    if (name == NULL || name[0] == '\0') {
        avr_refuse(&probe, "instantiate", "instanceName must be a non-empty string");
        return NULL;
    }
    if (token == NULL || strcmp(token, AVR_GUID) != 0) {
        avr_refuse(&probe, "instantiate", "GUID/instantiationToken %s does not match this FMU's %s",
                   token ? token : "(NULL)", AVR_GUID);
        return NULL;
    }
    AvrInstance *inst = calloc(1, sizeof *inst);
    char *copy = malloc(strlen(name) + 1);
    if (inst == NULL || copy == NULL) {
        free(inst);
        free(copy);
        avr_refuse(&probe, "instantiate", "out of memory");
        return NULL;
    }
    strcpy(copy, name);
    *inst = probe;
    inst->name = copy;
    inst->logging_on = logging_on;
    inst->phase = AVR_INSTANTIATED;
    set_start_values(inst);
    return inst;
}

void avr_free_instance(AvrInstance *inst) {
    if (inst == NULL) return;
    avr_networks_free(inst->net);
    avr_core_free(&inst->core);
    free(inst->name);
    free(inst);
}

AvrStatus avr_setup(AvrInstance *inst, const char *call, double start_time, int stop_defined, double stop_time) {
    char a[40], b[40];
    avr_fmt_double(a, sizeof a, start_time);
    if (!isfinite(start_time)) return avr_refuse(inst, call, "startTime = %s: must be finite", a);
    avr_fmt_double(b, sizeof b, stop_time);
    if (stop_defined && !(stop_time >= start_time))
        return avr_refuse(inst, call, "stopTime = %s: must be >= startTime = %s", b, a);
    inst->time = start_time;
    return AVR_OK;
}

/* Networks for the current n_neurons and seed (reused if unchanged) and a zero core state. */
AvrStatus avr_prepare_networks(AvrInstance *inst, const char *call, int n, uint32_t seed, AvrNetworks **net,
                               AvrCore *core) {
    *net = inst->net;
    if (*net == NULL || (*net)->n != n || (*net)->seed != seed) *net = avr_networks_new(n, seed);
    if (*net == NULL || avr_core_init(core, n) != 0) {
        if (*net != inst->net) avr_networks_free(*net);
        return avr_refuse(inst, call, "out of memory for %d neurons", n);
    }
    return AVR_OK;
}

void avr_adopt(AvrInstance *inst, AvrNetworks *net, AvrCore *core) {
    if (net != inst->net) avr_networks_free(inst->net);
    avr_core_free(&inst->core);
    inst->net = net;
    inst->core = *core;
}

AvrStatus avr_exit_init(AvrInstance *inst, const char *call) {
    AvrNetworks *net;
    AvrCore core;
    int n = (int)inst->values[AVR_VR_n_neurons];
    uint32_t seed = (uint32_t)inst->values[AVR_VR_seed];
    char why[400];
    if (avr_requires_problem(inst->values, AVR_N_VARS, 0.0, why, sizeof why)) return avr_refuse(inst, call, "%s", why);
    if (avr_prepare_networks(inst, call, n, seed, &net, &core) != AVR_OK) return AVR_ERROR;
    avr_adopt(inst, net, &core);
    inst->phase = AVR_STEP_MODE;
    debug(inst, "built 3 networks of %d neurons (seed %u)", net->n, (unsigned)net->seed);
    return AVR_OK;
}

void avr_reset(AvrInstance *inst) {
    set_start_values(inst);
    inst->phase = AVR_INSTANTIATED;
    inst->time = 0.0;
    avr_core_free(&inst->core); /* the networks stay for reuse by the next initialization */
}

/* ---- variables ------------------------------------------------------------------------ */
static const char *TYPE_NAMES[] = {"Real/Float64", "Integer/Int32", "Boolean"};

static void range_text(const AvrVar *v, char *out, size_t size) {
    char lo[40] = "-inf", hi[40] = "inf";
    if (v->has_min) avr_fmt_double(lo, sizeof lo, v->min);
    if (v->has_max) avr_fmt_double(hi, sizeof hi, v->max);
    snprintf(out, size, "[%s, %s]", lo, hi);
}

/* Why `x` is not a valid value of v (writes the reason, returns 1), or 0.  Texts are made
 * only for a refusal: setting a valid value costs a few comparisons. */
int avr_value_problem(const AvrVar *v, double x, char *out, size_t size) {
    const char *why;
    if (v->type == AVR_BOOLEAN) {
        if (x == 0.0 || x == 1.0) return 0;
        why = "a Boolean must be true (1) or false (0)";
    } else if (!isfinite(x)) {
        why = "must be a finite number in";
    } else if (v->type == AVR_INTEGER && x != floor(x)) {
        why = "must be an integer in";
    } else if ((v->has_min && x < v->min) || (v->has_max && x > v->max)) {
        why = "out of range";
    } else {
        return 0;
    }
    char range[100] = "", value[40];
    if (v->type != AVR_BOOLEAN) range_text(v, range, sizeof range);
    avr_fmt_double(value, sizeof value, x);
    snprintf(out, size, "%s = %s: %s%s%s", v->name, value, why, range[0] ? " " : "", range);
    return 1;
}

int avr_requires_problem(const double *values, uint32_t vr, double x, char *out, size_t size) {
    size_t used = 0;
    out[0] = '\0';
    for (int i = 0; i < AVR_N_REQUIRES; ++i) {
        int a = AVR_REQUIRES[i][0], b = AVR_REQUIRES[i][1];
        double va = (uint32_t)a == vr ? x : values[a], vb = (uint32_t)b == vr ? x : values[b];
        if (va == 0.0 || vb != 0.0) continue;
        char text_a[40], text_b[40];
        avr_fmt_double(text_a, sizeof text_a, va);
        avr_fmt_double(text_b, sizeof text_b, vb);
        int k = snprintf(out + used, size - used, "%s%s = %s requires %s > 0 (it is %s)", used ? "; " : "",
                         AVR_VARS[a].name, text_a, AVR_VARS[b].name, text_b);
        if (k > 0) used = used + (size_t)k < size ? used + (size_t)k : size - 1;
    }
    return used > 0;
}

static const AvrVar *lookup(const AvrInstance *inst, const char *call, uint32_t vr, AvrType type) {
    if (vr >= AVR_N_VARS) {
        avr_refuse(inst, call, "valueReference %u does not exist (0..%u)", (unsigned)vr, (unsigned)AVR_N_VARS - 1);
        return NULL;
    }
    const AvrVar *v = &AVR_VARS[vr];
    if (v->type != type) {
        avr_refuse(inst, call, "%s (valueReference %u) is a %s variable", v->name, (unsigned)vr, TYPE_NAMES[v->type]);
        return NULL;
    }
    return v;
}

AvrStatus avr_check_get(const AvrInstance *inst, const char *call, const uint32_t vr[], size_t n, AvrType type) {
    if (n > 0 && vr == NULL) return avr_refuse(inst, call, "NULL valueReference array with %zu values", n);
    for (size_t i = 0; i < n; ++i)
        if (lookup(inst, call, vr[i], type) == NULL) return AVR_ERROR;
    return AVR_OK;
}

AvrStatus avr_check_set(const AvrInstance *inst, const char *call, uint32_t vr, AvrType type, double value) {
    const AvrVar *v = lookup(inst, call, vr, type);
    if (v == NULL) return AVR_ERROR;
    if (v->causality == AVR_OUTPUT) return avr_refuse(inst, call, "%s is an output and cannot be set", v->name);
    if (inst->phase == AVR_STEP_MODE && v->causality == AVR_PARAMETER && v->variability == AVR_FIXED)
        return avr_refuse(inst, call, "%s is a fixed parameter: set it before ExitInitializationMode", v->name);
    char problem[400];
    if (avr_value_problem(v, value, problem, sizeof problem)) return avr_refuse(inst, call, "%s", problem);
    if (inst->phase == AVR_STEP_MODE && v->causality == AVR_PARAMETER &&
        avr_requires_problem(inst->values, vr, value, problem, sizeof problem)) /* in initialization: at its end */
        return avr_refuse(inst, call, "%s", problem);
    return AVR_OK;
}

/* ---- logging --------------------------------------------------------------------------- */
/* The length of s if it is a NUL-terminated, valid UTF-8 string of at most max_bytes bytes
 * (no overlong forms, no surrogates, nothing above U+10FFFF), else -1.  Reads at most
 * max_bytes + 1 bytes, and none past the terminating NUL. */
static long utf8_length(const char *s, size_t max_bytes) {
    size_t i = 0;
    while (i <= max_bytes) {
        const unsigned char c = (unsigned char)s[i];
        if (c == 0) return (long)i;
        size_t extra;
        unsigned lo = 0x80, hi = 0xBF;
        if (c < 0x80) extra = 0;
        else if (c >= 0xC2 && c <= 0xDF) extra = 1;
        else if (c >= 0xE0 && c <= 0xEF) extra = 2, lo = c == 0xE0 ? 0xA0 : 0x80, hi = c == 0xED ? 0x9F : 0xBF;
        else if (c >= 0xF0 && c <= 0xF4) extra = 3, lo = c == 0xF0 ? 0x90 : 0x80, hi = c == 0xF4 ? 0x8F : 0xBF;
        else return -1;
        for (size_t k = 1; k <= extra; ++k) {
            const unsigned char d = (unsigned char)s[i + k]; /* a NUL here ends the check: never read past it */
            if (d < (k == 1 ? lo : 0x80) || d > (k == 1 ? hi : 0xBF)) return -1;
        }
        i += 1 + extra;
    }
    return -1;
}

AvrStatus avr_check_categories(const AvrInstance *inst, const char *call, size_t n, const char *const categories[]) {
    if (n > 0 && categories == NULL) return avr_refuse(inst, call, "categories is NULL with nCategories = %zu", n);
    for (size_t i = 0; i < n; ++i) {
        if (categories[i] == NULL) return avr_refuse(inst, call, "categories[%zu] is NULL", i);
        if (utf8_length(categories[i], AVR_MAX_CATEGORY_BYTES) < 0)
            return avr_refuse(inst, call, "categories[%zu] is not valid UTF-8 of at most %u bytes", i,
                              (unsigned)AVR_MAX_CATEGORY_BYTES);
        int known = 0;
        for (int k = 0; k < AVR_N_LOG_CATEGORIES; ++k) known |= strcmp(categories[i], AVR_LOG_CATEGORIES[k]) == 0;
        if (!known) {
            char list[256] = "";
            for (int k = 0; k < AVR_N_LOG_CATEGORIES; ++k) {
                size_t used = strlen(list);
                snprintf(list + used, sizeof list - used, "%s%s", k ? ", " : "", AVR_LOG_CATEGORIES[k]);
            }
            return avr_refuse(inst, call, "categories[%zu] = \"%.100s\" is not a log category of this FMU (known: %s)",
                              i, categories[i], list);
        }
    }
    return AVR_OK;
}

/* ---- stepping ------------------------------------------------------------------------- */
AvrStatus avr_do_step(AvrInstance *inst, const char *call, double t, double h) {
    char a[40], b[40];
    avr_fmt_double(a, sizeof a, h);
    if (!(isfinite(h) && h > 0.0))
        return avr_refuse(inst, call, "communicationStepSize = %s: must be a finite number > 0", a);
    double tolerance = AVR_TIME_MATCH_RTOL * (fabs(inst->time) > 1.0 ? fabs(inst->time) : 1.0);
    avr_fmt_double(a, sizeof a, t);
    avr_fmt_double(b, sizeof b, inst->time);
    if (!(isfinite(t) && fabs(t - inst->time) <= tolerance))
        return avr_refuse(inst, call, "currentCommunicationPoint = %s: must equal the end of the last step (%s)", a, b);
    if (!isfinite(t + h) || !isfinite(inst->core.time_s + h))
        return avr_refuse(inst, call, "currentCommunicationPoint + communicationStepSize overflows");
    avr_step(inst->net, &inst->core, inst->values, h);
    inst->time = t + h;
    return AVR_OK;
}
