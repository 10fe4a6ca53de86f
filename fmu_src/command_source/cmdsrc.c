/*
 * The CommandSource instance, independent of the FMI version (see cmdsrc.h): reading and
 * checking the schedule, the phase checks, stepping.  Every refused call logs a message
 * naming the call and the reason, returns CS_ERROR and changes nothing.
 */
#include "cmdsrc.h"

#include <ctype.h>
#include <locale.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cs_guid.h"

const char *const CS_OUTPUT_NAMES[CS_N_OUTPUTS] = {"vx_des", "vy_des", "yaw_rate_des", "push_fx", "push_fy", "push_fz"};
static const char HEADER[] = "time,vx_des,vy_des,yaw_rate_des,push_fx,push_fy,push_fz";

/* ---- logging ------------------------------------------------------------------------------ */
CsStatus cs_refuse(const CsInstance *inst, const char *call, const char *fmt, ...) {
    char reason[900], message[1024];
    va_list args;
    va_start(args, fmt);
    vsnprintf(reason, sizeof reason, fmt, args);
    va_end(args);
    snprintf(message, sizeof message, "%s refused: %s", call, reason);
    if (inst != NULL && inst->log != NULL) inst->log(inst, CS_ERROR, "logStatusError", message);
    return CS_ERROR;
}

static void debug(const CsInstance *inst, const char *fmt, ...) {
    if (!inst->logging_on || inst->log == NULL) return;
    char message[1024];
    va_list args;
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    inst->log(inst, CS_OK, "logAll", message);
}

CsStatus cs_allowed(const CsInstance *inst, const char *call, unsigned mask) {
    if (inst == NULL) return CS_ERROR;
    if ((unsigned)inst->phase & mask) return CS_OK;
    if (mask == 0u) return cs_refuse(inst, call, "not provided by this FMU (see its modelDescription.xml)");
    char list[256] = "";
    int now = 0;
    for (int bit = 0; bit < CS_N_PHASES; ++bit) {
        if ((unsigned)inst->phase & (1u << bit)) now = bit;
        if (!(mask & (1u << bit))) continue;
        size_t used = strlen(list);
        snprintf(list + used, sizeof list - used, "%s%s", used ? ", " : "", inst->phase_names[bit]);
    }
    return cs_refuse(inst, call, "not allowed in state %s (allowed in: %s)", inst->phase_names[now], list);
}

CsStatus cs_check_categories(const CsInstance *inst, const char *call, size_t n, const char *const categories[]) {
    if (n > 0 && categories == NULL) return cs_refuse(inst, call, "categories is NULL with nCategories = %zu", n);
    return CS_OK;
}

/* ---- the schedule file ---------------------------------------------------------------------- */
static int hexval(int c) {
    if (c >= '0' && c <= '9') return c - '0';
    c = tolower(c);
    return (c >= 'a' && c <= 'f') ? c - 'a' + 10 : -1;
}

char *cs_path_from_uri(const char *uri) {
    if (uri == NULL || strncmp(uri, "file:", 5) != 0) return NULL;
    const char *p = uri + 5;
    if (strncmp(p, "//", 2) == 0) { /* file://host/path: only an empty host or localhost */
        p += 2;
        if (strncmp(p, "localhost/", 10) == 0) p += 9;
        else if (*p != '/') return NULL;
    }
    /* file:///C:/x -> C:/x */
    if (p[0] == '/' && isalpha((unsigned char)p[1]) && (p[2] == ':' || p[2] == '|')) ++p;
    char *out = malloc(strlen(p) + 1), *o = out;
    if (out == NULL) return NULL;
    for (; *p; ++p) {
        int hi, lo;
        if (*p == '%' && (hi = hexval((unsigned char)p[1])) >= 0 && (lo = hexval((unsigned char)p[2])) >= 0) {
            *o++ = (char)(hi * 16 + lo);
            p += 2;
        } else {
            *o++ = *p;
        }
    }
    *o = '\0';
    return out;
}

/* `text` for a log message, which FMI requires to be UTF-8: printable ASCII as is, any other
 * byte as \xHH, at most `size` - 1 characters ("..." at the end when cut). */
static const char *quoted(char *out, size_t size, const char *text) {
    static const char hex[] = "0123456789abcdef";
    size_t n = 0;
    for (const unsigned char *c = (const unsigned char *)text; *c; ++c) {
        if (n + 8 >= size) {
            memcpy(out + n, "...", 4);
            return out;
        }
        if (*c >= 0x20 && *c < 0x7f && *c != '\\') {
            out[n++] = (char)*c;
        } else {
            out[n++] = '\\', out[n++] = 'x', out[n++] = hex[*c >> 4], out[n++] = hex[*c & 15];
        }
    }
    out[n] = '\0';
    return out;
}

/* A decimal number in C's notation ('.' as the decimal point, whatever the host's locale). */
static int parse_number(const char *field, double *out) {
    char buf[128];
    size_t n = strlen(field);
    while (n > 0 && isspace((unsigned char)field[n - 1])) --n;
    while (n > 0 && isspace((unsigned char)*field)) ++field, --n;
    if (n == 0 || n >= sizeof buf) return 0;
    memcpy(buf, field, n);
    buf[n] = '\0';
    const struct lconv *lc = localeconv();
    char point = (lc && lc->decimal_point && lc->decimal_point[0]) ? lc->decimal_point[0] : '.';
    for (char *c = buf; *c; ++c)
        if (*c == '.') *c = point;
    char *end;
    *out = strtod(buf, &end);
    return *end == '\0' && isfinite(*out);
}

static CsStatus read_schedule(CsInstance *inst, const char *resources) {
    const char *call = "instantiate";
    if (resources == NULL || resources[0] == '\0')
        return cs_refuse(inst, call, "no resource location: the schedule is resources/%s", CS_SCHEDULE_FILE);
    size_t len = strlen(resources);
    char *path = malloc(len + sizeof CS_SCHEDULE_FILE + 2);
    if (path == NULL) return cs_refuse(inst, call, "out of memory");
    int sep = resources[len - 1] == '/' || resources[len - 1] == '\\';
    sprintf(path, "%s%s%s", resources, sep ? "" : "/", CS_SCHEDULE_FILE);
    FILE *f = fopen(path, "rb");
    if (f == NULL) {
        cs_refuse(inst, call, "cannot open the schedule %s", path);
        free(path);
        return CS_ERROR;
    }
    size_t cap = 16;
    inst->times = malloc(cap * sizeof(double));
    inst->values = malloc(cap * CS_N_OUTPUTS * sizeof(double));
    char line[4096];
    int lineno = 0, header_seen = 0;
    CsStatus status = CS_OK;
    while (status == CS_OK && fgets(line, sizeof line, f) != NULL) {
        ++lineno;
        size_t n = strlen(line);
        if (n == sizeof line - 1 && line[n - 1] != '\n') {
            status = cs_refuse(inst, call, "%s line %d: longer than %d characters", path, lineno, (int)sizeof line - 2);
            break;
        }
        while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r')) line[--n] = '\0';
        if (n == 0 || line[0] == '#') continue;
        if (!header_seen) {
            char shown[160];
            if (strcmp(line, HEADER) != 0)
                status = cs_refuse(inst, call, "%s line %d: the header must be \"%s\", not \"%s\"", path, lineno,
                                   HEADER, quoted(shown, sizeof shown, line));
            header_seen = 1;
            continue;
        }
        if (inst->n_rows == CS_MAX_ROWS) {
            status = cs_refuse(inst, call, "%s: more than %d rows", path, CS_MAX_ROWS);
            break;
        }
        if (inst->times == NULL || inst->values == NULL) {
            status = cs_refuse(inst, call, "out of memory");
            break;
        }
        if (inst->n_rows == cap) {
            cap *= 2;
            double *t = realloc(inst->times, cap * sizeof(double));
            if (t != NULL) inst->times = t;
            double *v = realloc(inst->values, cap * CS_N_OUTPUTS * sizeof(double));
            if (v != NULL) inst->values = v;
            if (t == NULL || v == NULL) {
                status = cs_refuse(inst, call, "out of memory");
                break;
            }
        }
        double row[1 + CS_N_OUTPUTS];
        char *cursor = line;
        for (int col = 0; col <= CS_N_OUTPUTS && status == CS_OK; ++col) {
            char *comma = strchr(cursor, ',');
            if ((comma == NULL) != (col == CS_N_OUTPUTS)) {
                status = cs_refuse(inst, call, "%s line %d: %d comma-separated numbers expected (%s)", path, lineno,
                                   1 + CS_N_OUTPUTS, HEADER);
                break;
            }
            if (comma != NULL) *comma = '\0';
            char shown[160];
            if (!parse_number(cursor, &row[col]))
                status = cs_refuse(inst, call, "%s line %d: %s = \"%s\" is not a finite number", path, lineno,
                                   col == 0 ? "time" : CS_OUTPUT_NAMES[col - 1], quoted(shown, sizeof shown, cursor));
            cursor = comma + 1;
        }
        if (status != CS_OK) break;
        if (inst->n_rows > 0 && !(row[0] > inst->times[inst->n_rows - 1]))
            status = cs_refuse(inst, call, "%s line %d: time = %.17g s must be after the previous row's %.17g s",
                               path, lineno, row[0], inst->times[inst->n_rows - 1]);
        if (status != CS_OK) break;
        inst->times[inst->n_rows] = row[0];
        memcpy(&inst->values[inst->n_rows * CS_N_OUTPUTS], &row[1], sizeof(double) * CS_N_OUTPUTS);
        ++inst->n_rows;
    }
    if (status == CS_OK && ferror(f)) status = cs_refuse(inst, call, "reading %s failed", path);
    if (status == CS_OK && inst->n_rows == 0)
        status = cs_refuse(inst, call, "%s has no rows (a header \"%s\" and at least one row)", path, HEADER);
    fclose(f);
    if (status == CS_OK) debug(inst, "%s: %zu rows from t = %.17g s", path, inst->n_rows, inst->times[0]);
    free(path);
    return status;
}

/* ---- life cycle ---------------------------------------------------------------------------- */
CsInstance *cs_instantiate(const char *name, const char *token, const char *resources, void *env, CsLogFn *log,
                           int logging_on, const char *const *phase_names) {
    CsInstance probe = {.name = (char *)(name ? name : ""), .env = env, .log = log, .phase_names = phase_names,
                        .logging_on = logging_on};
    if (name == NULL || name[0] == '\0') {
        cs_refuse(&probe, "instantiate", "instanceName must be a non-empty string");
        return NULL;
    }
    if (token == NULL || strcmp(token, CS_GUID) != 0) {
        cs_refuse(&probe, "instantiate", "GUID/instantiationToken %s does not match this FMU's %s",
                  token ? token : "(NULL)", CS_GUID);
        return NULL;
    }
    CsInstance *inst = calloc(1, sizeof *inst);
    char *copy = malloc(strlen(name) + 1);
    if (inst == NULL || copy == NULL) {
        free(inst);
        free(copy);
        cs_refuse(&probe, "instantiate", "out of memory");
        return NULL;
    }
    strcpy(copy, name);
    *inst = probe;
    inst->name = copy;
    inst->phase = CS_INSTANTIATED;
    if (read_schedule(inst, resources) != CS_OK) {
        cs_free(inst);
        return NULL;
    }
    return inst;
}

void cs_free(CsInstance *inst) {
    if (inst == NULL) return;
    free(inst->times);
    free(inst->values);
    free(inst->name);
    free(inst);
}

static int at_or_after(double t, double row_time) {
    double scale = fabs(row_time) > 1.0 ? fabs(row_time) : 1.0;
    return t >= row_time - CS_TIME_RTOL * scale;
}

/* The row in force at `t`, searching forward from `from` (time only moves forward). */
static size_t row_at(const CsInstance *inst, size_t from, double t) {
    size_t row = from;
    while (row + 1 < inst->n_rows && at_or_after(t, inst->times[row + 1])) ++row;
    return row;
}

CsStatus cs_setup(CsInstance *inst, const char *call, double start_time, int stop_defined, double stop_time) {
    if (!isfinite(start_time)) return cs_refuse(inst, call, "startTime = %.17g: must be finite", start_time);
    if (stop_defined && !(stop_time >= start_time))
        return cs_refuse(inst, call, "stopTime = %.17g: must be >= startTime = %.17g", stop_time, start_time);
    if (!at_or_after(start_time, inst->times[0]))
        return cs_refuse(inst, call, "startTime = %.17g s is before the schedule's first row (t = %.17g s)",
                         start_time, inst->times[0]);
    inst->start_time = start_time;
    inst->time = start_time;
    inst->row = row_at(inst, 0, start_time);
    return CS_OK;
}

CsStatus cs_enter_init(CsInstance *inst, const char *call) {
    (void)call;
    inst->time = inst->start_time;
    inst->row = row_at(inst, 0, inst->start_time);
    inst->phase = CS_INIT_MODE;
    return CS_OK;
}

CsStatus cs_exit_init(CsInstance *inst, const char *call) {
    (void)call; /* nothing to check: the outputs are the schedule's from the start */
    inst->phase = CS_STEP_MODE;
    return CS_OK;
}

void cs_reset(CsInstance *inst) {
    inst->phase = CS_INSTANTIATED;
    inst->start_time = inst->time = inst->times[0] > 0.0 ? inst->times[0] : 0.0;
    inst->row = row_at(inst, 0, inst->time);
}

/* ---- variables and stepping -------------------------------------------------------------------- */
CsStatus cs_check_get(const CsInstance *inst, const char *call, const unsigned vr[], size_t n) {
    if (n > 0 && vr == NULL) return cs_refuse(inst, call, "NULL valueReference array with %zu values", n);
    for (size_t i = 0; i < n; ++i)
        if (vr[i] >= CS_N_OUTPUTS)
            return cs_refuse(inst, call, "valueReference %u is not a Real variable of this FMU (0..%d)", vr[i],
                             CS_N_OUTPUTS - 1);
    return CS_OK;
}

double cs_output(const CsInstance *inst, unsigned vr) { return inst->values[inst->row * CS_N_OUTPUTS + vr]; }

CsStatus cs_do_step(CsInstance *inst, const char *call, double t, double h) {
    if (!(isfinite(h) && h > 0.0))
        return cs_refuse(inst, call, "communicationStepSize = %.17g: must be a finite number > 0", h);
    double tolerance = CS_TIME_RTOL * (fabs(inst->time) > 1.0 ? fabs(inst->time) : 1.0);
    if (!(isfinite(t) && fabs(t - inst->time) <= tolerance))
        return cs_refuse(inst, call, "currentCommunicationPoint = %.17g: must equal the end of the last step (%.17g)",
                         t, inst->time);
    inst->time = t + h;
    inst->row = row_at(inst, inst->row, inst->time);
    return CS_OK;
}
