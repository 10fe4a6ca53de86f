/*
 * The regulator's numerics in C: the same method, operation for operation, as
 * fmu_src/core/avr_core.py (networks from SplitMix64 streams, LIF-rate hidden layers, PES
 * learning with anti-windup, PD terms held per step_index).  No FMI here: the instance
 * layer (avr_instance.c) owns the FMI behaviour and calls avr_step.
 *
 * Parameters, inputs and outputs live in one array of AVR_N_VARS doubles indexed by the
 * generated value references AVR_VR_<name> (avr_vars.h), so a variable added to the
 * Python tables reaches the C code without a C edit; only its use in avr_step is code.
 */
#ifndef AVR_MODEL_H
#define AVR_MODEL_H

#include "avr_vars.h" /* first: avr_types.h sets up the C library */

#include <stdint.h>

#define AVR_N_NETS 3
#define AVR_N_ROWS 4  /* weight rows: x, y, pitch, roll (see avr_core.RegulatorState) */
#define AVR_N_INPUTS 8 /* network inputs: 2 longitudinal, 2 lateral, 4 torso */

typedef struct {
    int n;          /* neurons per network */
    uint32_t seed;
    /* Per network k (0 longitudinal, 1 lateral, 2 torso), as avr_core.NetworkSpec: */
    double *encoders[AVR_N_NETS];   /* (n, d) row-major unit vectors */
    double *max_rates[AVR_N_NETS];  /* (n,) Hz */
    double *intercepts[AVR_N_NETS]; /* (n,) */
    double *gain[AVR_N_NETS];       /* (n,) */
    double *bias[AVR_N_NETS];       /* (n,) */
    /* For the step: scaled encoders transposed, row r = network input r (8 rows of n), and bias - 1 (3 rows of n). */
    double *scaled_t;
    double *bias_m1;
} AvrNetworks;

typedef struct {
    int n;
    double *weights; /* (4, n) row-major, rad/Hz */
    /* Scratch of the current call.  Only active neurons (current above threshold) have a
     * rate; network k's are listed at offset k n: their indices (increasing) in `active`,
     * tau_rc * rate in `rates`, n_active[k] of them.  Silent neurons contribute exactly 0 to
     * every output and weight update, so they are skipped. */
    double *rates;
    int *active;
    int n_active[AVR_N_NETS];
    double *currents; /* n: one network's currents J - 1 */
    int64_t last_step_index; /* -1 before the first call */
    int64_t n_calls;
    double vx_at_step, vy_at_step, pd_x, pd_y, time_s;
    /* Stride accumulators of the y and roll learning signal (avr_core.RegulatorState):
     * step_index changes seen (the first call counts; saturates at AVR_STRIDE_READY),
     * calls and sums of vy, roll in the current step, means of the last two complete steps. */
    int64_t stride_boundaries, stride_calls;
    double stride_sum_vy, stride_sum_roll, vy_mean_prev, vy_mean_last, roll_mean_prev, roll_mean_last;
    /* The command reference (avr_regulator._advance_reference): after the last call, the sum
     * of ref_vx over the current step's calls, its mean over the step before. */
    double ref_vx, ref_vy, ref_sum_vx, ref_vx_step;
    /* step_index changes since the reference last moved (avr_regulator._advance_settled), up to
     * AVR_SETTLED_STEPS_MAX: the velocity networks wait for learn_settled_steps of them. */
    int64_t settled_steps;
} AvrCore;

#define AVR_STRIDE_READY 4 /* stride_boundaries once two steps are complete */

/* SplitMix64 as documented in avr_core.SplitMix64. */
uint64_t avr_splitmix64_mix(uint64_t z);
double avr_uniform(uint64_t key, uint64_t index); /* draw `index` (1-based) of the stream with `key` */

/* Build the three networks for (n, seed); NULL if out of memory.  avr_networks_free(NULL) is a no-op. */
AvrNetworks *avr_networks_new(int n, uint32_t seed);
void avr_networks_free(AvrNetworks *net);

/* Core state before the first call (zero weights); 0 on success, -1 if out of memory. */
int avr_core_init(AvrCore *core, int n);
void avr_core_free(AvrCore *core);

/* One call of length dt (> 0, finite): reads parameters and inputs from values[],
 * writes the outputs into values[] and advances core.  Inputs must be valid (the
 * instance layer checks every value when it is set). */
void avr_step(const AvrNetworks *net, AvrCore *core, double *values, double dt);

#endif
