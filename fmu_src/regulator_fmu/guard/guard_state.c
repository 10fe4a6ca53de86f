/*
 * FMU states: get, set, free, and the serialized form, checked completely here before
 * any byte reaches Python.
 *
 * Serialized form (format version 2, little endian):
 *
 *   offset  bytes  field
 *        0      4  magic "AVRG"
 *        4      4  u32 format version (2)
 *        8      8  f64 time of the state, s (finite)
 *       16      4  u32 FMI phase (0 instantiated .. 4 terminated)
 *       20     40  GUID of the FMU that saved it, NUL-padded
 *       60      4  u32 n_fixed, the number of fixed parameters (AVR_N_FIXED)
 *       64  12 n_fixed  per fixed parameter: u32 valueReference, f64 value
 *        h      8  u64 n, length of the slave's blob
 *      h+8      n  the slave's blob (fmu_src/fmi/avr_fmustate.py)
 *    h+8+n      8  u64 CRC-64/XZ of every byte before it
 *
 * A state is accepted only if the size, magic, version, lengths and checksum are right,
 * the GUID is this FMU's, the time is finite, the phase is known, the slave's blob says
 * the same phase and time as this header (its JSON begins with them, see agreement()), and its fixed
 * parameters (n_neurons, seed, the input scales) equal the instance's current values:
 * otherwise fmi2Error names the reason and nothing changes.  The CRC detects every
 * error of up to 64 consecutive bits (so every single-bit flip) and any other random
 * corruption with probability 1 - 2^-64.
 */
#define _GNU_SOURCE /* strtod_l */
#include <locale.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi_blob.h"
#include "guard.h"

#define STATE_MAGIC "AVRG"
#define STATE_VERSION 2u
#define GUID_FIELD 40u
#define FIXED_ENTRY 12u
#define HEAD_FIXED_OFFSET 64u
#define HEAD_BYTES (HEAD_FIXED_OFFSET + FIXED_ENTRY * AVR_N_FIXED + 8u)
#define CRC_BYTES 8u
/* The slave's blob: AVR_SLAVE_* generated from fmu_src/fmi/avr_fmustate.py (build_guard.py), and
 * AVR_SLAVE_REFUSED, what the slave's deserializer yields for a blob it refuses, then the reason. */
#include "avr_slave_blob.h"
#define SLAVE_VERSION_AT AVR_SLAVE_MAGIC_BYTES
#define SLAVE_JSON_BYTES_AT (SLAVE_VERSION_AT + sizeof(uint32_t))
#define SLAVE_CORE_BYTES_AT (SLAVE_JSON_BYTES_AT + sizeof(uint32_t))
#define SLAVE_REFUSED_BYTES (sizeof(AVR_SLAVE_REFUSED) - 1)

_Static_assert(sizeof(AVR_GUID) - 1 < GUID_FIELD, "the GUID must fit its field");

/* fmi2Error naming every fixed parameter whose saved value differs from the instance's. */
static fmi2Status check_fixed(Guard *g, const char *call, const double saved[AVR_N_FIXED]) {
    char list[700] = "";
    for (unsigned i = 0; i < AVR_N_FIXED; ++i) {
        if (memcmp(&saved[i], &g->fixed[i], sizeof(double)) == 0) continue;
        char was[32], now[32];
        format_double(saved[i], was, sizeof was);
        format_double(g->fixed[i], now, sizeof now);
        size_t used = strlen(list);
        snprintf(list + used, sizeof list - used, "%s%s = %s (this instance: %s)", used ? ", " : "",
                 AVR_VARS[AVR_FIXED_VRS[i]].name, was, now);
    }
    if (list[0] == '\0') return fmi2OK;
    return refuse(g, call, "the state was saved with other fixed parameters: %s. Set them to the state's values "
                  "before restoring it (fixed parameters can be set only before fmi2ExitInitializationMode; "
                  "call fmi2Reset first if needed)", list);
}

/* ---- CRC-64/XZ (ECMA-182 polynomial, reflected; check value of "123456789": 0x995DC9BBDF1939FA) -- */
/* ---- little-endian fields ------------------------------------------------------------- */
static void put_u32(fmi2Byte *p, uint32_t x) { for (int i = 0; i < 4; ++i) p[i] = (fmi2Byte)((x >> (8 * i)) & 0xFFu); }
static void put_u64(fmi2Byte *p, uint64_t x) { for (int i = 0; i < 8; ++i) p[i] = (fmi2Byte)((x >> (8 * i)) & 0xFFu); }
static uint32_t get_u32(const fmi2Byte *p) { uint32_t x = 0; for (int i = 3; i >= 0; --i) x = (x << 8) | (uint8_t)p[i]; return x; }
static uint64_t get_u64(const fmi2Byte *p) { uint64_t x = 0; for (int i = 7; i >= 0; --i) x = (x << 8) | (uint8_t)p[i]; return x; }
static void put_f64(fmi2Byte *p, double x) { uint64_t b; memcpy(&b, &x, 8); put_u64(p, b); }
static double get_f64(const fmi2Byte *p) { uint64_t b = get_u64(p); double x; memcpy(&x, &b, 8); return x; }

/* ---- checks ---------------------------------------------------------------------------- */
static GuardState *live_state(Guard *g, const char *call, fmi2FMUstate state) {
    GuardState *gs = (GuardState *)state;
    if (gs == NULL || gs->tag != STATE_TAG || gs->inner == NULL) {
        refuse(g, call, "the FMUstate is NULL, already freed, or not one of this FMU's states");
        return NULL;
    }
    return gs;
}

/* fmi2OK if the n bytes are a slave blob the slave will parse (header and lengths). */
static fmi2Status check_slave_blob(Guard *g, const char *call, const fmi2Byte *blob, uint64_t n) {
    if (n >= AVR_SLAVE_HEAD_BYTES && memcmp(blob, AVR_SLAVE_MAGIC, AVR_SLAVE_MAGIC_BYTES) == 0 &&
        get_u32(blob + SLAVE_VERSION_AT) != AVR_SLAVE_VERSION)
        return refuse(g, call, "the state's inner blob is of format version %u; this FMU reads version %u (older "
                      "states hold parameters this FMU no longer has)", (unsigned)get_u32(blob + SLAVE_VERSION_AT),
                      (unsigned)AVR_SLAVE_VERSION);
    if (n < AVR_SLAVE_HEAD_BYTES + AVR_SLAVE_CRC_BYTES || memcmp(blob, AVR_SLAVE_MAGIC, AVR_SLAVE_MAGIC_BYTES) != 0 ||
        (uint64_t)AVR_SLAVE_HEAD_BYTES + get_u32(blob + SLAVE_JSON_BYTES_AT) + get_u32(blob + SLAVE_CORE_BYTES_AT) +
                AVR_SLAVE_CRC_BYTES != n)
        return refuse(g, call, "the state's inner blob has a bad header (this FMU's serializer never writes that)");
    return fmi2OK;
}

/* strtod in the "C" locale: the slave writes '.' whatever locale the host has set. */
static locale_t c_locale;
static pthread_once_t c_locale_once = PTHREAD_ONCE_INIT;
static void c_locale_init(void) { c_locale = newlocale(LC_NUMERIC_MASK, "C", (locale_t)0); }

/* The slave's phase name for a guard phase: the slave has no stepFailed (a failed step leaves
 * it in stepComplete, as the guard's last successful time). */
static const char *slave_phase(enum Phase phase) {
    static const unsigned index[] = {[INSTANTIATED] = 0, [INIT_MODE] = 1, [STEP_COMPLETE] = 2, [STEP_FAILED] = 2,
                                     [TERMINATED] = 3};
    _Static_assert(AVR_SLAVE_N_PHASES == 4, "the slave's phases are instantiated .. terminated");
    return AVR_SLAVE_PHASES[index[phase]];
}

/* fmi2OK if the slave's blob (its header checked) says the phase and the time of the guard's
 * header `meta`: its JSON begins AVR_SLAVE_JSON_PREFIX phase AVR_SLAVE_JSON_TIME time
 * AVR_SLAVE_JSON_VALUES (json.dumps with sorted keys; the slave refuses any other form).  The
 * guard restores its phase and time from the header and the slave from its blob: a state in
 * which they differ would leave the two disagreeing (an exit from initialization mode that the
 * slave answers with fmi2Fatal, every doStep refused for its time). */
static fmi2Status agreement(Guard *g, const char *call, const fmi2Byte *blob, const GuardState *meta) {
    const size_t n_json = get_u32(blob + SLAVE_JSON_BYTES_AT);
    char head[160]; /* prefix, the longest phase name, a number of at most 32 characters, the next key */
    const size_t k = n_json < sizeof head - 1 ? n_json : sizeof head - 1;
    memcpy(head, blob + AVR_SLAVE_HEAD_BYTES, k);
    head[k] = '\0';
    const char *phase = slave_phase(meta->phase);
    char want[64];
    snprintf(want, sizeof want, "%s%s%s", AVR_SLAVE_JSON_PREFIX, phase, AVR_SLAVE_JSON_TIME);
    if (strncmp(head, want, strlen(want)) != 0)
        return refuse(g, call, "the state's header says phase %s, its slave part does not (header and contents "
                      "must agree)", PHASE_NAMES[meta->phase]);
    pthread_once(&c_locale_once, c_locale_init);
    if (c_locale == (locale_t)0) return refuse(g, call, "cannot read the state's time: no C locale");
    const char *number = head + strlen(want);
    char *end = NULL;
    const double time = strtod_l(number, &end, c_locale);
    if (end == number || end - number > 32 || strncmp(end, AVR_SLAVE_JSON_VALUES, strlen(AVR_SLAVE_JSON_VALUES)) != 0)
        return refuse(g, call, "the state's slave part has no readable time");
    if (!(time == meta->time)) {
        char a[32], b[32];
        format_double(meta->time, a, sizeof a);
        format_double(time, b, sizeof b);
        return refuse(g, call, "the state's header says time %s s, its slave part %s s (header and contents must "
                      "agree)", a, b);
    }
    return fmi2OK;
}

/* The slave checks a blob's contents (every value, the core's weights) when it deserializes
 * it, and yields AVR_SLAVE_REFUSED + the reason instead of raising (which pythonfmu would turn
 * into fmi2Fatal): read its verdict back; fmi2Error with the reason if it refused. */
static fmi2Status slave_verdict(Guard *g, const char *call, fmi2FMUstate inner_state) {
    size_t n = 0;
    fmi2Status s = track(g, inner.fmi2SerializedFMUstateSize(g->inner, inner_state, &n));
    if (s != fmi2OK || n < SLAVE_REFUSED_BYTES) return s;
    fmi2Byte *copy = malloc(n + 1);
    if (copy == NULL) return refuse(g, call, "out of memory");
    s = track(g, inner.fmi2SerializeFMUstate(g->inner, inner_state, copy, n));
    if (s == fmi2OK && memcmp(copy, AVR_SLAVE_REFUSED, SLAVE_REFUSED_BYTES) == 0) {
        copy[n] = '\0';
        const char *reason = copy + SLAVE_REFUSED_BYTES;
        s = refuse(g, call, "the state's contents are invalid: %.600s",
                   string_problem(reason, n) == NULL ? reason : "(no readable reason)");
    }
    free(copy);
    return s;
}

/* Checks a serialized state completely; fills meta (phase, time, fixed) and the inner blob. */
static fmi2Status check_serialized(Guard *g, const char *call, const fmi2Byte *s, size_t size, GuardState *meta,
                                   const fmi2Byte **blob, uint64_t *blob_size) {
    static const FmiBlobFormat format = {
        .magic = STATE_MAGIC, .magic_bytes = 4, .version_at = 4, .version = STATE_VERSION,
        .size_at = HEAD_BYTES - 8, .size_field_bytes = 8, .size_add = HEAD_BYTES + CRC_BYTES,
        .crc_bytes = CRC_BYTES, .guid_at = 20, .guid_bytes = GUID_FIELD, .guid = AVR_GUID,
        .min_bytes = HEAD_BYTES + CRC_BYTES};
    char why[300];
    if (fmi_blob_problem(&format, (const unsigned char *)s, size, why, sizeof why) != NULL)
        return refuse(g, call, "%s", why);
    if (get_u32(s + 60) != AVR_N_FIXED)
        return refuse(g, call, "the state lists %u fixed parameters, this FMU has %u", get_u32(s + 60), AVR_N_FIXED);
    uint64_t n = get_u64(s + HEAD_BYTES - 8);
    meta->time = get_f64(s + 8);
    uint32_t phase = get_u32(s + 16);
    if (!isfinite(meta->time)) return refuse(g, call, "the state's time is %g: must be finite", meta->time);
    if (phase > TERMINATED) return refuse(g, call, "the state has an unknown FMI phase %u", phase);
    meta->phase = (enum Phase)phase;
    for (unsigned i = 0; i < AVR_N_FIXED; ++i) {
        const fmi2Byte *entry = s + HEAD_FIXED_OFFSET + FIXED_ENTRY * i;
        if (get_u32(entry) != AVR_FIXED_VRS[i])
            return refuse(g, call, "the state's fixed-parameter table is not this FMU's");
        meta->fixed[i] = get_f64(entry + 4);
    }
    fmi2Status st = check_fixed(g, call, meta->fixed);
    if (st != fmi2OK) return st;
    *blob = s + HEAD_BYTES;
    *blob_size = n;
    st = check_slave_blob(g, call, *blob, n);
    return st == fmi2OK ? agreement(g, call, *blob, meta) : st;
}

/* ---- FMI functions ---------------------------------------------------------------------- */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    PROLOGUE(fmi2GetFMUstate);
    if (state == NULL) return refuse(g, call, "the FMUstate pointer is NULL");
    GuardState *gs = (GuardState *)*state;
    if (gs != NULL && gs->tag != STATE_TAG) return refuse(g, call, "*FMUstate is not one of this FMU's states");
    fmi2FMUstate fresh = NULL;
    fmi2Status s = track(g, inner.fmi2GetFMUstate(g->inner, &fresh));
    if (s != fmi2OK) return s;
    if (gs == NULL && (gs = calloc(1, sizeof *gs)) == NULL) {
        inner.fmi2FreeFMUstate(g->inner, &fresh);
        return refuse(g, call, "out of memory");
    }
    if (gs->inner != NULL) inner.fmi2FreeFMUstate(g->inner, &gs->inner);
    gs->tag = STATE_TAG;
    gs->inner = fresh;
    gs->phase = g->phase;
    gs->time = g->time;
    memcpy(gs->fixed, g->fixed, sizeof gs->fixed);
    *state = gs;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    PROLOGUE(fmi2SetFMUstate);
    GuardState *gs = live_state(g, call, state);
    if (gs == NULL) return fmi2Error;
    fmi2Status s = check_fixed(g, call, gs->fixed);
    if (s != fmi2OK) return s;
    s = track(g, inner.fmi2SetFMUstate(g->inner, gs->inner));
    if (s == fmi2OK) {
        g->phase = gs->phase;
        g->time = gs->time;
    }
    return s;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Guard *g = (Guard *)c;  /* allowed in every phase, also after a Fatal */
    if (g == NULL || g->tag != GUARD_TAG) return fmi2Error;
    if (state == NULL || *state == NULL) return fmi2OK;  /* freeing nothing is allowed */
    GuardState *gs = (GuardState *)*state;
    if (gs->tag != STATE_TAG) return refuse(g, "fmi2FreeFMUstate", "not one of this FMU's states");
    fmi2Status s = fmi2OK;
    /* after a Fatal pythonfmu's instance is gone: the Python object is left (a small leak, not a crash) */
    if (gs->inner != NULL && g->phase != FATAL) s = track(g, inner.fmi2FreeFMUstate(g->inner, &gs->inner));
    gs->tag = 0;
    free(gs);
    *state = NULL;
    return s;
}

/* The live state `state` and the size of its serialized form (header + slave blob + CRC). */
static fmi2Status serialized_size(Guard *g, const char *call, fmi2FMUstate state, GuardState **gs, size_t *n_blob) {
    if ((*gs = live_state(g, call, state)) == NULL) return fmi2Error;
    return track(g, inner.fmi2SerializedFMUstateSize(g->inner, (*gs)->inner, n_blob));
}

static void write_header(fmi2Byte *bytes, const GuardState *gs, size_t n_blob) {
    memset(bytes, 0, HEAD_BYTES);
    memcpy(bytes, STATE_MAGIC, 4);
    put_u32(bytes + 4, STATE_VERSION);
    put_f64(bytes + 8, gs->time);
    put_u32(bytes + 16, (uint32_t)gs->phase);
    memcpy(bytes + 20, AVR_GUID, sizeof(AVR_GUID) - 1);
    put_u32(bytes + 60, AVR_N_FIXED);
    for (unsigned i = 0; i < AVR_N_FIXED; ++i) {
        put_u32(bytes + HEAD_FIXED_OFFSET + FIXED_ENTRY * i, AVR_FIXED_VRS[i]);
        put_f64(bytes + HEAD_FIXED_OFFSET + FIXED_ENTRY * i + 4, gs->fixed[i]);
    }
    put_u64(bytes + HEAD_BYTES - 8, (uint64_t)n_blob);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    PROLOGUE(fmi2SerializedFMUstateSize);
    if (size == NULL) return refuse(g, call, "the size pointer is NULL");
    GuardState *gs;
    size_t n = 0;
    fmi2Status s = serialized_size(g, call, state, &gs, &n);
    if (s == fmi2OK) *size = HEAD_BYTES + n + CRC_BYTES;
    return s;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    PROLOGUE(fmi2SerializeFMUstate);
    if (bytes == NULL) return refuse(g, call, "the byte buffer is NULL");
    GuardState *gs;
    size_t n = 0;
    fmi2Status s = serialized_size(g, call, state, &gs, &n);
    if (s != fmi2OK) return s;
    if (size != HEAD_BYTES + n + CRC_BYTES)
        return refuse(g, call, "size = %zu, but this state needs %zu bytes (fmi2SerializedFMUstateSize)", size,
                      (size_t)(HEAD_BYTES + n + CRC_BYTES));
    write_header(bytes, gs, n);
    s = track(g, inner.fmi2SerializeFMUstate(g->inner, gs->inner, bytes + HEAD_BYTES, n));
    if (s == fmi2OK) put_u64(bytes + size - CRC_BYTES, fmi_crc64((const unsigned char *)bytes, size - CRC_BYTES));
    return s;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state) {
    PROLOGUE(fmi2DeSerializeFMUstate);
    if (serializedState == NULL || state == NULL) return refuse(g, call, "NULL byte buffer or FMUstate pointer");
    if (*state != NULL && ((GuardState *)*state)->tag != STATE_TAG)
        return refuse(g, call, "*FMUstate is not one of this FMU's states");
    GuardState meta = {0};
    const fmi2Byte *blob = NULL;
    uint64_t n = 0;
    fmi2Status s = check_serialized(g, call, serializedState, size, &meta, &blob, &n);
    if (s != fmi2OK) return s;
    GuardState *gs = calloc(1, sizeof *gs);
    if (gs == NULL) return refuse(g, call, "out of memory");
    s = track(g, inner.fmi2DeSerializeFMUstate(g->inner, blob, (size_t)n, &gs->inner));
    if (s == fmi2OK) s = slave_verdict(g, call, gs->inner);
    if (s != fmi2OK) {
        if (gs->inner != NULL && g->phase != FATAL) inner.fmi2FreeFMUstate(g->inner, &gs->inner);
        free(gs);
        return s;
    }
    gs->tag = STATE_TAG;
    gs->phase = meta.phase;
    gs->time = meta.time;
    memcpy(gs->fixed, meta.fixed, sizeof gs->fixed);
    if (*state != NULL) fmi2FreeFMUstate(c, state);
    *state = gs;
    return fmi2OK;
}
