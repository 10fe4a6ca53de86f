"""Scenario files: TOML parsed into frozen dataclasses, validated before anything runs.

A scenario file describes one closed-loop experiment: how long, which model, the
communication step, a piecewise-constant velocity command schedule, plant
perturbations (torso mass, torso COM offset, joint damping, pushes, terrain),
regulator parameter overrides (by FMU variable name), the arms to compare
(e.g. ``adaptive`` vs ``pd_only``) and the paper's claim with machine-checkable
checks for the report.

Every problem in a file is collected and reported at once (``ScenarioError.problems``),
each naming its field, e.g. ``push[1].duration_s = -0.1: must be > 0``; a file that
cannot be read (missing, a directory, not UTF-8) is one problem naming it. Scenario
names must be unique within a run (:func:`distinct`): the name is the output folder.

Layout of a file (every key below is known; anything else is an error)::

    name = "mass_15kg"              # [a-z0-9_-]+, used as the output folder name
    description = "..."
    tags = ["paper"]                # optional; `run paper` runs files tagged paper
    duration_s = 50.0               # whole number of communication steps
    model = "menagerie"             # "menagerie", "osu" or a path to an MJCF file
    comm_step_s = 0.005             # whole number of plant steps (0.5 ms)
    seed = 1                        # required: the regulator's `seed` parameter (weights init)
    perturbation_t_s = 0.0          # when the perturbation starts mattering (metrics)
    torso_mass_kg = 15.0            # absolute torso (pelvis) mass; or
    torso_added_mass_kg = 5.0       # mass added to the model's own torso mass
    torso_com_offset_m = [0.1, 0.0, 0.0]
    joint_damping_scale = 1.0
    compare = ["adaptive", "pd_only"]   # arms to run; default ["adaptive"]

    [[command]]                     # piecewise constant, the first at t_s = 0
    t_s = 0.0
    vx_des = 0.5
    vy_des = 0.0

    [[push]]                        # constant world-frame force on the pelvis
    t_s = 2.5
    force_n = [30.0, 0.0, 0.0]
    duration_s = 0.1

    [terrain]                       # the field spans [-size_m, size_m]^2; no ground outside
    max_height_m = 0.4
    max_slope_deg = 20.0
    seed = 3
    size_m = 20.0                   # optional

    [regulator]                     # overrides for every arm, by FMU parameter name
    learning_rate = 0.01

    [[arm]]                         # a named arm: its overrides go on top of [regulator]
    name = "hip_zero"
    description = "..."
    regulator = { psi_gain_swing_hip_pitch = 0.0 }

    [claim]
    text = "The paper's claim, paraphrased"
    source = "Castillo et al., IROS 2020, Sec. V"
    [[claim.check]]                 # arm.metric op value, or arm.metric op other_arm.metric
    arm = "adaptive"
    metric = "steady_state_error_vx"
    op = "<="
    value = 0.1

Built-in arms: ``adaptive`` (the ``[regulator]`` overrides as they are) and
``pd_only`` (the same with ``adaptation_enabled = false``).  A ``[[arm]]`` may not
reuse a built-in name, and every defined arm must be listed in ``compare`` when
``compare`` is given (no arm is silently left out).
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from scenarios.errors import ScenarioError

#: The plant's integration step (Cassie's 2 kHz); the master re-checks it against
#: ``plant.sim.SIM_DT_S`` when it runs.
PLANT_DT_S = 0.0005
DEFAULT_COMM_STEP_S = 0.005
BUILTIN_MODELS = ("menagerie", "osu")
BUILTIN_ARMS = ("adaptive", "pd_only")
#: Metrics a claim check may name (the keys of each arm in ``summary.json``).
CHECKABLE_METRICS = (
    "fell",
    "t_fall_s",
    "steady_state_error_vx",
    "steady_state_error_vy",
    "steady_state_error_vy_stride",
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
SUITE_DIR = Path(__file__).resolve().parent / "suite"

_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_\-]*$")
_GRID_TOL = 1e-9


# --------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class CommandPoint:
    """From ``t_s`` on (until the next point), command (vx_des, vy_des) in m/s."""

    t_s: float
    vx_des: float
    vy_des: float = 0.0


@dataclass(frozen=True)
class Push:
    """A constant world-frame force on the pelvis from ``t_s`` for ``duration_s``."""

    t_s: float
    force_n: tuple[float, float, float]
    duration_s: float


@dataclass(frozen=True)
class Terrain:
    """Random uneven terrain (plant.model.TerrainSpec)."""

    max_height_m: float
    max_slope_deg: float
    seed: int
    size_m: float = 20.0


@dataclass(frozen=True)
class Arm:
    """One regulator configuration run over the same plant and command schedule.

    ``overrides`` are the final FMU parameter values for this arm (the scenario's
    ``[regulator]`` table with the arm's own overrides on top), as sorted pairs.
    """

    name: str
    overrides: tuple[tuple[str, Any], ...]
    description: str = ""

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

    def describe(self) -> str:
        rhs = f"{self.other_arm}.{self.metric}" if self.other_arm else _fmt(self.value)
        return f"{self.arm}.{self.metric} {self.op} {rhs}"


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

    # ---- the time grid (integer counters, never accumulated floats)
    @property
    def n_comm_steps(self) -> int:
        return int(round(self.duration_s / self.comm_step_s))

    @property
    def plant_steps_per_comm(self) -> int:
        return int(round(self.comm_step_s / PLANT_DT_S))

    def command_at_step(self, k: int) -> tuple[float, float]:
        """The command in force over communication step ``k`` (piecewise constant)."""
        cmd = self.commands[0]
        for point in self.commands:
            if _to_step(point.t_s, self.comm_step_s) <= k:
                cmd = point
            else:
                break
        return cmd.vx_des, cmd.vy_des

    def push_force_at_step(self, k: int) -> tuple[float, float, float]:
        """Sum of the pushes active over communication step ``k``."""
        fx = fy = fz = 0.0
        for p in self.pushes:
            k0 = _to_step(p.t_s, self.comm_step_s)
            k1 = k0 + _to_step(p.duration_s, self.comm_step_s)
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

    def is_perturbed(self) -> bool:
        return bool(
            self.torso_mass_kg is not None
            or self.torso_added_mass_kg
            or any(self.torso_com_offset_m)
            or self.joint_damping_scale != 1.0
            or self.pushes
            or self.terrain is not None
        )


def _to_step(t: float, h: float) -> int:
    return int(round(t / h))


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v) if isinstance(v, str) else f"{v:g}" if isinstance(v, float) else str(v)


# --------------------------------------------------------------------------- field checking
class _Problems:
    """Collects problems; each names its field."""

    def __init__(self) -> None:
        self.items: list[str] = []

    def add(self, field: str, value: Any, why: str) -> None:
        self.items.append(f"{field} = {_show(value)}: {why}")

    def note(self, field: str, why: str) -> None:
        self.items.append(f"{field}: {why}")


def _show(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{...}"
    return str(v)


def _unknown_keys(table: Mapping[str, Any], known: tuple[str, ...], prefix: str, probs: _Problems) -> None:
    for key in table:
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else f"; known keys: {', '.join(known)}"
            probs.note(f"{prefix}{key}", "unknown key" + hint)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(table, key, field, probs, *, required=False, default=None, gt=None, ge=None, le=None, lt=None):
    if key not in table:
        if required:
            probs.note(field, "required")
        return default
    v = table[key]
    if not _is_number(v):
        probs.add(field, v, "must be a number")
        return default
    v = float(v)
    if not math.isfinite(v):
        probs.add(field, v, "must be finite")
        return default
    ok = True
    if gt is not None and not v > gt:
        probs.add(field, v, f"must be > {gt:g}")
        ok = False
    if ge is not None and not v >= ge:
        probs.add(field, v, f"must be >= {ge:g}")
        ok = False
    if le is not None and not v <= le:
        probs.add(field, v, f"must be <= {le:g}")
        ok = False
    if lt is not None and not v < lt:
        probs.add(field, v, f"must be < {lt:g}")
        ok = False
    return v if ok else default


def _integer(table, key, field, probs, *, required=False, default=None, ge=None):
    if key not in table:
        if required:
            probs.note(field, "required")
        return default
    v = table[key]
    if not isinstance(v, int) or isinstance(v, bool):
        probs.add(field, v, "must be an integer")
        return default
    if ge is not None and v < ge:
        probs.add(field, v, f"must be >= {ge}")
        return default
    return v


def _string(table, key, field, probs, *, required=False, default=""):
    if key not in table:
        if required:
            probs.note(field, "required")
        return default
    v = table[key]
    if not isinstance(v, str):
        probs.add(field, v, "must be a string")
        return default
    return v


def _vec3(table, key, field, probs, *, default=None):
    if key not in table:
        return default
    v = table[key]
    if not isinstance(v, list) or len(v) != 3 or not all(_is_number(x) for x in v):
        probs.add(field, v, "must be a list of 3 numbers [x, y, z]")
        return default
    if not all(math.isfinite(float(x)) for x in v):
        probs.add(field, v, "must be finite")
        return default
    return (float(v[0]), float(v[1]), float(v[2]))


def _table_list(doc, key, field, probs) -> list[dict]:
    if key not in doc:
        return []
    v = doc[key]
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        probs.add(field, v, f"must be an array of tables ([[{key}]])")
        return []
    return v


def _on_grid(t: float, h: float) -> bool:
    n = t / h
    return abs(n - round(n)) < 1e-6


# --------------------------------------------------------------------------- regulator params
def regulator_param_specs() -> dict[str, Any]:
    """The regulator core's PARAM_SPECS by name (VarSpec: name, type, default, min, max, ...)."""
    from fmu_src import avr_core

    return {spec.name: spec for spec in avr_core.PARAM_SPECS}


def _check_overrides(raw: Any, field: str, specs: Mapping[str, Any] | None, probs: _Problems) -> dict[str, Any]:
    """Check overrides by FMU parameter name: known name, type and range; return typed values."""
    if not isinstance(raw, dict):
        probs.add(field, raw, "must be a table of FMU parameter overrides")
        return {}
    if specs is None:
        return dict(raw)
    out: dict[str, Any] = {}
    names = tuple(specs)
    for key, v in raw.items():
        f = f"{field}.{key}"
        spec = specs.get(key)
        if spec is None:
            close = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else "; see the FMU's parameters (PARAM_SPECS)"
            probs.note(f, "unknown regulator parameter" + hint)
            continue
        kind = str(spec.type).lower()
        if kind.startswith("bool"):
            if not isinstance(v, bool):
                probs.add(f, v, "must be a boolean (true/false)")
                continue
            out[key] = v
            continue
        if kind.startswith("int"):
            if not isinstance(v, int) or isinstance(v, bool):
                probs.add(f, v, "must be an integer")
                continue
            value: Any = int(v)
        else:
            if not _is_number(v) or not math.isfinite(float(v)):
                probs.add(f, v, "must be a finite number")
                continue
            value = float(v)
        lo, hi = spec.min, spec.max
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            probs.add(f, v, f"out of range [{_show(lo)}, {_show(hi)}]" + (f" {spec.unit}" if getattr(spec, "unit", "") else ""))
            continue
        out[key] = value
    return out


def _core_validate(overrides: Mapping[str, Any], field: str, probs: _Problems) -> None:
    """Cross-field checks of the core (``validate_params``) on the merged parameter set."""
    from fmu_src import avr_core
    from fmu_src.avr_errors import ParameterError

    try:
        params = avr_core.RegulatorParams(**overrides)
        avr_core.validate_params(params)
    except ParameterError as exc:
        for p in exc.problems:
            probs.note(field, p)
    except TypeError as exc:  # pragma: no cover - only if the core's API drifts
        probs.note(field, f"cannot build RegulatorParams: {exc}")


# --------------------------------------------------------------------------- parse + validate
TOP_KEYS = (
    "name", "description", "tags", "duration_s", "model", "comm_step_s", "seed",
    "perturbation_t_s", "torso_mass_kg", "torso_added_mass_kg", "torso_com_offset_m",
    "joint_damping_scale", "compare", "command", "push", "terrain", "regulator", "arm", "claim",
)
COMMAND_KEYS = ("t_s", "vx_des", "vy_des")
PUSH_KEYS = ("t_s", "force_n", "duration_s")
TERRAIN_KEYS = ("max_height_m", "max_slope_deg", "seed", "size_m")
ARM_KEYS = ("name", "description", "regulator")
CLAIM_KEYS = ("text", "source", "check")
CHECK_KEYS = ("arm", "metric", "op", "value", "other_arm")


def parse_scenario(doc: Mapping[str, Any], source: str | None = None, *, base_dir: Path | None = None,
                   check_plant: bool = True) -> Scenario:
    """Validate a parsed TOML document; raise ScenarioError listing every problem.

    ``base_dir`` resolves a relative model path (the scenario file's folder).
    ``check_plant`` also checks what loading the plant would fail on (needs mujoco): the
    model parses safely, compiles and is a Cassie, and the perturbation is valid on it
    (:func:`scenarios.plantio.check_plant`).
    """
    probs = _Problems()
    _unknown_keys(doc, TOP_KEYS, "", probs)

    name = _string(doc, "name", "name", probs, required=True)
    if "name" in doc and isinstance(doc["name"], str) and not _NAME_RE.match(name):
        probs.add("name", name, "must match [a-z0-9][a-z0-9_-]* (it names the output folder)")
    description = _string(doc, "description", "description", probs)
    tags_raw = doc.get("tags", [])
    tags: tuple[str, ...] = ()
    if not isinstance(tags_raw, list) or not all(isinstance(t, str) for t in tags_raw):
        probs.add("tags", tags_raw, "must be a list of strings")
    else:
        tags = tuple(tags_raw)

    h = _number(doc, "comm_step_s", "comm_step_s", probs, default=DEFAULT_COMM_STEP_S, gt=0.0, le=1.0)
    h_ok = h is not None
    if "comm_step_s" in doc and h_ok and not _on_grid(h, PLANT_DT_S):
        probs.add("comm_step_s", h, f"must be a whole multiple of the plant step {PLANT_DT_S * 1000:g} ms")
        h_ok = False
    if not h_ok:
        h = DEFAULT_COMM_STEP_S  # keep checking the rest against a sane grid
    duration = _number(doc, "duration_s", "duration_s", probs, required=True, gt=0.0, le=3600.0)
    if duration is not None and h_ok and not _on_grid(duration, h):
        probs.add("duration_s", duration, f"must be a whole number of communication steps ({h:g} s)")

    model = _string(doc, "model", "model", probs, default="menagerie")
    if isinstance(doc.get("model", ""), str):
        model = resolve_model(model, base_dir, probs)
    seed = _integer(doc, "seed", "seed", probs, required=True, default=0, ge=0)  # seeds are explicit
    pert_t = _number(doc, "perturbation_t_s", "perturbation_t_s", probs, default=0.0, ge=0.0)
    if pert_t is not None and duration is not None and pert_t >= duration:
        probs.add("perturbation_t_s", pert_t, f"must be < duration_s = {duration:g}")

    # ---- perturbations
    mass = _number(doc, "torso_mass_kg", "torso_mass_kg", probs, gt=0.0, le=200.0)
    added = _number(doc, "torso_added_mass_kg", "torso_added_mass_kg", probs, gt=-50.0, le=200.0)
    if "torso_mass_kg" in doc and "torso_added_mass_kg" in doc:
        probs.note("torso_added_mass_kg", "give torso_mass_kg (absolute) or torso_added_mass_kg, not both")
    com = _vec3(doc, "torso_com_offset_m", "torso_com_offset_m", probs, default=(0.0, 0.0, 0.0))
    if com is not None and any(abs(c) > 0.5 for c in com):
        probs.add("torso_com_offset_m", list(com), "each component must be within [-0.5, 0.5] m")
    damping = _number(doc, "joint_damping_scale", "joint_damping_scale", probs, default=1.0, ge=0.0, le=10.0)

    # ---- command schedule
    commands: list[CommandPoint] = []
    cmd_tables = _table_list(doc, "command", "command", probs)
    if doc.get("command", []) == []:  # absent, or `command = []`
        probs.note("command", "required: at least one [[command]] with t_s = 0")
    for i, c in enumerate(cmd_tables):
        f = f"command[{i}]"
        _unknown_keys(c, COMMAND_KEYS, f + ".", probs)
        t = _number(c, "t_s", f + ".t_s", probs, required=True, ge=0.0)
        vx = _number(c, "vx_des", f + ".vx_des", probs, required=True, ge=-2.0, le=2.0)
        vy = _number(c, "vy_des", f + ".vy_des", probs, default=0.0, ge=-1.0, le=1.0)
        if t is not None and h_ok and not _on_grid(t, h):
            probs.add(f + ".t_s", t, f"must be on the communication grid (a multiple of {h:g} s)")
        if t is not None and duration is not None and t >= duration:
            probs.add(f + ".t_s", t, f"must be < duration_s = {duration:g}")
        if t is not None and vx is not None and vy is not None:
            commands.append(CommandPoint(t, vx, vy))
    if cmd_tables:
        ts = [c.get("t_s") for c in cmd_tables]
        if ts and ts[0] != 0 and _is_number(ts[0]):
            probs.add("command[0].t_s", ts[0], "the first command must be at t_s = 0")
        for i in range(1, len(ts)):
            if _is_number(ts[i]) and _is_number(ts[i - 1]) and not ts[i] > ts[i - 1]:
                probs.add(f"command[{i}].t_s", ts[i], f"must be > command[{i - 1}].t_s = {_show(ts[i - 1])} (increasing)")

    # ---- pushes
    pushes: list[Push] = []
    for i, p in enumerate(_table_list(doc, "push", "push", probs)):
        f = f"push[{i}]"
        _unknown_keys(p, PUSH_KEYS, f + ".", probs)
        t = _number(p, "t_s", f + ".t_s", probs, required=True, ge=0.0)
        force = _vec3(p, "force_n", f + ".force_n", probs)
        if "force_n" not in p:
            probs.note(f + ".force_n", "required")
        elif force is not None and math.sqrt(sum(x * x for x in force)) > 2000.0:
            probs.add(f + ".force_n", list(force), "magnitude must be <= 2000 N")
        dur = _number(p, "duration_s", f + ".duration_s", probs, required=True, gt=0.0)
        if t is not None and h_ok and not _on_grid(t, h):
            probs.add(f + ".t_s", t, f"must be on the communication grid (a multiple of {h:g} s)")
        if dur is not None and h_ok and not _on_grid(dur, h):
            probs.add(f + ".duration_s", dur, f"must be a whole number of communication steps ({h:g} s)")
        if t is not None and duration is not None and t >= duration:
            probs.add(f + ".t_s", t, f"must be < duration_s = {duration:g}")
        if t is not None and force is not None and dur is not None:
            pushes.append(Push(t, force, dur))

    # ---- terrain
    terrain = None
    if "terrain" in doc:
        tt = doc["terrain"]
        if not isinstance(tt, dict):
            probs.add("terrain", tt, "must be a table ([terrain])")
        else:
            _unknown_keys(tt, TERRAIN_KEYS, "terrain.", probs)
            hmax = _number(tt, "max_height_m", "terrain.max_height_m", probs, required=True, gt=0.0, le=1.0)
            smax = _number(tt, "max_slope_deg", "terrain.max_slope_deg", probs, required=True, gt=0.0, le=45.0)
            tseed = _integer(tt, "seed", "terrain.seed", probs, required=True, ge=0)
            size = _number(tt, "size_m", "terrain.size_m", probs, default=20.0, ge=2.0, le=100.0)
            if hmax is not None and smax is not None and tseed is not None and size is not None:
                terrain = Terrain(hmax, smax, tseed, size)

    # ---- regulator overrides and arms
    specs = None
    try:
        specs = regulator_param_specs()
    except ImportError as exc:
        probs.note("regulator", f"cannot check overrides: regulator core unavailable ({exc})")
    base = _check_overrides(doc.get("regulator", {}), "regulator", specs, probs)
    if "seed" in base and "seed" in doc:
        probs.note("regulator.seed", "the regulator's seed comes from the top-level `seed`; give it once")
    if specs is not None and "seed" in specs and "seed" not in base and seed is not None:
        base["seed"] = seed

    defined: dict[str, Arm] = {}
    for i, a in enumerate(_table_list(doc, "arm", "arm", probs)):
        f = f"arm[{i}]"
        _unknown_keys(a, ARM_KEYS, f + ".", probs)
        aname = _string(a, "name", f + ".name", probs, required=True)
        if not aname:
            continue
        if not _NAME_RE.match(aname):
            probs.add(f + ".name", aname, "must match [a-z0-9][a-z0-9_-]*")
        if aname in BUILTIN_ARMS:
            probs.add(f + ".name", aname, f"is a built-in arm ({', '.join(BUILTIN_ARMS)}); pick another name")
            continue
        if aname in defined:
            probs.add(f + ".name", aname, "duplicate arm name")
            continue
        own = _check_overrides(a.get("regulator", {}), f + ".regulator", specs, probs)
        defined[aname] = Arm(aname, tuple(sorted({**base, **own}.items())), _string(a, "description", f + ".description", probs))

    arm_names: list[str]
    if "compare" in doc:
        comp = doc["compare"]
        if not isinstance(comp, list) or not comp or not all(isinstance(x, str) for x in comp):
            probs.add("compare", comp, "must be a non-empty list of arm names")
            arm_names = []
        else:
            arm_names = list(comp)
            for j, n in enumerate(comp):
                if n not in BUILTIN_ARMS and n not in defined:
                    known = BUILTIN_ARMS + tuple(defined)
                    close = difflib.get_close_matches(n, known, n=1, cutoff=0.6)
                    hint = f"; did you mean {close[0]!r}?" if close else f"; known arms: {', '.join(known)}"
                    probs.add(f"compare[{j}]", n, "unknown arm" + hint)
                if comp.count(n) > 1 and comp.index(n) == j:
                    probs.add("compare", comp, f"arm {n!r} listed twice")
            for n in defined:
                if n not in comp:
                    probs.note("compare", f"arm {n!r} is defined in [[arm]] but not listed; list it or remove it")
    else:
        arm_names = list(defined) if defined else ["adaptive"]

    arms: list[Arm] = []
    for n in arm_names:
        if n == "adaptive":
            arms.append(Arm("adaptive", tuple(sorted(base.items())), "all Psi outputs, adaptation on"))
        elif n == "pd_only":
            ov = {**base, "adaptation_enabled": False}
            arms.append(Arm("pd_only", tuple(sorted(ov.items())), "adaptation off (PD terms only)"))
        elif n in defined:
            arms.append(defined[n])
    if specs is not None:
        for arm in arms:
            _core_validate(arm.overrides_dict(), f"arm {arm.name!r} parameters", probs)

    # ---- claim
    claim = None
    if "claim" in doc:
        ct = doc["claim"]
        if not isinstance(ct, dict):
            probs.add("claim", ct, "must be a table ([claim])")
        else:
            _unknown_keys(ct, CLAIM_KEYS, "claim.", probs)
            text = _string(ct, "text", "claim.text", probs, required=True)
            src = _string(ct, "source", "claim.source", probs)
            checks = []
            for j, ch in enumerate(_table_list(ct, "check", "claim.check", probs)):
                f = f"claim.check[{j}]"
                _unknown_keys(ch, CHECK_KEYS, f + ".", probs)
                carm = _string(ch, "arm", f + ".arm", probs, required=True)
                if carm and arm_names and carm not in arm_names:
                    probs.add(f + ".arm", carm, f"not an arm of this scenario ({', '.join(arm_names)})")
                metric = _string(ch, "metric", f + ".metric", probs, required=True)
                if metric and metric not in CHECKABLE_METRICS:
                    close = difflib.get_close_matches(metric, CHECKABLE_METRICS, n=1, cutoff=0.6)
                    hint = f"; did you mean {close[0]!r}?" if close else f"; known: {', '.join(CHECKABLE_METRICS)}"
                    probs.add(f + ".metric", metric, "unknown metric" + hint)
                op = _string(ch, "op", f + ".op", probs, required=True)
                if op and op not in CHECK_OPS:
                    probs.add(f + ".op", op, f"must be one of {', '.join(CHECK_OPS)}")
                other = ch.get("other_arm")
                value = ch.get("value")
                if ("value" in ch) == ("other_arm" in ch):
                    probs.note(f, "give exactly one of value or other_arm")
                if other is not None:
                    if not isinstance(other, str):
                        probs.add(f + ".other_arm", other, "must be a string")
                        other = None
                    elif arm_names and other not in arm_names:
                        probs.add(f + ".other_arm", other, f"not an arm of this scenario ({', '.join(arm_names)})")
                if "value" in ch and not (_is_number(value) or isinstance(value, bool)):
                    probs.add(f + ".value", value, "must be a number or a boolean")
                checks.append(ClaimCheck(carm, metric, op, value, other))
            claim = Claim(text, src, tuple(checks))

    scenario = None
    if not probs.items:
        scenario = Scenario(
            name=name, description=description, duration_s=duration, model=model, comm_step_s=h,
            seed=seed, commands=tuple(commands), arms=tuple(arms), tags=tags, perturbation_t_s=pert_t,
            torso_mass_kg=mass, torso_added_mass_kg=added, torso_com_offset_m=com,
            joint_damping_scale=damping, pushes=tuple(pushes), terrain=terrain, claim=claim, source=source,
        )
        if check_plant:
            _check_plant(scenario, probs)
    if probs.items:
        raise ScenarioError(probs.items, source=source)
    return scenario


def _check_plant(scenario: Scenario, probs: _Problems) -> None:
    """What loading the plant would fail on (the model compiles and is a Cassie, the
    perturbation is valid on it): :func:`scenarios.plantio.check_plant`."""
    from scenarios.plantio import check_plant

    for field, problem in check_plant(scenario):
        probs.note(field, problem)


def resolve_model(model: str, base_dir: Path | None, probs: _Problems | None = None) -> str:
    """``menagerie``/``osu`` as they are; a path resolved against the scenario's folder."""
    if model in BUILTIN_MODELS:
        return model
    path = Path(model).expanduser()
    if not path.is_absolute() and base_dir is not None and (base_dir / path).exists():
        path = base_dir / path
    if not path.exists():
        if probs is not None:
            probs.add("model", model, f"must be one of {', '.join(BUILTIN_MODELS)} or an existing MJCF (.xml) path")
        return model
    if path.suffix.lower() != ".xml":
        if probs is not None:
            probs.add("model", model, "a model path must be an MJCF .xml file")
    return str(path.resolve())


def override(scenario: Scenario, *, model: str | None = None, duration_s: float | None = None,
             base_dir: Path | None = None, check_plant: bool = True) -> Scenario:
    """The scenario with another model and/or duration (CLI flags), re-checked (a new
    model is compiled and checked as in :func:`parse_scenario` unless ``check_plant`` is false)."""
    probs = _Problems()
    changes: dict[str, Any] = {}
    if model is not None:
        changes["model"] = resolve_model(model, base_dir or Path.cwd(), probs)
    if duration_s is not None:
        d = _number({"duration_s": duration_s}, "duration_s", "--duration", probs, gt=0.0, le=3600.0)
        if d is not None and not _on_grid(d, scenario.comm_step_s):
            probs.add("--duration", d, f"must be a whole number of communication steps ({scenario.comm_step_s:g} s)")
        changes["duration_s"] = d
    if not probs.items and changes:
        scenario = dataclasses.replace(scenario, **changes)
        if check_plant and model is not None:
            _check_plant(scenario, probs)
    if probs.items:
        raise ScenarioError(probs.items, source=scenario.source)
    return scenario


def load_scenario(path: str | Path, *, check_plant: bool = True) -> Scenario:
    """Read and validate one scenario file (every problem reported at once)."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except FileNotFoundError:
        raise ScenarioError([f"file not found: {path}"], source=str(path)) from None
    except IsADirectoryError:
        raise ScenarioError(["is a directory, not a scenario file"], source=str(path)) from None
    except OSError as exc:
        raise ScenarioError([f"cannot read: {exc.strerror or exc}"], source=str(path)) from None
    except UnicodeDecodeError as exc:
        raise ScenarioError([f"not UTF-8 text (TOML files must be UTF-8): byte {exc.object[exc.start]:#04x} "
                             f"at offset {exc.start}"], source=str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError([f"TOML syntax error: {exc}"], source=str(path)) from None
    return parse_scenario(doc, source=str(path), base_dir=path.parent, check_plant=check_plant)


def suite_files() -> list[Path]:
    return sorted(SUITE_DIR.glob("*.toml"))


def load_suite(*, check_plant: bool = True) -> list[Scenario]:
    """Every suite file, validated; all problems of all files in one ScenarioError."""
    scenarios, problems = [], []
    for f in suite_files():
        try:
            scenarios.append(load_scenario(f, check_plant=check_plant))
        except ScenarioError as exc:
            problems.extend(f"{f.name}: {p}" for p in exc.problems)
    for s in scenarios:
        stem = Path(s.source).stem
        if s.name != stem:
            problems.append(f"{Path(s.source).name}: name = {s.name!r}: must equal the file name ({stem!r})")
    scenarios, clashes = distinct(scenarios)
    if problems or clashes:
        raise ScenarioError(problems + clashes, source=str(SUITE_DIR))
    return scenarios


def distinct(scenarios: list[Scenario]) -> tuple[list[Scenario], list[str]]:
    """Each scenario once (one file named twice runs once), and a problem for every name
    that two different files share (the name is the output folder: one would be lost)."""
    first: dict[str, Scenario] = {}
    unique, problems = [], []
    for s in scenarios:
        other = first.setdefault(s.name, s)
        if other is s:
            unique.append(s)
        elif _same_file(other.source, s.source):
            continue
        else:
            problems.append(f"name = {s.name!r}: in both {other.source} and {s.source}; scenario names must be "
                            "unique (each names its output folder)")
    return unique, problems


def _same_file(a: str | None, b: str | None) -> bool:
    try:
        return a is not None and b is not None and Path(a).resolve() == Path(b).resolve()
    except OSError:
        return a == b


def resolve_targets(targets: list[str], *, check_plant: bool = True) -> list[Scenario]:
    """``all``, ``paper``, a suite scenario name, or a path to a scenario file; every
    scenario once. ScenarioError lists every problem (invalid files, unknown names, two
    files with one name)."""
    out: list[Scenario] = []
    problems: list[str] = []
    suite: list[Scenario] | None = None
    for t in targets:
        p = Path(t)
        if t.endswith(".toml") or p.exists():
            try:
                out.append(load_scenario(p, check_plant=check_plant))
            except ScenarioError as exc:
                problems.extend(f"{t}: {q}" for q in exc.problems)
            continue
        if suite is None:
            try:
                suite = load_suite(check_plant=check_plant)
            except ScenarioError as exc:
                problems.extend(f"suite: {q}" for q in exc.problems)
                suite = []
        if t == "all":
            out.extend(suite)
        elif t == "paper":
            out.extend(s for s in suite if "paper" in s.tags)
        else:
            match = [s for s in suite if s.name == t]
            if match:
                out.extend(match)
            elif suite or not problems:
                names = [s.name for s in suite] + ["all", "paper"]
                close = difflib.get_close_matches(t, names, n=1, cutoff=0.5)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                problems.append(f"{t!r}: no such scenario in the suite or file{hint}")
    unique, clashes = distinct(out)
    if problems or clashes:
        raise ScenarioError(problems + clashes)
    return unique
