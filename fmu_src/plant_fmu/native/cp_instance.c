/*
 * The CassiePlantNative instance (see cp_instance.h): the same rules as the pythonfmu
 * CassiePlant (fmu_src/fmi/avr_slavebase.py, fmu_src/plant_fmu/cassie_plant_slave.py,
 * fmu_core.py): a refused call changes nothing and the instance stays usable.
 *
 * FMU state blob (little endian, every double as its 8 IEEE bytes):
 *   "CPNS" u32 version u32 total bytes  char[40] GUID (NUL padded)     header
 *   u32 phase bit  u32 has walker  f64 time  f64 values[CP_N_VARS]  (version 2; terrain_field_file's
 *                                       value is 0 there: its text is not part of a state)
 *   walker (has walker only): i32 substep  i32 fell  char[160] fall reason
 *     f64 vx_des_mps vy_des_mps yaw_rate_des_radps
 *     controller memory: f64 offsets[6] vx_ref vy_ref vx_des vy_des yaw_rate_ref yaw_rate_des
 *       i32 mode  i32 stance  i64 step_index  f64 t_step_start tau vx_step_avg vy_filt vx_filt
 *       step_start_xy[2] swing_start[2] last_t yaw_ref
 *     u32 n  f64 MuJoCo integration state[n] (mj_getState, mjSTATE_INTEGRATION)
 *     f64 servo gains[20] (-kp, -kd of each motor, actuator order)
 *   u32 CRC-32 (zlib's) of every byte before it
 * A blob is set only if it is one this FMU can have written: the CRC and GUID, a known phase,
 * every variable of its type and in its range, the fixed parameters equal to this instance's
 * (terrain_field_file's text is the instance's own: a walker the state needs is built on it),
 * and a walker state a run can reach (plant.sim.CassieWalker.state_problems: finite values
 * within MuJoCo's mjMAXVAL, unit quaternions, ordered step times, ...).
 */
#include "cp_instance.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi_blob.h"

static const char *const TYPE_NAMES[] = {"Real", "Integer", "Boolean", "String"};

static void vlog(const CpInstance *inst, CpStatus status, const char *category, const char *fmt, va_list ap) {
    char msg[1400];
    vsnprintf(msg, sizeof msg, fmt, ap);
    if (inst->log) inst->log(inst, status, category, msg);
}

CpStatus cp_refuse(const CpInstance *inst, const char *call, const char *fmt, ...) {
    char msg[1200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (inst->log) {
        char full[1400];
        snprintf(full, sizeof full, "%s refused: %s", call, msg);
        inst->log(inst, CP_ERROR, "logStatusError", full);
    }
    return CP_ERROR;
}

void cp_debug(const CpInstance *inst, const char *fmt, ...) {
    if (!inst->logging_on) return;
    va_list ap;
    va_start(ap, fmt);
    vlog(inst, CP_OK, "logAll", fmt, ap);
    va_end(ap);
}

static const char *phase_name(const CpInstance *inst, CpPhase p) {
    for (int i = 0; i < CP_N_PHASES; i++)
        if (p == (CpPhase)(1u << i)) return inst->phase_names[i];
    return "?";
}

CpStatus cp_allowed(const CpInstance *inst, const char *call, unsigned mask) {
    if (inst == NULL) return CP_ERROR;
    if ((unsigned)inst->phase & mask) return CP_OK;
    if (mask == 0u) return cp_refuse(inst, call, "not provided by this FMU (see its modelDescription.xml)");
    char list[200] = "";
    for (int i = 0; i < CP_N_PHASES; i++)
        if (mask & (1u << i)) {
            if (list[0]) strncat(list, ", ", sizeof list - strlen(list) - 1);
            strncat(list, inst->phase_names[i], sizeof list - strlen(list) - 1);
        }
    return cp_refuse(inst, call, "not allowed in state %s (allowed in: %s)", phase_name(inst, inst->phase),
                     list[0] ? list : "none");
}

CpStatus cp_check_categories(const CpInstance *inst, const char *call, size_t n, const char *const categories[]) {
    if (n > 0 && categories == NULL) return cp_refuse(inst, call, "categories is NULL with nCategories = %zu", n);
    for (size_t i = 0; i < n; i++) {
        int known = 0;
        for (int k = 0; k < CP_N_LOG_CATEGORIES && categories[i]; k++) known |= !strcmp(categories[i], CP_LOG_CATEGORIES[k]);
        if (!known)
            return cp_refuse(inst, call, "category %zu is not one the model description declares (logStatusError, logAll)", i);
    }
    return CP_OK;
}

static void defaults(CpInstance *inst) {
    for (int i = 0; i < CP_N_VARS; i++) inst->values[i] = CP_VARS[i].start;
    inst->time = 0.0;
}

CpInstance *cp_instantiate(const char *name, const char *token, const char *resources, void *env, CpLogFn *log,
                           int logging_on, const char *const *phase_names) {
    CpInstance probe = {.name = (char *)(name ? name : ""), .env = env, .log = log, .phase_names = phase_names};
    if (token == NULL || strcmp(token, CP_GUID) != 0) {
        cp_refuse(&probe, "instantiate", "the GUID/instantiationToken %s is not this FMU's (%s)", token ? token : "(null)",
                  CP_GUID);
        return NULL;
    }
    char why[300];
    if (cp_mujoco_load(why, sizeof why)) {
        cp_refuse(&probe, "instantiate", "%s", why);
        return NULL;
    }
    if (resources == NULL || !resources[0]) {
        cp_refuse(&probe, "instantiate", "no resource location: the FMU needs its resources (the Cassie models)");
        return NULL;
    }
    CpInstance *inst = calloc(1, sizeof *inst);
    if (inst == NULL) return NULL;
    inst->name = malloc(strlen(probe.name) + 1);
    inst->resources = malloc(strlen(resources) + 1);
    if (inst->name == NULL || inst->resources == NULL) {
        free(inst->name);
        free(inst->resources);
        free(inst);
        return NULL;
    }
    strcpy(inst->name, probe.name);
    strcpy(inst->resources, resources);
    inst->env = env;
    inst->log = log;
    inst->logging_on = logging_on;
    inst->phase_names = phase_names;
    inst->phase = CP_INSTANTIATED;
    defaults(inst);
    return inst;
}

void cp_free_instance(CpInstance *inst) {
    if (inst == NULL) return;
    if (inst->has_walker) cp_free(&inst->walker);
    free(inst->resources);
    free(inst->terrain_field);
    free(inst->name);
    free(inst);
}

CpStatus cp_setup(CpInstance *inst, const char *call, double start_time) {
    if (!isfinite(start_time)) return cp_refuse(inst, call, "startTime = %.17g: must be finite", start_time);
    inst->time = start_time;
    return CP_OK;
}

/* plant.perturbation.Perturbation.problems beyond the declared ranges: the torso mass, the floor
 * friction and the link mass factors are > 0, and a floor slope tilts the flat floor, so it is not
 * given with an uneven terrain. */
static int param_problem(const double *v, char *out, size_t n) {
    static const int positive[] = {CP_VR_torso_mass_kg, CP_VR_floor_friction};
    for (size_t i = 0; i < sizeof positive / sizeof positive[0]; i++) {
        const CpVar *p = &CP_VARS[positive[i]];
        const char *unit = strcmp(p->unit, "1") ? p->unit : ""; /* "1": dimensionless */
        if (!(v[positive[i]] > 0.0)) {
            snprintf(out, n, "%s = %.17g%s%s: must be in (0, %g]%s%s", p->name, v[positive[i]], unit[0] ? " " : "", unit,
                     p->max, unit[0] ? " " : "", unit);
            return 1;
        }
    }
    for (int i = 0; i < CP_N_LINK_MASS; i++) {
        const CpVar *p = &CP_VARS[CP_LINK_MASS[i].vr];
        if (!(v[CP_LINK_MASS[i].vr] > 0.0)) {
            snprintf(out, n, "%s = %.17g: must be in (0, %g]", p->name, v[CP_LINK_MASS[i].vr], p->max);
            return 1;
        }
    }
    double slope = v[CP_VR_floor_slope_deg], cross_slope = v[CP_VR_floor_cross_slope_deg];
    if (v[CP_VR_terrain_max_height_m] != 0.0 && (slope != 0.0 || cross_slope != 0.0)) {
        snprintf(out, n, "floor_slope_deg = %.17g deg, floor_cross_slope_deg = %.17g deg with terrain_max_height_m = "
                 "%.17g m: the slopes tilt the flat floor; give a slope or a terrain, not both", slope, cross_slope,
                 v[CP_VR_terrain_max_height_m]);
        return 1;
    }
    return 0;
}

static int start_walker(const CpInstance *inst, const double *values, CpWalker *w, char *err, int errlen) {
    if (param_problem(values, err, (size_t)errlen)) return -1;
    char models[4200];
    snprintf(models, sizeof models, "%s/models", inst->resources);
    return cp_start(w, models, values, inst->terrain_field, err, errlen);
}

CpStatus cp_exit_init(CpInstance *inst, const char *call) {
    char err[1200];
    if (start_walker(inst, inst->values, &inst->walker, err, sizeof err)) return cp_refuse(inst, call, "%s", err);
    inst->has_walker = 1;
    cp_outputs(&inst->walker, inst->values);
    inst->phase = CP_STEP_MODE;
    return CP_OK;
}

void cp_reset(CpInstance *inst) {
    if (inst->has_walker) cp_free(&inst->walker);
    inst->has_walker = 0;
    free(inst->terrain_field);
    inst->terrain_field = NULL;
    defaults(inst);
    inst->phase = CP_INSTANTIATED;
}

static const CpVar *lookup(const CpInstance *inst, const char *call, uint32_t vr, CpType type) {
    if (vr >= CP_N_VARS) {
        cp_refuse(inst, call, "valueReference %u does not exist (0..%u)", (unsigned)vr, (unsigned)CP_N_VARS - 1);
        return NULL;
    }
    const CpVar *v = &CP_VARS[vr];
    if (v->type != type) {
        cp_refuse(inst, call, "%s (valueReference %u) is a %s variable", v->name, (unsigned)vr, TYPE_NAMES[v->type]);
        return NULL;
    }
    return v;
}

CpStatus cp_check_get(const CpInstance *inst, const char *call, const uint32_t vr[], size_t n, CpType type) {
    if (n > 0 && vr == NULL) return cp_refuse(inst, call, "valueReferences is NULL with %zu of them", n);
    for (size_t i = 0; i < n; i++)
        if (!lookup(inst, call, vr[i], type)) return CP_ERROR;
    return CP_OK;
}

/* Why x is not a legal value of v (0: it is). */
static int value_problem(const CpVar *v, double x, char *out, size_t n) {
    const char *why;
    if (v->type == CP_BOOLEAN) {
        if (x == 0.0 || x == 1.0) return 0;
        why = "a Boolean must be true (1) or false (0)";
    } else if (v == &CP_VARS[CP_VR_terrain_field_file]) { /* a text, kept beside the values */
        if (x == 0.0) return 0;
        snprintf(out, n, "%s: its place among the values must hold 0", v->name);
        return 1;
    } else if (v->type == CP_STRING) {
        if (x >= 0 && x < CP_N_MODELS && x == floor(x)) return 0;
        snprintf(out, n, "%s: not one of 'menagerie', 'osu'", v->name);
        return 1;
    } else if (!isfinite(x)) {
        why = "must be a finite number in";
    } else if (v->type == CP_INTEGER && x != floor(x)) {
        why = "must be an integer in";
    } else if ((v->has_min && x < v->min) || (v->has_max && x > v->max)) {
        why = "out of range";
    } else {
        return 0;
    }
    char range[120] = "";
    if (v->type != CP_BOOLEAN && (v->has_min || v->has_max))
        snprintf(range, sizeof range, " [%.17g, %.17g]%s%s", v->has_min ? v->min : -INFINITY,
                 v->has_max ? v->max : INFINITY, v->unit[0] ? " " : "", v->unit);
    snprintf(out, n, "%s = %.17g: %s%s", v->name, x, why, range);
    return 1;
}

CpStatus cp_check_set(const CpInstance *inst, const char *call, uint32_t vr, CpType type, double x) {
    const CpVar *v = lookup(inst, call, vr, type);
    if (!v) return CP_ERROR;
    if (v->causality == CP_OUTPUT) return cp_refuse(inst, call, "%s is an output and cannot be set", v->name);
    if (inst->phase == CP_STEP_MODE && v->causality == CP_PARAMETER)
        return cp_refuse(inst, call, "%s is a fixed parameter: set it before the end of initialization", v->name);
    char problem[300];
    if (value_problem(v, x, problem, sizeof problem)) return cp_refuse(inst, call, "%s", problem);
    return CP_OK;
}

/* Why `text` cannot be String variable vr's value (NULL: it can); its value in values[] then. */
static CpStatus check_text(const CpInstance *inst, const char *call, uint32_t vr, const char *text, double *index) {
    if (cp_check_set(inst, call, vr, CP_STRING, 0.0) != CP_OK) return CP_ERROR;
    if (vr == CP_VR_terrain_field_file) {
        if (text == NULL || strlen(text) > CP_MAX_TEXT_BYTES)
            return cp_refuse(inst, call, "terrain_field_file: must be a path (text) of at most %d bytes",
                             CP_MAX_TEXT_BYTES);
        *index = 0.0;
        return CP_OK;
    }
    for (int k = 0; k < CP_N_MODELS && text; k++)
        if (!strcmp(text, CP_MODEL_NAMES[k])) {
            *index = k;
            return CP_OK;
        }
    return cp_refuse(inst, call, "cassie_model = '%.100s': must be one of 'menagerie', 'osu'", text ? text : "(null)");
}

CpStatus cp_set_strings(CpInstance *inst, const char *call, const uint32_t vr[], const char *const text[], size_t n) {
    if (n > 0 && (vr == NULL || text == NULL)) return cp_refuse(inst, call, "NULL vr or value array with nvr = %zu", n);
    if (n > CP_N_VARS) return cp_refuse(inst, call, "%zu values: more than the variables", n);
    double index[CP_N_VARS];
    char *copy = NULL; /* the last terrain_field_file text given */
    for (size_t i = 0; i < n; i++)
        if (check_text(inst, call, vr[i], text[i], &index[i]) != CP_OK) return CP_ERROR;
    for (size_t i = n; i-- > 0;)
        if (vr[i] == CP_VR_terrain_field_file) {
            if ((copy = malloc(strlen(text[i]) + 1)) == NULL) return cp_refuse(inst, call, "out of memory");
            strcpy(copy, text[i]);
            break;
        }
    for (size_t i = 0; i < n; i++) inst->values[vr[i]] = index[i];
    if (copy != NULL) {
        free(inst->terrain_field);
        inst->terrain_field = copy;
    }
    return CP_OK;
}

const char *cp_get_string(const CpInstance *inst, uint32_t vr) {
    if (vr == CP_VR_terrain_field_file) return inst->terrain_field ? inst->terrain_field : "";
    return CP_MODEL_NAMES[(int)inst->values[vr]];
}

/* fmu_core.plant_steps: the step as a whole number of plant steps, or -1. */
static long plant_steps(double h) {
    double n = h / CP_PLANT_STEP_S;
    if (!(isfinite(n) && n >= 1.0 - CP_STEPS_TOL && fabs(n - nearbyint(n)) <= CP_STEPS_TOL && h <= CP_MAX_STEP_S))
        return -1;
    return (long)nearbyint(n);
}

CpStatus cp_do_step(CpInstance *inst, const char *call, double t, double h) {
    if (!(isfinite(h) && h > 0.0))
        return cp_refuse(inst, call, "communicationStepSize = %.17g: must be a finite number > 0", h);
    double tol = CP_TIME_MATCH_RTOL * (fabs(inst->time) > 1.0 ? fabs(inst->time) : 1.0);
    if (!(isfinite(t) && fabs(t - inst->time) <= tol))
        return cp_refuse(inst, call, "currentCommunicationPoint = %.17g: must equal the end of the last step (%.17g) to "
                         "within %g s", t, inst->time, tol);
    if (!(h <= CP_MAX_STEP_S))
        return cp_refuse(inst, call, "communicationStepSize = %.17g s: exceeds the maximum communication step %g s of "
                         "this FMU (take several steps)", h, CP_MAX_STEP_S);
    long n = plant_steps(h);
    if (n < 0)
        return cp_refuse(inst, call, "communicationStepSize = %.17g s: must be a whole multiple of the plant step %g s",
                         h, CP_PLANT_STEP_S);
    int fell = inst->values[CP_VR_fell] != 0.0;
    cp_advance(&inst->walker, inst->values, n);
    cp_outputs(&inst->walker, inst->values);
    if (inst->values[CP_VR_fell] != 0.0 && !fell)
        cp_debug(inst, "CassiePlant fell at t = %.4f s: %s", inst->values[CP_VR_plant_time], inst->walker.fall_reason);
    inst->time = t + h;
    return CP_OK;
}

/* ---- FMU state ------------------------------------------------------------------------------ */
#define CP_PI 3.141592653589793 /* math.pi */
#define MAGIC "CPNS"
#define STATE_VERSION 2u /* 2: the values include terrain_field_file's place */
#define GUID_BYTES 40
#define HEADER_BYTES (4 + 4 + 4 + GUID_BYTES)
#define N_GAINS (CC_NSIDES * CC_NMOTOR * 2)

/* The smallest blob: header, phase, walker flag, time, the values and the CRC (no walker). */
#define MIN_BLOB_BYTES (HEADER_BYTES + 4 + 4 + 8 + 8 * CP_N_VARS + 4)

/* The framing every C FMU of the project checks alike (fmi_blob.c): magic, version, the size
 * the header states, the CRC-32 over every byte before it, the GUID of the FMU that saved it. */
static CpStatus check_frame(const CpInstance *inst, const char *call, const unsigned char *bytes, size_t size) {
    static const FmiBlobFormat format = {
        .magic = MAGIC, .magic_bytes = 4, .version_at = 4, .version = STATE_VERSION,
        .version_note = "(version 1 states predate terrain_field_file)",
        .size_at = 8, .size_field_bytes = 4, .size_add = 0, .crc_bytes = 4,
        .guid_at = 12, .guid_bytes = GUID_BYTES, .guid = CP_GUID, .min_bytes = MIN_BLOB_BYTES};
    char why[400];
    if (fmi_blob_problem(&format, bytes, size, why, sizeof why) != NULL)
        return cp_refuse(inst, call, "not a state of this CassiePlantNative FMU: %s", why);
    return CP_OK;
}

typedef struct {
    unsigned char *p; /* NULL: only count */
    size_t at, size;
    int bad; /* reading past the end */
} Buf;

static void put(Buf *b, const void *x, size_t n) {
    if (b->p) memcpy(b->p + b->at, x, n);
    b->at += n;
}
static void put_u32(Buf *b, uint32_t x) {
    unsigned char v[4] = {(unsigned char)x, (unsigned char)(x >> 8), (unsigned char)(x >> 16), (unsigned char)(x >> 24)};
    put(b, v, 4);
}
static void put_u64(Buf *b, uint64_t x) {
    put_u32(b, (uint32_t)x);
    put_u32(b, (uint32_t)(x >> 32));
}
static void put_f64(Buf *b, double x) {
    uint64_t u;
    memcpy(&u, &x, 8);
    put_u64(b, u);
}
static void get(Buf *b, void *x, size_t n) {
    if (b->bad || b->size - b->at < n) {
        b->bad = 1;
        memset(x, 0, n);
        return;
    }
    memcpy(x, b->p + b->at, n);
    b->at += n;
}
static uint32_t get_u32(Buf *b) {
    unsigned char v[4];
    get(b, v, 4);
    return (uint32_t)v[0] | (uint32_t)v[1] << 8 | (uint32_t)v[2] << 16 | (uint32_t)v[3] << 24;
}
static uint64_t get_u64(Buf *b) {
    uint64_t lo = get_u32(b);
    return lo | (uint64_t)get_u32(b) << 32;
}
static double get_f64(Buf *b) {
    uint64_t u = get_u64(b);
    double x;
    memcpy(&x, &u, 8);
    return x;
}

/* The walker part: what CassieWalker.get_state holds. */
typedef struct {
    int substep, fell;
    char fall_reason[160];
    double vx_des_mps, vy_des_mps, yaw_rate_des_radps;
    CcMemory mem;
    int nstate;
    double *state; /* nstate */
    double gains[N_GAINS];
} WalkerState;

static void put_walker(Buf *b, const CpWalker *w) {
    put_u32(b, (uint32_t)w->substep);
    put_u32(b, (uint32_t)w->fell);
    put(b, w->fall_reason, sizeof w->fall_reason);
    put_f64(b, w->vx_des_mps);
    put_f64(b, w->vy_des_mps);
    put_f64(b, w->yaw_rate_des_radps);
    const CcMemory *m = &w->ctrl.mem;
    for (int k = 0; k < CC_NOFFSETS; k++) put_f64(b, m->offsets[k]);
    double head[] = {m->vx_ref, m->vy_ref, m->vx_des, m->vy_des, m->yaw_rate_ref, m->yaw_rate_des};
    for (size_t k = 0; k < sizeof head / sizeof *head; k++) put_f64(b, head[k]);
    put_u32(b, (uint32_t)m->mode);
    put_u32(b, (uint32_t)m->stance);
    put_u64(b, (uint64_t)m->step_index);
    double tail[] = {m->t_step_start, m->tau, m->vx_step_avg, m->vy_filt, m->vx_filt, m->step_start_xy[0],
                     m->step_start_xy[1], m->swing_start[0], m->swing_start[1], m->last_t, m->yaw_ref};
    for (size_t k = 0; k < sizeof tail / sizeof *tail; k++) put_f64(b, tail[k]);
    int n = mj_stateSize(w->m, mjSTATE_INTEGRATION);
    put_u32(b, (uint32_t)n);
    if (b->p) {
        double *s = malloc(sizeof(double) * (size_t)(n ? n : 1));
        if (s) mj_getState(w->m, w->d, s, mjSTATE_INTEGRATION);
        for (int i = 0; i < n; i++) put_f64(b, s ? s[i] : NAN);
        free(s);
    } else {
        b->at += 8 * (size_t)n;
    }
    for (int s = 0; s < CC_NSIDES; s++)
        for (int j = 0; j < CC_NMOTOR; j++) {
            int a = w->ctrl.fx.act[s][j];
            put_f64(b, w->m->actuator_biasprm[mjNBIAS * a + 1]);
            put_f64(b, w->m->actuator_biasprm[mjNBIAS * a + 2]);
        }
}

static size_t blob_bytes(const CpInstance *inst, int with_walker) {
    Buf b = {NULL, 0, 0, 0};
    put(&b, NULL, HEADER_BYTES);
    b.at += 4 + 4 + 8 + 8 * CP_N_VARS;
    if (with_walker) put_walker(&b, &inst->walker);
    return b.at + 4;
}

CpStatus cp_fmustate_get(CpInstance *inst, const char *call, void **state) {
    if (state == NULL) return cp_refuse(inst, call, "FMUstate pointer is NULL");
    size_t n = blob_bytes(inst, inst->has_walker);
    CpBlob *blob = *state;
    if (blob == NULL || blob->size != n) { /* a new blob, or the old one resized (FMI: overwrite *state) */
        CpBlob *fresh = malloc(sizeof(CpBlob) + n);
        if (fresh == NULL) return cp_refuse(inst, call, "out of memory for a state of %zu bytes", n);
        free(blob);
        blob = fresh;
        blob->size = n;
        *state = blob;
    }
    Buf b = {blob->bytes, 0, n, 0};
    char guid[GUID_BYTES] = {0};
    strncpy(guid, CP_GUID, GUID_BYTES - 1);
    put(&b, MAGIC, 4);
    put_u32(&b, STATE_VERSION);
    put_u32(&b, (uint32_t)n);
    put(&b, guid, GUID_BYTES);
    put_u32(&b, (uint32_t)inst->phase);
    put_u32(&b, (uint32_t)inst->has_walker);
    put_f64(&b, inst->time);
    for (int i = 0; i < CP_N_VARS; i++) put_f64(&b, inst->values[i]);
    if (inst->has_walker) put_walker(&b, &inst->walker);
    put_u32(&b, fmi_crc32(blob->bytes, b.at));
    return CP_OK;
}

void cp_fmustate_free(void **state) {
    if (state == NULL) return;
    free(*state);
    *state = NULL;
}

CpStatus cp_fmustate_size(const CpInstance *inst, const char *call, const void *state, size_t *size) {
    if (state == NULL || size == NULL) return cp_refuse(inst, call, "FMUstate or size is NULL");
    *size = ((const CpBlob *)state)->size;
    return CP_OK;
}

CpStatus cp_fmustate_serialize(const CpInstance *inst, const char *call, const void *state, unsigned char *bytes,
                               size_t size) {
    const CpBlob *blob = state;
    if (blob == NULL || bytes == NULL) return cp_refuse(inst, call, "FMUstate or the byte array is NULL");
    if (size != blob->size)
        return cp_refuse(inst, call, "size = %zu: the serialized state has %zu bytes (SerializedFMUstateSize)", size,
                         blob->size);
    memcpy(bytes, blob->bytes, size);
    return CP_OK;
}

/* Number checks of a walker state, each naming the field and its allowed range. */
typedef struct {
    char *out;
    size_t n;
    int count;
} Problems;

static void problem(Problems *p, const char *fmt, ...)
#if defined(__GNUC__) && !defined(__MINGW32__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static void problem(Problems *p, const char *fmt, ...) {
    if (p->count++) return; /* the first one is reported */
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(p->out, p->n, fmt, ap);
    va_end(ap);
}

static int number(Problems *p, const char *name, double x, double lo, double hi) {
    if (!(x >= lo && x <= hi)) {
        problem(p, "controller %s = %.17g: must be a finite number in [%g, %g]", name, x, lo, hi);
        return 0;
    }
    return 1;
}

static void input_range(Problems *p, const char *label, double x, int vr) {
    const CpVar *v = &CP_VARS[vr];
    if (!(x >= v->min && x <= v->max))
        problem(p, "%s = %.17g: out of range [%g, %g] (the input %s's)", label, x, v->min, v->max, v->name);
}

/* Read and check the walker part against the model of `w` (CassieWalker.state_problems and
 * fmu_core._command_problems); 0 if it is a state a run can reach. */
static int read_walker(Buf *b, const CpWalker *w, WalkerState *ws, Problems *p) {
    const mjModel *m = w->m;
    const double bound = mjMAXVAL;
    ws->substep = (int)get_u32(b);
    ws->fell = (int)get_u32(b);
    get(b, ws->fall_reason, sizeof ws->fall_reason);
    ws->vx_des_mps = get_f64(b);
    ws->vy_des_mps = get_f64(b);
    ws->yaw_rate_des_radps = get_f64(b);
    CcMemory *mm = &ws->mem;
    for (int k = 0; k < CC_NOFFSETS; k++) mm->offsets[k] = get_f64(b);
    mm->vx_ref = get_f64(b);
    mm->vy_ref = get_f64(b);
    mm->vx_des = get_f64(b);
    mm->vy_des = get_f64(b);
    mm->yaw_rate_ref = get_f64(b);
    mm->yaw_rate_des = get_f64(b);
    mm->mode = (int)get_u32(b);
    mm->stance = (int)get_u32(b);
    mm->step_index = (long long)get_u64(b);
    double *tail[] = {&mm->t_step_start, &mm->tau, &mm->vx_step_avg, &mm->vy_filt, &mm->vx_filt, &mm->step_start_xy[0],
                      &mm->step_start_xy[1], &mm->swing_start[0], &mm->swing_start[1], &mm->last_t, &mm->yaw_ref};
    for (size_t k = 0; k < sizeof tail / sizeof *tail; k++) *tail[k] = get_f64(b);
    ws->nstate = (int)get_u32(b);
    int expected = mj_stateSize(m, mjSTATE_INTEGRATION);
    if (b->bad) return problem(p, "the walker state is truncated"), -1;
    if (ws->nstate != expected)
        return problem(p, "physics state has %d values, this model needs %d", ws->nstate, expected), -1;
    ws->state = malloc(sizeof(double) * (size_t)(expected ? expected : 1));
    if (ws->state == NULL) return problem(p, "out of memory"), -1;
    for (int i = 0; i < expected; i++) ws->state[i] = get_f64(b);
    for (int i = 0; i < N_GAINS; i++) ws->gains[i] = get_f64(b);
    if (b->bad) return problem(p, "the walker state is truncated"), -1;
    /* physics (CassiePhysics.physics_state_problems) */
    for (int i = 0; i < expected; i++)
        if (!(fabs(ws->state[i]) <= bound)) {
            problem(p, "physics state[%d] = %.17g: must be finite, in [%g, %g]", i, ws->state[i], -bound, bound);
            break;
        }
    double time_s = ws->state[0]; /* mjSTATE_TIME comes first */
    if (!(time_s >= 0.0)) problem(p, "physics time = %.17g: must be >= 0", time_s);
    int at_qpos = 1; /* then qpos */
    for (int j = 0; j < m->njnt; j++) {
        int kind = m->jnt_type[j];
        if (kind != mjJNT_FREE && kind != mjJNT_BALL) continue;
        int at = at_qpos + m->jnt_qposadr[j] + (kind == mjJNT_FREE ? 3 : 0);
        const double *q = ws->state + at;
        double norm = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        if (!(fabs(norm - 1.0) <= 1e-6))
            problem(p, "physics qpos[%d:%d] (a quaternion) has norm %.17g: must be 1 (within 1e-06)", at - 1, at + 3, norm);
    }
    for (int i = 0; i < N_GAINS; i++)
        if (!(ws->gains[i] <= 0.0)) {
            problem(p, "servo gains (-kp, -kd)[%d] = %.17g: each must be <= 0", i, ws->gains[i]);
            break;
        }
    /* walker fields */
    int sub = w->ctrl.p.control_substeps;
    if (ws->substep < 0 || ws->substep >= sub) problem(p, "walker substep = %d: must be an int in [0, %d)", ws->substep, sub);
    if (ws->fell != 0 && ws->fell != 1) problem(p, "walker fell = %d: must be 0 or 1", ws->fell);
    if (!memchr(ws->fall_reason, 0, sizeof ws->fall_reason)) problem(p, "walker fall_reason is not a text");
    input_range(p, "walker vx_des_mps", ws->vx_des_mps, CP_VR_vx_des);
    input_range(p, "walker vy_des_mps", ws->vy_des_mps, CP_VR_vy_des);
    input_range(p, "walker yaw_rate_des_radps", ws->yaw_rate_des_radps, CP_VR_yaw_rate_des);
    /* controller memory (NominalController.memory_problems) */
    static const char *const offset_names[CC_NOFFSETS] = {"delta_swing_hip_pitch", "delta_swing_knee",
                                                          "delta_swing_hip_roll", "delta_stance_hip_roll",
                                                          "delta_stance_hip_pitch", "delta_stance_knee"};
    for (int k = 0; k < CC_NOFFSETS; k++) {
        char label[80];
        snprintf(label, sizeof label, "controller offsets['%s']", offset_names[k]);
        input_range(p, label, mm->offsets[k], CP_VR_FIRST_OFFSET + k);
    }
    input_range(p, "controller vx_des", mm->vx_des, CP_VR_vx_des);
    input_range(p, "controller vx_ref", mm->vx_ref, CP_VR_vx_des);
    input_range(p, "controller vy_des", mm->vy_des, CP_VR_vy_des);
    input_range(p, "controller vy_ref", mm->vy_ref, CP_VR_vy_des);
    input_range(p, "controller yaw_rate_des", mm->yaw_rate_des, CP_VR_yaw_rate_des);
    input_range(p, "controller yaw_rate_ref", mm->yaw_rate_ref, CP_VR_yaw_rate_des);
    number(p, "vx_step_avg", mm->vx_step_avg, -bound, bound);
    number(p, "vy_filt", mm->vy_filt, -bound, bound);
    number(p, "vx_filt", mm->vx_filt, -bound, bound);
    number(p, "yaw_ref", mm->yaw_ref, -bound, bound);
    if (mm->mode < CC_STAND || mm->mode > CC_WALK) problem(p, "controller mode = %d: must be 0 (stand), 1 (shift) or 2 (walk)", mm->mode);
    if (mm->stance != CC_LEFT && mm->stance != CC_RIGHT) problem(p, "controller stance = %d: must be 0 (left) or 1 (right)", mm->stance);
    if (mm->step_index < 0 || mm->step_index > 2147483647LL)
        problem(p, "controller step_index = %lld: must be an int in [0, 2147483647]", mm->step_index);
    number(p, "tau", mm->tau, 0.0, w->ctrl.p.switch_max_tau);
    number(p, "_step_start_xy[0]", mm->step_start_xy[0], -bound, bound);
    number(p, "_step_start_xy[1]", mm->step_start_xy[1], -bound, bound);
    number(p, "_swing_start[0]", mm->swing_start[0], -CP_PI, CP_PI);
    number(p, "_swing_start[1]", mm->swing_start[1], -CP_PI, CP_PI);
    if (number(p, "t_step_start", mm->t_step_start, 0.0, bound) && number(p, "_last_t", mm->last_t, 0.0, bound)
        && !(mm->t_step_start <= mm->last_t && mm->last_t <= time_s))
        problem(p, "controller t_step_start = %.17g, _last_t = %.17g: must satisfy 0 <= t_step_start <= _last_t <= the "
                "simulated time %.17g", mm->t_step_start, mm->last_t, time_s);
    return p->count ? -1 : 0;
}

static void apply_walker(CpWalker *w, const WalkerState *ws) {
    mj_setState(w->m, w->d, ws->state, mjSTATE_INTEGRATION);
    int i = 0;
    for (int s = 0; s < CC_NSIDES; s++)
        for (int j = 0; j < CC_NMOTOR; j++) {
            int a = w->ctrl.fx.act[s][j];
            w->m->actuator_biasprm[mjNBIAS * a + 1] = ws->gains[i++];
            w->m->actuator_biasprm[mjNBIAS * a + 2] = ws->gains[i++];
        }
    w->ctrl.mem = ws->mem;
    cc_memory_restored(&w->ctrl);
    w->substep = ws->substep;
    w->fell = ws->fell;
    memcpy(w->fall_reason, ws->fall_reason, sizeof w->fall_reason);
    w->vx_des_mps = ws->vx_des_mps;
    w->vy_des_mps = ws->vy_des_mps;
    w->yaw_rate_des_radps = ws->yaw_rate_des_radps;
}

static CpStatus check_and_set(CpInstance *inst, const char *call, const unsigned char *bytes, size_t size) {
    if (check_frame(inst, call, bytes, size) != CP_OK) return CP_ERROR;
    Buf b = {(unsigned char *)bytes, HEADER_BYTES, size - 4, 0}; /* the body: after the header, before the CRC */
    uint32_t phase = get_u32(&b), has_walker = get_u32(&b);
    double time = get_f64(&b), values[CP_N_VARS];
    for (int i = 0; i < CP_N_VARS; i++) values[i] = get_f64(&b);
    if (b.bad) return cp_refuse(inst, call, "the state is truncated");
    if (phase != CP_INSTANTIATED && phase != CP_INIT_MODE && phase != CP_STEP_MODE && phase != CP_TERMINATED)
        return cp_refuse(inst, call, "state phase %u is not an FMI phase", phase);
    if (has_walker != (phase == CP_STEP_MODE || phase == CP_TERMINATED))
        return cp_refuse(inst, call, "a state in phase %s %s a walker", phase_name(inst, (CpPhase)phase),
                         has_walker ? "cannot carry" : "must carry");
    if (!isfinite(time)) return cp_refuse(inst, call, "state time = %.17g: must be finite", time);
    char why[300];
    for (int i = 0; i < CP_N_VARS; i++) {
        const CpVar *v = &CP_VARS[i];
        if (v->causality == CP_OUTPUT ? (v->type == CP_REAL ? !isfinite(values[i]) : value_problem(v, values[i], why, sizeof why))
                                      : value_problem(v, values[i], why, sizeof why)) {
            if (v->causality == CP_OUTPUT && v->type == CP_REAL) snprintf(why, sizeof why, "%s = %.17g: must be finite", v->name, values[i]);
            return cp_refuse(inst, call, "state value %s", why);
        }
        if (v->causality == CP_PARAMETER && values[i] != inst->values[i])
            return cp_refuse(inst, call, "the state's fixed parameter %s = %.17g differs from this instance's %.17g", v->name,
                             values[i], inst->values[i]);
    }
    WalkerState ws = {0};
    CpWalker fresh;
    int started = 0;
    if (has_walker) {
        if (!inst->has_walker) {
            char err[1200];
            if (start_walker(inst, values, &fresh, err, sizeof err))
                return cp_refuse(inst, call, "cannot build the walker the state needs: %s", err);
            started = 1;
        }
        char text[600];
        Problems p = {text, sizeof text, 0};
        if (read_walker(&b, started ? &fresh : &inst->walker, &ws, &p) || b.at != b.size) {
            if (!p.count) snprintf(text, sizeof text, "%zu bytes too many", b.size - b.at);
            free(ws.state);
            if (started) cp_free(&fresh);
            return cp_refuse(inst, call, "invalid CassiePlant walker state: %s", text);
        }
    } else if (b.at != b.size) {
        return cp_refuse(inst, call, "the state has %zu bytes too many", b.size - b.at);
    }
    {
        if (started) {
            inst->walker = fresh;
            inst->has_walker = 1;
        }
        if (has_walker) {
            apply_walker(&inst->walker, &ws);
        } else if (inst->has_walker) {
            cp_free(&inst->walker);
            inst->has_walker = 0;
        }
        memcpy(inst->values, values, sizeof values);
        inst->phase = (CpPhase)phase;
        inst->time = time;
    }
    free(ws.state);
    return CP_OK;
}

CpStatus cp_fmustate_set(CpInstance *inst, const char *call, const void *state) {
    const CpBlob *blob = state;
    if (blob == NULL) return cp_refuse(inst, call, "FMUstate is NULL");
    return check_and_set(inst, call, blob->bytes, blob->size);
}

CpStatus cp_fmustate_deserialize(const CpInstance *inst, const char *call, const unsigned char *bytes, size_t size,
                                 void **state) {
    if (bytes == NULL || state == NULL) return cp_refuse(inst, call, "the byte array or FMUstate pointer is NULL");
    if (size > ((size_t)1 << 30)) return cp_refuse(inst, call, "size = %zu: not a CassiePlantNative state", size);
    /* the framing now; the contents (variables, walker) when the state is set */
    if (check_frame(inst, call, bytes, size) != CP_OK) return CP_ERROR;
    CpBlob *blob = malloc(sizeof(CpBlob) + size);
    if (blob == NULL) return cp_refuse(inst, call, "out of memory for a state of %zu bytes", size);
    blob->size = size;
    memcpy(blob->bytes, bytes, size);
    *state = blob;
    return CP_OK;
}
