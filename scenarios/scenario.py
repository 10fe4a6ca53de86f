"""The scenario model: frozen dataclasses a validated scenario file becomes.

Times are on the communication grid; the schedule is read by integer step counters
(never accumulated floats). :mod:`scenarios.spec` builds these from TOML.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from plant.terrain import TerrainSpec as _TerrainSpec

#: The plant's integration step (Cassie's 2 kHz); the master re-checks it against
#: ``plant.sim.SIM_DT_S`` when it runs.
PLANT_DT_S = 0.0005
DEFAULT_COMM_STEP_S = 0.005
DEFAULT_MODEL = "menagerie"
BUILTIN_MODELS = ("menagerie", "osu")
BUILTIN_ARMS = ("adaptive", "pd_only", "rl_hzd")
#: What drives an arm: the regulator (FMU or core, per ``--regulator``) or the fixed
#: RL-HZD policy (:mod:`scenarios.rl_hzd`, in-process whatever ``--regulator`` says).
CONTROLLERS = ("regulator", "rl_hzd")
#: Half-size of the terrain square and radius of its flat start patch, m, unless the file
#: says: the plant's own defaults.
DEFAULT_TERRAIN_SIZE_M = _TerrainSpec.size_m
DEFAULT_FLAT_RADIUS_M = _TerrainSpec.flat_radius_m
#: Metrics a claim check may name (the keys of each arm in ``summary.json``).
CHECKABLE_METRICS = (
    "fell",
    "t_fall_s",
    "steady_state_error_vx",
    "steady_state_error_vy",
    "steady_state_error_vy_stride",
    "steady_state_error_yaw_rate",
    "run_error_vx",
    "convergence_time_s",
    "mean_vx_last_s",
    "mean_vy_last_s",
    "max_abs_pitch_rad",
    "max_abs_roll_rad",
    "mean_delta_swing_hip_pitch_last_s",
    "mean_delta_swing_knee_last_s",
)
CHECK_OPS = ("<", "<=", ">", ">=", "==", "!=")


@dataclass(frozen=True)
class CommandPoint:
    """From ``t_s`` on (until the next point), command (vx_des, vy_des) in m/s (heading
    frame) and yaw_rate_des in rad/s (positive turns left)."""

    t_s: float
    vx_des: float
    vy_des: float = 0.0
    yaw_rate_des: float = 0.0


@dataclass(frozen=True)
class Push:
    """A constant world-frame force on the pelvis from ``t_s`` for ``duration_s``."""

    t_s: float
    force_n: tuple[float, float, float]
    duration_s: float


@dataclass(frozen=True)
class Terrain:
    """Random uneven terrain (the plant's TerrainSpec)."""

    max_height_m: float
    max_slope_deg: float
    seed: int
    size_m: float = DEFAULT_TERRAIN_SIZE_M
    flat_radius_m: float = DEFAULT_FLAT_RADIUS_M


@dataclass(frozen=True)
class Arm:
    """One regulator configuration run over the same plant and command schedule.

    ``overrides`` are the final FMU parameter values for this arm (the scenario's
    ``[regulator]`` table with the arm's own overrides on top), as sorted pairs;
    ``controller`` is one of ``CONTROLLERS`` (the ``rl_hzd`` arm has no overrides).
    """

    name: str
    overrides: tuple[tuple[str, Any], ...]
    description: str = ""
    controller: str = "regulator"

    def overrides_dict(self) -> dict[str, Any]:
        return dict(self.overrides)


@dataclass(frozen=True)
class ClaimCheck:
    """``arm.metric op value`` or ``arm.metric op other_arm.metric``."""

    arm: str
    metric: str
    op: str
    value: Any = None
    other_arm: str | None = None


@dataclass(frozen=True)
class Claim:
    text: str
    source: str = ""
    checks: tuple[ClaimCheck, ...] = ()


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    duration_s: float
    model: str
    comm_step_s: float
    seed: int
    commands: tuple[CommandPoint, ...]
    arms: tuple[Arm, ...]
    tags: tuple[str, ...] = ()
    perturbation_t_s: float = 0.0
    torso_mass_kg: float | None = None
    torso_added_mass_kg: float | None = None
    torso_com_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joint_damping_scale: float = 1.0
    pushes: tuple[Push, ...] = ()
    terrain: Terrain | None = None
    claim: Claim | None = None
    source: str | None = None

    @property
    def n_comm_steps(self) -> int:
        return to_step(self.duration_s, self.comm_step_s)

    def command_at_step(self, k: int) -> tuple[float, float, float]:
        """The command (vx_des, vy_des, yaw_rate_des) in force over communication step
        ``k`` (piecewise constant)."""
        cmd = self.commands[0]
        for point in self.commands:
            if to_step(point.t_s, self.comm_step_s) <= k:
                cmd = point
            else:
                break
        return cmd.vx_des, cmd.vy_des, cmd.yaw_rate_des

    def push_force_at_step(self, k: int) -> tuple[float, float, float]:
        """Sum of the pushes active over communication step ``k``."""
        fx = fy = fz = 0.0
        for p in self.pushes:
            k0 = to_step(p.t_s, self.comm_step_s)
            k1 = k0 + to_step(p.duration_s, self.comm_step_s)
            if k0 <= k < k1:
                fx += p.force_n[0]
                fy += p.force_n[1]
                fz += p.force_n[2]
        return (fx, fy, fz)

    def arm(self, name: str) -> Arm:
        for a in self.arms:
            if a.name == name:
                return a
        raise KeyError(f"scenario {self.name!r} has no arm {name!r}; arms: {[a.name for a in self.arms]}")


def to_step(t: float, h: float) -> int:
    """The grid step of time ``t`` on a grid of step ``h``."""
    return int(round(t / h))
