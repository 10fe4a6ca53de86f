/*
 * The CassiePlant FMU's walker in C: plant/sim.py's CassieWalker and the parts of
 * fmu_src/plant_fmu/fmu_core.py below the FMI layer (start, apply_inputs, advance, outputs),
 * over MuJoCo's C API and the C controller (plant/native/cassie_ctrl.c).
 */
#ifndef CASSIE_PLANT_H
#define CASSIE_PLANT_H

#include "cp_vars.h" /* first: the floating-point contract (through cc_params.h) */
#include "cassie_ctrl.h"

typedef struct {
    mjModel *m;
    mjData *d;
    CcController ctrl;
    int substep;
    int fell;
    char fall_reason[160];
    double vx_des_mps, vy_des_mps, yaw_rate_des_radps;
} CpWalker;

/* fmu_core.start: the model `model_index` (CP_MODEL_FILES) from models_dir with the
 * perturbation of the parameter values (indexed by value reference), on the terrain of the
 * height-field file terrain_file when terrain_max_height_m > 0 (cp_terrain.h), at rest in the
 * home pose.  0, or -1 with the reason in err (the walker then holds nothing). */
int cp_start(CpWalker *w, const char *models_dir, const double *values, const char *terrain_file, char *err,
             int errlen);
void cp_free(CpWalker *w);
/* fmu_core.apply_inputs then CassieWalker.advance(n_steps); inputs indexed by value reference. */
void cp_advance(CpWalker *w, const double *values, long n_steps);
/* fmu_core.outputs into values (by value reference). */
void cp_outputs(CpWalker *w, double *values);

#endif
