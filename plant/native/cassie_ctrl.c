/*
 * The nominal Cassie walking controller: plant/controller.py (with plant/kinematics.py,
 * plant/gaits.py and the sensing of plant/cassie.py and plant/terrain.py) operation for
 * operation.  Each function names the Python it mirrors; expressions keep Python's
 * evaluation order (left to right, one rounding per operation), min/max keep Python's
 * semantics (the first argument unless the second is strictly smaller/larger).
 */
#include "cassie_ctrl.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PASSIVE_SHIN 0
#define PASSIVE_HEEL 1
static const char *const SIDE_NAMES[CC_NSIDES] = {"left", "right"};
static const char *const MOTOR_NAMES[CC_NMOTOR] = {"hip-roll", "hip-yaw", "hip-pitch", "knee", "foot"};

/* plant/controller.py constants */
#define MAX_STEP_SINE 0.5
#define MIN_LEG_COS 0.5
#define SHIFT_RAMP_FRACTION 0.7
#define MIN_SHIFT_RAMP_S 1e-3
#define MIN_STEP_DURATION_S 1e-6
#define DOUBLE_SUPPORT_SHARE 0.5
#define SINGLE_SUPPORT_SHARE 1.0
#define TAU_2PI 6.283185307179586 /* math.tau */

static double py_min(double a, double b) { return b < a ? b : a; }
static double py_max(double a, double b) { return b > a ? b : a; }

/* CPython's math.hypot is correctly rounded for two arguments (glibc's hypot is not, in the
 * last bit for about 1 argument pair in 200): the double nearest to sqrt(x^2 + y^2), chosen
 * among the neighbours of the rounded estimate with the squares evaluated in quadruple
 * precision (exact for the squares, a relative 2^-113 for their sum). */
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__)) && !defined(__clang__)
typedef __float128 wide_t;
#else
typedef long double wide_t; /* quadruple on aarch64 Linux */
#endif
static double cr_hypot(double x, double y) {
    x = fabs(x);
    y = fabs(y);
    double h = sqrt(x * x + y * y);
    wide_t s = (wide_t)x * (wide_t)x + (wide_t)y * (wide_t)y;
    double best = h;
    wide_t e = (wide_t)h * (wide_t)h - s;
    if (e < 0) e = -e;
    double cands[2] = {nextafter(h, 0.0), nextafter(h, INFINITY)};
    for (int i = 0; i < 2; i++) {
        wide_t ei = (wide_t)cands[i] * (wide_t)cands[i] - s;
        if (ei < 0) ei = -ei;
        if (ei < e) {
            e = ei;
            best = cands[i];
        }
    }
    return best;
}

/* ------------------------------------------------------------------ plant/kinematics.py */
static double bezier(const double *coeffs, int ncoef, double s) {
    s = s < 0.0 ? 0.0 : (s > 1.0 ? 1.0 : s);
    int n = ncoef - 1;
    double t = 1.0 - s, b[CC_MAX_BEZIER];
    for (int i = 0; i < ncoef; i++) b[i] = coeffs[i];
    for (int r = 1; r <= n; r++)
        for (int i = 0; i < n - r + 1; i++) b[i] = t * b[i] + s * b[i + 1];
    return b[0];
}

static double horner(const double *coeffs, double x) {
    double r = 0.0;
    for (int i = 0; i <= CC_FIT_DEGREE; i++) r = r * x + coeffs[i];
    return r;
}

static double dot_from(const double *a, const double *b, int from, int to) {
    double acc = 0.0;
    for (int i = from; i < to; i++) acc += a[i] * b[i];
    return acc;
}

/* kinematics._fit: Householder QR of the column-scaled Vandermonde matrix. */
#define NPTS CC_KNEE_GRID_POINTS
#define NCOEF (CC_FIT_DEGREE + 1)
static int fit(const double *xs, const double *ys, double *out) {
    double powers[NCOEF][NPTS], cols[NCOEF][NPTS], scale[NCOEF], rhs[NPTS], v[NPTS];
    for (int i = 0; i < NPTS; i++) powers[0][i] = 1.0;
    for (int k = 1; k < NCOEF; k++)
        for (int i = 0; i < NPTS; i++) powers[k][i] = powers[k - 1][i] * xs[i];
    for (int k = 0; k < NCOEF; k++) {
        memcpy(cols[k], powers[CC_FIT_DEGREE - k], sizeof cols[k]);
        scale[k] = sqrt(dot_from(cols[k], cols[k], 0, NPTS));
        for (int i = 0; i < NPTS; i++) cols[k][i] = cols[k][i] / scale[k];
    }
    memcpy(rhs, ys, sizeof rhs);
    for (int k = 0; k < NCOEF; k++) {
        double *ck = cols[k];
        double alpha = sqrt(dot_from(ck, ck, k, NPTS));
        if (ck[k] > 0.0) alpha = -alpha;
        for (int i = 0; i < NPTS; i++) v[i] = i < k ? 0.0 : (i == k ? ck[k] - alpha : ck[i]);
        double vv = dot_from(v, v, k, NPTS);
        if (vv == 0.0) return -1;
        for (int c = k; c <= NCOEF; c++) {
            double *col = c < NCOEF ? cols[c] : rhs;
            double f = 2.0 * dot_from(v, col, k, NPTS) / vv;
            for (int i = k; i < NPTS; i++) col[i] -= f * v[i];
        }
    }
    double coeffs[NCOEF];
    for (int k = NCOEF - 1; k >= 0; k--) {
        double acc = rhs[k];
        for (int j = k + 1; j < NCOEF; j++) acc -= cols[j][k] * coeffs[j];
        coeffs[k] = acc / cols[k][k];
    }
    for (int k = 0; k < NCOEF; k++) out[k] = coeffs[k] / scale[k];
    return 0;
}

/* LegKinematics.__init__ for one side. */
static int leg_kinematics(CcController *c, int side, const int *passive_qadr, char *err, int errlen) {
    const mjModel *m = c->m;
    CcFixed *fx = &c->fx;
    mjData *dd = mj_makeData(m);
    if (!dd) {
        snprintf(err, errlen, "cannot allocate MuJoCo data for the leg kinematics");
        return -1;
    }
    memcpy(dd->qpos, c->d->qpos, sizeof(mjtNum) * m->nq);
    const int *qadr = fx->qadr[side];
    int q_knee = qadr[CC_KNEE], q_tarsus = qadr[CC_NMOTOR];
    double tarsus_offset = dd->qpos[q_tarsus] + dd->qpos[q_knee];
    dd->qpos[fx->free_qadr + 3] = 1;
    dd->qpos[fx->free_qadr + 4] = 0;
    dd->qpos[fx->free_qadr + 5] = 0;
    dd->qpos[fx->free_qadr + 6] = 0;
    dd->qpos[qadr[CC_HIP_ROLL]] = 0.0;
    dd->qpos[qadr[CC_HIP_YAW]] = 0.0;
    dd->qpos[qadr[CC_HIP_PITCH]] = 0.0;
    dd->qpos[passive_qadr[PASSIVE_SHIN]] = 0.0;
    dd->qpos[passive_qadr[PASSIVE_HEEL]] = 0.0;
    double knees[NPTS], lengths[NPTS], angles[NPTS];
    double step = (CC_KNEE_GRID_HI - CC_KNEE_GRID_LO) / (NPTS - 1); /* numpy.linspace */
    for (int i = 0; i < NPTS; i++) knees[i] = (double)i * step + CC_KNEE_GRID_LO;
    knees[NPTS - 1] = CC_KNEE_GRID_HI;
    for (int i = 0; i < NPTS; i++) {
        dd->qpos[q_knee] = knees[i];
        dd->qpos[q_tarsus] = tarsus_offset - knees[i];
        mj_kinematics(m, dd);
        const mjtNum *a = dd->xanchor + 3 * fx->foot_jid[side], *b = dd->xanchor + 3 * fx->hip_pitch_jid[side];
        double v0 = a[0] - b[0], v2 = a[2] - b[2];
        lengths[i] = cr_hypot(v0, v2);
        angles[i] = atan2(v0, -v2);
    }
    mj_deleteData(dd);
    if (fit(knees, lengths, fx->length_poly[side]) || fit(knees, angles, fx->angle_poly[side])
        || fit(lengths, knees, fx->knee_poly[side])) {
        snprintf(err, errlen, "%s leg kinematics: the sample points are not distinct enough for the fit",
                 SIDE_NAMES[side]);
        return -1;
    }
    double lo = lengths[0], hi = lengths[0];
    for (int i = 1; i < NPTS; i++) {
        lo = py_min(lo, lengths[i]);
        hi = py_max(hi, lengths[i]);
    }
    fx->length_lo[side] = lo;
    fx->length_hi[side] = hi;
    return 0;
}

static double knee_for_length(const CcController *c, int side, double length_m) {
    return horner(c->fx.knee_poly[side], py_min(py_max(length_m, c->fx.length_lo[side]), c->fx.length_hi[side]));
}

static double angle_offset(const CcController *c, int side, double knee) {
    return horner(c->fx.angle_poly[side], knee);
}

/* ------------------------------------------------------------------ plant/gaits.py */
static void bracket(const double *grid, int n, double x, int *i, int *j, double *w) {
    if (x <= grid[0]) {
        *i = *j = 0;
        *w = 0.0;
        return;
    }
    if (x >= grid[n - 1]) {
        *i = *j = n - 1;
        *w = 0.0;
        return;
    }
    int k = 0;
    while (k < n && !(x < grid[k])) k++; /* bisect_right */
    *j = k;
    *i = k - 1;
    *w = (x - grid[*i]) / (grid[*j] - grid[*i]);
}

static CcGait lookup(const CcGaitLibrary *lib, double vx, double vy) {
    int i0, i1, j0, j1;
    double wx, wy;
    bracket(lib->vx, lib->nvx, vx, &i0, &i1, &wx);
    bracket(lib->vy, lib->nvy, vy, &j0, &j1, &wy);
    const double *f00 = &lib->points[i0 * lib->nvy + j0].step_time_s;
    const double *f01 = &lib->points[i0 * lib->nvy + j1].step_time_s;
    const double *f10 = &lib->points[i1 * lib->nvy + j0].step_time_s;
    const double *f11 = &lib->points[i1 * lib->nvy + j1].step_time_s;
    CcGait g;
    double *out = &g.step_time_s;
    for (int k = 0; k < (int)(sizeof(CcGait) / sizeof(double)); k++)
        out[k] = ((1 - wx) * ((1 - wy) * f00[k] + wy * f01[k]) + wx * ((1 - wy) * f10[k] + wy * f11[k]));
    return g;
}

/* ------------------------------------------------------------------ sensing (plant/cassie.py) */
static void quat_to_euler_zyx(double w, double x, double y, double z, double *yaw, double *pitch, double *roll) {
    *yaw = atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
    *pitch = asin(py_max(-1.0, py_min(1.0, 2.0 * (w * y - z * x))));
    *roll = atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y));
}

void cc_heading_state(const CcController *c, double out[8]) {
    const mjData *d = c->d;
    int qa = c->fx.free_qadr, da = c->fx.free_dadr;
    double yaw, pitch, roll;
    quat_to_euler_zyx(d->qpos[qa + 3], d->qpos[qa + 4], d->qpos[qa + 5], d->qpos[qa + 6], &yaw, &pitch, &roll);
    double v0 = d->qvel[da], v1 = d->qvel[da + 1], a0 = d->qvel[da + 3], a1 = d->qvel[da + 4], a2 = d->qvel[da + 5];
    const mjtNum *r = d->xmat + 9 * c->fx.pelvis_body;
    double wx = r[0] * a0 + r[1] * a1 + r[2] * a2;
    double wy = r[3] * a0 + r[4] * a1 + r[5] * a2;
    double wz = r[6] * a0 + r[7] * a1 + r[8] * a2;
    double cy = cos(yaw), sn = sin(yaw);
    out[0] = yaw;
    out[1] = pitch;
    out[2] = roll;
    out[3] = cy * v0 + sn * v1;
    out[4] = -sn * v0 + cy * v1;
    out[5] = cy * wx + sn * wy;
    out[6] = -sn * wx + cy * wy;
    out[7] = wz;
}

double cc_ground_height(const CcController *c, double x, double y) {
    const CcFixed *f = &c->fx;
    if (!f->has_terrain) {
        if (!f->has_plane) return f->flat_m;
        return f->flat_m + f->pl_sx * (x - f->pl_x0) + f->pl_sy * (y - f->pl_y0);
    }
    if (!(isfinite(x) && isfinite(y))) return NAN;
    double sx = f->hf_sx, sy = f->hf_sy;
    int nrow = f->hf_nrow, ncol = f->hf_ncol;
    double u = (py_min(py_max(x - f->hf_gx, -sx), sx) + sx) / (2 * sx) * (ncol - 1);
    double v = (py_min(py_max(y - f->hf_gy, -sy), sy) + sy) / (2 * sy) * (nrow - 1);
    int ju = (int)u, iv = (int)v;
    int j0 = ju < ncol - 2 ? ju : ncol - 2, i0 = iv < nrow - 2 ? iv : nrow - 2;
    double fu = u - j0, fv = v - i0;
    const float *data = f->hf_data;
    double d00 = data[i0 * ncol + j0], d01 = data[i0 * ncol + j0 + 1];
    double d10 = data[(i0 + 1) * ncol + j0], d11 = data[(i0 + 1) * ncol + j0 + 1];
    double h = ((1 - fv) * ((1 - fu) * d00 + fu * d01) + fv * ((1 - fu) * d10 + fu * d11));
    return f->hf_gz + f->hf_sz * h;
}

static int foot_side(const CcController *c, int geom) {
    const mjModel *m = c->m;
    for (int s = 0; s < CC_NSIDES; s++)
        if (geom >= 0 && geom < m->ngeom && m->geom_bodyid[geom] == c->fx.foot_body[s]
            && (m->geom_contype[geom] || m->geom_conaffinity[geom]))
            return s;
    return -1;
}

void cc_foot_forces(const CcController *c, double out[2]) {
    const mjData *d = c->d;
    out[0] = out[1] = 0.0;
    for (int i = 0; i < d->ncon; i++) {
        int s = foot_side(c, d->contact[i].geom1);
        if (s < 0) s = foot_side(c, d->contact[i].geom2);
        if (s < 0) continue;
        mjtNum f6[6];
        mj_contactForce(c->m, d, i, f6);
        out[s] += fabs(f6[0]);
    }
}

/* ------------------------------------------------------------------ set-up */
static int find(const mjModel *m, int type, const char *name, const char *what, char *err, int errlen) {
    int i = mj_name2id(m, type, name);
    if (i < 0) snprintf(err, errlen, "Cassie model has no %s named '%s'", what, name);
    return i;
}

int cc_controller_size(void) { return (int)sizeof(CcController); }
CcMemory *cc_memory_ptr(CcController *c) { return &c->mem; }
CcTargets *cc_targets_ptr(CcController *c) { return &c->targets; }

/* GroundHeight.__init__: the terrain hfield, or the first world-body plane's height (and its
 * slope when the plane is tilted). */
static void ground_setup(CcFixed *f, const mjModel *m) {
    int gid = mj_name2id(m, mjOBJ_GEOM, "terrain");
    f->has_terrain = gid >= 0;
    if (f->has_terrain) {
        int hid = m->geom_dataid[gid];
        f->hf_nrow = m->hfield_nrow[hid];
        f->hf_ncol = m->hfield_ncol[hid];
        f->hf_data = m->hfield_data + m->hfield_adr[hid];
        f->hf_sx = m->hfield_size[4 * hid];
        f->hf_sy = m->hfield_size[4 * hid + 1];
        f->hf_sz = m->hfield_size[4 * hid + 2];
        f->hf_gx = m->geom_pos[3 * gid];
        f->hf_gy = m->geom_pos[3 * gid + 1];
        f->hf_gz = m->geom_pos[3 * gid + 2];
    } else {
        f->flat_m = 0.0;
        f->has_plane = 0;
        for (int g = 0; g < m->ngeom; g++)
            if (m->geom_type[g] == mjGEOM_PLANE && m->geom_bodyid[g] == 0) {
                f->flat_m = m->geom_pos[3 * g + 2];
                mjtNum mat[9];
                mju_quat2Mat(mat, m->geom_quat + 4 * g);
                double nx = mat[2], ny = mat[5], nz = mat[8]; /* the plane's z axis in the world */
                if (nx != 0.0 || ny != 0.0) {
                    f->has_plane = 1;
                    f->pl_x0 = m->geom_pos[3 * g];
                    f->pl_y0 = m->geom_pos[3 * g + 1];
                    f->pl_sx = -nx / nz;
                    f->pl_sy = -ny / nz;
                }
                break;
            }
    }
}

double cc_model_ground_height(const mjModel *m, double x, double y) {
    CcController c;
    memset(&c, 0, sizeof c);
    ground_setup(&c.fx, m);
    return cc_ground_height(&c, x, y);
}

static int resolve_ids(CcController *c, int passive[CC_NSIDES][2], char *err, int errlen) {
    const mjModel *m = c->m;
    CcFixed *f = &c->fx;
    char name[64];
    if ((f->pelvis_body = find(m, mjOBJ_BODY, "cassie-pelvis", "body", err, errlen)) < 0) return -1;
    int js[8], nj = 0;
    for (int j = 0; j < m->njnt && nj < 8; j++)
        if (m->jnt_bodyid[j] == f->pelvis_body) js[nj++] = j;
    if (nj == 1 && m->jnt_type[js[0]] == mjJNT_FREE) {
        f->free_qadr = m->jnt_qposadr[js[0]];
        f->free_dadr = m->jnt_dofadr[js[0]];
    } else if (nj == 4 && m->jnt_type[js[0]] == mjJNT_SLIDE && m->jnt_type[js[1]] == mjJNT_SLIDE
               && m->jnt_type[js[2]] == mjJNT_SLIDE && m->jnt_type[js[3]] == mjJNT_BALL) {
        f->free_qadr = m->jnt_qposadr[js[0]];
        f->free_dadr = m->jnt_dofadr[js[0]];
    } else {
        snprintf(err, errlen, "the pelvis must float on one free joint or x/y/z slides + a ball joint");
        return -1;
    }
    static const char *const passive_names[2] = {"shin", "heel-spring"};
    for (int s = 0; s < CC_NSIDES; s++) {
        for (int j = 0; j < CC_NMOTOR; j++) {
            snprintf(name, sizeof name, "%s-%s", SIDE_NAMES[s], MOTOR_NAMES[j]);
            int jid = find(m, mjOBJ_JOINT, name, "joint", err, errlen);
            int a = find(m, mjOBJ_ACTUATOR, name, "actuator", err, errlen);
            if (jid < 0 || a < 0) return -1;
            f->qadr[s][j] = m->jnt_qposadr[jid];
            f->dadr[s][j] = m->jnt_dofadr[jid];
            f->act[s][j] = a;
            if (j == CC_HIP_PITCH) f->hip_pitch_jid[s] = jid;
            if (j == CC_FOOT) f->foot_jid[s] = jid;
        }
        snprintf(name, sizeof name, "%s-tarsus", SIDE_NAMES[s]);
        int t = find(m, mjOBJ_JOINT, name, "joint", err, errlen);
        if (t < 0) return -1;
        f->qadr[s][CC_NMOTOR] = m->jnt_qposadr[t];
        for (int k = 0; k < 2; k++) {
            snprintf(name, sizeof name, "%s-%s", SIDE_NAMES[s], passive_names[k]);
            int p = find(m, mjOBJ_JOINT, name, "joint", err, errlen);
            if (p < 0) return -1;
            passive[s][k] = m->jnt_qposadr[p];
        }
        snprintf(name, sizeof name, "%s-foot", SIDE_NAMES[s]);
        if ((f->foot_body[s] = find(m, mjOBJ_BODY, name, "body", err, errlen)) < 0) return -1;
        f->foot_geom0[s] = -1;
        for (int g = 0; g < m->ngeom; g++)
            if (m->geom_bodyid[g] == f->foot_body[s] && (m->geom_contype[g] || m->geom_conaffinity[g])) {
                f->foot_geom0[s] = g;
                break;
            }
        if (f->foot_geom0[s] < 0) {
            snprintf(err, errlen, "%s-foot has no collision geom", SIDE_NAMES[s]);
            return -1;
        }
    }
    ground_setup(f, m);
    return 0;
}

int cc_configure_servos(mjModel *m, mjData *d, char *err, int errlen) {
    char name[64];
    for (int s = 0; s < CC_NSIDES; s++)
        for (int j = 0; j < CC_NMOTOR; j++) {
            snprintf(name, sizeof name, "%s-%s", SIDE_NAMES[s], MOTOR_NAMES[j]);
            int a = find(m, mjOBJ_ACTUATOR, name, "actuator", err, errlen);
            if (a < 0) return -1;
            double lo = fabs(m->actuator_ctrlrange[2 * a]), hi = fabs(m->actuator_ctrlrange[2 * a + 1]);
            double lim = m->actuator_gear[6 * a] * (hi > lo ? hi : lo); /* gear * max(|lo|, |hi|) */
            for (int k = 0; k < 6; k++) m->actuator_gear[6 * a + k] = 0.0;
            m->actuator_gear[6 * a] = 1.0;
            m->actuator_gaintype[a] = mjGAIN_FIXED;
            m->actuator_biastype[a] = mjBIAS_AFFINE;
            for (int k = 0; k < mjNGAIN; k++) m->actuator_gainprm[mjNGAIN * a + k] = 0.0;
            m->actuator_gainprm[mjNGAIN * a] = 1.0;
            for (int k = 0; k < mjNBIAS; k++) m->actuator_biasprm[mjNBIAS * a + k] = 0.0;
            m->actuator_ctrllimited[a] = 0;
            m->actuator_forcelimited[a] = 1;
            m->actuator_forcerange[2 * a] = -lim;
            m->actuator_forcerange[2 * a + 1] = lim;
        }
    for (int i = 0; i < m->nu; i++) d->ctrl[i] = 0.0;
    return 0;
}

/* ------------------------------------------------------------------ NominalController */
static void refresh_gait(CcController *c, double dt) {
    CcMemory *mm = &c->mem;
    const CcParams *p = &c->p;
    double a = p->accel_limit_mps2 * dt, tx, ty;
    if (mm->mode != CC_WALK) {
        tx = 0.0;
        ty = 0.0;
    } else {
        tx = mm->vx_des;
        ty = mm->vy_des;
    }
    double nx = mm->vx_ref + py_max(-a, py_min(a, tx - mm->vx_ref));
    double ny = mm->vy_ref + py_max(-a, py_min(a, ty - mm->vy_ref));
    double tw = mm->mode == CC_WALK ? mm->yaw_rate_des : 0.0;
    if (tw != mm->yaw_rate_ref) {
        double aw = p->yaw_accel_limit_radps2 * dt;
        mm->yaw_rate_ref = mm->yaw_rate_ref + py_max(-aw, py_min(aw, tw - mm->yaw_rate_ref));
    }
    if (nx != mm->vx_ref || ny != mm->vy_ref || !c->has_gait) {
        mm->vx_ref = nx;
        mm->vy_ref = ny;
        c->gait = lookup(c->gaits, nx, ny);
        c->has_gait = 1;
    }
}

void cc_set_command(CcController *c, double vx, double vy, double yaw_rate, const CcGaitLibrary *lib) {
    c->mem.vx_des = vx;
    c->mem.vy_des = vy;
    c->gaits = lib ? lib : &cc_library_gait;
    c->mem.yaw_rate_des = yaw_rate;
    c->has_gait = 0;
    refresh_gait(c, 0.0);
}

int cc_set_offsets(CcController *c, const double *offsets) {
    for (int k = 0; k < CC_NOFFSETS; k++)
        if (!isfinite(offsets[k])) return -1;
    memcpy(c->mem.offsets, offsets, sizeof c->mem.offsets);
    return 0;
}

void cc_memory_restored(CcController *c) {
    c->gait = lookup(c->gaits, c->mem.vx_ref, c->mem.vy_ref);
    c->has_gait = 1;
}

typedef struct {
    double t, pitch, roll, roll_rate, pitch_rate, yaw_rate, yaw_err;
    double q[CC_NSIDES][CC_NMOTOR + 1], qd[CC_NSIDES][CC_NMOTOR];
} Sensed;

static double low_pass(double filtered, double value, double dt, double tau_s) {
    double a = dt > 0 ? dt / (tau_s + dt) : 0.0;
    return filtered + a * (value - filtered);
}

static double neutral_angle(double speed, double step_time_s, double leg_length_m) {
    return asin(py_max(-MAX_STEP_SINE, py_min(MAX_STEP_SINE, speed * step_time_s / (2 * leg_length_m))));
}

static const mjtNum *anchor(const CcController *c, int jid) { return c->d->xanchor + 3 * jid; }

static void leg_angles(const CcController *c, int side, double yaw, double out[2]) {
    const mjtNum *f = anchor(c, c->fx.foot_jid[side]), *h = anchor(c, c->fx.hip_pitch_jid[side]);
    double v0 = f[0] - h[0], v1 = f[1] - h[1], v2 = f[2] - h[2];
    double cy = cos(yaw), s = sin(yaw);
    double fx = cy * v0 + s * v1, fy = -s * v0 + cy * v1;
    out[0] = atan2(fx, -v2);
    out[1] = atan2(fy, -v2);
}

static int swing_side(const CcController *c) { return c->mem.stance == CC_LEFT ? CC_RIGHT : CC_LEFT; }

static void start_step(CcController *c, double t, double yaw, int new_stance) {
    CcMemory *mm = &c->mem;
    const mjtNum *q = c->d->qpos + c->fx.free_qadr;
    double x = q[0], y = q[1];
    double dt = t - mm->t_step_start;
    if (mm->mode == CC_WALK && dt > MIN_STEP_DURATION_S) {
        double dx = x - mm->step_start_xy[0], dy = y - mm->step_start_xy[1];
        mm->vx_step_avg = (cos(yaw) * dx + sin(yaw) * dy) / dt;
        mm->step_index += 1;
    }
    mm->step_start_xy[0] = x;
    mm->step_start_xy[1] = y;
    mm->t_step_start = t;
    mm->stance = new_stance;
    leg_angles(c, swing_side(c), yaw, mm->swing_start);
}

static void advance_phase(CcController *c, double t, double yaw) {
    CcMemory *mm = &c->mem;
    const CcParams *p = &c->p;
    if (mm->mode == CC_STAND && t >= p->stand_time_s) mm->mode = CC_SHIFT;
    if (mm->mode == CC_SHIFT && t >= p->stand_time_s + p->shift_time_s) {
        start_step(c, t, yaw, p->first_stance);
        mm->mode = CC_WALK;
    }
    if (mm->mode != CC_WALK) {
        mm->tau = 0.0;
        return;
    }
    mm->tau = (t - mm->t_step_start) / c->gait.step_time_s;
    int touchdown = 0;
    if (mm->tau > p->switch_min_tau) {
        double f[2];
        cc_foot_forces(c, f);
        double swing, stance;
        if (swing_side(c) == CC_LEFT) {
            swing = f[0];
            stance = f[1];
        } else {
            swing = f[1];
            stance = f[0];
        }
        touchdown = swing > p->touchdown_force_n || (swing > p->touchdown_share_min_force_n && swing >= stance);
    }
    if (touchdown || mm->tau >= p->switch_max_tau) {
        start_step(c, t, yaw, swing_side(c));
        mm->tau = 0.0;
    }
}

static double sense(CcController *c, Sensed *sd) {
    CcMemory *mm = &c->mem;
    const CcParams *p = &c->p;
    double t = c->d->time, hs[8];
    cc_heading_state(c, hs);
    double yaw = hs[0];
    double dt = py_max(t - mm->last_t, 0.0);
    mm->last_t = t;
    if (mm->yaw_rate_ref != 0.0) mm->yaw_ref = remainder(mm->yaw_ref + mm->yaw_rate_ref * dt, TAU_2PI);
    double yaw_err = remainder(yaw - mm->yaw_ref, TAU_2PI);
    mm->vy_filt = low_pass(mm->vy_filt, hs[4], dt, p->vy_filter_tau_s);
    mm->vx_filt = low_pass(mm->vx_filt, hs[3], dt, p->vx_filter_tau_s);
    refresh_gait(c, dt);
    for (int s = 0; s < CC_NSIDES; s++) {
        for (int j = 0; j <= CC_NMOTOR; j++) sd->q[s][j] = c->d->qpos[c->fx.qadr[s][j]];
        for (int j = 0; j < CC_NMOTOR; j++) sd->qd[s][j] = c->d->qvel[c->fx.dadr[s][j]];
    }
    sd->t = t;
    sd->pitch = hs[1];
    sd->roll = hs[2];
    sd->roll_rate = hs[5];
    sd->pitch_rate = hs[6];
    sd->yaw_rate = hs[7];
    sd->yaw_err = yaw_err;
    return yaw;
}

static void default_targets(CcController *c, const Sensed *sd, CcTargets *tg) {
    for (int s = 0; s < CC_NSIDES; s++)
        for (int j = 0; j < CC_NMOTOR; j++) {
            tg->q[s][j] = sd->q[s][j];
            tg->qd[s][j] = 0.0;
            tg->ff[s][j] = 0.0;
            tg->kp[s][j] = c->p.kp[j];
            tg->kd[s][j] = c->p.kd[j];
        }
}

static double level_foot(const CcController *c, const double *q_leg, double pitch) {
    return c->fx.foot_flat_sum + pitch - q_leg[CC_HIP_PITCH] - q_leg[CC_KNEE] - q_leg[CC_NMOTOR];
}

static void stance_targets(CcController *c, CcTargets *tg, const Sensed *sd, int s, double share,
                           double shift_roll) {
    const CcParams *p = &c->p;
    const double *off = c->mem.offsets;
    const double *q = sd->q[s], *qd = sd->qd[s];
    tg->q[s][CC_HIP_PITCH] = (q[CC_HIP_PITCH] - (sd->pitch - c->gait.torso_pitch_des_rad)) - off[CC_D_STANCE_HIP_PITCH];
    tg->qd[s][CC_HIP_PITCH] = qd[CC_HIP_PITCH] - sd->pitch_rate;
    tg->kp[s][CC_HIP_PITCH] = p->torso_pitch_kp * share;
    tg->kd[s][CC_HIP_PITCH] = p->torso_pitch_kd * share;
    tg->q[s][CC_HIP_ROLL] = q[CC_HIP_ROLL] + sd->roll + off[CC_D_STANCE_HIP_ROLL] + shift_roll;
    tg->qd[s][CC_HIP_ROLL] = qd[CC_HIP_ROLL] + sd->roll_rate;
    tg->kp[s][CC_HIP_ROLL] = p->torso_roll_kp * share;
    tg->kd[s][CC_HIP_ROLL] = p->torso_roll_kd * share;
    if (share == SINGLE_SUPPORT_SHARE) tg->ff[s][CC_HIP_ROLL] = p->stance_hip_roll_ff_nm * (s == CC_LEFT ? 1.0 : -1.0);
    tg->q[s][CC_KNEE] = c->fx.stance_knee[s] + off[CC_D_STANCE_KNEE];
    tg->ff[s][CC_KNEE] = p->stance_knee_ff_nm * share;
    tg->q[s][CC_HIP_YAW] = q[CC_HIP_YAW] + sd->yaw_err;
    tg->qd[s][CC_HIP_YAW] = qd[CC_HIP_YAW] + sd->yaw_rate - c->mem.yaw_rate_ref;
    tg->q[s][CC_FOOT] = q[CC_FOOT];
    tg->kp[s][CC_FOOT] = 0.0;
    tg->kd[s][CC_FOOT] = 0.0;
}

static void standing_targets(CcController *c, CcTargets *tg, const Sensed *sd, double yaw) {
    const CcParams *p = &c->p;
    const mjData *d = c->d;
    const mjtNum *com = d->subtree_com + 3 * c->fx.pelvis_body, *vcom = d->subtree_linvel + 3 * c->fx.pelvis_body;
    const mjtNum *fl = d->geom_xpos + 3 * c->fx.foot_geom0[CC_LEFT], *fr = d->geom_xpos + 3 * c->fx.foot_geom0[CC_RIGHT];
    double feet0 = 0.5 * (fl[0] + fr[0]), feet1 = 0.5 * (fl[1] + fr[1]);
    double cy = cos(yaw), s_ = sin(yaw);
    double ex = cy * (com[0] - feet0) + s_ * (com[1] - feet1);
    double evx = cy * vcom[0] + s_ * vcom[1];
    double shift = 0.0;
    if (c->mem.mode == CC_SHIFT) {
        double r = py_min(1.0, (sd->t - p->stand_time_s) / py_max(p->shift_time_s * SHIFT_RAMP_FRACTION, MIN_SHIFT_RAMP_S));
        double side = p->first_stance == CC_LEFT ? 1.0 : -1.0;
        shift = side * p->shift_distance_m * (3 * r * r - 2 * r * r * r);
    }
    double ey = -s_ * (com[0] - feet0) + cy * (com[1] - feet1);
    double evy = -s_ * vcom[0] + cy * vcom[1];
    double shift_roll = -(p->stand_lat_kp * (shift - ey) - p->stand_lat_kd * evy);
    for (int s = 0; s < CC_NSIDES; s++) {
        stance_targets(c, tg, sd, s, DOUBLE_SUPPORT_SHARE, shift_roll);
        tg->q[s][CC_FOOT] = level_foot(c, sd->q[s], sd->pitch);
        tg->kp[s][CC_FOOT] = p->kp[CC_FOOT];
        tg->kd[s][CC_FOOT] = p->kd[CC_FOOT];
        tg->ff[s][CC_FOOT] = -(p->stand_com_kp * ex + p->stand_com_kd * evx);
    }
}

static void landing_angles(const CcController *c, double *theta, double *phi) {
    const CcParams *p = &c->p;
    const CcMemory *mm = &c->mem;
    const CcGait *g = &c->gait;
    double step_time_s = g->step_time_s, leg_length_m = p->stance_leg_length_m;
    double v_np = mm->vx_ref + p->neutral_point_blend * (mm->vx_filt - mm->vx_ref);
    *theta = (neutral_angle(v_np, step_time_s, leg_length_m) + g->leg_angle_offset_rad + mm->offsets[CC_D_SWING_HIP_PITCH]);
    double side = swing_side(c) == CC_LEFT ? 1.0 : -1.0;
    *phi = (neutral_angle(mm->vy_ref, step_time_s, leg_length_m) + g->lateral_offset_rad + side * g->step_width_rad
            + mm->offsets[CC_D_SWING_HIP_ROLL] + p->lateral_speed_gain * (mm->vy_filt - mm->vy_ref)
            + p->turn_lateral_gain * mm->vx_ref * mm->yaw_rate_ref);
}

static void swing_foot_xy(const CcController *c, const mjtNum *hip, double theta, double phi, double yaw_err,
                          double *gx, double *gy) {
    double yaw = c->mem.yaw_ref + yaw_err;
    double cy = cos(yaw), s = sin(yaw);
    double reach = c->p.stance_leg_length_m;
    double fx = reach * sin(theta), fy = reach * sin(phi);
    *gx = hip[0] + cy * fx - s * fy;
    *gy = hip[1] + s * fx + cy * fy;
}

static void walking_targets(CcController *c, CcTargets *tg, const Sensed *sd) {
    const CcParams *p = &c->p;
    const CcMemory *mm = &c->mem;
    const CcGait *g = &c->gait;
    const CcGaitLibrary *lib = c->gaits;
    int sw = swing_side(c);
    stance_targets(c, tg, sd, mm->stance, SINGLE_SUPPORT_SHARE, 0.0);
    double b = bezier(lib->swing_shape, lib->n_swing_shape, mm->tau / lib->swing_end_tau);
    double theta_f, phi_f;
    landing_angles(c, &theta_f, &phi_f);
    double theta0 = mm->swing_start[0], phi0 = mm->swing_start[1];
    double theta = theta0 + (theta_f - theta0) * b;
    double phi = phi0 + (phi_f - phi0) * b;
    double height = bezier(lib->swing_height, lib->n_swing_height, mm->tau / lib->height_end_tau);
    const mjtNum *hip = anchor(c, c->fx.hip_pitch_jid[sw]);
    double gx, gy;
    swing_foot_xy(c, hip, theta, phi, sd->yaw_err, &gx, &gy);
    double z_ankle = cc_ground_height(c, gx, gy) + c->fx.ankle_height0 + height;
    double length = (hip[2] - z_ankle) / py_max(cos(theta) * cos(phi), MIN_LEG_COS);
    length = py_min(py_max(length, p->swing_leg_min_length_m), p->swing_leg_max_length_m);
    double knee = knee_for_length(c, sw, length);
    tg->q[sw][CC_KNEE] = knee + mm->offsets[CC_D_SWING_KNEE] * b;
    tg->q[sw][CC_HIP_PITCH] = theta + sd->pitch - angle_offset(c, sw, knee);
    tg->q[sw][CC_HIP_ROLL] = phi - sd->roll;
    tg->q[sw][CC_HIP_YAW] = -sd->yaw_err + 0.5 * mm->yaw_rate_ref * g->step_time_s;
    tg->q[sw][CC_FOOT] = level_foot(c, sd->q[sw], sd->pitch);
    (void)g;
}

static void write_servos(CcController *c, const CcTargets *tg) {
    for (int s = 0; s < CC_NSIDES; s++)
        for (int j = 0; j < CC_NMOTOR; j++) {
            int a = c->fx.act[s][j];
            double ctrl = tg->kp[s][j] * tg->q[s][j] + tg->kd[s][j] * tg->qd[s][j] + tg->ff[s][j];
            c->m->actuator_biasprm[mjNBIAS * a + 1] = -tg->kp[s][j];
            c->m->actuator_biasprm[mjNBIAS * a + 2] = -tg->kd[s][j];
            c->d->ctrl[a] = ctrl;
        }
}

void cc_update(CcController *c) {
    Sensed sd;
    double yaw = sense(c, &sd);
    advance_phase(c, sd.t, yaw);
    CcTargets *tg = &c->targets;
    default_targets(c, &sd, tg);
    if (c->mem.mode == CC_STAND || c->mem.mode == CC_SHIFT)
        standing_targets(c, tg, &sd, yaw);
    else
        walking_targets(c, tg, &sd);
    write_servos(c, tg);
}

void cc_advance(CcController *c, long n, int *substep) {
    int sub = c->p.control_substeps;
    while (n > 0) {
        long k = sub - *substep < n ? sub - *substep : n;
        for (long i = 0; i < k; i++) mj_step(c->m, c->d);
        n -= k;
        *substep += (int)k;
        if (*substep >= sub) {
            *substep = 0;
            cc_update(c);
        }
    }
}

int cc_fallen(const CcController *c, double height_m, double tilt_rad) {
    const mjModel *m = c->m;
    const mjData *d = c->d;
    for (int i = 0; i < m->nq; i++)
        if (!isfinite(d->qpos[i])) return 1;
    for (int i = 0; i < m->nv; i++)
        if (!isfinite(d->qvel[i])) return 1;
    const mjtNum *q = d->qpos + c->fx.free_qadr;
    if (q[2] - cc_ground_height(c, q[0], q[1]) < height_m) return 1;
    double zz = d->xmat[9 * c->fx.pelvis_body + 8];
    return acos(zz > 1.0 ? 1.0 : (zz < -1.0 ? -1.0 : zz)) > tilt_rad;
}

void cc_sense(const CcController *c, double out[CC_NSENSE]) {
    const CcMemory *mm = &c->mem;
    const mjtNum *q = c->d->qpos + c->fx.free_qadr;
    cc_heading_state(c, out);
    cc_foot_forces(c, out + 8);
    out[10] = q[0];
    out[11] = q[1];
    out[12] = q[2];
    out[13] = c->d->time;
    out[14] = mm->vx_step_avg;
    out[15] = mm->vy_filt;
    out[16] = (double)mm->step_index;
    out[17] = mm->stance == CC_LEFT ? 0.0 : 1.0;
    out[18] = mm->tau;
}

int cc_init(CcController *c, mjModel *m, mjData *d, const CcParams *p, char *err, int errlen) {
    memset(c, 0, sizeof *c);
    c->m = m;
    c->m_const = m;
    c->d = d;
    c->p = p ? *p : cc_default_params;
    if (c->p.control_substeps < 1 || c->p.first_stance < 0 || c->p.first_stance >= CC_NSIDES) {
        snprintf(err, errlen, "control_substeps must be >= 1 and first_stance 0 (left) or 1 (right)");
        return -1;
    }
    int passive[CC_NSIDES][2];
    if (resolve_ids(c, passive, err, errlen)) return -1;
    for (int s = 0; s < CC_NSIDES; s++)
        if (leg_kinematics(c, s, passive[s], err, errlen)) return -1;
    CcFixed *f = &c->fx;
    const int *la = f->qadr[CC_LEFT];
    f->foot_flat_sum = d->qpos[la[CC_HIP_PITCH]] + d->qpos[la[CC_KNEE]] + d->qpos[la[CC_NMOTOR]] + d->qpos[la[CC_FOOT]];
    f->ankle_height0 = 0.5 * (anchor(c, f->foot_jid[CC_LEFT])[2] + anchor(c, f->foot_jid[CC_RIGHT])[2]);
    CcMemory *mm = &c->mem;
    mm->mode = CC_STAND;
    mm->stance = c->p.first_stance;
    mm->step_start_xy[0] = d->qpos[f->free_qadr];
    mm->step_start_xy[1] = d->qpos[f->free_qadr + 1];
    mm->last_t = d->time;
    double hs[8];
    cc_heading_state(c, hs);
    mm->yaw_ref = hs[0];
    for (int s = 0; s < CC_NSIDES; s++) f->stance_knee[s] = knee_for_length(c, s, c->p.stance_leg_length_m);
    c->gaits = &cc_default_gait;
    c->has_gait = 0;
    cc_update(c);
    return 0;
}
