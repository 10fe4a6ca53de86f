"""The scenario model: frozen dataclasses a validated scenario file becomes.

Times are on the communication grid; the schedule is read by integer step counters
(never accumulated floats). :mod:`scenarios.lang.spec` builds these from TOML.
"""
from __future__ import annotations

import bisect
import functools
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


#: The body a push acts on unless it names another (the MuJoCo body name of both models).
PELVIS = "cassie-pelvis"


@dataclass(frozen=True)
class CommandPoint:
    """From ``t_s`` on (until the next point), command (vx_des, vy_des) in m/s (heading
    frame) and yaw_rate_des in rad/s (positive turns left). ``ramp``: the command
    reaches these values linearly from the previous point's (a ramp over the
    communication steps between the two points' times) instead of stepping at ``t_s``."""

    t_s: float
    vx_des: float
    vy_des: float = 0.0
    yaw_rate_des: float = 0.0
    ramp: bool = False


@dataclass(frozen=True)
class Push:
    """A constant world-frame force on ``body`` (at its COM) from ``t_s`` for ``duration_s``."""

    t_s: float
    force_n: tuple[float, float, float]
    duration_s: float
    body: str = PELVIS


@dataclass(frozen=True)
class LinkMass:
    """One link's mass: ``scale`` times the model's, or ``mass_kg`` (exactly one is set)."""

    body: str
    scale: float | None = None
    mass_kg: float | None = None


@dataclass(frozen=True)
class Event:
    """At ``t_s`` during the walk, the plant changes: each field given replaces the
    scenario's value of the same name from then on (None: unchanged)."""

    t_s: float
    torso_mass_kg: float | None = None
    torso_com_offset_m: tuple[float, float, float] | None = None
    joint_damping_scale: float | None = None
    floor_friction: float | None = None


@dataclass(frozen=True)
class CommandProfile:
    """A seeded random command: a new (vx_des, vy_des) drawn uniformly every ``hold_s``,
    held (``shape = "stepped"``) or reached linearly (``"ramped"``)."""

    shape: str
    seed: int
    hold_s: float
    vx_range: tuple[float, float]
    vy_range: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class RandomPushes:
    """``count`` pushes drawn from ``seed``: start time uniform in ``t_range_s`` (on the
    grid), horizontal direction uniform in [0, 360) deg, magnitude uniform in
    ``magnitude_range_n``, each ``duration_s`` long, on a body drawn from ``bodies``."""

    count: int
    seed: int
    t_range_s: tuple[float, float]
    magnitude_range_n: tuple[float, float]
    duration_s: float
    bodies: tuple[str, ...] = (PELVIS,)


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
    floor_friction: float | None = None
    slope_deg: float = 0.0
    cross_slope_deg: float = 0.0
    link_masses: tuple[LinkMass, ...] = ()
    events: tuple[Event, ...] = ()
    command_profile: CommandProfile | None = None
    random_pushes: RandomPushes | None = None

    @property
    def n_comm_steps(self) -> int:
        return to_step(self.duration_s, self.comm_step_s)

    def command_at_step(self, k: int) -> tuple[float, float, float]:
        """The command (vx_des, vy_des, yaw_rate_des) in force over communication step
        ``k`` (piecewise constant): the last point of the schedule, read in order up to the
        first one that starts after ``k``, that starts at or before ``k`` (the first point
        before any). O(log n): a bisection over the points' running-maximum start steps."""
        starts, points = self._command_index
        i = max(bisect.bisect_right(starts, k) - 1, 0)
        cmd = points[i]
        if i + 1 < len(points) and points[i + 1].ramp and starts[i + 1] > starts[i]:
            nxt, a = points[i + 1], (k - starts[i]) / (starts[i + 1] - starts[i])
            return (cmd.vx_des + a * (nxt.vx_des - cmd.vx_des), cmd.vy_des + a * (nxt.vy_des - cmd.vy_des),
                    cmd.yaw_rate_des + a * (nxt.yaw_rate_des - cmd.yaw_rate_des))
        return cmd.vx_des, cmd.vy_des, cmd.yaw_rate_des

    def push_force_at_step(self, k: int) -> tuple[float, float, float]:
        """Sum of the pelvis pushes active over communication step ``k`` (push ``p`` is active over
        steps ``[k0, k0 + n)``), added from 0.0 in the file's order. O(log n): a bisection
        over the steps where the set of active pushes changes, each segment's sum computed
        once, the first time it is asked for."""
        bounds, sums, active = self._push_index
        i = bisect.bisect_right(bounds, k) - 1
        if i < 0:
            return (0.0, 0.0, 0.0)
        if sums[i] is None:
            fx = fy = fz = 0.0
            for j in active[i]:
                f = self.pushes[j].force_n
                fx += f[0]
                fy += f[1]
                fz += f[2]
            sums[i] = (fx, fy, fz)
        return sums[i]

    @property
    def push_switch_steps(self) -> list[int]:
        """The steps at which the pushes in force change (their sum is constant in between)."""
        return self._push_index[0]

    @functools.cached_property
    def _command_index(self) -> tuple[list[int], tuple[CommandPoint, ...]]:
        """(running maximum of the points' start steps, the points): the first point
        starting after ``k`` is the first whose running maximum exceeds ``k``, which is
        where a linear scan of the schedule stops."""
        starts, top = [], None
        for point in self.commands:
            step = to_step(point.t_s, self.comm_step_s)
            top = step if top is None else max(top, step)
            starts.append(top)
        return starts, self.commands

    @functools.cached_property
    def _push_index(self) -> tuple[list[int], list, list[tuple[int, ...]]]:
        """(the steps where the active set changes, each segment's force, filled in when
        first asked for, and the pushes active over each segment in file order)."""
        spans = []
        for j, p in enumerate(self.pushes):
            if p.body != PELVIS:  # body_forces_at_step
                continue
            k0 = to_step(p.t_s, self.comm_step_s)
            spans.append((k0, k0 + to_step(p.duration_s, self.comm_step_s), j))
        bounds = sorted({k for k0, k1, _ in spans if k0 < k1 for k in (k0, k1)})
        starts: dict[int, list[int]] = {}
        ends: dict[int, list[int]] = {}
        for k0, k1, j in spans:
            if k0 < k1:
                starts.setdefault(k0, []).append(j)
                ends.setdefault(k1, []).append(j)
        active: list[tuple[int, ...]] = []
        now: set[int] = set()
        for b in bounds:
            now.difference_update(ends.get(b, ()))
            now.update(starts.get(b, ()))
            active.append(tuple(sorted(now)))
        return bounds, [None] * len(bounds), active

    def body_forces_at_step(self, k: int) -> dict[str, tuple[float, float, float]]:
        """{body: sum of its pushes active over step ``k``} for the pushes on bodies other
        than the pelvis (the pelvis': :meth:`push_force_at_step`)."""
        out: dict[str, tuple[float, float, float]] = {}
        for p in self.pushes:
            if p.body == PELVIS:
                continue
            k0 = to_step(p.t_s, self.comm_step_s)
            if k0 <= k < k0 + to_step(p.duration_s, self.comm_step_s):
                f = out.get(p.body, (0.0, 0.0, 0.0))
                out[p.body] = (f[0] + p.force_n[0], f[1] + p.force_n[1], f[2] + p.force_n[2])
        return out

    @property
    def pushed_bodies(self) -> tuple[str, ...]:
        """The bodies other than the pelvis that some push acts on."""
        return tuple(sorted({p.body for p in self.pushes if p.body != PELVIS}))

    def events_at_step(self, k: int) -> tuple[Event, ...]:
        """The events taking place at the start of communication step ``k``."""
        return tuple(e for e in self.events if to_step(e.t_s, self.comm_step_s) == k)

    def arm(self, name: str) -> Arm:
        for a in self.arms:
            if a.name == name:
                return a
        raise KeyError(f"scenario {self.name!r} has no arm {name!r}; arms: {[a.name for a in self.arms]}")


def to_step(t: float, h: float) -> int:
    """The grid step of time ``t`` on a grid of step ``h``."""
    return int(round(t / h))
