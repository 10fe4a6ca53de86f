"""Closed-loop walking of the Cassie plant with the nominal controller.

The regulator is the project's core ``fmu_src.core.avr_core.Regulator`` in-process
with adaptation off (the paper-form PD, default gains:
``scenarios.gaits.make_gaits.PD_ONLY_PARAMS``) called every 10 ms like the
co-simulation's communication step.  Every run starts from rest in the ``home``
pose (stand, weight shift, walk; no velocity kick).  Default runs are short (~10 s wall in
all); the 60 s matrix, perturbations and pushes are ``@pytest.mark.long``: run
them with ``pytest -m long tests/plant/test_walking.py`` (not ``slow``: nengo's pytest
plugin claims that marker and skips it unless ``--slow`` is given);
~5 min on one core.
"""
from __future__ import annotations

import pytest

from fmu_src.core.avr_core import Regulator
from plant.constants import OFFSET_NAMES
from scenarios.gaits.make_gaits import PD_ONLY_PARAMS, simulate_walk
from plant.perturbation import Perturbation
from plant.model import load_model


class FixedOffsets:
    """The core's PD (adaptation off) plus constant extra offsets (rad), to check the
    sign conventions; same ``step(inputs, dt_s)`` as the core."""

    def __init__(self, extra):
        self.core = Regulator(PD_ONLY_PARAMS)
        self.extra = extra

    def step(self, inputs, dt_s):
        out = self.core.step(inputs, dt_s)
        return {k: out[k] + self.extra.get(k, 0.0) for k in OFFSET_NAMES}


@pytest.fixture(scope="module")
def menagerie():
    return load_model("menagerie")


def test_walks_10s_from_rest_at_0p5(menagerie):
    r = simulate_walk(menagerie, 0.5, 0.0, 10.0)
    assert not r.fell, r.fall_reason
    # Tolerance 0.05 m/s: the calibrated gait settles within ~0.01 m/s after ~4 s.
    assert abs(r.steady_vx(5.0) - 0.5) < 0.05
    _, vy = r.mean_velocity_xy(5.0)
    assert abs(vy) < 0.05  # lateral drift
    assert r.max_abs_yaw_rad < 0.15  # heading hold through the hip yaws (P only: ~0.05 rad)


def test_walks_in_place_10s(menagerie):
    r = simulate_walk(menagerie, 0.0, 0.0, 10.0)
    assert not r.fell, r.fall_reason
    assert abs(r.steady_vx(5.0)) < 0.05


def test_osu_walks_10s():
    r = simulate_walk(load_model("osu"), 0.5, 0.0, 10.0)
    assert not r.fell, r.fall_reason
    assert abs(r.steady_vx(5.0) - 0.5) < 0.05


def test_swing_offset_signs_closed_loop(menagerie):
    """+delta_swing_hip_pitch slows the robot; +delta_swing_hip_roll pushes it toward -y."""
    runs = {}
    for sgn in (+1, -1):
        reg = FixedOffsets({"delta_swing_hip_pitch": 0.01 * sgn, "delta_swing_hip_roll": 0.03 * sgn})
        r = simulate_walk(menagerie, 0.5, 0.0, 7.0, regulator=reg)
        assert not r.fell, r.fall_reason
        runs[sgn] = (r.steady_vx(4.0), r.mean_velocity_xy(4.0)[1])
    assert runs[+1][0] < runs[-1][0] - 0.02
    assert runs[+1][1] < runs[-1][1] - 0.02


# ----------------------------------------------------------------------- slow
SPEED_CASES = [(0.0, 0.0), (0.25, 0.0), (0.5, 0.0), (0.75, 0.0), (1.0, 0.0), (0.3, -0.2), (0.3, 0.2)]


@pytest.mark.long
@pytest.mark.parametrize("source", ["menagerie", "osu"])
@pytest.mark.parametrize("vx,vy", SPEED_CASES)
def test_speed_matrix_60s(source, vx, vy):
    r = simulate_walk(load_model(source), vx, vy, 60.0)
    assert not r.fell, r.fall_reason
    assert r.max_abs_yaw_rad < 0.2
    if source == "menagerie":  # nominal model: steady-state error <= 0.05 m/s (the criterion)
        assert abs(r.steady_vx(30.0) - vx) <= 0.05
        assert abs(r.mean_velocity_xy(30.0)[1] - vy) <= 0.05


@pytest.mark.long
@pytest.mark.parametrize("mass_kg,com_dx_m", [(15.0, 0.0), (20.0, 0.0), (23.0, 0.0),
                                              (None, 0.05), (None, 0.1), (None, -0.1)])
def test_perturbed_30s(mass_kg, com_dx_m):
    """PD-only must not fall; the speed error it leaves is the adaptive regulator's job."""
    pert = Perturbation(torso_mass_kg=mass_kg, torso_com_offset_m=(com_dx_m, 0.0, 0.0))
    r = simulate_walk(load_model("menagerie", pert), 0.5, 0.0, 30.0)
    assert not r.fell, r.fall_reason


@pytest.mark.long
@pytest.mark.parametrize("force_x", [30.0, -25.0])
def test_push_while_walking(menagerie, force_x):
    r = simulate_walk(menagerie, 0.5, 0.0, 15.0, push=(8.0, 0.1, (force_x, 0.0, 0.0)))
    assert not r.fell, r.fall_reason


def _terrain_walk(seed: int, duration_s: float):
    """The terrain_mass_com plant (+5 kg, COM +0.1 m, slopes <= 20 deg, heights <= 0.4 m)
    on terrain ``seed``, 0.5 m/s from rest with the adaptive core every 5 ms."""
    from plant.constants import NOMINAL_TORSO_MASS_KG
    from plant.sim import CassieWalker
    from scenarios.cosim.inprocess import apply_regulator
    from plant.terrain import TerrainSpec

    terrain = TerrainSpec(max_height_m=0.4, max_slope_deg=20.0, seed=seed, size_m=45.0)
    pert = Perturbation(torso_mass_kg=NOMINAL_TORSO_MASS_KG + 5.0, torso_com_offset_m=(0.1, 0.0, 0.0),
                        terrain=terrain)
    walker = CassieWalker(load_model("menagerie", pert))
    walker.set_command(0.5, 0.0)
    regulator = Regulator()
    while walker.time_s < duration_s and not walker.fell():
        apply_regulator(walker, regulator, 0.005)
        walker.advance(10)
    return walker


def test_early_touchdown_on_an_up_slope_ends_the_step():
    """Terrain seed 5 with +5 kg and COM +0.1 m: the swing foot lands early on the rising
    ground and takes the weight gradually (below ``touchdown_force_n``).  Holding the stance
    until ``switch_max_tau`` unloaded the stance leg and the torso pitched over at 3.8 s
    (x = 2.2 m); with the weight-share touchdown the walker is still up at 8 s."""
    walker = _terrain_walk(5, 8.0)
    assert not walker.fell(), walker.fall_reason
    assert walker.physics.pelvis_position()[0] > 3.0  # past the slope it fell on


def test_swing_foot_height_follows_the_ground_under_the_foot():
    """Terrain seed 7 (the suite's terrain_mass_com): a 0.2 m rise within 0.7 m, then a
    crest.  With the swing height referred to the ground under the hip, the foot was
    driven into the rise ahead of it and over the crest it reached for ground it was not
    over; the walker, overspeeding from the COM offset, fell at 4.8 s (x = 3.4 m).
    Referred to the ground under the foot's target it walks on (12 of 12 terrain seeds)."""
    walker = _terrain_walk(7, 8.0)
    assert not walker.fell(), walker.fall_reason
    assert walker.physics.pelvis_position()[0] > 4.0  # past the crest it fell on
