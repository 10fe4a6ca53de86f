/*
 * Uneven terrain in the native CassiePlant: the height field is generated once, in Python, and
 * handed over as data (the FMU has no FFT and no PCG64 of its own).  The host writes the file
 * with plant.terrain.write_field for the FMU's terrain_* parameters and names it in the String
 * parameter terrain_field_file; the layout is plant/terrain.py's FIELD_MAGIC.  The file is
 * checked whole before the model is touched (framing, CRC-32, the spec it was made from equal to
 * the parameters, its size, every sample in range), then built into the model as
 * plant.terrain.add_terrain builds it, so the compiled model carries the same bits.
 */
#include "cp_terrain.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi_blob.h"

#define FIELD_MAGIC "CPTF"
#define FIELD_VERSION 1u
#define FIELD_HEADER_BYTES 68 /* plant.terrain.FIELD_HEADER.size */
#define FIELD_SAMPLES_AT FIELD_HEADER_BYTES
/* The largest file: CP_TERRAIN_MAX_SAMPLES per side. */
#define FIELD_MAX_BYTES (FIELD_HEADER_BYTES + 4.0 * CP_TERRAIN_MAX_SAMPLES * CP_TERRAIN_MAX_SAMPLES + 4)

static uint32_t le32(const unsigned char *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static double le_f64(const unsigned char *p) {
    uint64_t u = (uint64_t)le32(p) | (uint64_t)le32(p + 4) << 32;
    double x;
    memcpy(&x, &u, 8);
    return x;
}
static float le_f32(const unsigned char *p) {
    uint32_t u = le32(p);
    float x;
    memcpy(&x, &u, 4);
    return x;
}

/* TerrainSpec.samples_per_side: max(3, round(2 size / resolution) + 1), rounding half to even
 * as Python's round (nearbyint in the default rounding mode). */
static long samples_per_side(double size_m) {
    long n = (long)nearbyint(2.0 * size_m / CP_TERRAIN_RESOLUTION_M) + 1;
    return n < 3 ? 3 : n;
}

/* The file's spec field at `at` against the parameter: 0 if equal, else the refusal in err. */
static int same(const unsigned char *p, size_t at, double param, const char *name, const char *path, char *err,
                int errlen) {
    double x = le_f64(p + at);
    if (x == param) return 0;
    snprintf(err, errlen, "terrain_field_file '%s' holds the field of %s = %.17g, but the parameter is %.17g: "
             "write the field of these parameters (plant.terrain.write_field)", path, name, x, param);
    return -1;
}

static int check(const unsigned char *p, size_t size, const char *path, const double *v, char *err, int errlen) {
    if (size < FIELD_HEADER_BYTES + 4 || memcmp(p, FIELD_MAGIC, 4) != 0) {
        snprintf(err, errlen, "terrain_field_file '%s' (%zu bytes) is not a height-field file: it must be one "
                 "plant.terrain.write_field writes (header 'CPTF')", path, size);
        return -1;
    }
    if (le32(p + 4) != FIELD_VERSION) {
        snprintf(err, errlen, "terrain_field_file '%s': format version %u, this FMU reads version %u", path,
                 (unsigned)le32(p + 4), FIELD_VERSION);
        return -1;
    }
    if (le32(p + 8) != size) {
        snprintf(err, errlen, "terrain_field_file '%s': %zu bytes, its header says %u (truncated or padded)", path,
                 size, (unsigned)le32(p + 8));
        return -1;
    }
    if (fmi_crc32(p, size - 4) != le32(p + size - 4)) {
        snprintf(err, errlen, "terrain_field_file '%s': checksum mismatch, the file is corrupted", path);
        return -1;
    }
    if (same(p, 12, v[CP_VR_terrain_max_height_m], "terrain_max_height_m", path, err, errlen) ||
        same(p, 20, v[CP_VR_terrain_max_slope_deg], "terrain_max_slope_deg", path, err, errlen) ||
        same(p, 28, v[CP_VR_terrain_size_m], "terrain_size_m", path, err, errlen) ||
        same(p, 36, CP_TERRAIN_FLAT_RADIUS_M, "flat_radius_m (this FMU's is fixed)", path, err, errlen) ||
        same(p, 44, CP_TERRAIN_RESOLUTION_M, "resolution_m (this FMU's is fixed)", path, err, errlen))
        return -1;
    if ((double)le32(p + 52) != v[CP_VR_terrain_seed]) {
        snprintf(err, errlen, "terrain_field_file '%s' holds the field of terrain_seed = %u, but the parameter is "
                 "%.17g: write the field of these parameters (plant.terrain.write_field)", path,
                 (unsigned)le32(p + 52), v[CP_VR_terrain_seed]);
        return -1;
    }
    long n = samples_per_side(v[CP_VR_terrain_size_m]);
    if ((long)le32(p + 56) != n || size != FIELD_HEADER_BYTES + 4 * (size_t)n * (size_t)n + 4) {
        snprintf(err, errlen, "terrain_field_file '%s': %u samples per side in %zu bytes; terrain_size_m = %.17g "
                 "needs %ld per side (%zu bytes)", path, (unsigned)le32(p + 56), size, v[CP_VR_terrain_size_m], n,
                 FIELD_HEADER_BYTES + 4 * (size_t)n * (size_t)n + 4);
        return -1;
    }
    double peak = le_f64(p + 60);
    if (!(peak >= 0.0 && peak <= v[CP_VR_terrain_max_height_m])) {
        snprintf(err, errlen, "terrain_field_file '%s': peak height %.17g m, must be in [0, terrain_max_height_m = "
                 "%.17g] m", path, peak, v[CP_VR_terrain_max_height_m]);
        return -1;
    }
    for (size_t i = 0; i < (size_t)n * (size_t)n; i++) {
        float s = le_f32(p + FIELD_SAMPLES_AT + 4 * i);
        if (!(s >= 0.0f && s <= (peak > 0.0 ? 1.0f : 0.0f))) {
            snprintf(err, errlen, "terrain_field_file '%s': sample %zu = %.9g, must be in [0, %g] (heights over the "
                     "peak)", path, i, (double)s, peak > 0.0 ? 1.0 : 0.0);
            return -1;
        }
    }
    return 0;
}

int cp_terrain_load(CpTerrain *t, const char *path, const double *values, char *err, int errlen) {
    memset(t, 0, sizeof *t);
    if (path == NULL || path[0] == '\0') {
        snprintf(err, errlen, "terrain_max_height_m = %.17g m needs the height field: set terrain_field_file to a "
                 "file plant.terrain.write_field wrote for the terrain_* parameters (this FMU cannot generate it)",
                 values[CP_VR_terrain_max_height_m]);
        return -1;
    }
    FILE *f = fopen(path, "rb");
    if (f == NULL) {
        snprintf(err, errlen, "terrain_field_file '%s' cannot be opened: it must name a readable height-field file",
                 path);
        return -1;
    }
    long size = -1;
    if (fseek(f, 0, SEEK_END) == 0) size = ftell(f);
    if (size < 0 || (double)size > FIELD_MAX_BYTES || fseek(f, 0, SEEK_SET) != 0) {
        fclose(f);
        snprintf(err, errlen, "terrain_field_file '%s': %ld bytes, a height field has at most %.0f", path, size,
                 FIELD_MAX_BYTES);
        return -1;
    }
    unsigned char *p = malloc(size ? (size_t)size : 1);
    if (p == NULL || fread(p, 1, (size_t)size, f) != (size_t)size) {
        fclose(f);
        free(p);
        snprintf(err, errlen, "terrain_field_file '%s': cannot read its %ld bytes", path, size);
        return -1;
    }
    fclose(f);
    if (check(p, (size_t)size, path, values, err, errlen)) {
        free(p);
        return -1;
    }
    t->n = (int)le32(p + 56);
    t->size_m = values[CP_VR_terrain_size_m];
    t->peak = le_f64(p + 60);
    t->samples = malloc(sizeof(float) * (size_t)t->n * (size_t)t->n);
    if (t->samples == NULL) {
        free(p);
        snprintf(err, errlen, "out of memory for the %d x %d height field", t->n, t->n);
        return -1;
    }
    for (size_t i = 0; i < (size_t)t->n * (size_t)t->n; i++) t->samples[i] = le_f32(p + FIELD_SAMPLES_AT + 4 * i);
    free(p);
    return 0;
}

void cp_terrain_free(CpTerrain *t) {
    free(t->samples);
    t->samples = NULL;
}

/* plant.terrain.add_terrain: the hfield and its geom, with the contact parameters of the first
 * world-body plane, which it replaces (every world plane is deleted). */
int cp_terrain_add(mjSpec *spec, const CpTerrain *t, char *err, int errlen) {
    mjsBody *world = mjs_findBody(spec, "world");
    if (world == NULL) {
        snprintf(err, errlen, "the model has no world body");
        return -1;
    }
    int n_planes = 0;
    for (mjsElement *e = mjs_firstChild(world, mjOBJ_GEOM, 0); e; e = mjs_nextChild(world, e, 0))
        n_planes += mjs_asGeom(e)->type == mjGEOM_PLANE;
    mjsElement **planes = malloc(sizeof *planes * (size_t)(n_planes ? n_planes : 1));
    if (planes == NULL) {
        snprintf(err, errlen, "out of memory");
        return -1;
    }
    int k = 0;
    for (mjsElement *e = mjs_firstChild(world, mjOBJ_GEOM, 0); e; e = mjs_nextChild(world, e, 0))
        if (mjs_asGeom(e)->type == mjGEOM_PLANE) planes[k++] = e;
    mjsHField *hf = mjs_addHField(spec);
    mjs_setName(hf->element, CP_TERRAIN_NAME);
    hf->nrow = hf->ncol = t->n;
    /* MuJoCo scales the normalised samples by size[2]: the peak keeps the heights' own bits */
    const double size[4] = {t->size_m, t->size_m, t->peak > 1e-6 ? t->peak : 1e-6, CP_TERRAIN_BASE_M};
    memcpy(hf->size, size, sizeof size);
    mjs_setFloat(hf->userdata, t->samples, t->n * t->n);
    mjsGeom *geom = mjs_addGeom(world, NULL);
    mjs_setName(geom->element, CP_TERRAIN_NAME);
    geom->type = mjGEOM_HFIELD;
    mjs_setString(geom->hfieldname, CP_TERRAIN_NAME);
    geom->pos[0] = geom->pos[1] = geom->pos[2] = 0.0;
    if (n_planes) {
        const mjsGeom *src = mjs_asGeom(planes[0]);
        geom->contype = src->contype;
        geom->conaffinity = src->conaffinity;
        geom->condim = src->condim;
        memcpy(geom->friction, src->friction, sizeof geom->friction);
        memcpy(geom->solref, src->solref, sizeof geom->solref);
        memcpy(geom->solimp, src->solimp, sizeof geom->solimp);
        geom->solmix = src->solmix;
        geom->priority = src->priority;
        geom->margin = src->margin;
        geom->gap = src->gap;
        geom->group = src->group;
        geom->pos[2] = src->pos[2];
    } else {
        geom->contype = 1;
        geom->conaffinity = 15;
        geom->condim = 3;
    }
    const float rgba[4] = {0.45f, 0.5f, 0.4f, 1.0f};
    memcpy(geom->rgba, rgba, sizeof rgba);
    for (int i = 0; i < n_planes; i++) mjs_delete(spec, planes[i]);
    free(planes);
    return 0;
}
