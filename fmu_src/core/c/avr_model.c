/*
 * The regulator's numerics (see avr_model.h).  Each function mirrors the numpy core's
 * function of the same purpose, operation for operation and in the same order, using
 * only +, -, *, /, sqrt and frexp-by-bits (each exact or correctly rounded by IEEE 754;
 * no libm log1p/expm1/hypot, whose last bits differ between C libraries).  So with
 * IEEE float64, no FMA contraction (-ffp-contract=off) and no -ffast-math, the networks
 * and every call give the same bits as avr_core, on every machine (see avr_network's
 * docstring for the numpy side).
 */
#include "avr_model.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The element-wise loops also get an AVX2 clone where GCC can pick one at load time (ELF
 * ifunc): the same IEEE operations in the same order (no FMA contraction), four lanes wide. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && !defined(AVR_NO_CLONES)
#define VECTOR_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define VECTOR_CLONES
#endif

#define TAU_RATIO (AVR_TAU_REF / AVR_TAU_RC)
#define INV_TAU_RC (1.0 / AVR_TAU_RC)
#define SPLITMIX_GAMMA UINT64_C(0x9E3779B97F4A7C15)

static const int DIMS[AVR_N_NETS] = {2, 2, 4};
static const int FIRST_INPUT[AVR_N_NETS] = {0, 2, 4};

/* ---- random numbers (avr_network.SplitMix64) ------------------------------------------ */
uint64_t avr_splitmix64_mix(uint64_t z) {
    z = (z ^ (z >> 30)) * UINT64_C(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94D049BB133111EB);
    return z ^ (z >> 31);
}

double avr_uniform(uint64_t key, uint64_t index) {
    return (double)(avr_splitmix64_mix(key + index * SPLITMIX_GAMMA) >> 11) * 0x1p-53;
}

static uint64_t stream_key(uint32_t seed, int net, int field) {
    return avr_splitmix64_mix(16u * (uint64_t)seed + 4u * (uint64_t)net + (uint64_t)field);
}

/* avr_network.sphere_encoders: rejection from the cube, candidates in stream order. */
static void sphere_encoders(uint64_t key, int n, int d, double *out) {
    uint64_t index = 0;
    for (int have = 0; have < n;) {
        double v[4] = {0.0, 0.0, 0.0, 0.0};
        for (int j = 0; j < d; ++j) v[j] = 2.0 * avr_uniform(key, ++index) - 1.0;
        double r2 = v[0] * v[0];
        for (int j = 1; j < d; ++j) r2 = r2 + v[j] * v[j];
        if (r2 > 0.0 && r2 <= 1.0) {
            double norm = sqrt(r2);
            for (int j = 0; j < d; ++j) out[(size_t)have * d + j] = v[j] / norm;
            ++have;
        }
    }
}

static void uniform_range(uint64_t key, int n, double lo, double hi, double *out) {
    for (int i = 0; i < n; ++i) out[i] = lo + (hi - lo) * avr_uniform(key, (uint64_t)i + 1);
}

/* ---- fixed elementary functions (avr_network.expm1_fixed, log1p_fixed) ----------------- */

/* exp(x) - 1 for 0 <= x <= 1: sum_{i=1..20} x^i / i! by Horner, the 1/i! as in
 * avr_network._series_coefficients (20! is exact in a double). */
static double expm1_fixed(double x) {
    double coef[20], factorial = 1.0;
    for (int i = 1; i <= 20; ++i) {
        factorial = factorial * i;
        coef[i - 1] = 1.0 / factorial;
    }
    double total = coef[19] * x;
    for (int i = 18; i >= 0; --i) total = (total + coef[i]) * x;
    return total;
}

/* log(1 + y) for finite y >= 0: u = 1 + y = m' 2^k with m' in [1/2, 1) (from u's bits,
 * exact for u >= 1); m = m' sqrt2; s = (m - 1) / (m + 1); log u = (k - 1/2) ln2 +
 * s (2 + sum_{i=1..9} 2/(2i+1) s^(2i)), Horner in s^2.  Straight-line code (no calls,
 * no branches) so that the rate loop below vectorizes. */
static inline double log1p_fixed(double y) {
    double u = 1.0 + y, m, k;
    uint64_t bits, m_bits, k_bits;
    memcpy(&bits, &u, sizeof bits);
    m_bits = (bits & UINT64_C(0x000FFFFFFFFFFFFF)) | UINT64_C(0x3FE0000000000000); /* m' in [1/2, 1) */
    k_bits = (bits >> 52) | UINT64_C(0x4330000000000000); /* 2^52 + biased exponent, exactly */
    memcpy(&m, &m_bits, sizeof m);
    memcpy(&k, &k_bits, sizeof k);
    k = k - (0x1p52 + 1022.0); /* exact; an int-to-double conversion would not vectorize with AVX2 */
    m = m * AVR_SQRT2;
    double s = (m - 1.0) / (m + 1.0), z = s * s;
    double tail = (2.0 / 19.0) * z;
    tail = (tail + 2.0 / 17.0) * z;
    tail = (tail + 2.0 / 15.0) * z;
    tail = (tail + 2.0 / 13.0) * z;
    tail = (tail + 2.0 / 11.0) * z;
    tail = (tail + 2.0 / 9.0) * z;
    tail = (tail + 2.0 / 7.0) * z;
    tail = (tail + 2.0 / 5.0) * z;
    tail = (tail + 2.0 / 3.0) * z;
    return (k - 0.5) * AVR_LN2 + (tail + 2.0) * s;
}

/* ---- networks (avr_network._make_network, lif_gain_bias, Networks) ------------------------ */
static void make_network(AvrNetworks *net, int k) {
    int n = net->n, d = DIMS[k];
    sphere_encoders(stream_key(net->seed, k, 0), n, d, net->encoders[k]);
    uniform_range(stream_key(net->seed, k, 1), n, AVR_MAX_RATE_LO_HZ, AVR_MAX_RATE_HI_HZ, net->max_rates[k]);
    uniform_range(stream_key(net->seed, k, 2), n, AVR_INTERCEPT_LO, AVR_INTERCEPT_HI, net->intercepts[k]);
    for (int i = 0; i < n; ++i) {
        double j_max_minus_1 = 1.0 / expm1_fixed((1.0 / net->max_rates[k][i] - AVR_TAU_REF) / AVR_TAU_RC);
        double gain = j_max_minus_1 / (1.0 - net->intercepts[k][i]);
        net->gain[k][i] = gain;
        net->bias[k][i] = 1.0 - gain * net->intercepts[k][i];
        net->bias_m1[(size_t)k * n + i] = net->bias[k][i] - 1.0;
        for (int j = 0; j < d; ++j)
            net->scaled_t[(size_t)(FIRST_INPUT[k] + j) * n + i] = net->encoders[k][(size_t)i * d + j] * gain;
    }
}

AvrNetworks *avr_networks_new(int n, uint32_t seed) {
    if (n < 1) return NULL;
    size_t per_net = 0;
    for (int k = 0; k < AVR_N_NETS; ++k) per_net += (size_t)n * (DIMS[k] + 4);
    size_t total = per_net + (size_t)n * (AVR_N_INPUTS + AVR_N_NETS);
    AvrNetworks *net = calloc(1, sizeof *net);
    double *block = calloc(total, sizeof *block);
    if (net == NULL || block == NULL) {
        free(net);
        free(block);
        return NULL;
    }
    net->n = n;
    net->seed = seed;
    double *p = block;
    for (int k = 0; k < AVR_N_NETS; ++k) {
        net->encoders[k] = p, p += (size_t)n * DIMS[k];
        net->max_rates[k] = p, p += n;
        net->intercepts[k] = p, p += n;
        net->gain[k] = p, p += n;
        net->bias[k] = p, p += n;
    }
    net->scaled_t = p, p += (size_t)n * AVR_N_INPUTS;
    net->bias_m1 = p;
    for (int k = 0; k < AVR_N_NETS; ++k) make_network(net, k);
    return net;
}

void avr_networks_free(AvrNetworks *net) {
    if (net == NULL) return;
    free(net->encoders[0]); /* the start of the one block */
    free(net);
}

int avr_core_init(AvrCore *core, int n) {
    memset(core, 0, sizeof *core);
    core->weights = calloc((size_t)AVR_N_ROWS * n, sizeof(double));
    core->rates = calloc((size_t)AVR_N_NETS * n, sizeof(double));
    core->active = calloc((size_t)AVR_N_NETS * n, sizeof(int));
    core->currents = calloc((size_t)n, sizeof(double));
    if (core->weights == NULL || core->rates == NULL || core->active == NULL || core->currents == NULL) {
        avr_core_free(core);
        return -1;
    }
    core->n = n;
    core->last_step_index = -1;
    return 0;
}

void avr_core_free(AvrCore *core) {
    free(core->weights);
    free(core->rates);
    free(core->active);
    free(core->currents);
    core->weights = core->rates = core->currents = NULL;
    core->active = NULL;
    core->n = 0;
}

/* ---- one call (avr_regulator.step) -------------------------------------------------------- */
#define V(name) values[AVR_VR_##name]

/* v[0..d-1] divided by their norm if it exceeds 1; the norm is sqrt(((v0 v0 + v1 v1) + v2 v2) + ...)
 * (avr_network._into_unit_ball; no overflow: inputs and scales are range-checked, |v| <= 1e4). */
static void into_unit_ball(double *v, int d) {
    double norm2 = v[0] * v[0];
    for (int i = 1; i < d; ++i) norm2 = norm2 + v[i] * v[i];
    double norm = sqrt(norm2);
    if (norm > 1.0)
        for (int i = 0; i < d; ++i) v[i] = v[i] / norm;
}

/* The 8 network inputs, scaled and radially projected into the unit ball (avr_network.scaled_inputs). */
static void network_inputs(const double *values, double x[AVR_N_INPUTS]) {
    double vs = V(velocity_scale_mps), sa = V(angle_scale_rad), sr = V(rate_scale_radps);
    x[0] = V(vx) / vs, x[1] = V(vx_des) / vs;
    x[2] = V(vy) / vs, x[3] = V(vy_des) / vs;
    x[4] = V(pitch) / sa, x[5] = V(roll) / sa, x[6] = V(pitch_rate) / sr, x[7] = V(roll_rate) / sr;
    into_unit_ball(x, 2);
    into_unit_ball(x + 2, 2);
    into_unit_ball(x + 4, 4);
}

/* The active neurons of network k for input x and their tau_rc * LIF rates
 * (avr_network.lif_rates_times_tau_rc): indices into active[], rates into rates[]; returns
 * their number.  The currents are computed for all n; the active ones are packed
 * branch-free, then their rates computed in one straight loop that the compiler
 * vectorizes: no unpredictable branch per neuron, no work for silent ones. */
VECTOR_CLONES static int network_rates(const AvrNetworks *net, int k, const double x[AVR_N_INPUTS],
                                       double *restrict cur, double *restrict rates, int *restrict active) {
    int n = net->n;
    const double *restrict bias_m1 = net->bias_m1 + (size_t)k * n;
    const double *restrict e0 = net->scaled_t + (size_t)FIRST_INPUT[k] * n;
    const double *restrict e1 = e0 + n;
    double x0 = x[FIRST_INPUT[k]], x1 = x[FIRST_INPUT[k] + 1];
    if (DIMS[k] == 2) {
        for (int i = 0; i < n; ++i) cur[i] = x0 * e0[i] + x1 * e1[i] + bias_m1[i];
    } else {
        const double *restrict e2 = e1 + n, *restrict e3 = e2 + n;
        double x2 = x[FIRST_INPUT[k] + 2], x3 = x[FIRST_INPUT[k] + 3];
        for (int i = 0; i < n; ++i) cur[i] = x0 * e0[i] + x1 * e1[i] + x2 * e2[i] + x3 * e3[i] + bias_m1[i];
    }
    int m = 0;
    for (int i = 0; i < n; ++i) { /* j = J - 1 > 0: active */
        rates[m] = cur[i];
        active[m] = i;
        m += cur[i] > 0.0;
    }
    for (int i = 0; i < m; ++i) {
        double j = rates[i] > 1e-300 ? rates[i] : 1e-300;
        rates[i] = 1.0 / (log1p_fixed(1.0 / j) + TAU_RATIO);
    }
    return m;
}

static const int NET_OF_ROW[AVR_N_ROWS] = {0, 1, 2, 2};

/* sum over the active neurons of network k of w[i] * rate[i], in increasing i: the dense
 * sum without its zero terms. */
static double sparse_dot(const AvrCore *core, int k, const double *restrict w) {
    const double *restrict rates = core->rates + (size_t)k * core->n;
    const int *restrict active = core->active + (size_t)k * core->n;
    double sum = 0.0;
    for (int i = 0; i < core->n_active[k]; ++i) sum += w[active[i]] * rates[i];
    return sum;
}

/* The factor every weight is scaled by before a call's PES step (avr_regulator._leak_factor). */
static double leak_factor(double leakage, double dt) {
    if (leakage == 0.0) return 1.0;
    double amount = leakage * dt;
    return amount < 1.0 ? 1.0 - amount : 0.0;
}

/* w[i] * keep + 0.0 for every weight of a row (+ 0.0: an underflow gives +0.0, as the numpy core). */
VECTOR_CLONES static void leak_row(double *restrict w, int n, double keep) {
    for (int i = 0; i < n; ++i) w[i] = w[i] * keep + 0.0;
}

/* |h|^2 of network k's rates, summed in neuron order over the active neurons. */
static double rates_squared(const AvrCore *core, int k) {
    const double *restrict rates = core->rates + (size_t)k * core->n;
    double squares = 0.0;
    for (int i = 0; i < core->n_active[k]; ++i) squares += rates[i] * rates[i];
    return squares;
}

/* Learning with anti-windup (avr_regulator._adapt, _pes_update): raw = unsaturated outputs.
 * A silent neuron's weight would change by coef * 0: it is left as it is.  The remedy
 * against drift (off at 0): the leak before the PES step. */
static void learn(AvrCore *core, const double *values, double dt, const double dots[AVR_N_ROWS],
                  const double raw[AVR_N_ROWS]) {
    int n = core->n;
    double alpha = -V(learning_rate) * dt / (double)n * INV_TAU_RC;
    double lim = V(psi_limit);
    /* x and pitch: this call's error; y and roll: the stride error (avr_regulator._learning_errors) */
    int ready = core->stride_boundaries >= AVR_STRIDE_READY;
    double e_y = ready ? V(vy_des) - 0.5 * (core->vy_mean_prev + core->vy_mean_last) : 0.0;
    double e_roll = ready ? V(roll_des) - 0.5 * (core->roll_mean_prev + core->roll_mean_last) : 0.0;
    double e_x = V(vx_des) - V(vx);
    if ((double)core->settled_steps < V(learn_settled_steps)) e_x = e_y = 0.0; /* waiting for a settled command */
    double err[AVR_N_ROWS] = {e_x, e_y, V(pitch_des) - V(pitch), e_roll};
    double keep = leak_factor(V(leakage_per_s), dt);
    /* leakage_mode 1 (avr_regulator._keep_current_output): coef + amount (w . h) / |h|^2 for a row
     * w reading rates h, so that after the leak w -> (1 - amount) w the part of w along h is back
     * and the row's output at this call is kept; a network with no active neuron adds nothing. */
    int keep_output = keep != 1.0 && V(leakage_mode) == 1.0;
    double squares[AVR_N_NETS];
    if (keep_output)
        for (int k = 0; k < AVR_N_NETS; ++k) squares[k] = rates_squared(core, k);
    for (int r = 0; r < AVR_N_ROWS; ++r) {
        int saturated_outward = (raw[r] >= lim || raw[r] <= -lim) && raw[r] * err[r] < 0.0;
        double coef = saturated_outward ? 0.0 : alpha * err[r];
        double *restrict w = core->weights + (size_t)r * n;
        int k = NET_OF_ROW[r];
        if (keep_output && squares[k] != 0.0) coef = coef + ((1.0 - keep) * dots[r]) / squares[k];
        if (keep != 1.0) leak_row(w, n, keep);
        if (coef == 0.0) continue;
        const double *restrict rates = core->rates + (size_t)k * n;
        const int *restrict active = core->active + (size_t)k * n;
        for (int i = 0; i < core->n_active[k]; ++i) w[active[i]] = coef * rates[i] + w[active[i]];
    }
}

/* Saturated network outputs psi (x, y, pitch, roll) from the weights before this call's update. */
static void network_outputs(AvrCore *core, const AvrNetworks *net, double *values, double dt, int64_t si,
                            double psi[AVR_N_ROWS]) {
    double x[AVR_N_INPUTS];
    int n = net->n;
    network_inputs(values, x);
    for (int k = 0; k < AVR_N_NETS; ++k)
        core->n_active[k] = network_rates(net, k, x, core->currents, core->rates + (size_t)k * n,
                                          core->active + (size_t)k * n);
    double dots[AVR_N_ROWS], raw[AVR_N_ROWS];
    for (int r = 0; r < AVR_N_ROWS; ++r) {
        dots[r] = sparse_dot(core, NET_OF_ROW[r], core->weights + (size_t)r * n);
        raw[r] = dots[r] * INV_TAU_RC;
    }
    double lim = V(psi_limit);
    for (int r = 0; r < AVR_N_ROWS; ++r) psi[r] = raw[r] > lim ? lim : (raw[r] < -lim ? -lim : raw[r]);
    if (V(learning_rate) != 0.0 && si >= (int64_t)V(learn_from_step)) learn(core, values, dt, dots, raw);
}

/* The safety bound +-delta_limit_rad on the six joint offsets (as the numpy core: values
 * inside pass unchanged, bit for bit; 0 - limit, not -limit, so a limit of 0 gives +0.0). */
static void clip_offsets(double *values, double limit) {
    static const int offsets[] = {AVR_VR_delta_swing_hip_pitch, AVR_VR_delta_swing_knee,
                                  AVR_VR_delta_swing_hip_roll, AVR_VR_delta_stance_hip_roll,
                                  AVR_VR_delta_stance_hip_pitch, AVR_VR_delta_stance_knee};
    double hi = limit, lo = 0.0 - limit;
    for (size_t i = 0; i < sizeof offsets / sizeof offsets[0]; ++i) {
        double v = values[offsets[i]];
        values[offsets[i]] = v > hi ? hi : (v < lo ? lo : v);
    }
}

/* The stride accumulators (avr_regulator._advance_stride): at a change of step_index the step
 * that ends is closed if it was seen from its start; this call starts the new step's sums. */
static void advance_stride(AvrCore *c, int64_t si, double vy, double roll) {
    if (si == c->last_step_index) {
        if (c->stride_calls < AVR_MAX_CALLS) c->stride_calls += 1; /* as avr_regulator: stops at MAX_CALLS */
        c->stride_sum_vy = c->stride_sum_vy + vy;
        c->stride_sum_roll = c->stride_sum_roll + roll;
        return;
    }
    if (c->stride_boundaries >= 2) {
        double calls = (double)c->stride_calls;
        c->vy_mean_prev = c->vy_mean_last, c->vy_mean_last = c->stride_sum_vy / calls;
        c->roll_mean_prev = c->roll_mean_last, c->roll_mean_last = c->stride_sum_roll / calls;
    }
    if (c->stride_boundaries < AVR_STRIDE_READY) c->stride_boundaries += 1;
    c->stride_calls = 1;
    c->stride_sum_vy = vy, c->stride_sum_roll = roll;
}

/* value moved toward target by at most amount (avr_regulator._toward). */
static double toward(double value, double target, double amount) {
    double change = target - value;
    if (change > amount) change = amount;
    else if (change < -amount) change = -amount;
    return value + change;
}

/* The command reference (avr_regulator._advance_reference), before advance_stride (it reads
 * the calls of the step that ends). */
static void advance_reference(AvrCore *c, const double *values, int64_t si, double dt) {
    double limit = V(command_accel_limit_mps2);
    int first = c->last_step_index < 0;
    if (limit == 0.0) {
        c->ref_vx = V(vx_des), c->ref_vy = V(vy_des);
    } else {
        double amount = limit * dt;
        c->ref_vx = toward(first ? V(vx) : c->ref_vx, V(vx_des), amount);
        c->ref_vy = toward(first ? V(vy) : c->ref_vy, V(vy_des), amount);
    }
    if (si == c->last_step_index) {
        c->ref_sum_vx = c->ref_sum_vx + c->ref_vx;
    } else if (first) {
        c->ref_sum_vx = c->ref_vx, c->ref_vx_step = c->ref_vx;
    } else { /* the step that ends now had stride_calls calls */
        c->ref_vx_step = c->ref_sum_vx / (double)c->stride_calls;
        c->ref_sum_vx = c->ref_vx;
    }
}

/* settled_steps after this call (avr_regulator._advance_settled): 0 while the reference (after
 * advance_reference; prev_x, prev_y its value before) is not settled, else one more at each
 * change of step_index, up to AVR_SETTLED_STEPS_MAX. With learn_ramp_max_mps2 = 0 settled means
 * ref_vx, ref_vy and ref_vx_step within AVR_SETTLED_TOLERANCE_MPS of the command; with a > 0,
 * ref_vx and ref_vy within it and each moved by at most a dt (+ the tolerance) since the last
 * call (not checked at the first call). */
static void advance_settled(AvrCore *c, const double *values, int64_t si, double prev_x, double prev_y,
                            double dt) {
    double tol = AVR_SETTLED_TOLERANCE_MPS, ramp = V(learn_ramp_max_mps2) * dt;
    int moved;
    if (fabs(c->ref_vx - V(vx_des)) > tol || fabs(c->ref_vy - V(vy_des)) > tol)
        moved = 1;
    else if (ramp == 0.0)
        moved = fabs(c->ref_vx_step - V(vx_des)) > tol;
    else
        moved = c->last_step_index >= 0
                && (fabs(c->ref_vx - prev_x) > ramp + tol || fabs(c->ref_vy - prev_y) > ramp + tol);
    if (moved)
        c->settled_steps = 0;
    else if (si != c->last_step_index && c->settled_steps < AVR_SETTLED_STEPS_MAX)
        c->settled_steps += 1;
}

void avr_step(const AvrNetworks *net, AvrCore *core, double *values, double dt) {
    double vx = V(vx), vy = V(vy);
    int64_t si = (int64_t)V(step_index);
    double ref_x_before = core->ref_vx, ref_y_before = core->ref_vy;
    advance_reference(core, values, si, dt);
    advance_settled(core, values, si, ref_x_before, ref_y_before, dt);
    /* With the limit on, PD, network inputs and learning read the reference in place of the
     * command (restored below for the error outputs). */
    double vx_des = V(vx_des), vy_des = V(vy_des);
    if (V(command_accel_limit_mps2) != 0.0) V(vx_des) = core->ref_vx_step, V(vy_des) = core->ref_vy;
    if (si != core->last_step_index) { /* PD_x, PD_y: recomputed when step_index changes, held otherwise */
        int first = core->last_step_index < 0;
        double vx_prev = first ? vx : core->vx_at_step, vy_prev = first ? vy : core->vy_at_step;
        core->pd_x = V(Kp_x) * (vx - V(vx_des)) + V(Kd_x) * (vx - vx_prev);
        core->pd_y = V(Kp_y) * (vy - V(vy_des)) + V(Kd_y) * (vy - vy_prev);
        core->vx_at_step = vx, core->vy_at_step = vy;
    }
    advance_stride(core, si, vy, V(roll));
    double pd_pitch = V(Kp_pitch) * (V(pitch) - V(pitch_des)) + V(Kd_pitch) * V(pitch_rate);
    double pd_roll = V(Kp_roll) * (V(roll) - V(roll_des)) + V(Kd_roll) * V(roll_rate);
    double psi[AVR_N_ROWS] = {0.0, 0.0, 0.0, 0.0};
    if (V(adaptation_enabled) != 0.0) {
        network_outputs(core, net, values, dt, si, psi);
        double g_roll = V(psi_gain_stance_hip_roll);
        V(delta_swing_hip_pitch) = core->pd_x + V(psi_gain_swing_hip_pitch) * psi[0];
        V(delta_swing_knee) = V(psi_gain_swing_knee) * psi[0] + 0.0; /* -0.0 -> 0.0 */
        V(delta_swing_hip_roll) = core->pd_y + V(psi_gain_swing_hip_roll) * psi[1];
        V(delta_stance_hip_roll) = pd_roll + g_roll * psi[1] + g_roll * psi[3];
        V(delta_stance_hip_pitch) = pd_pitch + V(psi_gain_stance_hip_pitch) * psi[2];
        V(delta_stance_knee) = V(psi_gain_stance_knee) * psi[2] + 0.0;
    } else { /* exactly the classic PD regulator; the weights are kept */
        V(delta_swing_hip_pitch) = core->pd_x;
        V(delta_swing_knee) = 0.0;
        V(delta_swing_hip_roll) = core->pd_y;
        V(delta_stance_hip_roll) = pd_roll;
        V(delta_stance_hip_pitch) = pd_pitch;
        V(delta_stance_knee) = 0.0;
    }
    clip_offsets(values, V(delta_limit_rad));
    V(psi_x) = psi[0], V(psi_y) = psi[1], V(psi_pitch) = psi[2], V(psi_roll) = psi[3];
    V(vx_des) = vx_des, V(vy_des) = vy_des;
    V(error_vx) = vx - V(vx_des);
    V(error_vy) = vy - V(vy_des);
    V(error_pitch) = V(pitch) - V(pitch_des);
    V(error_roll) = V(roll) - V(roll_des);
    core->last_step_index = si;
    if (core->n_calls < AVR_MAX_CALLS) core->n_calls += 1;
    core->time_s += dt;
}
