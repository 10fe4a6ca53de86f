/*
 * The walker: model loading with the perturbation (plant/model.py, plant/perturbation.py),
 * the standing start (CassiePhysics.reset_standing), the servos and the controller
 * (NominalController), stepping with the controller every control_substeps plant steps
 * (CassieWalker.advance), the latched fall check (CassiePhysics.fall_reason) and the outputs
 * (fmu_core.outputs).  Same operations in the same order as the Python, so the same bits.
 */
#include "cassie_plant.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cp_terrain.h"

static int check_names(const mjModel *m, char *err, int errlen) {
    for (int i = 0; i < CP_N_JOINT_NAMES; i++)
        if (mj_name2id(m, mjOBJ_JOINT, CP_JOINT_NAMES[i]) < 0) {
            snprintf(err, errlen, "model is not the Cassie model this FMU expects: no joint '%s'", CP_JOINT_NAMES[i]);
            return -1;
        }
    return 0;
}

/* plant.model._add_home_key */
static int add_home_key(mjSpec *spec, const mjModel *m, char *err, int errlen) {
    double *qpos = malloc(sizeof(double) * (m->nq ? m->nq : 1));
    if (!qpos) {
        snprintf(err, errlen, "out of memory");
        return -1;
    }
    memcpy(qpos, m->qpos0, sizeof(double) * m->nq);
    int pelvis = mj_name2id(m, mjOBJ_BODY, CP_PELVIS_BODY);
    for (int j = 0; j < m->njnt; j++) {
        int adr = m->jnt_qposadr[j], typ = m->jnt_type[j];
        const char *name = mj_id2name(m, mjOBJ_JOINT, j);
        if (m->jnt_bodyid[j] == pelvis) {
            if (typ == mjJNT_FREE) {
                for (int k = 0; k < 3; k++) qpos[adr + k] = CP_HOME_PELVIS_POS[k];
                for (int k = 0; k < 4; k++) qpos[adr + 3 + k] = CP_HOME_PELVIS_QUAT[k];
            } else if (typ == mjJNT_BALL) {
                for (int k = 0; k < 4; k++) qpos[adr + k] = CP_HOME_PELVIS_QUAT[k];
            } else if (typ == mjJNT_SLIDE) {
                const mjtNum *ax = m->jnt_axis + 3 * j;
                qpos[adr] = ax[0] * CP_HOME_PELVIS_POS[0] + ax[1] * CP_HOME_PELVIS_POS[1] + ax[2] * CP_HOME_PELVIS_POS[2];
            }
        } else if (name) {
            for (int i = 0; i < CP_N_HOME_JOINTS; i++)
                if (!strcmp(name, CP_HOME_JOINTS[i].name)) {
                    for (int k = 0; k < CP_HOME_JOINTS[i].n; k++) qpos[adr + k] = CP_HOME_JOINTS[i].q[k];
                    break;
                }
        }
    }
    mjsKey *key = mjs_addKey(spec);
    mjs_setName(key->element, CP_HOME_KEY);
    mjs_setDouble(key->qpos, qpos, m->nq);
    free(qpos);
    return 0;
}

/* mujoco.mj_setConst on a scratch MjData (the walker's is made afterwards). */
static void set_const(mjModel *m) {
    mjData *d = mj_makeData(m);
    mj_setConst(m, d);
    mj_deleteData(d);
}

/* plant.perturbation.slope_quat: the orientation (w, x, y, z) of the plane rising tan(slope) per
 * metre along +x and tan(cross_slope) along +y, the rotation of +z onto the plane's unit normal
 * about their cross product.  The same operations in the same order as the Python's scalar math:
 * math.radians is x * (pi / 180), math.tan/acos/sqrt are the C library's. */
static void slope_quat(double slope_deg, double cross_slope_deg, double quat[4]) {
    const double deg_to_rad = 3.141592653589793238462643383279502884 / 180.0;
    double tx = -tan(slope_deg * deg_to_rad), ty = -tan(cross_slope_deg * deg_to_rad);
    double norm = sqrt((tx * tx + ty * ty) + 1.0);
    double n0 = tx / norm, n1 = ty / norm, n2 = 1.0 / norm;
    double a0 = -n1, a1 = n0; /* +z x n */
    double a_len = sqrt(a0 * a0 + a1 * a1);
    double axis[3] = {a0 / a_len, a1 / a_len, 0.0};
    double c = n2 > 1.0 ? 1.0 : n2 < -1.0 ? -1.0 : n2;
    mju_axisAngle2Quat(quat, axis, acos(c));
}

/* plant.perturbation.apply_environment with the FMU's parameters (fmu_core.perturbation_from_values):
 * the floor friction (a value other than the models' 1) on every world-body geom, with a contact
 * priority above every geom's, the floor slopes (either other than 0) as the orientation of every
 * world-body plane (tilted about the point under the origin, where the robot starts), and each link
 * mass factor other than 1 on its body's mass and inertia (the inertia times new/old mass), then
 * mj_setConst, in the Python's order.  0, or -1 with err naming the parameter of a body the model
 * lacks. */
static int apply_environment(mjModel *m, const double *v, char *err, int errlen) {
    double friction = v[CP_VR_floor_friction];
    int links = 0;
    for (int i = 0; i < CP_N_LINK_MASS; i++) {
        const CpLinkMass *l = &CP_LINK_MASS[i];
        if (v[l->vr] == 1.0) continue;
        links = 1;
        if (mj_name2id(m, mjOBJ_BODY, l->body) <= 0) { /* plant.perturbation.model_problems */
            snprintf(err, errlen, "%s = %.17g: the model has no body '%s'", CP_VARS[l->vr].name, v[l->vr], l->body);
            return -1;
        }
    }
    double slope = v[CP_VR_floor_slope_deg], cross_slope = v[CP_VR_floor_cross_slope_deg];
    int sloped = slope != 0.0 || cross_slope != 0.0;
    if (friction == CP_MODEL_FLOOR_FRICTION && !sloped && !links) return 0;
    if (friction != CP_MODEL_FLOOR_FRICTION) { /* plant.perturbation.set_floor_friction */
        int top = 0;
        for (int g = 0; g < m->ngeom; g++)
            if (g == 0 || m->geom_priority[g] > top) top = m->geom_priority[g];
        for (int g = 0; g < m->ngeom; g++)
            if (m->geom_bodyid[g] == 0) {
                m->geom_friction[3 * g] = friction;
                m->geom_priority[g] = top + 1;
            }
    }
    if (sloped) {
        double quat[4];
        slope_quat(slope, cross_slope, quat);
        for (int g = 0; g < m->ngeom; g++)
            if (m->geom_bodyid[g] == 0 && m->geom_type[g] == mjGEOM_PLANE)
                memcpy(m->geom_quat + 4 * g, quat, sizeof quat);
    }
    for (int i = 0; i < CP_N_LINK_MASS; i++) { /* plant.perturbation._set_link_mass */
        const CpLinkMass *l = &CP_LINK_MASS[i];
        if (v[l->vr] == 1.0) continue;
        int b = mj_name2id(m, mjOBJ_BODY, l->body);
        double mass = m->body_mass[b] * v[l->vr];
        double ratio = mass / m->body_mass[b];
        for (int k = 0; k < 3; k++) m->body_inertia[3 * b + k] *= ratio;
        m->body_mass[b] = mass;
    }
    set_const(m);
    return 0;
}

/* plant.model.load_model: the file, its home key, the terrain (NULL: the flat floor). */
static mjModel *load_model(const char *path, const double *v, const CpTerrain *terrain, char *err, int errlen) {
    char msg[1000] = "";
    mjSpec *spec = mj_parseXML(path, NULL, msg, sizeof msg);
    if (!spec) {
        snprintf(err, errlen, "cannot load model %s: %s", path, msg);
        return NULL;
    }
    mjModel *m = mj_compile(spec, NULL);
    if (!m) {
        snprintf(err, errlen, "cannot compile model %s: %s", path, mjs_getError(spec));
        mj_deleteSpec(spec);
        return NULL;
    }
    if (check_names(m, err, errlen)) {
        mj_deleteModel(m);
        mj_deleteSpec(spec);
        return NULL;
    }
    int edit = 0;
    if (mj_name2id(m, mjOBJ_KEY, CP_HOME_KEY) < 0) {
        if (add_home_key(spec, m, err, errlen)) {
            mj_deleteModel(m);
            mj_deleteSpec(spec);
            return NULL;
        }
        edit = 1;
    }
    if (terrain != NULL) {
        if (cp_terrain_add(spec, terrain, err, errlen)) {
            mj_deleteModel(m);
            mj_deleteSpec(spec);
            return NULL;
        }
        edit = 1;
    }
    if (edit) {
        mj_deleteModel(m);
        m = mj_compile(spec, NULL);
        if (!m) {
            snprintf(err, errlen, "cannot compile model %s after edits: %s", path, mjs_getError(spec));
            mj_deleteSpec(spec);
            return NULL;
        }
    }
    mj_deleteSpec(spec);
    /* plant.perturbation.apply_to_compiled */
    int pelvis = mj_name2id(m, mjOBJ_BODY, CP_PELVIS_BODY);
    int changed = 0;
    double mass = v[CP_VR_torso_mass_kg];
    if (mass != CP_NOMINAL_TORSO_MASS_KG) {
        double m0 = m->body_mass[pelvis];
        m->body_mass[pelvis] = mass;
        double ratio = mass / m0;
        for (int k = 0; k < 3; k++) m->body_inertia[3 * pelvis + k] *= ratio;
        changed = 1;
    }
    double com[3] = {v[CP_VR_torso_com_offset_x_m], v[CP_VR_torso_com_offset_y_m], v[CP_VR_torso_com_offset_z_m]};
    if (com[0] != 0 || com[1] != 0 || com[2] != 0) {
        for (int k = 0; k < 3; k++) m->body_ipos[3 * pelvis + k] += com[k];
        changed = 1;
    }
    double damping = v[CP_VR_joint_damping_scale];
    if (damping != 1.0) {
        for (int i = 0; i < m->nv; i++) m->dof_damping[i] *= damping;
        changed = 1;
    }
    if (changed) set_const(m);
    if (apply_environment(m, v, err, errlen)) {
        mj_deleteModel(m);
        return NULL;
    }
    return m;
}

void cp_free(CpWalker *w) {
    if (w->d) mj_deleteData(w->d);
    if (w->m) mj_deleteModel(w->m);
    w->d = NULL;
    w->m = NULL;
}

int cp_start(CpWalker *w, const char *models_dir, const double *values, const char *terrain_file, char *err,
             int errlen) {
    memset(w, 0, sizeof *w);
    CpTerrain terrain;
    const int uneven = values[CP_VR_terrain_max_height_m] != 0.0;
    if (uneven && cp_terrain_load(&terrain, terrain_file, values, err, errlen)) return -1;
    int model = (int)values[CP_VR_cassie_model];
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", models_dir, CP_MODEL_FILES[model]);
    w->m = load_model(path, values, uneven ? &terrain : NULL, err, errlen);
    if (uneven) cp_terrain_free(&terrain);
    if (!w->m) return -1;
    mjModel *m = w->m;
    if (m->opt.timestep != CP_PLANT_STEP_S) {
        snprintf(err, errlen, "model '%s' has a %.17g s step, the FMU needs %.17g s", CP_MODEL_NAMES[model],
                 m->opt.timestep, CP_PLANT_STEP_S);
        cp_free(w);
        return -1;
    }
    mjData *d = w->d = mj_makeData(m);
    if (!d) {
        snprintf(err, errlen, "cannot allocate MuJoCo data");
        cp_free(w);
        return -1;
    }
    /* CassiePhysics.reset_standing */
    int key = mj_name2id(m, mjOBJ_KEY, CP_HOME_KEY);
    mj_resetData(m, d);
    mj_resetDataKeyframe(m, d, key);
    for (int i = 0; i < m->nv; i++) d->qvel[i] = 0.0;
    mj_kinematics(m, d);
    int pelvis = mj_name2id(m, mjOBJ_BODY, CP_PELVIS_BODY), free_qadr = -1;
    for (int j = 0; j < m->njnt && free_qadr < 0; j++)
        if (m->jnt_bodyid[j] == pelvis) free_qadr = m->jnt_qposadr[j];
    const mjtNum *p = d->xpos + 3 * pelvis;
    d->qpos[free_qadr + 2] += cc_model_ground_height(m, p[0], p[1]);
    mj_forward(m, d);
    /* NominalController.__init__ (the servos first: they touch no state cc_init reads) */
    if (cc_configure_servos(m, d, err, errlen) || cc_init(&w->ctrl, m, d, NULL, err, errlen)) {
        cp_free(w);
        return -1;
    }
    cc_set_command(&w->ctrl, 0.0, 0.0, 0.0, NULL);
    return 0;
}

/* CassiePhysics.fall_reason */
static int fall_reason(CpWalker *w, char *out, int n) {
    const mjModel *m = w->m;
    const mjData *d = w->d;
    for (int i = 0; i < m->nq; i++)
        if (!isfinite(d->qpos[i])) return snprintf(out, n, "non-finite state"), 1;
    for (int i = 0; i < m->nv; i++)
        if (!isfinite(d->qvel[i])) return snprintf(out, n, "non-finite state"), 1;
    const mjtNum *q = d->qpos + w->ctrl.fx.free_qadr;
    double h = q[2] - cc_ground_height(&w->ctrl, q[0], q[1]);
    if (h < CP_FALL_HEIGHT_M) return snprintf(out, n, "pelvis height %.3f m < %g m", h, CP_FALL_HEIGHT_M), 1;
    double zz = d->xmat[9 * w->ctrl.fx.pelvis_body + 8];
    double tilt = acos(zz > 1.0 ? 1.0 : (zz < -1.0 ? -1.0 : zz));
    if (tilt > CP_FALL_TILT_RAD) return snprintf(out, n, "pelvis tilt %.3f rad > %g rad", tilt, CP_FALL_TILT_RAD), 1;
    return 0;
}

void cp_advance(CpWalker *w, const double *v, long n) {
    double vx = v[CP_VR_vx_des], vy = v[CP_VR_vy_des], wz = v[CP_VR_yaw_rate_des];
    if (vx != w->vx_des_mps || vy != w->vy_des_mps || wz != w->yaw_rate_des_radps) {
        w->vx_des_mps = vx;
        w->vy_des_mps = vy;
        w->yaw_rate_des_radps = wz;
        cc_set_command(&w->ctrl, vx, vy, wz, NULL);
    }
    double offsets[CC_NOFFSETS];
    for (int k = 0; k < CC_NOFFSETS; k++) offsets[k] = v[CP_VR_FIRST_OFFSET + k];
    cc_set_offsets(&w->ctrl, offsets); /* the FMI layer has checked the ranges */
    mjtNum *f = w->d->xfrc_applied + 6 * w->ctrl.fx.pelvis_body;
    f[0] = v[CP_VR_push_fx];
    f[1] = v[CP_VR_push_fy];
    f[2] = v[CP_VR_push_fz];
    int sub = w->ctrl.p.control_substeps;
    while (n > 0) {
        long k = sub - w->substep < n ? sub - w->substep : n;
        for (long i = 0; i < k; i++) mj_step(w->m, w->d);
        n -= k;
        w->substep += (int)k;
        if (w->substep >= sub) {
            w->substep = 0;
            cc_update(&w->ctrl);
        }
    }
    if (!w->fell) w->fell = fall_reason(w, w->fall_reason, sizeof w->fall_reason);
}

void cp_outputs(CpWalker *w, double *v) {
    double hs[8], forces[2];
    cc_heading_state(&w->ctrl, hs);
    const CcMemory *mm = &w->ctrl.mem;
    const mjtNum *q = w->d->qpos + w->ctrl.fx.free_qadr;
    v[CP_VR_vx] = mm->vx_step_avg;
    v[CP_VR_vy] = mm->vy_filt;
    v[CP_VR_pitch] = hs[1];
    v[CP_VR_roll] = hs[2];
    v[CP_VR_pitch_rate] = hs[6];
    v[CP_VR_roll_rate] = hs[5];
    v[CP_VR_step_index] = (double)mm->step_index;
    v[CP_VR_pelvis_x] = q[0];
    v[CP_VR_pelvis_y] = q[1];
    v[CP_VR_pelvis_z] = q[2];
    cc_foot_forces(&w->ctrl, forces);
    v[CP_VR_left_foot_force] = forces[0];
    v[CP_VR_right_foot_force] = forces[1];
    v[CP_VR_pelvis_vx] = hs[3];
    v[CP_VR_pelvis_vy] = hs[4];
    v[CP_VR_yaw] = hs[0];
    v[CP_VR_yaw_rate] = hs[7];
    v[CP_VR_stance] = mm->stance == CC_LEFT ? 0.0 : 1.0;
    v[CP_VR_gait_phase] = mm->tau;
    v[CP_VR_plant_time] = w->d->time;
    if (!w->fell) w->fell = fall_reason(w, w->fall_reason, sizeof w->fall_reason);
    v[CP_VR_fell] = w->fell ? 1.0 : 0.0;
}
