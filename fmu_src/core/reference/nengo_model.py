"""The regulator's three PES networks as a nengo 4.1 model: the reference that
``tests/core/test_nengo_crosscheck.py`` compares the core against and that
``benchmarks/bench_regulator.py`` times.  Test/benchmark code only (nengo is a test
dependency; no FMU carries this module).

Each network is an ``Ensemble`` with the core's *explicit* encoders, gains and biases
(``normalize_encoders=False``: they are unit already, re-normalising moves ulps) and
``LIFRate(0.02, 0.002)`` neurons; its outputs come from a ``Connection(ens.neurons,
out, transform=0, learning_rule_type=PES(learning_rate, pre_synapse=None),
synapse=None)`` whose error Node replays the regulator's ``E = desired - actual``
(for y and roll the stride error, computed here independently of the core).
"""
import nengo
import numpy as np

from fmu_src.core.avr_network import build_networks
from fmu_src.core.reference.rates import network_inputs


def build_reference(params, inputs, dt):
    """``(model, parts)`` replaying ``inputs`` (row k at t = (k + 1) dt); ``parts`` maps
    each network's name to ``(ensemble, output node, learning connection)``."""
    nets = build_networks(params)
    xs = [np.array([network_inputs(u, params)[k] for u in inputs]) for k in range(3)]
    e = np.array([[u.vx_des - u.vx, 0.0, params.pitch_des - u.pitch, 0.0] for u in inputs])
    e[:, [1, 3]] = stride_errors(inputs, params)
    errors = [e[:, [0, 0]], e[:, [1, 1]], e[:, [2, 2, 3]]]  # one error per output

    def at(table):  # node function: row of step k at t = (k + 1) dt
        return lambda t: table[min(max(int(round(t / dt)) - 1, 0), len(table) - 1)]

    parts = {}
    with nengo.Network(seed=0) as model:
        for k, net in enumerate(nets):
            inp = nengo.Node(at(xs[k]), label=f"x_{net.name}")
            ens = nengo.Ensemble(net.n_neurons, net.dimensions, encoders=net.encoders,
                                 gain=net.gain, bias=net.bias, normalize_encoders=False,
                                 neuron_type=nengo.LIFRate(tau_rc=0.02, tau_ref=0.002),
                                 label=net.name)
            nengo.Connection(inp, ens, synapse=None)
            n_out = errors[k].shape[1]
            out = nengo.Node(size_in=n_out)
            conn = nengo.Connection(
                ens.neurons, out, transform=np.zeros((n_out, net.n_neurons)),
                learning_rule_type=nengo.PES(learning_rate=params.learning_rate,
                                             pre_synapse=None),
                synapse=None)
            nengo.Connection(nengo.Node(at(errors[k]), label=f"E_{net.name}"), conn.learning_rule,
                             synapse=None)
            parts[net.name] = (ens, out, conn)
    return model, parts


def stride_errors(inputs, params):
    """(k, 2) errors of the y and roll rows at each call: desired minus the mean of the
    last two complete steps' means (a step: the calls from one change of step_index to
    the next; the first run of calls is not one), 0 until two steps are complete."""
    runs, start = [], 0  # [first, end) call indices of each run of equal step_index
    for k in range(1, len(inputs) + 1):
        if k == len(inputs) or inputs[k].step_index != inputs[k - 1].step_index:
            runs.append((start, k))
            start = k
    out = np.zeros((len(inputs), 2))
    means = [np.mean([[u.vy, u.roll] for u in inputs[a:b]], axis=0) for a, b in runs]
    for r in range(3, len(runs)):  # runs 1 and 2 complete at the start of run 3
        stride = 0.5 * (means[r - 2] + means[r - 1])
        for k in range(*runs[r]):
            out[k] = (inputs[k].vy_des - stride[0], params.roll_des - stride[1])
    return out
