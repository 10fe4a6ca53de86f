/*
 * Uneven terrain in the native CassiePlant: the height field a host hands over as a file
 * (plant.terrain.write_field, named by the terrain_field_file parameter), checked against the
 * terrain_* parameters and built into the model as plant.terrain.add_terrain builds it.
 */
#ifndef CP_TERRAIN_H
#define CP_TERRAIN_H

#include "cassie_plant.h" /* first: the floating-point contract; MuJoCo (mj_dyn.h on Windows) */

typedef struct {
    int n;           /* samples per side */
    double size_m;   /* half-length of the square field */
    double peak;     /* the highest height, m */
    float *samples;  /* n * n heights / peak, row i at y = -size_m + i * spacing */
} CpTerrain;

/* Read and check the file `path` against the parameter values (indexed by value reference):
 * 0, or -1 with the reason in err naming terrain_field_file and the allowed values (t then holds
 * nothing to free). */
int cp_terrain_load(CpTerrain *t, const char *path, const double *values, char *err, int errlen);
void cp_terrain_free(CpTerrain *t);
/* Replace the world's planes of `spec` by the terrain's hfield geom; 0, or -1 with err. */
int cp_terrain_add(mjSpec *spec, const CpTerrain *t, char *err, int errlen);

#endif
