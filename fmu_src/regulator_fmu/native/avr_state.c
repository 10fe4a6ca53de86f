/*
 * The FMU state of an instance as one self-checking blob (see avr_instance.h).
 *
 * FMU state blob, little-endian, format version 5 (offsets in bytes; versions 1, without
 * the stride accumulators, 2, without the command reference, 3, without settled_steps, and 4,
 * with the retired error_deadzone_mps, weight_norm_max and overspeed_unlearn, are refused
 * naming them):
 *     0  "AVRNATIV"            magic
 *     8  u32 version           12  u32 total size in bytes
 *    16  GUID, NUL-padded to 48 bytes (a state of another FMU build is refused)
 *    64  u32 number of variables   68  u32 phase bit   72  f64 time
 *    80  u32 n_neurons of the weights (0: no networks yet)   84  u32 seed of the networks
 *    88  i64 last_step_index   96  i64 n_calls
 *   104  f64 vx_at_step, vy_at_step, pd_x, pd_y, time_s
 *   144  i64 stride_boundaries (0..4)   152  i64 stride_calls
 *   160  f64 stride_sum_vy, stride_sum_roll, vy_mean_prev, vy_mean_last, roll_mean_prev,
 *        roll_mean_last, ref_vx, ref_vy, ref_sum_vx, ref_vx_step
 *   240  i64 settled_steps (0..AVR_SETTLED_STEPS_MAX)
 *   248  f64 value of every variable, in value-reference order
 *        f64 weights (4 rows of n_neurons)
 *   end-4: u32 CRC-32 (zlib's) of every byte before it
 * A blob is refused unless its size, checksum, GUID and variable count match and every
 * value is finite, of its type and within its range, the networks it names are the
 * ones its variables define, and its counters are ones a run can reach (check_counters).  In memory an FMUstate is this same blob, so get/set and
 * serialize/deserialize round trips are bit-exact by construction.
 */
#include "avr_instance.h" /* first: see avr_types.h */

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "avr_guid.h"
#include "fmi_blob.h"

#define BLOB_MAGIC "AVRNATIV"
#define BLOB_VERSION 5u
#define BLOB_GUID_BYTES 48
#define BLOB_HEADER 248
#define SETTLED_OFFSET 240
#define N_CORE_DOUBLES 5
#define STRIDE_OFFSET 144
#define N_TAIL_DOUBLES 10 /* after stride_calls: the stride sums and means, then the command reference */

/* zlib's CRC-32 (reflected polynomial 0xEDB88320), table built on the stack per call. */
static void put_u32(unsigned char *p, uint32_t x) {
    for (int i = 0; i < 4; ++i) p[i] = (unsigned char)(x >> (8 * i));
}
static void put_u64(unsigned char *p, uint64_t x) {
    for (int i = 0; i < 8; ++i) p[i] = (unsigned char)(x >> (8 * i));
}
static void put_f64(unsigned char *p, double x) {
    uint64_t bits;
    memcpy(&bits, &x, sizeof bits);
    put_u64(p, bits);
}
static uint32_t get_u32(const unsigned char *p) {
    uint32_t x = 0;
    for (int i = 3; i >= 0; --i) x = (x << 8) | p[i];
    return x;
}
static uint64_t get_u64(const unsigned char *p) {
    uint64_t x = 0;
    for (int i = 7; i >= 0; --i) x = (x << 8) | p[i];
    return x;
}
static double get_f64(const unsigned char *p) {
    uint64_t bits = get_u64(p);
    double x;
    memcpy(&x, &bits, sizeof x);
    return x;
}

static size_t blob_size(int n) {
    return BLOB_HEADER + 8u * AVR_N_VARS + 8u * AVR_N_ROWS * (size_t)n + 4u;
}

static int has_networks(AvrPhase phase) {
    return phase == AVR_STEP_MODE || phase == AVR_TERMINATED;
}

static AvrBlob *state_get(const AvrInstance *inst, AvrBlob *reuse) {
    int n = has_networks(inst->phase) ? inst->core.n : 0;
    size_t size = blob_size(n);
    AvrBlob *blob = reuse;
    if (blob == NULL || blob->size != size) {
        blob = malloc(sizeof *blob + size);
        if (blob == NULL) return NULL;
        free(reuse);
    }
    unsigned char *p = blob->bytes;
    memset(p, 0, size);
    blob->size = size;
    memcpy(p, BLOB_MAGIC, 8);
    put_u32(p + 8, BLOB_VERSION);
    put_u32(p + 12, (uint32_t)size);
    memcpy(p + 16, AVR_GUID, strlen(AVR_GUID) < BLOB_GUID_BYTES ? strlen(AVR_GUID) : BLOB_GUID_BYTES - 1);
    put_u32(p + 64, AVR_N_VARS);
    put_u32(p + 68, (uint32_t)inst->phase);
    put_f64(p + 72, inst->time);
    if (n > 0) {
        const AvrCore *c = &inst->core;
        put_u32(p + 80, (uint32_t)n);
        put_u32(p + 84, inst->net->seed);
        put_u64(p + 88, (uint64_t)c->last_step_index);
        put_u64(p + 96, (uint64_t)c->n_calls);
        const double core[N_CORE_DOUBLES] = {c->vx_at_step, c->vy_at_step, c->pd_x, c->pd_y, c->time_s};
        for (int i = 0; i < N_CORE_DOUBLES; ++i) put_f64(p + 104 + 8 * i, core[i]);
        put_u64(p + STRIDE_OFFSET, (uint64_t)c->stride_boundaries);
        put_u64(p + STRIDE_OFFSET + 8, (uint64_t)c->stride_calls);
        const double tail[N_TAIL_DOUBLES] = {c->stride_sum_vy, c->stride_sum_roll, c->vy_mean_prev,
                                             c->vy_mean_last, c->roll_mean_prev, c->roll_mean_last,
                                             c->ref_vx, c->ref_vy, c->ref_sum_vx, c->ref_vx_step};
        for (int i = 0; i < N_TAIL_DOUBLES; ++i) put_f64(p + STRIDE_OFFSET + 16 + 8 * i, tail[i]);
        put_u64(p + SETTLED_OFFSET, (uint64_t)c->settled_steps);
    }
    for (int vr = 0; vr < AVR_N_VARS; ++vr) put_f64(p + BLOB_HEADER + 8 * vr, inst->values[vr]);
    unsigned char *w = p + BLOB_HEADER + 8 * AVR_N_VARS;
    for (size_t i = 0; i < (size_t)AVR_N_ROWS * n; ++i) put_f64(w + 8 * i, inst->core.weights[i]);
    put_u32(p + size - 4, fmi_crc32(p, size - 4));
    return blob;
}


static int finite_doubles(const unsigned char *p, size_t count) {
    for (size_t i = 0; i < count; ++i)
        if (!isfinite(get_f64(p + 8 * i))) return 0;
    return 1;
}

/* The header's framing (fmi_blob.c: magic, version, size, checksum, GUID), then the variable count. */
static AvrStatus check_frame(const AvrInstance *inst, const char *call, const unsigned char *p, size_t size) {
    static const FmiBlobFormat format = {
        .magic = BLOB_MAGIC, .magic_bytes = 8, .version_at = 8, .version = BLOB_VERSION,
        .version_note = "(older states predate the stride-averaged lateral/roll learning (version 1), the command reference (version 2), the settled-step count (version 3) or the retirement of error_deadzone_mps, weight_norm_max and overspeed_unlearn (version 4) and cannot be continued)",
        .size_at = 12, .size_field_bytes = 4, .size_add = 0, .crc_bytes = 4,
        .guid_at = 16, .guid_bytes = BLOB_GUID_BYTES, .guid = AVR_GUID,
        .min_bytes = BLOB_HEADER + 8u * AVR_N_VARS + 4u}; /* blob_size(0) */
    char why[400];
    if (fmi_blob_problem(&format, p, size, why, sizeof why) != NULL) return avr_refuse(inst, call, "%s", why);
    if (get_u32(p + 64) != AVR_N_VARS)
        return avr_refuse(inst, call, "state has %u variables, this FMU %d", (unsigned)get_u32(p + 64), AVR_N_VARS);
    return AVR_OK;
}

static AvrStatus check_counters(const AvrInstance *inst, const char *call, const unsigned char *p);

/* The contents: phase, time, every value in its range, networks consistent with the values. */
static AvrStatus check_contents(const AvrInstance *inst, const char *call, const unsigned char *p, size_t size) {
    uint32_t phase = get_u32(p + 68), n = get_u32(p + 80);
    if (phase != AVR_INSTANTIATED && phase != AVR_INIT_MODE && phase != AVR_STEP_MODE && phase != AVR_TERMINATED)
        return avr_refuse(inst, call, "state has an unknown phase %u", (unsigned)phase);
    if ((n > 0) != has_networks((AvrPhase)phase) || size != blob_size((int)n))
        return avr_refuse(inst, call, "state with %u neurons does not fit its phase or size", (unsigned)n);
    if (!isfinite(get_f64(p + 72))) return avr_refuse(inst, call, "state has a non-finite time");
    const unsigned char *values = p + BLOB_HEADER;
    double saved[AVR_N_VARS];
    char problem[400];
    for (int vr = 0; vr < AVR_N_VARS; ++vr) {
        double x = saved[vr] = get_f64(values + 8 * vr);
        if (AVR_VARS[vr].causality == AVR_OUTPUT ? !isfinite(x)
                                                 : avr_value_problem(&AVR_VARS[vr], x, problem, sizeof problem))
            return avr_refuse(inst, call, "state has an invalid value of %s", AVR_VARS[vr].name);
    }
    if (avr_requires_problem(saved, AVR_N_VARS, 0.0, problem, sizeof problem))
        return avr_refuse(inst, call, "state has parameters no instance can have: %s", problem);
    if (n == 0) return AVR_OK;
    if (n != (uint32_t)get_f64(values + 8 * AVR_VR_n_neurons) || get_u32(p + 84) != (uint32_t)get_f64(values + 8 * AVR_VR_seed))
        return avr_refuse(inst, call, "state's networks do not match its n_neurons and seed");
    if (!finite_doubles(p + 104, N_CORE_DOUBLES) || !finite_doubles(p + STRIDE_OFFSET + 16, N_TAIL_DOUBLES) || !finite_doubles(values + 8 * AVR_N_VARS, (size_t)AVR_N_ROWS * n))
        return avr_refuse(inst, call, "state contains non-finite values");
    return check_counters(inst, call, p);
}

/* The counters a run can reach (as avr_statebytes.counter_problems): it starts with
 * last_step_index -1, n_calls 0, time_s 0 and no stride; each call sets last_step_index to its
 * step_index, adds one to n_calls (stopping at AVR_MAX_CALLS) and its dt > 0 to time_s;
 * stride_calls counts the calls of the current step, so at most n_calls; settled_steps counts
 * step_index changes, at most one per call, up to AVR_SETTLED_STEPS_MAX.  Beyond these the
 * next step's arithmetic would overflow (signed overflow is undefined behaviour). */
static AvrStatus check_counters(const AvrInstance *inst, const char *call, const unsigned char *p) {
    const int64_t last = (int64_t)get_u64(p + 88), n_calls = (int64_t)get_u64(p + 96);
    const int64_t boundaries = (int64_t)get_u64(p + STRIDE_OFFSET), stride_calls = (int64_t)get_u64(p + STRIDE_OFFSET + 8);
    const double time_s = get_f64(p + 104 + 8 * 4), max_step_index = AVR_VARS[AVR_VR_step_index].max;
    if (n_calls < 0 || n_calls > AVR_MAX_CALLS)
        return avr_refuse(inst, call, "state has n_calls = %lld: must be in [0, %lld]", (long long)n_calls,
                          (long long)AVR_MAX_CALLS);
    if (last < -1 || (double)last > max_step_index || (last == -1) != (n_calls == 0))
        return avr_refuse(inst, call, "state has last_step_index = %lld with n_calls = %lld: must be in [-1, %.0f], "
                          "-1 exactly before the first call", (long long)last, (long long)n_calls, max_step_index);
    if (!(time_s >= 0.0 && (n_calls > 0 || time_s == 0.0)))
        return avr_refuse(inst, call, "state has time_s = %g with n_calls = %lld: a sum of steps > 0 (0 before the "
                          "first call)", time_s, (long long)n_calls);
    if (boundaries < 0 || boundaries > AVR_STRIDE_READY || stride_calls < 0 || stride_calls > n_calls ||
        (boundaries == 0) != (stride_calls == 0))
        return avr_refuse(inst, call, "state has stride_boundaries = %lld, stride_calls = %lld: must be in [0, %d] "
                          "and [0, n_calls = %lld], both 0 or neither", (long long)boundaries, (long long)stride_calls,
                          AVR_STRIDE_READY, (long long)n_calls);
    const int64_t settled = (int64_t)get_u64(p + SETTLED_OFFSET);
    if (settled < 0 || settled > n_calls || settled > AVR_SETTLED_STEPS_MAX)
        return avr_refuse(inst, call, "state has settled_steps = %lld: must be in [0, min(n_calls = %lld, %lld)]",
                          (long long)settled, (long long)n_calls, (long long)AVR_SETTLED_STEPS_MAX);
    return AVR_OK;
}

/* A state restores only into an instance whose fixed parameters have the state's values
 * (as the pythonfmu FMU's guard rules): every differing one is named. */
static AvrStatus check_fixed(const AvrInstance *inst, const char *call, const unsigned char *p) {
    char differ[600] = "";
    size_t used = 0;
    for (int vr = 0; vr < AVR_N_VARS; ++vr) {
        const AvrVar *v = &AVR_VARS[vr];
        double saved = get_f64(p + BLOB_HEADER + 8 * vr);
        if (v->causality != AVR_PARAMETER || v->variability != AVR_FIXED || saved == inst->values[vr]) continue;
        int k = snprintf(differ + used, sizeof differ - used, "%s%s = %.17g (this instance: %.17g)",
                         used ? ", " : "", v->name, saved, inst->values[vr]);
        if (k > 0) used = used + (size_t)k < sizeof differ ? used + (size_t)k : sizeof differ - 1;
    }
    if (used == 0) return AVR_OK;
    return avr_refuse(inst, call, "the state was saved with other fixed parameters: %s. Set them to the state's "
                      "values before restoring it (fixed parameters can be set only before initialization ends)",
                      differ);
}

AvrStatus avr_state_check(const AvrInstance *inst, const char *call, const unsigned char *bytes, size_t size) {
    AvrStatus s = check_frame(inst, call, bytes, size);
    if (s == AVR_OK) s = check_contents(inst, call, bytes, size);
    return s == AVR_OK ? check_fixed(inst, call, bytes) : s;
}

static AvrStatus state_set(AvrInstance *inst, const char *call, const AvrBlob *blob) {
    if (blob == NULL) return avr_refuse(inst, call, "FMUstate is NULL");
    const unsigned char *p = blob->bytes;
    if (avr_state_check(inst, call, p, blob->size) != AVR_OK) return AVR_ERROR;
    int n = (int)get_u32(p + 80);
    if (n > 0) {
        AvrNetworks *net;
        AvrCore core;
        if (avr_prepare_networks(inst, call, n, get_u32(p + 84), &net, &core) != AVR_OK) return AVR_ERROR;
        core.last_step_index = (int64_t)get_u64(p + 88);
        core.n_calls = (int64_t)get_u64(p + 96);
        double *scalars[N_CORE_DOUBLES] = {&core.vx_at_step, &core.vy_at_step, &core.pd_x, &core.pd_y, &core.time_s};
        for (int i = 0; i < N_CORE_DOUBLES; ++i) *scalars[i] = get_f64(p + 104 + 8 * i);
        core.stride_boundaries = (int64_t)get_u64(p + STRIDE_OFFSET);
        core.stride_calls = (int64_t)get_u64(p + STRIDE_OFFSET + 8);
        double *tail[N_TAIL_DOUBLES] = {&core.stride_sum_vy, &core.stride_sum_roll, &core.vy_mean_prev,
                                        &core.vy_mean_last, &core.roll_mean_prev, &core.roll_mean_last,
                                        &core.ref_vx, &core.ref_vy, &core.ref_sum_vx, &core.ref_vx_step};
        for (int i = 0; i < N_TAIL_DOUBLES; ++i) *tail[i] = get_f64(p + STRIDE_OFFSET + 16 + 8 * i);
        core.settled_steps = (int64_t)get_u64(p + SETTLED_OFFSET);
        const unsigned char *w = p + BLOB_HEADER + 8 * AVR_N_VARS;
        for (size_t i = 0; i < (size_t)AVR_N_ROWS * n; ++i) core.weights[i] = get_f64(w + 8 * i);
        avr_adopt(inst, net, &core);
    } else {
        avr_core_free(&inst->core);
    }
    inst->phase = (AvrPhase)get_u32(p + 68);
    inst->time = get_f64(p + 72);
    for (int vr = 0; vr < AVR_N_VARS; ++vr) inst->values[vr] = get_f64(p + BLOB_HEADER + 8 * vr);
    return AVR_OK;
}

/* ---- the FMI FMUstate functions ------------------------------------------------------- */
AvrStatus avr_fmustate_get(AvrInstance *inst, const char *call, void **state) {
    if (state == NULL) return avr_refuse(inst, call, "FMUstate pointer is NULL");
    AvrBlob *blob = state_get(inst, (AvrBlob *)*state);
    if (blob == NULL) return avr_refuse(inst, call, "out of memory");
    *state = blob;
    return AVR_OK;
}

AvrStatus avr_fmustate_set(AvrInstance *inst, const char *call, const void *state) {
    return state_set(inst, call, (const AvrBlob *)state);
}

void avr_fmustate_free(void **state) {
    if (state == NULL) return;
    free(*state);
    *state = NULL;
}

AvrStatus avr_fmustate_size(const AvrInstance *inst, const char *call, const void *state, size_t *size) {
    if (state == NULL || size == NULL) return avr_refuse(inst, call, "NULL FMUstate or size pointer");
    *size = ((const AvrBlob *)state)->size;
    return AVR_OK;
}

AvrStatus avr_fmustate_serialize(const AvrInstance *inst, const char *call, const void *state, unsigned char *bytes,
                                 size_t size) {
    const AvrBlob *blob = (const AvrBlob *)state;
    if (blob == NULL || bytes == NULL) return avr_refuse(inst, call, "NULL FMUstate or byte buffer");
    if (size != blob->size) return avr_refuse(inst, call, "size = %zu, but this state needs %zu bytes", size, blob->size);
    memcpy(bytes, blob->bytes, size);
    return AVR_OK;
}

AvrStatus avr_fmustate_deserialize(const AvrInstance *inst, const char *call, const unsigned char *bytes, size_t size,
                                   void **state) {
    if (bytes == NULL || state == NULL) return avr_refuse(inst, call, "NULL byte buffer or FMUstate pointer");
    if (avr_state_check(inst, call, bytes, size) != AVR_OK) return AVR_ERROR;
    AvrBlob *blob = malloc(sizeof *blob + size);
    if (blob == NULL) return avr_refuse(inst, call, "out of memory");
    blob->size = size;
    memcpy(blob->bytes, bytes, size);
    free(*state); /* a state the host passes back to be replaced */
    *state = blob;
    return AVR_OK;
}
