"""The C controller (plant/native/) gives the Python controller's servo commands bit for bit.

Both controllers run on one MuJoCo simulation: at every control step (every 4 plant steps)
the Python controller updates and its commands (ctrl and the servo gains in biasprm) are
kept, then the C controller updates from the same state and must write the same bytes; its
memory (step-averaged speed, filtered speeds, phase, stance, step count, heading) must equal
the Python controller's too.  The regulator core (PD only) closes the loop every 10 ms.
Scenarios: nominal walking, a heavy torso, uneven terrain, command changes (speed, lateral
speed, turning), a push, and the OSU model.
"""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from fmu_src.core.avr_core import Regulator
from fmu_src.core.avr_params import RegulatorParams
from plant.constants import OFFSET_NAMES, SIDES
from plant.model import load_model
from plant.native.native_ctrl import MODES, NativeController, NativeLibrary, build_library
from plant.perturbation import Perturbation
from plant.sim import CassieWalker
from plant.terrain import TerrainSpec
from scenarios.cosim.inprocess import apply_regulator

#: Simulated seconds per scenario: standing (0.3 s), the weight shift (0.5 s), then at
#: least 8 walking steps.
WALK_S = 4.0
#: Plant steps per regulator call (10 ms).
REGULATOR_STEPS = 20


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    return NativeLibrary(build_library(tmp_path_factory.mktemp("cassie_ctrl")))


def _commands(walker):
    ids = walker.controller._act_ids
    return (walker.data.ctrl[ids].tobytes() + walker.model.actuator_biasprm[ids, 1:3].tobytes())


def _memory_pairs(py, c):
    m = c.memory
    pairs = [("vx_step_avg", py.vx_step_avg, m.vx_step_avg), ("vy_filt", py.vy_filt, m.vy_filt),
             ("vx_filt", py.vx_filt, m.vx_filt), ("tau", py.tau, m.tau), ("yaw_ref", py.yaw_ref, m.yaw_ref),
             ("vx_des", py.vx_des, m.vx_des), ("vy_des", py.vy_des, m.vy_des),
             ("yaw_rate_des", py.yaw_rate_des, m.yaw_rate_des), ("vx_ref", py.vx_ref, m.vx_ref),
             ("vy_ref", py.vy_ref, m.vy_ref), ("yaw_rate_ref", py.yaw_rate_ref, m.yaw_rate_ref),
             ("t_step_start", py.t_step_start, m.t_step_start),
             ("swing_start0", py._swing_start[0], m.swing_start[0]),
             ("swing_start1", py._swing_start[1], m.swing_start[1])]
    return [(n, struct.pack("<d", a), struct.pack("<d", b)) for n, a, b in pairs] + [
        ("step_index", py.step_index, m.step_index), ("stance", py.stance, SIDES[m.stance]),
        ("mode", py.mode, MODES[m.mode])]


def _run(native, model, events, seconds=WALK_S):
    """Walk ``seconds`` with both controllers on one simulation; ``events`` maps a time (s)
    to a function of the walker and the C controller.  Returns (control steps, steps walked)."""
    walker = CassieWalker(model)
    py = walker.controller
    init_commands = _commands(walker)
    c = NativeController(native, walker.physics, walker.params)
    assert _commands(walker) == init_commands, "the first update (at construction) differs"
    walker.set_command(0.5, 0.0)
    c.set_command(0.5, 0.0, walker.gaits)
    regulator = Regulator(RegulatorParams(adaptation_enabled=False))
    sub, phys = walker.params.control_substeps, walker.physics
    n_steps, checked = int(round(seconds / walker.SIM_DT_S)), 0
    pending = sorted(events.items())
    for k in range(n_steps):
        if k % REGULATOR_STEPS == 0:
            while pending and pending[0][0] <= walker.time_s + 1e-9:
                pending.pop(0)[1](walker, c)
            offsets = apply_regulator(walker, regulator, REGULATOR_STEPS * walker.SIM_DT_S)
            c.set_offsets(offsets)
        phys.step(1)
        if (k + 1) % sub == 0:
            py.update()
            expected = _commands(walker)
            c.update()
            got = _commands(walker)
            if got != expected:
                e = np.frombuffer(expected, float)
                g = np.frombuffer(got, float)
                bad = np.flatnonzero(e != g)
                pytest.fail(f"t={walker.time_s:.4f} s: C commands differ at {bad.tolist()}: "
                            f"python {e[bad].tolist()} C {g[bad].tolist()}")
            for name, a, b in _memory_pairs(py, c):
                assert a == b, f"t={walker.time_s:.4f} s: controller {name} differs: python {a!r} C {b!r}"
            checked += 1
    assert not walker.fell(), walker.fall_reason
    return checked, py.step_index


def _set_command(vx, vy, yaw_rate=0.0):
    def event(walker, c):
        walker.set_command(vx, vy, yaw_rate)
        c.set_command(vx, vy, walker.gaits, yaw_rate)
    return event


def _push(force):
    return lambda walker, c: walker.set_pelvis_force(force)


SCENARIOS = {
    "nominal": ("menagerie", None, {}),
    "heavy_torso": ("menagerie", Perturbation(torso_mass_kg=18.0, torso_com_offset_m=(0.02, 0.0, 0.03)), {}),
    "terrain": ("menagerie", Perturbation(terrain=TerrainSpec(max_height_m=0.06, max_slope_deg=8.0, seed=3)), {}),
    "command_change": ("menagerie", None, {2.0: _set_command(0.8, 0.1, 0.3), 3.0: _set_command(0.3, -0.1, -0.2)}),
    "push": ("menagerie", Perturbation(joint_damping_scale=1.5),
             {2.0: _push([60.0, 30.0, 0.0]), 2.2: _push([0.0, 0.0, 0.0])}),
    "osu": ("osu", None, {}),
    "slope": ("menagerie", Perturbation(slope_deg=3.0, cross_slope_deg=-2.0), {}),
}


@pytest.mark.parametrize("name", SCENARIOS)
def test_c_controller_matches_python_bit_for_bit(native, name):
    source, perturbation, events = SCENARIOS[name]
    checked, steps = _run(native, load_model(source, perturbation), events)
    assert checked == int(WALK_S / 0.002)
    assert steps >= 8, f"only {steps} walking steps: the comparison must cover walking"


def test_ground_height_is_the_plant_s(native):
    """The C terrain lookup returns the plant's GroundHeight bits, inside, at and beyond the edge."""
    model = load_model("menagerie", Perturbation(terrain=TerrainSpec(max_height_m=0.2, max_slope_deg=12.0,
                                                                     seed=11, size_m=4.0)))
    walker = CassieWalker(model)
    c = NativeController(native, walker.physics, walker.params)
    rng = np.random.default_rng(0)
    points = [*rng.uniform(-5.0, 5.0, (2000, 2)).tolist(), (4.0, 4.0), (-4.0, -4.0), (0.0, 0.0)]
    for x, y in points:
        assert struct.pack("<d", c.ground_height_m(x, y)) == struct.pack("<d", walker.physics.ground_height_m(x, y))
    assert math.isnan(c.ground_height_m(math.nan, 0.0))


def test_ground_height_on_a_tilted_floor_is_the_plant_s(native):
    """On a sloped floor (no terrain) the C lookup gives the plant's tilted-plane heights, not the level floor's."""
    model = load_model("menagerie", Perturbation(slope_deg=4.0, cross_slope_deg=-3.0))
    walker = CassieWalker(model)
    c = NativeController(native, walker.physics, walker.params)
    rng = np.random.default_rng(1)
    for x, y in [*rng.uniform(-20.0, 20.0, (500, 2)).tolist(), (0.0, 0.0)]:
        assert struct.pack("<d", c.ground_height_m(x, y)) == struct.pack("<d", walker.physics.ground_height_m(x, y))
    assert c.ground_height_m(10.0, 0.0) > 0.5, "the floor rises along +x"


def test_offsets_must_be_finite(native):
    walker = CassieWalker(load_model("menagerie"))
    c = NativeController(native, walker.physics, walker.params)
    with pytest.raises(ValueError, match="delta_swing_knee must be finite"):
        c.set_offsets({"delta_swing_knee": math.inf})
    with pytest.raises(KeyError, match="allowed: " + ", ".join(OFFSET_NAMES)):
        c.set_offsets({"delta_knee": 0.0})
    assert list(c.memory.offsets) == [0.0] * 6


def _walk_telemetry(model, events, **walker_kwargs):
    """Walk 4 s on a CassieWalker with the regulator core (PD only) every 10 ms; ``events`` maps a
    time (s) to a function of the walker. Returns the telemetry of every 10 ms, packed as doubles."""
    walker = CassieWalker(model, **walker_kwargs)
    walker.set_command(0.5, 0.0)
    regulator = Regulator(RegulatorParams(adaptation_enabled=False))
    pending, out = sorted(events.items()), []
    for _ in range(int(round(WALK_S / (REGULATOR_STEPS * walker.SIM_DT_S)))):
        while pending and pending[0][0] <= walker.time_s + 1e-9:
            pending.pop(0)[1](walker)
        walker.set_offsets(apply_regulator(walker, regulator, REGULATOR_STEPS * walker.SIM_DT_S))
        walker.advance(REGULATOR_STEPS)
        out.append(struct.pack(f"<{len(walker.telemetry())}d", *walker.telemetry().values()))
    assert not walker.fell(), walker.fall_reason
    return out, walker


def test_walker_with_the_c_controller_walks_the_python_walker_s_bits(native):
    """CassieWalker(controller="native") gives the Python walker's telemetry bit for bit through what the
    scenarios and campaigns change: link masses, floor friction, a slope, a mid-walk plant change
    (mass, COM, damping, friction), a push on a link and a command change."""
    model = load_model("menagerie", Perturbation(link_mass_scale=(("left-shin", 1.5),), floor_friction=0.7,
                                                 slope_deg=2.0, torso_added_mass_kg=4.0))
    events = {1.5: lambda w: w.change_plant(torso_mass_kg=16.0, torso_com_shift_m=(0.02, 0.0, 0.0),
                                            damping_factor=2.0, floor_friction=0.9),
              2.0: lambda w: w.set_body_force("left-knee", [30.0, 10.0, 0.0]),
              2.1: lambda w: w.set_body_force("left-knee", [0.0, 0.0, 0.0]),
              2.5: lambda w: w.set_command(0.8, 0.05, 0.2)}
    python, _ = _walk_telemetry(model, events)
    c, walker = _walk_telemetry(model, events, controller="native", native_library=native)
    assert walker.controller_kind == "native" and walker.controller.step_index >= 8
    first = next((i for i, (a, b) in enumerate(zip(python, c)) if a != b), None)
    assert first is None, f"telemetry differs from t = {first * 0.01:.2f} s"
    with pytest.raises(NotImplementedError, match="controller='python'"):
        walker.get_state()


def _walk_until_fall(model, **walker_kwargs):
    """Walk at 0.5 m/s, pushed forward by 300 N from 1 s on, until the walker falls (4 s at most):
    the telemetry and regulator inputs of every 10 ms, packed as doubles, and the fall."""
    walker = CassieWalker(model, **walker_kwargs)
    walker.set_command(0.5, 0.0)
    out = []
    while not walker.fell() and walker.time_s < WALK_S:
        if abs(walker.time_s - 1.0) < 1e-9:
            walker.set_pelvis_force([300.0, 0.0, 0.0])
        walker.advance(REGULATOR_STEPS)
        signals = [*walker.telemetry().values(), *walker.regulator_inputs().values()]
        out.append(struct.pack(f"<{len(signals)}d", *signals))
    return out, walker.time_s, walker.fall_reason


def test_the_c_walker_falls_where_the_python_walker_falls(native):
    """The C stepping, fall test and sensing (cc_advance, cc_fallen, cc_sense) end a falling walk at
    the Python walker's time, for its reason, with its signals bit for bit on the way."""
    model = load_model("menagerie")
    python = _walk_until_fall(model)
    c = _walk_until_fall(model, controller="native", native_library=native)
    assert python[2] is not None and python[1] < WALK_S, "the push must make the walker fall"
    assert c[1:] == python[1:]
    first = next((i for i, (a, b) in enumerate(zip(python[0], c[0])) if a != b), None)
    assert first is None and len(c[0]) == len(python[0]), f"signals differ from step {first}"


@pytest.mark.parametrize("state", ["standing", "pelvis_at_the_height_limit", "pelvis_just_below_it", "tilted",
                                   "non_finite_velocity"])
def test_the_c_fall_test_is_the_python_one(native, state):
    """cc_fallen answers what CassiePhysics.fall_reason says, on each side of each limit."""
    import mujoco

    from plant.cassie import FALL_HEIGHT_M, FALL_TILT_RAD

    walker = CassieWalker(load_model("menagerie"), controller="native", native_library=native)
    ph = walker.physics
    m, d, qa = ph.model, ph.data, ph.free_qadr
    if state == "pelvis_at_the_height_limit":  # the flat floor is at 0: not lower than the limit
        d.qpos[qa + 2] = FALL_HEIGHT_M
    elif state == "pelvis_just_below_it":
        d.qpos[qa + 2] = math.nextafter(FALL_HEIGHT_M, 0.0)
    elif state == "tilted":  # about x, just past the limit
        half = (FALL_TILT_RAD + 1e-6) / 2
        d.qpos[qa + 3:qa + 7] = [math.cos(half), math.sin(half), 0.0, 0.0]
    elif state == "non_finite_velocity":
        d.qvel[0] = math.nan
    mujoco.mj_kinematics(m, d)
    expected = state != "standing" and state != "pelvis_at_the_height_limit"
    assert (ph.fall_reason() is not None) == expected
    assert walker.controller.fallen(FALL_HEIGHT_M, FALL_TILT_RAD) == expected


def test_walker_refuses_an_unknown_controller():
    with pytest.raises(ValueError, match="controller = 'c': must be one of python, native"):
        CassieWalker(load_model("menagerie"), controller="c")


#: What the sanitized walker does in its own process (the library's path is its argument): walk on a
#: flat floor and on terrain, pushed until it falls, every C call of the walker's loop on the way.
SANITIZED_WALK = """
import math, sys
from plant.cassie import FALL_HEIGHT_M, FALL_TILT_RAD
from plant.model import load_model
from plant.native.native_ctrl import NativeLibrary
from plant.perturbation import Perturbation
from plant.sim import CassieWalker
from plant.terrain import TerrainSpec
lib = NativeLibrary(sys.argv[1])
for pert in (None, Perturbation(terrain=TerrainSpec(max_height_m=0.1, max_slope_deg=10.0, seed=3))):
    w = CassieWalker(load_model("menagerie", pert), controller="native", native_library=lib)
    w.set_command(0.5, 0.0)
    for k in range(300):
        if k == 100:
            w.set_pelvis_force([300.0, 0.0, 0.0])
        w.advance(7)
        w.telemetry(), w.regulator_inputs()
    assert w.fell()
    w.data.qvel[0] = math.nan
    assert w.controller.fallen(FALL_HEIGHT_M, FALL_TILT_RAD)
print("walked")
"""


@pytest.mark.sanitize
def test_the_walker_s_c_calls_under_asan_and_ubsan_with_zero_findings(tmp_path):
    import os
    import subprocess
    import sys

    from native.test_native_hosts import SANITIZE

    lib = build_library(tmp_path, extra_flags=SANITIZE)
    assert b"__asan_report" in lib.read_bytes() and b"__ubsan_handle" in lib.read_bytes()  # instrumented
    libasan = subprocess.run(["gcc", "-print-file-name=libasan.so"], capture_output=True, text=True).stdout.strip()
    # Python itself is not instrumented and keeps memory until exit: leak checking would report it, not us.
    env = {**os.environ, "LD_PRELOAD": libasan, "ASAN_OPTIONS": "detect_leaks=0:halt_on_error=1",
           "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1"}
    run = subprocess.run([sys.executable, "-c", SANITIZED_WALK, str(lib)], env=env, capture_output=True, text=True,
                         timeout=900)
    findings = run.stderr.count("ERROR: AddressSanitizer") + run.stderr.count("runtime error:")
    assert run.returncode == 0 and findings == 0 and run.stdout.strip() == "walked", run.stderr[-4000:]
