/*
 * The nominal Cassie walking controller in C: plant/controller.py operation for operation.
 *
 * The Python controller is the readable reference (its docstring is the method); this is the
 * same computation in the same order, so on one CPU architecture with the same libm it gives
 * the same bits (no FMA contraction: see the pragma in cc_params.h; libm's cos, sin, atan2,
 * asin where Python calls math.*; CPython's correctly rounded hypot; Python's min/max
 * semantics).  The parameters and the gait library are generated into cc_params.h from
 * plant/controller_params.py and plant/data/gait_library.json (plant/native/native_ctrl.py),
 * and the ground is the model's own hfield, read as plant/terrain.py's GroundHeight reads it.
 */
#ifndef CASSIE_CTRL_H
#define CASSIE_CTRL_H

#include "cc_params.h"
#include <mujoco/mujoco.h>
#include "mj_dyn.h"

#define CC_NSIDES 2
#define CC_NMOTOR 5
#define CC_NOFFSETS 6
enum { CC_LEFT = 0, CC_RIGHT = 1 };
enum { CC_STAND = 0, CC_SHIFT = 1, CC_WALK = 2 };
/* motor joints of one leg, actuator order (plant.constants.MOTOR_JOINTS) */
enum { CC_HIP_ROLL = 0, CC_HIP_YAW = 1, CC_HIP_PITCH = 2, CC_KNEE = 3, CC_FOOT = 4 };
/* offsets, the regulator's output order (plant.constants.OFFSET_NAMES) */
enum { CC_D_SWING_HIP_PITCH = 0, CC_D_SWING_KNEE, CC_D_SWING_HIP_ROLL,
       CC_D_STANCE_HIP_ROLL, CC_D_STANCE_HIP_PITCH, CC_D_STANCE_KNEE };

/* Everything the controller carries from one update to the next
 * (NominalController.MEMORY_FIELDS, in that order). */
typedef struct {
    double offsets[CC_NOFFSETS];
    double vx_ref, vy_ref, vx_des, vy_des, yaw_rate_ref, yaw_rate_des;
    int mode, stance;
    long long step_index;
    double t_step_start, tau, vx_step_avg, vy_filt, vx_filt;
    double step_start_xy[2], swing_start[2];
    double last_t, yaw_ref;
} CcMemory;

/* Ids resolved by name and constants fixed at construction. */
typedef struct {
    int pelvis_body, free_qadr, free_dadr;
    int qadr[CC_NSIDES][CC_NMOTOR + 1]; /* motor joints then tarsus */
    int dadr[CC_NSIDES][CC_NMOTOR];
    int act[CC_NSIDES][CC_NMOTOR];
    int hip_pitch_jid[CC_NSIDES], foot_jid[CC_NSIDES], foot_geom0[CC_NSIDES];
    int foot_body[CC_NSIDES];
    /* ground: hfield (has_terrain), or a flat height, tilted (has_plane: plant.perturbation's slope,
       height flat_m + pl_sx (x - pl_x0) + pl_sy (y - pl_y0)) or level */
    int has_terrain, hf_nrow, hf_ncol, has_plane;
    const float *hf_data;
    double hf_sx, hf_sy, hf_sz, hf_gx, hf_gy, hf_gz, flat_m;
    double pl_x0, pl_y0, pl_sx, pl_sy;
    /* leg kinematics fits (highest power first) and ranges */
    double length_poly[CC_NSIDES][CC_FIT_DEGREE + 1], angle_poly[CC_NSIDES][CC_FIT_DEGREE + 1];
    double knee_poly[CC_NSIDES][CC_FIT_DEGREE + 1], length_lo[CC_NSIDES], length_hi[CC_NSIDES];
    double foot_flat_sum, ankle_height0, stance_knee[CC_NSIDES];
} CcFixed;

/* The servo targets of one update, per side and motor joint (position rad, velocity rad/s,
 * feedforward N m, gains). */
typedef struct {
    double q[CC_NSIDES][CC_NMOTOR], qd[CC_NSIDES][CC_NMOTOR], ff[CC_NSIDES][CC_NMOTOR];
    double kp[CC_NSIDES][CC_NMOTOR], kd[CC_NSIDES][CC_NMOTOR];
} CcTargets;

typedef struct {
    const mjModel *m_const;
    mjModel *m; /* the controller writes the servo gains (actuator_biasprm) */
    mjData *d;
    CcParams p;
    const CcGaitLibrary *gaits; /* the library set_command chose; the default gait before */
    CcGait gait;
    int has_gait;
    CcMemory mem;
    CcFixed fx;
    CcTargets targets;
} CcController;

/* The uncalibrated default gait library (plant.gaits.GaitLibrary.uniform(GaitParams())). */
extern const CcGaitLibrary cc_default_gait;
/* The committed gait library (plant/data/gait_library.json). */
extern const CcGaitLibrary cc_library_gait;
/* ControllerParams() defaults. */
extern const CcParams cc_default_params;

/* Size of CcController, for a caller that allocates it (ctypes). */
CC_API int cc_controller_size(void);
/* Set up on the model and data (the standing pose, servos configured by cc_configure_servos
 * beforehand or by the caller) and run the first update, as NominalController.__init__.
 * 0, or -1 with a message naming the missing part in err. */
CC_API int cc_init(CcController *c, mjModel *m, mjData *d, const CcParams *p, char *err, int errlen);
/* NominalController.set_command; lib NULL = the committed library. */
CC_API void cc_set_command(CcController *c, double vx, double vy, double yaw_rate, const CcGaitLibrary *lib);
/* NominalController.set_offsets (six offsets, OFFSET_NAMES order); -1 (nothing changed) if one is not finite. */
CC_API int cc_set_offsets(CcController *c, const double *offsets);
/* NominalController.update. */
CC_API void cc_update(CcController *c);
/* CassieWalker.advance's stepping: n plant steps (mj_step), the update every control_substeps
 * steps; *substep counts the steps since the last update, across calls. */
CC_API void cc_advance(CcController *c, long n, int *substep);
/* CassiePhysics.fall_reason's test: 1 for a non-finite state, the pelvis less than height_m above
 * the ground under it or tilted more than tilt_rad from upright, else 0. */
CC_API int cc_fallen(const CcController *c, double height_m, double tilt_rad);
/* The walker's signals in one call: cc_heading_state's eight (0-7), cc_foot_forces' two (8-9), the
 * pelvis position (10-12), the time (13), vx_step_avg, vy_filt, step_index, stance (0 left, 1 right)
 * and tau (14-18). */
#define CC_NSENSE 19
CC_API void cc_sense(const CcController *c, double out[CC_NSENSE]);
/* Look the gait up again for the memory's gait speed (after the memory was restored). */
CC_API void cc_memory_restored(CcController *c);
/* The ground height under (x, y), m (plant.terrain.GroundHeight). */
CC_API double cc_ground_height(const CcController *c, double x, double y);
/* The ground height under (x, y) of a model, m, without a controller (set-up only: it reads the
 * model's ground each call). */
CC_API double cc_model_ground_height(const mjModel *m, double x, double y);
/* Contact normal force on the (left, right) foot, N (CassiePhysics.foot_normal_forces_n). */
CC_API void cc_foot_forces(const CcController *c, double out[2]);
/* CassiePhysics.heading_state: yaw, pitch, roll, vx, vy, roll_rate, pitch_rate, yaw_rate. */
CC_API void cc_heading_state(const CcController *c, double out[8]);
/* The memory and the last targets (q, qd, ff, kp, kd, each [side][motor joint]), for ctypes. */
CC_API CcMemory *cc_memory_ptr(CcController *c);
CC_API CcTargets *cc_targets_ptr(CcController *c);
/* CassiePhysics.configure_pd_servos on a model as loaded (gear and ctrlrange as in the file). */
CC_API int cc_configure_servos(mjModel *m, mjData *d, char *err, int errlen);

#endif
