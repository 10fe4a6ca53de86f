"""Long closed-loop runs (``-m long``): the learned outputs stay bounded over 10 minutes
(fixed commands), and 30 minutes of a command changing every 10 s, with and without pushes,
neither fall nor drift (the issue-25 setup; docs/adaptation.md).

Before the y and roll rows learned from stride-averaged errors, a 10 min walk with a
20 kg torso and forward/lateral speed changes let the step-to-step alternation of
psi_roll grow linearly (2e-4 rad in the 1st minute, 8e-4 in the 2nd, 5.4e-3 in the
10th) and psi_y likewise (1.2e-4 in the 2nd minute, 9.4e-4 in the 10th): PES
integrated the correlation between the stance-side sway and the networks' rates.
"""
from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from scenarios.campaign.catalog import CAMPAIGN_DIR
from scenarios.cosim import master
from scenarios.cosim.regulators import InProcessRegulator
from scenarios.lang import spec
from scenarios.results import metrics

LONG_RUN = {
    "name": "long_20kg_speed_changes",
    "description": "10 min, 20 kg torso, forward and lateral speed changes",
    "duration_s": 600.0, "model": "menagerie", "comm_step_s": 0.005, "seed": 1,
    "torso_mass_kg": 20.0, "compare": ["adaptive"],
    "command": [{"t_s": t, "vx_des": vx, "vy_des": vy} for t, vx, vy in (
        (0.0, 0.5, 0.0), (100.0, 0.8, 0.1), (200.0, 0.3, -0.1), (300.0, 0.6, 0.0),
        (400.0, 0.4, 0.15), (500.0, 0.7, 0.0))],
}
#: Alternation amplitudes at the level of numerical noise do not count as growth: 5e-5
#: rad (0.003 deg) is far below anything the joints respond to, and below every
#: amplitude the unbounded learning reached after its 3rd minute.
NOISE_FLOOR_RAD = 5e-5


@pytest.mark.long
def test_ten_minutes_with_a_20kg_torso_stay_bounded():
    scenario = spec.parse_scenario(LONG_RUN)
    (result,) = master.run_scenario(scenario, "inprocess", arms=("adaptive",))
    assert not result.fell, result.fall_reason
    rows = result.rows
    minute = [[metrics.step_alternation(rows, f"out_{name}", 60.0 * m, 60.0 * (m + 1)) for m in range(10)]
              for name in ("psi_x", "psi_y", "psi_pitch", "psi_roll")]
    for name, amp in zip(("psi_x", "psi_y", "psi_pitch", "psi_roll"), minute):
        # Reference: the largest amplitude over minutes 2-5 (after the first minute's
        # convergence, covering three speed regimes).  Bounded learning keeps the last
        # minute within twice that (measured ratios after the fix: psi_y 1.7, psi_pitch
        # 1.4, psi_x and psi_roll < 1); the linear growth before it gave 3.3 (psi_y) and
        # 2.3 (psi_roll), and 9.4e-4 / 5.4e-3 rad absolute.
        reference = max(amp[1:5])
        assert amp[9] <= 2.0 * reference + NOISE_FLOOR_RAD, (name, amp)
    ex, _ = metrics.velocity_errors(rows)
    last = rows["t"] >= 590.0
    assert np.mean(np.abs(ex[last])) < 0.01  # still tracks (measured 0.000)


# ------------------------------------------------- 30 minutes of changing commands (issue 25)
#: The issue-25 drift setup (benchmarks/bench_drift.py runs it per remedy): the paper rule's
#: weights drift on it until the robot falls (seeds 1 and 2 at 488 s and 483 s of 600 s).
DRIFT_PERTURBATION = {"torso_mass_kg": 20.0, "torso_com_offset_m": [0.05, -0.03, 0.0],
                      "joint_damping_scale": 3.0, "perturbation_t_s": 0.0}
THIRTY_MINUTES_S = 1800.0
WINDOW_S = 300.0


#: The regulator settings of the robustness study's design (its [base.regulator], the variants
#: ramp and control; the FMU's defaults are the other shipped design), walked with every
#: command ramped to from the one before (0.1 m/s^2 at most over 10 s), so that its learning
#: on slow ramps acts. The settings of retired designs were walked at e24b83a.
STUDY_SETTINGS = tomllib.loads((CAMPAIGN_DIR / "robustness_random.toml").read_text())["base"]["regulator"]


def changing_command_walk(seed: int, duration_s: float, pushes: bool, regulator: dict | None = None,
                          ramped: bool = False) -> dict:
    """The drift setup as a scenario: a seeded command every 10 s (vx in [0, 1] m/s, vy in
    [-0.2, 0.2] m/s), network ``seed``; with ``pushes`` a 25 N, 0.1 s pelvis push every 60 s
    (at 35 s, 95 s, ...), its direction turning 90 degrees each time; ``regulator``: the
    regulator's parameters other than its defaults; with ``ramped`` each command after the
    first is reached linearly from the one before over the 10 s."""
    rng = np.random.default_rng(25)
    commands = [{"t_s": 10.0 * k, "vx_des": round(float(rng.uniform(0.0, 1.0)), 3),
                 "vy_des": round(float(rng.uniform(-0.2, 0.2)), 3)} for k in range(int(duration_s // 10.0))]
    if ramped:
        commands = [dict(c, ramp=True) if k else c for k, c in enumerate(commands)]
    doc = {"name": f"long_changing_commands_seed{seed}", "description": "30 min, command every 10 s",
           "duration_s": duration_s, "model": "menagerie", "comm_step_s": 0.005, "seed": seed,
           "compare": ["adaptive"], "command": commands, **DRIFT_PERTURBATION}
    if regulator:
        doc["regulator"] = dict(regulator)
    if pushes:
        doc["push"] = [{"t_s": 60.0 * k + 35.0, "duration_s": 0.1,
                        "force_n": [round(25.0 * math.cos(k * math.pi / 2), 9),
                                    round(25.0 * math.sin(k * math.pi / 2), 9), 0.0]}
                       for k in range(int(duration_s // 60.0))]
    return doc


class NormRecorder(InProcessRegulator):
    """The core in the loop (the FMUs' bits, tests/native/test_native_crosscheck.py), recording the
    Euclidean norm of each weight row (x, y, pitch, roll) every ``every_s``."""

    def __init__(self, every_s: float) -> None:
        super().__init__()
        self.every_s, self.norms = every_s, []

    def start(self, parameters, t0, t_stop):
        super().start(parameters, t0, t_stop)
        self._next = t0 + self.every_s

    def step(self, t, h, inputs):
        out = super().step(t, h, inputs)
        if t + h >= self._next - 1e-9:  # (1e-9 s: far below the 5 ms step)
            w = self._step_fn.__self__.state.weights
            self.norms.append((t + h, np.sqrt(np.sum(w * w, axis=1))))
            self._next += self.every_s
        return out


@pytest.mark.long
@pytest.mark.parametrize("settings, ramped", [(None, False), (STUDY_SETTINGS, True)],
                         ids=["defaults", "study_settings_ramped"])
@pytest.mark.parametrize("pushes", [False, True], ids=["no_pushes", "pushes"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_thirty_minutes_of_changing_commands_stay_stable(seed, pushes, settings, ramped):
    """Default parameters (the leakage on), and the robustness study's settings (with
    learning on slow ramps, on ramped commands): no fall in 30 min; the error per 5-minute
    window does not grow; the weight norms level off."""
    scenario = spec.parse_scenario(changing_command_walk(seed, THIRTY_MINUTES_S, pushes, settings, ramped))
    recorder = NormRecorder(WINDOW_S)
    result = master.run_arm(scenario, scenario.arms[0], recorder)
    assert not result.fell, (result.t_fall_s, result.fall_reason)
    ex, _ = metrics.velocity_errors(result.rows)
    t = result.rows["t"]
    errors = [float(np.mean(np.abs(ex[(t >= a) & (t < a + WINDOW_S)])))
              for a in np.arange(0.0, THIRTY_MINUTES_S, WINDOW_S)]
    norms = np.array([n for _, n in recorder.norms])  # (6, 4): at 5, 10, ..., 30 min
    print(f"\nseed {seed}, pushes {pushes}, settings {settings}: |e_vx| per 5 min {np.round(errors, 3).tolist()}; "
          f"|w| x row {norms[:, 0].tolist()}")
    # Not growing: no window of the second quarter-hour has a mean error above 1.25 times the
    # worst of windows 2 and 3 (minutes 5-15, after the first window's convergence) plus
    # 0.005 m/s; the windows hold different commands, so some spread is not growth.
    assert max(errors[3:]) <= 1.25 * max(errors[1:3]) + 0.005, errors
    # Levelling off: no row's norm at 25 or 30 min exceeds 1.2 times its largest value at
    # 10, 15 or 20 min (the norms follow the command a little; the plain rule's x row grew by
    # 68 % between 100 s and 400 s and kept growing until the fall).
    assert np.all(norms[4:].max(axis=0) <= 1.2 * norms[1:4].max(axis=0)), norms
