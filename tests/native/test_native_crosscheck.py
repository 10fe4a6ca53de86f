"""The native FMUs compute what the numpy core computes.

* Networks: the C core (compiled here, called through ctypes) builds the same encoders,
  maximum rates, intercepts, gains and biases, bit for bit.
* A recorded closed loop: 60 s of real MuJoCo walking (12,000 calls of 5 ms, the numpy
  core in the loop with adaptation on and one psi_gain at 0, a speed change at 30 s) is
  replayed through the numpy core and through both native FMUs (fmpy FMU2Slave and
  FMU3Slave): every output is the same double, bit for bit (the issue asked for 1e-9).
* The fixed elementary functions agree with the C library's to a few ulp.
* The same recorded run with each remedy against drift (leakage, dead-zone, norm
  projection), with the rate-limited command reference, and with all of them: the same
  bits in C as in the core.
* delta_limit_rad binds in C as in the core.  (The importers run every regulator FMU:
  tests/fmu/test_fmu_importers.py.)
"""
import ctypes
import math
import shutil

import numpy as np
import pytest

from fmu_src.core import avr_core
from fmu_src.core.avr_specs import INPUT_SPECS
from fmu_src.core.avr_network import SplitMix64, build_networks
from fmu_src.regulator_fmu.native.header import vars_header
from support.native_support import CC, H, OUTPUT_NAMES, AnySlave, compile_c, core_outputs, input_sequence, require
from support.paths import REPO_ROOT
from fmu_src.core.avr_network import expm1_fixed, log1p_fixed
from fmu_src.core.avr_params import RegulatorParams

INPUT_NAMES = [s.name for s in INPUT_SPECS]
#: the recorded run's regulator: adaptation on (default), one psi_gain at 0
LOOP_PARAMS = {"psi_gain_swing_knee": 0.0}
LOOP_STEPS = 12_000


class _Net(ctypes.Structure):
    _fields_ = [("n", ctypes.c_int), ("seed", ctypes.c_uint32)] + [
        (f, ctypes.POINTER(ctypes.c_double) * 3) for f in ("encoders", "max_rates", "intercepts", "gain", "bias")]


@pytest.fixture(scope="module")
def c_core(tmp_path_factory):
    """The C model core (avr_model.c and the generated header) as a shared library."""
    require(CC)
    tmp = tmp_path_factory.mktemp("c_core")
    (tmp / "avr_vars.h").write_text(vars_header())
    for name in ("avr_types.h", "avr_model.h", "avr_model.c"):
        shutil.copy(REPO_ROOT / "fmu_src" / "core" / "c" / name, tmp / name)
    lib = ctypes.CDLL(str(compile_c(CC, [tmp / "avr_model.c"], tmp / "libavr_model.so", "-std=c99", "-O2",
                                    "-ffp-contract=off", "-shared", "-fPIC", f"-I{tmp}", "-lm")))
    lib.avr_networks_new.restype = ctypes.POINTER(_Net)
    lib.avr_networks_new.argtypes = [ctypes.c_int, ctypes.c_uint32]
    lib.avr_networks_free.argtypes = [ctypes.POINTER(_Net)]
    lib.avr_splitmix64_mix.restype = ctypes.c_uint64
    lib.avr_splitmix64_mix.argtypes = [ctypes.c_uint64]
    return lib


def test_splitmix64_is_the_published_generator(c_core):
    # SplitMix64 seeded with 0 (Vigna's splitmix64.c): key(0, 0, 0) = mix(0) = 0
    stream = SplitMix64(0, 0, 0)
    assert stream.key == 0 and c_core.avr_splitmix64_mix(0) == 0
    first = SplitMix64.mix(np.array([1, 2], dtype=np.uint64) * np.uint64(SplitMix64.GAMMA))
    assert [int(x) for x in first] == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4]
    for z in (1, 2**63 + 12345, 2**64 - 1):
        assert c_core.avr_splitmix64_mix(z) == int(SplitMix64.mix(np.array([z], dtype=np.uint64))[0])


@pytest.mark.parametrize("n, seed", [(1000, 0), (1, 7), (333, 2**31 - 1), (10_000, 12345)])
def test_c_and_numpy_build_the_same_networks(c_core, n, seed):
    ptr = c_core.avr_networks_new(n, seed)
    c = ptr.contents
    try:
        for k, net in enumerate(build_networks(RegulatorParams(n_neurons=n, seed=seed))):
            def arr(field, m):
                return np.ctypeslib.as_array(getattr(c, field)[k], shape=(m,)).copy()
            assert np.array_equal(arr("encoders", n * net.dimensions).reshape(n, -1), net.encoders)
            assert np.array_equal(arr("max_rates", n), net.max_rates)
            assert np.array_equal(arr("intercepts", n), net.intercepts)
            assert np.array_equal(arr("gain", n), net.gain)
            assert np.array_equal(arr("bias", n), net.bias)
    finally:
        c_core.avr_networks_free(ptr)


@pytest.fixture(scope="session")
def closed_loop_inputs():
    """The regulator inputs of 60 s of MuJoCo walking with the numpy core in the loop (the C
    walking controller, the run's default: a third less time than the Python one, which gives
    the same bits, tests/plant/test_native_controller.py)."""
    from plant.model import load_model
    from plant.sim import CassieWalker
    from scenarios.cosim.inprocess import apply_regulator

    walker = CassieWalker(load_model("menagerie"), controller="native")
    walker.set_command(0.5, 0.0)
    regulator = avr_core.Regulator(RegulatorParams(**LOOP_PARAMS))
    recorded = []

    class Recorder:
        def step(self, inputs, dt_s):
            recorded.append({name: getattr(inputs, name) for name in INPUT_NAMES})
            return regulator.step(inputs, dt_s)

    for k in range(LOOP_STEPS):
        if k == LOOP_STEPS // 2:
            walker.set_command(0.6, 0.0)
        apply_regulator(walker, Recorder(), H)
        walker.advance(round(H / walker.model.opt.timestep))
        assert not walker.fell(), walker.fall_reason
    return recorded


@pytest.fixture(scope="session")
def closed_loop_reference(closed_loop_inputs):
    return core_outputs(closed_loop_inputs, **LOOP_PARAMS)


@pytest.mark.parametrize("fmi", [2, 3])
def test_recorded_closed_loop_matches_the_core(native_fmus, closed_loop_inputs, closed_loop_reference, fmi):
    reference = closed_loop_reference
    psi = reference[:, [OUTPUT_NAMES.index(n) for n in ("psi_x", "psi_y", "psi_pitch", "psi_roll")]]
    assert np.abs(psi).max() > 1e-3  # the networks really learned during the run
    assert np.all(reference[:, OUTPUT_NAMES.index("delta_swing_knee")] == 0.0)  # its psi_gain is 0
    slave = AnySlave(native_fmus[fmi]).init(**LOOP_PARAMS)
    out = np.array([slave.step(k, u) for k, u in enumerate(closed_loop_inputs)])
    slave.close()
    diff = np.abs(out - reference).max()
    print(f"\nFMI {fmi}.0 native vs numpy core, {len(out)} calls: max |difference| = {diff:.3g}")
    assert np.array_equal(out.view(np.uint64), reference.view(np.uint64))  # every bit, -0.0 too


#: The remedy against drift (and all settings, with the command reference and learning on
#: settled commands), set so that it acts on the recorded run: the leak halves a weight in ~14 s.
REMEDIES = {
    "leakage": {"leakage_per_s": 0.05},
    "leakage_keeps_output": {"leakage_per_s": 0.05, "leakage_mode": 1},
    "command_reference": {"command_accel_limit_mps2": 0.5},  # the run's speed change at 30 s
    # the velocity rows wait 3 steps after the reference settles, at the start and after 30 s
    "settled_learning": {"command_accel_limit_mps2": 0.5, "learn_settled_steps": 3},
    # slow ramps count as settled: here the count starts when the reference reaches the
    # command, one step before its step mean does
    "learn_ramp_max": {"command_accel_limit_mps2": 0.5, "learn_settled_steps": 3,
                       "learn_ramp_max_mps2": 0.25},
    "all": {"leakage_per_s": 0.05, "leakage_mode": 1, "command_accel_limit_mps2": 0.5,
            "learn_settled_steps": 3, "learn_ramp_max_mps2": 0.25},
}
#: A remedy that builds on another must also act beyond it on the recorded run.
ACTS_BEYOND = {"settled_learning": "command_reference",  # the wait, beyond the reference it needs
               "learn_ramp_max": "settled_learning"}
_remedy_reference = {}


def _remedy_outputs(inputs, remedy):
    """The numpy core's outputs on the recorded run with ``remedy``, computed once."""
    if remedy not in _remedy_reference:
        _remedy_reference[remedy] = core_outputs(inputs, **{**LOOP_PARAMS, **REMEDIES[remedy]})
    return _remedy_reference[remedy]


@pytest.mark.parametrize("remedy", list(REMEDIES))
@pytest.mark.parametrize("fmi", [2, 3])
def test_remedies_against_drift_match_the_core(native_fmus, closed_loop_inputs, closed_loop_reference,
                                               fmi, remedy):
    """Each remedy changes the recorded run's outputs (it acts) and the native FMUs give the
    numpy core's bits with it."""
    reference = _remedy_outputs(closed_loop_inputs, remedy)
    assert not np.array_equal(reference, closed_loop_reference)  # the remedy acts on this run
    if remedy in ACTS_BEYOND:
        assert not np.array_equal(reference, _remedy_outputs(closed_loop_inputs, ACTS_BEYOND[remedy]))
    slave = AnySlave(native_fmus[fmi]).init(**{**LOOP_PARAMS, **REMEDIES[remedy]})
    out = np.array([slave.step(k, u) for k, u in enumerate(closed_loop_inputs)])
    slave.close()
    assert np.array_equal(out.view(np.uint64), reference.view(np.uint64))  # every bit, -0.0 too


def _ramped(inputs):
    """The recorded inputs with the command replaced by ramps: vx_des 0.5 m/s to 30 s, then
    up at 0.1 m/s^2 for 3 s, down at 0.4 m/s^2 for 1 s from 40 s; vy_des up at 0.1 m/s^2
    for 1 s from 45 s, back at 0.4 m/s^2 at 50 s. A replay, not a closed loop: the same
    inputs for the core and the FMUs."""
    out = []
    for k, u in enumerate(inputs):
        t = k * H
        vx_des = 0.5 + 0.1 * min(max(t - 30.0, 0.0), 3.0) - 0.4 * min(max(t - 40.0, 0.0), 1.0)
        vy_des = 0.1 * min(max(t - 45.0, 0.0), 1.0) - 0.4 * min(max(t - 50.0, 0.0), 0.25)
        out.append(dict(u, vx_des=vx_des, vy_des=vy_des))
    return out


#: learn_ramp_max_mps2 on the ramped replay: the settings and the limits it is computed with.
RAMP_PARAMS = {**LOOP_PARAMS, "command_accel_limit_mps2": 0.5, "learn_settled_steps": 3}
RAMP_LIMITS = (0.0, 0.25, 0.39, 0.41)


@pytest.fixture(scope="module")
def ramp_reference(closed_loop_inputs):
    """The ramped replay and the numpy core's outputs on it for each of RAMP_LIMITS (once for both FMI versions)."""
    seq = _ramped(closed_loop_inputs)
    return seq, {a: core_outputs(seq, **RAMP_PARAMS, learn_ramp_max_mps2=a) for a in RAMP_LIMITS}


@pytest.mark.parametrize("fmi", [2, 3])
def test_ramp_settling_matches_the_core(native_fmus, ramp_reference, fmi):
    """learn_ramp_max_mps2 in C as in the core where commands ramp: the 0.1 m/s^2 ramps count
    as settled at 0.25 (the velocity rows learn on them, unlike with 0) and the 0.4 m/s^2
    ones do not (the rows learn as with a limit just below 0.4, not as with one above)."""
    seq, ref = ramp_reference
    params = RAMP_PARAMS
    assert not np.array_equal(ref[0.25], ref[0.0])  # learning on the slow ramps
    assert np.array_equal(ref[0.25], ref[0.39]) and not np.array_equal(ref[0.39], ref[0.41])
    slave = AnySlave(native_fmus[fmi]).init(**params, learn_ramp_max_mps2=0.25)
    out = np.array([slave.step(k, u) for k, u in enumerate(seq)])
    slave.close()
    assert np.array_equal(out.view(np.uint64), ref[0.25].view(np.uint64))


@pytest.mark.parametrize("fmi", [2, 3])
def test_offset_limit_binds_the_same_in_c(native_fmus, fmi):
    """delta_limit_rad clips the six offsets in C exactly as in the core: a limit far below
    the PD terms that a 1 m/s speed error with Kp_x 0.3 and a 0.2 rad pitch produce."""
    params = {"n_neurons": 50, "seed": 3, "Kp_x": 0.3, "Kp_y": 0.3, "Kp_pitch": 1.0, "Kp_roll": 1.0,
              "delta_limit_rad": 0.02, "learning_rate": 1e-3}
    seq = [dict(u, vx=u["vx"] + 1.0, vy=u["vy"] - 1.0, pitch=0.2, roll=-0.2) for u in input_sequence(60, seed=5)]
    reference = core_outputs(seq, **params)
    deltas = reference[:, [OUTPUT_NAMES.index(n) for n in OUTPUT_NAMES if n.startswith("delta_")]]
    assert np.abs(deltas).max() == 0.02 and (np.abs(deltas) == 0.02).mean() > 0.5  # the limit binds
    slave = AnySlave(native_fmus[fmi]).init(**params)
    out = np.array([slave.step(k, u) for k, u in enumerate(seq)])
    slave.close()
    assert np.array_equal(out, reference)


@pytest.mark.parametrize("seed", [0, 1])
def test_fixed_functions_agree_with_the_c_library(seed):
    """log1p_fixed and expm1_fixed are libm's functions to a few ulp where the networks use
    them (log1p of 1/j, j in (0, 40]: y >= 0.025; expm1 of (0.025, 0.15]) and beyond."""
    rng = np.random.default_rng(seed)

    def log1p_pair(y):
        return log1p_fixed(y.copy()), np.array([math.log1p(v) for v in y])

    # Each bound: the series' truncation (< 3e-17 relative) and ~6 roundings, plus the
    # rounding of u = 1 + y, an absolute error of up to 1.1e-16 in log u: relative
    # 1.1e-16 / log1p(y), 5e-15 at y = 0.02, hence rtol 1e-14 there, 1e-15 above y = 1.
    np.testing.assert_allclose(*log1p_pair(rng.uniform(0.02, 1.0, 2000)), rtol=1e-14, atol=0)
    np.testing.assert_allclose(*log1p_pair(10.0 ** rng.uniform(0, 300, 2000)), rtol=1e-15, atol=0)
    # below the networks' range only an absolute bound holds (log1p's job, not ours): the
    # 1.1e-16 of 1 + y and the rounding of (k - 1/2) ln2 ~ 0.35 and of 2 atanh(s) ~ -0.35
    np.testing.assert_allclose(*log1p_pair(10.0 ** rng.uniform(-12, -2, 2000)), rtol=0, atol=4e-16)
    x = rng.uniform(0.0, 1.0, 2000)
    # 4 ulp: 20 Horner steps on terms below 1, truncation < 2e-20
    np.testing.assert_allclose(expm1_fixed(x), [math.expm1(v) for v in x], rtol=8.9e-16, atol=0)
    with pytest.raises(ValueError, match="expm1_fixed"):
        expm1_fixed(np.array([1.5]))
