"""Long closed-loop runs (``-m long``): the learned outputs stay bounded over 10 minutes.

Before the y and roll rows learned from stride-averaged errors, a 10 min walk with a
20 kg torso and forward/lateral speed changes let the step-to-step alternation of
psi_roll grow linearly (2e-4 rad in the 1st minute, 8e-4 in the 2nd, 5.4e-3 in the
10th) and psi_y likewise (1.2e-4 in the 2nd minute, 9.4e-4 in the 10th): PES
integrated the correlation between the stance-side sway and the networks' rates.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenarios.cosim import master
from scenarios.results import metrics
from scenarios.lang import spec

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
