"""Cross-check of the numpy core against nengo 4.1, the reference the networks follow.

A nengo model is built with the core's *explicit* encoders, gains and biases
(``nengo.Ensemble(..., encoders=, gain=, bias=, neuron_type=LIFRate(0.02, 0.002))``),
each regulator's output a ``Connection(ens.neurons, out, transform=zeros,
learning_rule_type=PES(learning_rate, pre_synapse=None), synapse=None)`` with its error
fed through a Node.  Both are driven by the same seeded random walk of inputs.

Conventions reconciled here (each checked by the assertions, not assumed):

* Error sign.  nengo's PES applies ``delta = -kappa dt / n * outer(err, a)`` and calls
  ``err = actual - target``.  The regulator applies the same formula with
  ``E = desired - actual`` of the *velocity/angle*, so the signal fed to nengo's error
  connection is exactly the regulator's E (e.g. ``vx_des - vx`` for both longitudinal
  outputs); this is what makes Psi grow positive when vx > vx_des.
* Timing.  In nengo step k first applies the delta computed in step k-1
  (``weights += delta``), then computes the output from the rates of step k, then
  computes the new delta from step k's error.  The core's ``step`` returns Psi from
  the weights before its own update, so output k agrees with nengo's output k with no
  shift; the weights probed in nengo step k (updates 0..k-1 applied) equal the core's
  state after k calls (updates 0..k-1), i.e. nengo's probe is one update behind.
* Scaling.  nengo 4 scales PES by ``kappa * dt / n_neurons``, like the core.

Tolerances: ``rtol=1e-9, atol=1e-10`` as required; the observed differences are
~1e-14 relative (summation order of the dot products, and the core's fixed-series log1p
against numpy's: docs/method.md, "Numerics").
"""
import numpy as np
import pytest

nengo = pytest.importorskip("nengo")

from fmu_src.core.avr_core import Regulator
from fmu_src.core.avr_params import RegulatorInputs, RegulatorParams
from fmu_src.core.avr_network import build_networks
from fmu_src.core.reference.nengo_model import build_reference  # noqa: E402
from fmu_src.core.reference.rates import neuron_rates  # noqa: E402

RTOL, ATOL = 1e-9, 1e-10


def lif():
    return nengo.LIFRate(tau_rc=0.02, tau_ref=0.002)


def random_walk(seed, n_steps):
    """Seeded random walk of regulator inputs; excursions beyond the input scales
    exercise the radial projection; the step index advances every 40 calls."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0.0, 1.0, (n_steps, 8)), axis=0)
    walk *= np.array([0.05, 0.03, 0.02, 0.01, 0.01, 0.01, 0.05, 0.05])
    walk += np.array([0.5, 0.0, 0.6, 0.0, 0.0, 0.0, 0.0, 0.0])
    return [RegulatorInputs(*map(float, row), step_index=k // 40)
            for k, row in enumerate(walk)]


def nengo_run(params, seq, dt):
    """Simulate the three PES networks in nengo; returns (outputs, weights, built ensembles)."""
    model, parts = build_reference(params, seq, dt)
    probes = {}
    with model:
        for name, (ens, out, conn) in parts.items():
            probes[name] = (ens, nengo.Probe(out, synapse=None),
                            nengo.Probe(conn, "weights", synapse=None))
    with nengo.Simulator(model, dt=dt, progress_bar=False, optimize=True) as sim:
        for _ in seq:
            sim.step()
    outs = {name: sim.data[p] for name, (_, p, _) in probes.items()}
    weights = {name: sim.data[w] for name, (_, _, w) in probes.items()}
    built = {name: sim.data[ens] for name, (ens, _, _) in probes.items()}
    return outs, weights, built


@pytest.mark.parametrize("n_neurons, dt, n_steps, learning_rate, seed", [
    (300, 0.005, 400, 2e-5, 1),
    (1000, 0.001, 300, 1e-4, 2),
])
def test_core_matches_nengo_pes_networks(n_neurons, dt, n_steps, learning_rate, seed):
    # psi_limit at its maximum and no saturation reached (asserted below): nengo has no
    # output clip, so anti-windup must not engage for the comparison to be meaningful.  The
    # remedies against drift off: nengo's PES is the paper's plain rule.
    params = RegulatorParams(n_neurons=n_neurons, seed=seed, learn_from_step=0, learning_rate=learning_rate,
                             psi_limit=1.0, Kp_x=0.0, Kd_x=0.0, Kp_y=0.0, Kd_y=0.0,
                             pitch_des=0.02, roll_des=-0.01, leakage_per_s=0.0)
    seq = random_walk(seed, n_steps)
    reg = Regulator(params)
    ours, weights_after = [], []
    for u in seq:
        ours.append(reg.step(u, dt))
        weights_after.append(reg.state.weights)
    outs, weights, built = nengo_run(params, seq, dt)

    # nengo built exactly the networks we gave it
    for net in reg.networks:
        b = built[net.name]
        assert np.array_equal(b.gain, net.gain) and np.array_equal(b.bias, net.bias)
        assert np.array_equal(b.scaled_encoders, net.scaled_encoders)

    col = {k: np.array([o[k] for o in ours]) for k in ours[0]}
    lo, la, to = outs["longitudinal"], outs["lateral"], outs["torso"]
    assert np.max(np.abs(np.concatenate([lo, la, to], 1))) < 0.9  # never saturated
    assert np.max(np.abs(lo)) > 0.05 and np.max(np.abs(to)) > 0.01  # learned something
    np.testing.assert_allclose(col["psi_x"], lo[:, 0], rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(col["delta_swing_knee"], lo[:, 1], rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(col["psi_y"], la[:, 0], rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(col["psi_pitch"], to[:, 0], rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(col["delta_stance_knee"], to[:, 1], rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(col["psi_roll"], to[:, 2], rtol=RTOL, atol=ATOL)
    # Kp_roll = Kd_roll = 0: stance hip roll = Psi_y[1] + Psi_torso[2]
    np.testing.assert_allclose(col["delta_stance_hip_roll"], la[:, 1] + to[:, 2],
                               rtol=RTOL, atol=ATOL)

    # weights: nengo's probe at step k has the updates of steps 0..k-1 applied, i.e.
    # the core's state after k calls; compare all steps, in the per-output layout.
    ours_w = np.array(weights_after)  # (K, 4, n) after calls 1..K
    for name, rows in (("longitudinal", [0, 0]), ("lateral", [1, 1]),
                       ("torso", [2, 2, 3])):
        ng = weights[name]  # (K, n_out, n)
        assert np.all(ng[0] == 0.0)
        np.testing.assert_allclose(ours_w[:-1][:, rows], ng[1:], rtol=RTOL, atol=ATOL)
        scale = np.max(np.abs(ng))
        assert np.max(np.abs(ours_w[:-1][:, rows] - ng[1:])) <= 1e-12 * scale


def test_gain_bias_match_nengo_lifrate():
    params = RegulatorParams(n_neurons=2000, seed=5)
    for net in build_networks(params):
        gain, bias = lif().gain_bias(net.max_rates, net.intercepts)
        # Same analytic curve, algebraically rearranged (expm1 vs 1/(1-exp)): agreement
        # to ~1e-15 relative; 1e-12 leaves room for libm differences.
        np.testing.assert_allclose(net.gain, gain, rtol=1e-12)
        np.testing.assert_allclose(net.bias, bias, rtol=1e-12, atol=1e-12)
        mr, ic = lif().max_rates_intercepts(net.gain, net.bias)
        np.testing.assert_allclose(mr, net.max_rates, rtol=1e-9)  # log1p of ~1/x: ill-cond.
        np.testing.assert_allclose(ic, net.intercepts, rtol=1e-12, atol=1e-12)


def test_neuron_rates_match_nengo_lifrate_rates():
    params = RegulatorParams(n_neurons=500, seed=9)
    rng = np.random.default_rng(0)
    for net in build_networks(params):
        for _ in range(20):
            x = rng.normal(size=net.dimensions)
            x /= max(1.0, np.linalg.norm(x))
            want = lif().rates((net.encoders @ x)[None, :], net.gain, net.bias)[0]
            got = neuron_rates(net, x)
            assert np.array_equal(got == 0.0, want == 0.0)
            # rates up to ~450 Hz; differences come only from the rounding of the
            # current (gain * (e.x) + bias vs (gain * e).x + bias), ~1e-13 relative
            np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-9)
