"""The RL-HZD policy: six HZD trajectory offsets from the regulator's inputs.

Structure (the HZD policy of the paper's RL baseline, reduced to what fits two cores):
the same inputs as the adaptive regulator, scaled by fixed constants, and a bias,

    features = [vx - vx_des, vy - vy_des, vx_des, vy_des, pitch, roll,
                pitch_rate, roll_rate] / scales  ++  [1]
    delta    = clip(W @ features, -DELTA_LIMIT_RAD, DELTA_LIMIT_RAD)       (rad, 6 outputs;
               each row's sum taken left to right in scalar arithmetic, no BLAS)

sampled when a new walking step starts (``step_index`` changes) and held during the step,
as the regulator's PD terms are.  ``W`` (6 x 9) is learned offline on the nominal model and
never changes in use: under a model change the policy has no integral action, which is the
behaviour the paper reports for its RL baseline.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from plant.constants import OFFSET_NAMES

FEATURE_NAMES = ("error_vx", "error_vy", "vx_des", "vy_des", "pitch", "roll",
                 "pitch_rate", "roll_rate", "bias")
#: Fixed feature scales (m/s, m/s, m/s, m/s, rad, rad, rad/s, rad/s, 1): O(1) features.
FEATURE_SCALES = np.array([0.5, 0.2, 1.0, 0.2, 0.1, 0.1, 1.0, 1.0, 1.0])
#: Output clip (rad): the offsets the gait can absorb without tripping.
DELTA_LIMIT_RAD = 0.3
DEFAULT_POLICY = Path(__file__).with_name("policy.json")
FORMAT = "cassie-avr rl_hzd policy 1"


def features(inputs) -> np.ndarray:
    """The policy's feature vector from a ``RegulatorInputs``-like object."""
    raw = np.array([inputs.vx - inputs.vx_des, inputs.vy - inputs.vy_des, inputs.vx_des,
                    inputs.vy_des, inputs.pitch, inputs.roll, inputs.pitch_rate,
                    inputs.roll_rate, 1.0])
    return raw / FEATURE_SCALES


@dataclass
class HzdPolicy:
    """A fixed linear policy with the regulator's ``step(inputs, dt) -> dict`` interface."""

    weights: np.ndarray = field(default_factory=lambda: np.zeros((len(OFFSET_NAMES), len(FEATURE_NAMES))))
    _held: np.ndarray = field(default=None, init=False, repr=False)
    _step: int = field(default=-1, init=False, repr=False)

    def __post_init__(self):
        w = np.asarray(self.weights, dtype=float)
        shape = (len(OFFSET_NAMES), len(FEATURE_NAMES))
        if w.shape != shape or not np.all(np.isfinite(w)):
            raise ValueError(f"weights: must be a finite {shape[0]} x {shape[1]} array, got shape {w.shape}")
        self.weights = w
        self._held = np.zeros(shape[0])

    def action(self, inputs) -> np.ndarray:
        """The six offsets (rad) for these inputs, without holding.

        ``W @ features`` is summed feature by feature, left to right, in scalar arithmetic:
        a numpy matrix product goes through the BLAS kernel OpenBLAS picks for the CPU,
        whose summation order (and FMA use) differs from one CPU to another."""
        f = features(inputs).tolist()
        out = []
        for row in self.weights.tolist():
            acc = 0.0
            for w, x in zip(row, f):
                acc += w * x
            out.append(min(max(acc, -DELTA_LIMIT_RAD), DELTA_LIMIT_RAD))
        return np.array(out)

    def step(self, inputs, dt: float) -> dict[str, float]:
        """One call: a new action at each new walking step, held in between."""
        if inputs.step_index != self._step:
            self._step = inputs.step_index
            self._held = self.action(inputs)
        return dict(zip(OFFSET_NAMES, map(float, self._held)))


def save_policy(path: Path, weights: np.ndarray, settings: dict, curve: list[dict]) -> None:
    """Write weights with the training settings and curve (JSON, exact floats)."""
    doc = {"format": FORMAT, "feature_names": list(FEATURE_NAMES),
           "feature_scales": FEATURE_SCALES.tolist(), "outputs": list(OFFSET_NAMES),
           "delta_limit_rad": DELTA_LIMIT_RAD, "weights": np.asarray(weights).tolist(),
           "training": settings, "curve": curve}
    Path(path).write_text(json.dumps(doc, indent=1) + "\n")


def load_policy(path: Path = DEFAULT_POLICY) -> HzdPolicy:
    """Read a policy written by :func:`save_policy`; ValueError names what does not fit."""
    doc = json.loads(Path(path).read_text())
    problems = []
    if doc.get("format") != FORMAT:
        problems.append(f"format = {doc.get('format')!r}: must be {FORMAT!r}")
    if doc.get("feature_names") != list(FEATURE_NAMES):
        problems.append(f"feature_names: must be {list(FEATURE_NAMES)}")
    if doc.get("feature_scales") != FEATURE_SCALES.tolist():
        problems.append(f"feature_scales: must be {FEATURE_SCALES.tolist()}")
    if doc.get("outputs") != list(OFFSET_NAMES):
        problems.append(f"outputs: must be {list(OFFSET_NAMES)}")
    if problems:
        raise ValueError(f"{path}: " + "; ".join(problems))
    return HzdPolicy(np.array(doc["weights"], dtype=float))
