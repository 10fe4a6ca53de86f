"""The section parsers of a scenario file, sharing one :class:`~scenarios.lang.fields.Problems`.

Each parser reads one part of the document (header, command schedule, pushes,
perturbation and terrain, regulator overrides and arms, claim), records every problem
it finds and returns what it could read. Rules live where they belong: regulator
parameter names, types and ranges in the regulator core
(:func:`fmu_src.core.avr_core.params_from_overrides`); perturbation and terrain ranges in
the plant (``Perturbation.problems``, via :mod:`scenarios.lang.plantio`). This module keeps
only what the scenario alone knows: the time grid, the schedule's order, which keys go
together, arm names and claim checks.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from fmu_src.core.avr_errors import ParameterError
from scenarios.lang import plantio
from scenarios.lang.fields import (Problems, did_you_mean, integer, name, number, on_grid, string, table,
                              table_list, unknown_keys, vec3)
from scenarios.lang.formatting import is_number, show
from scenarios.lang.scenario import (BUILTIN_ARMS, BUILTIN_MODELS, CHECK_OPS, CHECKABLE_METRICS, DEFAULT_COMM_STEP_S,
                                DEFAULT_FLAT_RADIUS_M, DEFAULT_MODEL, DEFAULT_TERRAIN_SIZE_M, PLANT_DT_S, Arm, Claim, ClaimCheck,
                                CommandPoint, CommandProfile, Event, LinkMass, PELVIS, Push, RandomPushes,
                                Terrain)
from fmu_src.core.avr_params import params_from_overrides
from fmu_src.core.avr_profiles import profile_overrides, unknown_profile
from fmu_src.core.avr_specs import PARAM_SPECS, check_param

TOP_KEYS = (
    "name", "description", "tags", "duration_s", "model", "comm_step_s", "seed",
    "perturbation_t_s", "torso_mass_kg", "torso_added_mass_kg", "torso_com_offset_m",
    "joint_damping_scale", "compare", "command", "push", "terrain", "regulator", "arm", "claim",
    "floor_friction", "slope_deg", "cross_slope_deg", "link_mass", "event", "command_profile", "random_pushes",
)
COMMAND_KEYS = ("t_s", "vx_des", "vy_des", "yaw_rate_des", "ramp")
PUSH_KEYS = ("t_s", "force_n", "duration_s", "body")
LINK_MASS_KEYS = ("body", "scale", "mass_kg")
EVENT_KEYS = ("t_s", "torso_mass_kg", "torso_com_offset_m", "joint_damping_scale", "floor_friction")
COMMAND_PROFILE_KEYS = ("shape", "seed", "hold_s", "vx_des", "vy_des")
COMMAND_PROFILE_SHAPES = ("stepped", "ramped")
RANDOM_PUSHES_KEYS = ("count", "seed", "t_s", "magnitude_n", "duration_s", "bodies")
#: Most pushes a [random_pushes] table draws.
MAX_RANDOM_PUSHES = 100
TERRAIN_KEYS = ("max_height_m", "max_slope_deg", "seed", "size_m", "flat_radius_m")
ARM_KEYS = ("name", "description", "regulator")
CLAIM_KEYS = ("text", "source", "check")
CHECK_KEYS = ("arm", "metric", "op", "value", "other_arm")
MAX_DURATION_S = 3600.0
MAX_COMM_STEP_S = 1.0
#: Command bounds, m/s: the regulator's walking envelope.
MAX_ABS_VX_DES = 2.0
MAX_ABS_VY_DES = 1.0
#: Yaw-rate command bound, rad/s (the walker's gaits are calibrated within +-0.5 rad/s).
MAX_ABS_YAW_RATE_DES = 1.0
MAX_PUSH_FORCE_N = 2000.0
#: Most [[command]] or [[push]] entries a file may hold: one every 36 ms over the longest
#: run (MAX_DURATION_S); the master looks each step's up in O(log n) (scenarios.lang.scenario).
MAX_SCHEDULE_POINTS = 100_000
ARM_DESCRIPTIONS = {"adaptive": "all Psi outputs, adaptation on", "pd_only": "adaptation off (PD terms only)",
                    "rl_hzd": "RL-HZD policy: ARS-trained on the nominal model, fixed (scenarios/rl_hzd)"}


@dataclass(frozen=True)
class Grid:
    """The communication grid times are checked against (``ok``: the file's own step is
    valid; else ``h`` is the default and grid checks are skipped) and the duration."""

    h: float
    ok: bool
    duration: float | None

    def check_time(self, t: float | None, field: str, probs: Problems) -> None:
        """``t`` on the communication grid."""
        if t is not None and self.ok and not on_grid(t, self.h):
            probs.add(field, t, f"must be on the communication grid (a multiple of {self.h:g} s)")

    def check_span(self, dt: float | None, field: str, probs: Problems) -> None:
        """``dt`` a whole number of communication steps, at least one."""
        if dt is None or not self.ok:
            return
        if not on_grid(dt, self.h):
            probs.add(field, dt, f"must be a whole number of communication steps ({self.h:g} s)")
        elif round(dt / self.h) < 1:
            probs.add(field, dt, f"must be at least one communication step ({self.h:g} s)")

    def check_before_end(self, t: float | None, field: str, probs: Problems) -> None:
        """``t`` before the end of the run."""
        if t is not None and self.duration is not None and t >= self.duration:
            probs.add(field, t, f"must be < duration_s = {self.duration:g}")


def resolve_model(model: str, base_dir: Path | None, probs: Problems | None = None, field: str = "model") -> str:
    """``menagerie``/``osu`` as they are; a path resolved against the scenario's folder (problems
    noted under ``field``)."""
    if model in BUILTIN_MODELS:
        return model
    path = Path(model).expanduser()
    if not path.is_absolute() and base_dir is not None and (base_dir / path).exists():
        path = base_dir / path
    if not path.exists():
        if probs is not None:
            probs.add(field, model, f"must be one of {', '.join(BUILTIN_MODELS)} or an existing MJCF (.xml) path")
        return model
    if path.suffix.lower() != ".xml":
        if probs is not None:
            probs.add(field, model, "a model path must be an MJCF .xml file")
    return str(path.resolve())


# --------------------------------------------------------------------------- header
def header(doc: Mapping[str, Any], base_dir: Path | None, probs: Problems) -> tuple[dict[str, Any], Grid]:
    """Name, description, tags, the time grid, model, seed, perturbation time."""
    unknown_keys(doc, TOP_KEYS, "", probs)
    out: dict[str, Any] = {"name": name(doc, "name", "name", probs, " (it names the output folder)"),
                           "description": string(doc, "description", "description", probs), "tags": ()}
    tags = doc.get("tags", [])
    if not isinstance(tags, list) or not all(isinstance(t, str) for t in tags):
        probs.add("tags", tags, "must be a list of strings")
    else:
        out["tags"] = tuple(tags)
    grid = _grid(doc, probs)
    out["comm_step_s"], out["duration_s"] = grid.h, grid.duration
    model = string(doc, "model", "model", probs, default=DEFAULT_MODEL)
    out["model"] = resolve_model(model, base_dir, probs) if isinstance(doc.get("model", ""), str) else model
    out["seed"] = integer(doc, "seed", "seed", probs, required=True, default=0)  # seeds are explicit; range: arms
    pert_t = number(doc, "perturbation_t_s", "perturbation_t_s", probs, default=0.0, ge=0.0)
    grid.check_before_end(pert_t, "perturbation_t_s", probs)
    out["perturbation_t_s"] = pert_t
    return out, grid


def _grid(doc: Mapping[str, Any], probs: Problems) -> Grid:
    """The communication step (a whole number of plant steps) and the duration on it."""
    h = number(doc, "comm_step_s", "comm_step_s", probs, default=DEFAULT_COMM_STEP_S, gt=0.0, le=MAX_COMM_STEP_S)
    ok = h is not None
    if "comm_step_s" in doc and ok and not on_grid(h, PLANT_DT_S):
        probs.add("comm_step_s", h, f"must be a whole multiple of the plant step {PLANT_DT_S * 1000:g} ms")
        ok = False
    grid = Grid(h if ok else DEFAULT_COMM_STEP_S, ok, None)  # a bad step: check the rest on a sane grid
    duration = number(doc, "duration_s", "duration_s", probs, required=True, gt=0.0, le=MAX_DURATION_S)
    grid.check_span(duration, "duration_s", probs)
    return Grid(grid.h, ok, duration)


# --------------------------------------------------------------------------- schedule
def _schedule(doc: Mapping[str, Any], key: str, probs: Problems) -> list[dict]:
    """The ``[[key]]`` tables, at most :data:`MAX_SCHEDULE_POINTS` of them (else none are read)."""
    tables = table_list(doc, key, key, probs)
    if len(tables) > MAX_SCHEDULE_POINTS:
        probs.note(key, f"{len(tables)} [[{key}]] entries; at most {MAX_SCHEDULE_POINTS}")
        return []
    return tables


def commands(doc: Mapping[str, Any], grid: Grid, probs: Problems) -> tuple[CommandPoint, ...]:
    """The piecewise-constant command schedule: the first at t = 0, times increasing."""
    out: list[CommandPoint] = []
    tables = _schedule(doc, "command", probs)
    if doc.get("command", []) == []:  # absent, or `command = []`
        probs.note("command", "required: at least one [[command]] with t_s = 0")
    for i, c in enumerate(tables):
        f = f"command[{i}]"
        unknown_keys(c, COMMAND_KEYS, f + ".", probs)
        t = number(c, "t_s", f + ".t_s", probs, required=True, ge=0.0)
        vx = number(c, "vx_des", f + ".vx_des", probs, required=True, ge=-MAX_ABS_VX_DES, le=MAX_ABS_VX_DES)
        vy = number(c, "vy_des", f + ".vy_des", probs, default=0.0, ge=-MAX_ABS_VY_DES, le=MAX_ABS_VY_DES)
        yaw_rate = number(c, "yaw_rate_des", f + ".yaw_rate_des", probs, default=0.0, ge=-MAX_ABS_YAW_RATE_DES,
                          le=MAX_ABS_YAW_RATE_DES)
        grid.check_time(t, f + ".t_s", probs)
        grid.check_before_end(t, f + ".t_s", probs)
        ramp = flag(c, "ramp", f + ".ramp", probs)
        if ramp and i == 0:
            probs.add(f + ".ramp", ramp, "the first command has no previous point to ramp from")
        if t is not None and vx is not None and vy is not None and yaw_rate is not None:
            out.append(CommandPoint(t, vx, vy, yaw_rate, ramp))
    ts = [c.get("t_s") for c in tables]
    if ts and ts[0] != 0 and is_number(ts[0]):
        probs.add("command[0].t_s", ts[0], "the first command must be at t_s = 0")
    for i in range(1, len(ts)):
        if is_number(ts[i]) and is_number(ts[i - 1]) and not ts[i] > ts[i - 1]:
            probs.add(f"command[{i}].t_s", ts[i], f"must be > command[{i - 1}].t_s = {show(ts[i - 1])} (increasing)")
    return tuple(out)


def pushes(doc: Mapping[str, Any], grid: Grid, probs: Problems) -> tuple[Push, ...]:
    """Constant forces on the pelvis (or the ``body`` named) on the communication grid,
    within the run; the body is checked against the model by :func:`scenarios.lang.plantio.check_plant`."""
    out: list[Push] = []
    for i, p in enumerate(_schedule(doc, "push", probs)):
        f = f"push[{i}]"
        unknown_keys(p, PUSH_KEYS, f + ".", probs)
        t = number(p, "t_s", f + ".t_s", probs, required=True, ge=0.0)
        force = vec3(p, "force_n", f + ".force_n", probs)
        if "force_n" not in p:
            probs.note(f + ".force_n", "required")
        elif force is not None and math.sqrt(sum(x * x for x in force)) > MAX_PUSH_FORCE_N:
            probs.add(f + ".force_n", list(force), f"magnitude must be <= {MAX_PUSH_FORCE_N:g} N")
        dur = number(p, "duration_s", f + ".duration_s", probs, required=True, gt=0.0)
        grid.check_time(t, f + ".t_s", probs)
        grid.check_span(dur, f + ".duration_s", probs)
        grid.check_before_end(t, f + ".t_s", probs)
        body = string(p, "body", f + ".body", probs, default=PELVIS)
        if t is not None and force is not None and dur is not None:
            out.append(Push(t, force, dur, body))
    return tuple(out)


# --------------------------------------------------------------------------- plant
def perturbation(doc: Mapping[str, Any], probs: Problems) -> dict[str, Any]:
    """Torso mass (absolute or added), COM offset, joint damping and terrain; their ranges
    are the plant's (checked here on the plant's nominal torso mass, and again on the
    model's own by :func:`scenarios.lang.plantio.check_plant`)."""
    out = {
        "torso_mass_kg": number(doc, "torso_mass_kg", "torso_mass_kg", probs),
        "torso_added_mass_kg": number(doc, "torso_added_mass_kg", "torso_added_mass_kg", probs),
        "torso_com_offset_m": vec3(doc, "torso_com_offset_m", "torso_com_offset_m", probs, default=(0.0, 0.0, 0.0)),
        "joint_damping_scale": number(doc, "joint_damping_scale", "joint_damping_scale", probs, default=1.0),
    }
    env = environment(doc, probs)
    out.update(env)
    values, out["terrain"] = _terrain(doc, probs)
    unreadable = [f"terrain.{k}=" for k, v in values.items() if v is None]  # already reported
    plant_values = {k: v for k, v in out.items() if k != "terrain"}
    found = plantio.perturbation_problems(**plant_values, terrain=values or None)
    for p in found:
        if not p.startswith(tuple(unreadable)):
            probs.note("perturbation", p)
    if not found:  # the plant FMU's ranges, on values the plant itself accepts
        for field, value, why in plantio.plant_parameter_problems(**plant_values, terrain=values or None):
            probs.add(field, value, why)
    return out


def _terrain(doc: Mapping[str, Any], probs: Problems) -> tuple[dict[str, Any], Terrain | None]:
    """The ``[terrain]`` values as read (None where unreadable) and the Terrain if all are."""
    tt = table(doc, "terrain", "terrain", probs)
    if tt is None:
        return {}, None
    unknown_keys(tt, TERRAIN_KEYS, "terrain.", probs)
    values = {
        "max_height_m": number(tt, "max_height_m", "terrain.max_height_m", probs, required=True),
        "max_slope_deg": number(tt, "max_slope_deg", "terrain.max_slope_deg", probs, required=True),
        "seed": integer(tt, "seed", "terrain.seed", probs, required=True),
        "size_m": number(tt, "size_m", "terrain.size_m", probs, default=DEFAULT_TERRAIN_SIZE_M),
        "flat_radius_m": number(tt, "flat_radius_m", "terrain.flat_radius_m", probs,
                                default=DEFAULT_FLAT_RADIUS_M),
    }
    complete = all(v is not None for v in values.values())
    return values, Terrain(**values) if complete else None


def flag(table: Mapping[str, Any], key: str, field: str, probs: Problems, default: bool = False) -> bool:
    """An optional boolean."""
    if key not in table:
        return default
    v = table[key]
    if not isinstance(v, bool):
        probs.add(field, v, "must be true or false")
        return default
    return v


def environment(doc: Mapping[str, Any], probs: Problems) -> dict[str, Any]:
    """Floor friction, floor slope and ``[[link_mass]]``: read here, their ranges are the
    plant's (``Perturbation.problems``, checked by :func:`perturbation`), the link's body is
    checked against the model by :func:`scenarios.lang.plantio.check_plant`."""
    out: dict[str, Any] = {
        "floor_friction": number(doc, "floor_friction", "floor_friction", probs),
        "slope_deg": number(doc, "slope_deg", "slope_deg", probs, default=0.0),
        "cross_slope_deg": number(doc, "cross_slope_deg", "cross_slope_deg", probs, default=0.0),
    }
    links: list[LinkMass] = []
    for i, t in enumerate(table_list(doc, "link_mass", "link_mass", probs)):
        f = f"link_mass[{i}]"
        unknown_keys(t, LINK_MASS_KEYS, f + ".", probs)
        body = string(t, "body", f + ".body", probs, required=True)
        scale = number(t, "scale", f + ".scale", probs)
        kg = number(t, "mass_kg", f + ".mass_kg", probs)
        if ("scale" in t) == ("mass_kg" in t):
            probs.note(f, "give exactly one of scale (times the model's mass) or mass_kg")
        elif body and (scale is not None or kg is not None):
            links.append(LinkMass(body, scale, kg))
    out["link_masses"] = tuple(links)
    return out


def events(doc: Mapping[str, Any], grid: Grid, start: Mapping[str, Any], probs: Problems) -> tuple[Event, ...]:
    """``[[event]]``: plant changes during the walk, on the grid, within the run, in time
    order; each value's range is the plant's (the same as the top-level key of that name).
    ``start``: the scenario's own values (a damping change needs a non-zero start scale)."""
    from plant.perturbation import Perturbation

    out: list[Event] = []
    last = None
    for i, e in enumerate(_schedule(doc, "event", probs)):
        f = f"event[{i}]"
        unknown_keys(e, EVENT_KEYS, f + ".", probs)
        t = number(e, "t_s", f + ".t_s", probs, required=True, gt=0.0)
        grid.check_time(t, f + ".t_s", probs)
        grid.check_before_end(t, f + ".t_s", probs)
        if t is not None and last is not None and not t > last:
            probs.add(f + ".t_s", t, f"must be > event[{i - 1}].t_s = {last:g} (increasing)")
        last = t if t is not None else last
        values = {"torso_mass_kg": number(e, "torso_mass_kg", f + ".torso_mass_kg", probs),
                  "torso_com_offset_m": vec3(e, "torso_com_offset_m", f + ".torso_com_offset_m", probs),
                  "joint_damping_scale": number(e, "joint_damping_scale", f + ".joint_damping_scale", probs),
                  "floor_friction": number(e, "floor_friction", f + ".floor_friction", probs)}
        if not any(k in e for k in values):
            probs.note(f, f"changes nothing; give at least one of {', '.join(values)}")
        given = {k: v for k, v in values.items() if v is not None}
        plant = Perturbation(**given)
        for problem in plant.problems():
            probs.note(f, problem)
        if "joint_damping_scale" in given and not start.get("joint_damping_scale"):
            probs.add(f + ".joint_damping_scale", given["joint_damping_scale"],
                      "a damping change needs a non-zero joint_damping_scale to start from")
        if t is not None and not any(v is None and k in e for k, v in values.items()):
            out.append(Event(t, **given))
    return tuple(out)


def _range_pair(t: Mapping[str, Any], key: str, field: str, probs: Problems, lo: float, hi: float,
                required: bool = True) -> tuple[float, float] | None:
    """``[low, high]`` with lo <= low <= high <= hi."""
    if key not in t:
        if required:
            probs.note(field, "required: [low, high]")
        return None
    v = t[key]
    if not (isinstance(v, list) and len(v) == 2 and all(as_finite_number(x) for x in v)):
        probs.add(field, v, "must be [low, high], two finite numbers")
        return None
    a, b = float(v[0]), float(v[1])
    if not (lo <= a <= b <= hi):
        probs.add(field, v, f"must satisfy {lo:g} <= low <= high <= {hi:g}")
        return None
    return a, b


def as_finite_number(x: Any) -> bool:
    return is_number(x) and math.isfinite(float(x))


def command_profile(doc: Mapping[str, Any], grid: Grid, probs: Problems) -> CommandProfile | None:
    """``[command_profile]``: a seeded random command instead of ``[[command]]``."""
    t = table(doc, "command_profile", "command_profile", probs)
    if t is None:
        return None
    if "command" in doc:
        probs.note("command_profile", "give [[command]] or [command_profile], not both")
    unknown_keys(t, COMMAND_PROFILE_KEYS, "command_profile.", probs)
    shape = string(t, "shape", "command_profile.shape", probs, required=True)
    if isinstance(t.get("shape"), str) and shape not in COMMAND_PROFILE_SHAPES:
        probs.add("command_profile.shape", shape, f"must be one of {', '.join(COMMAND_PROFILE_SHAPES)}")
    seed = integer(t, "seed", "command_profile.seed", probs, required=True, ge=0)
    hold = number(t, "hold_s", "command_profile.hold_s", probs, required=True, gt=0.0)
    grid.check_span(hold, "command_profile.hold_s", probs)
    vx = _range_pair(t, "vx_des", "command_profile.vx_des", probs, -MAX_ABS_VX_DES, MAX_ABS_VX_DES)
    vy = _range_pair(t, "vy_des", "command_profile.vy_des", probs, -MAX_ABS_VY_DES, MAX_ABS_VY_DES,
                     required=False) or (0.0, 0.0)
    if None in (seed, hold, vx) or shape not in COMMAND_PROFILE_SHAPES:
        return None
    return CommandProfile(shape, seed, hold, vx, vy)


def profile_commands(profile: CommandProfile, grid: Grid) -> tuple[CommandPoint, ...]:
    """The command points of ``profile`` over the run: a point every ``hold_s`` from 0,
    (vx_des, vy_des) uniform in the ranges from ``numpy.random.default_rng(seed)``."""
    import numpy as np

    rng = np.random.default_rng(profile.seed)
    n = max(1, math.ceil(round(grid.duration / profile.hold_s, 9)))
    out = []
    for i in range(n):
        vx = round(float(rng.uniform(*profile.vx_range)), 4)
        vy = round(float(rng.uniform(*profile.vy_range)), 4)
        out.append(CommandPoint(round(i * profile.hold_s, 9), vx, vy, 0.0,
                                ramp=profile.shape == "ramped" and i > 0))
    return tuple(out)


def random_pushes(doc: Mapping[str, Any], grid: Grid, probs: Problems) -> RandomPushes | None:
    """``[random_pushes]``: seeded pushes added to the ``[[push]]`` ones."""
    t = table(doc, "random_pushes", "random_pushes", probs)
    if t is None:
        return None
    unknown_keys(t, RANDOM_PUSHES_KEYS, "random_pushes.", probs)
    count = integer(t, "count", "random_pushes.count", probs, required=True, ge=0)
    if count is not None and count > MAX_RANDOM_PUSHES:
        probs.add("random_pushes.count", count, f"must be <= {MAX_RANDOM_PUSHES}")
        count = None
    seed = integer(t, "seed", "random_pushes.seed", probs, required=True, ge=0)
    span = _range_pair(t, "t_s", "random_pushes.t_s", probs, 0.0, grid.duration or MAX_DURATION_S)
    if span is not None and grid.duration is not None and span[1] >= grid.duration:
        probs.add("random_pushes.t_s", list(span), f"the latest start must be < duration_s = {grid.duration:g}")
        span = None
    mag = _range_pair(t, "magnitude_n", "random_pushes.magnitude_n", probs, 0.0, MAX_PUSH_FORCE_N)
    dur = number(t, "duration_s", "random_pushes.duration_s", probs, required=True, gt=0.0)
    grid.check_span(dur, "random_pushes.duration_s", probs)
    bodies = t.get("bodies", [PELVIS])
    if not (isinstance(bodies, list) and bodies and all(isinstance(b, str) for b in bodies)):
        probs.add("random_pushes.bodies", bodies, "must be a non-empty list of body names")
        bodies = None
    if None in (count, seed, span, mag, dur, bodies):
        return None
    return RandomPushes(count, seed, span, mag, dur, tuple(bodies))


def drawn_pushes(spec: RandomPushes, grid: Grid) -> tuple[Push, ...]:
    """The pushes of ``spec``: start uniform in ``t_range_s`` snapped to the grid (within
    the range), direction uniform in [0, 360) deg in the horizontal plane, magnitude
    uniform, body uniform among ``bodies``; from ``numpy.random.default_rng(seed)``."""
    import numpy as np

    rng = np.random.default_rng(spec.seed)
    lo_k, hi_k = math.ceil(spec.t_range_s[0] / grid.h - 1e-9), math.floor(spec.t_range_s[1] / grid.h + 1e-9)
    out = []
    for _ in range(spec.count):
        k = int(rng.integers(lo_k, hi_k, endpoint=True)) if hi_k >= lo_k else lo_k
        heading = float(rng.uniform(0.0, 2.0 * math.pi))
        mag = float(rng.uniform(*spec.magnitude_range_n))
        body = spec.bodies[int(rng.integers(len(spec.bodies)))]
        force = (round(mag * math.cos(heading), 4), round(mag * math.sin(heading), 4), 0.0)
        out.append(Push(round(k * grid.h, 9), force, spec.duration_s, body))
    return tuple(out)


# --------------------------------------------------------------------------- regulator and arms
def regulator_param_specs() -> dict[str, Any]:
    """The regulator core's PARAM_SPECS by name (VarSpec: name, type, default, min, max, ...)."""
    return {spec.name: spec for spec in PARAM_SPECS}


def overrides(raw: Any, field: str, probs: Problems) -> dict[str, Any]:
    """FMU parameter overrides checked by the regulator core, one by one so each problem
    names its field (``field.name``; ``name`` alone for top-level keys, ``field = ""``);
    returns the core's normalised values of the good ones.  ``profile = "NAME"`` applies
    a named profile (``fmu_src.core.avr_profiles``) first, the table's other keys on top of
    it.  The rules between parameters are checked on each arm's whole set (:func:`arms`)."""
    if not isinstance(raw, dict):
        probs.add(field, raw, "must be a table of FMU parameter overrides")
        return {}
    known = regulator_param_specs()
    out: dict[str, Any] = {}
    if "profile" in raw:
        f = f"{field}.profile" if field else "profile"
        problem = unknown_profile(raw["profile"])
        if problem is None:
            out.update(profile_overrides(raw["profile"]))
        else:
            probs.note(f, problem)
    for key, v in raw.items():
        f = f"{field}.{key}" if field else key
        if key == "profile":
            continue
        if key not in known:
            probs.note(f, "unknown regulator parameter" + did_you_mean(key, known, "; see the FMU's parameters "
                                                                               "(PARAM_SPECS) or give a profile"))
            continue
        value, problem = check_param(known[key], v)
        if problem is None:
            out[key] = value
        else:
            _core_problem(f, key, v, problem, probs)
    return out


def _core_problem(field: str, key: str, value: Any, problem: str, probs: Problems) -> None:
    """The core's ``"name = value: why"`` as ``field = value: why``."""
    own = f"{key} = {value!r}: "
    if problem.startswith(own):
        probs.add(field, value, problem[len(own):])
    else:
        probs.note(field, problem)


def arms(doc: Mapping[str, Any], seed: int | None, probs: Problems) -> tuple[tuple[Arm, ...], list[str]]:
    """The arms to run (``compare``, else the defined ones, else ``adaptive``) and their names."""
    base = overrides(doc.get("regulator", {}), "regulator", probs)
    if "seed" in base and "seed" in doc:
        probs.note("regulator.seed", "the regulator's seed comes from the top-level `seed`; give it once")
    if "seed" not in base and seed is not None:  # the top-level seed is the regulator's `seed`
        base.update(overrides({"seed": seed}, "", probs))
    defined = _defined_arms(doc, base, probs)
    names = _compare(doc, defined, probs) if "compare" in doc else (list(defined) or ["adaptive"])
    builtin = {"adaptive": Arm("adaptive", tuple(sorted(base.items())), ARM_DESCRIPTIONS["adaptive"]),
               "pd_only": Arm("pd_only", tuple(sorted({**base, "adaptation_enabled": False}.items())),
                              ARM_DESCRIPTIONS["pd_only"]),
               "rl_hzd": Arm("rl_hzd", (), ARM_DESCRIPTIONS["rl_hzd"], controller="rl_hzd")}
    out = tuple(defined[n] if n in defined else builtin[n] for n in names if n in defined or n in builtin)
    for arm in out:
        try:
            params_from_overrides(arm.overrides)
        except ParameterError as exc:
            for p in exc.problems:
                probs.note(f"arm {arm.name!r} parameters", p)
    return out, names


def arms_with_profile(arms_: tuple[Arm, ...], profile: Any, field: str, probs: Problems) -> tuple[Arm, ...] | None:
    """``arms_`` with every regulator arm's overrides on top of ``profile``'s values (None and a
    problem if the profile is unknown or an arm's whole set breaks a rule of the core)."""
    problem = unknown_profile(profile)
    if problem is not None:
        probs.note(field, problem)
        return None
    out = []
    for arm in arms_:
        if arm.controller == "regulator":
            arm = dataclasses.replace(arm, overrides=tuple(sorted({**profile_overrides(profile),
                                                                    **arm.overrides_dict()}.items())))
            try:
                params_from_overrides(arm.overrides)
            except ParameterError as exc:
                for p in exc.problems:
                    probs.note(f"{field} {profile}, arm {arm.name!r} parameters", p)
        out.append(arm)
    return tuple(out)


def _defined_arms(doc: Mapping[str, Any], base: dict[str, Any], probs: Problems) -> dict[str, Arm]:
    """The ``[[arm]]`` tables: named, not built-in, unique, overrides on top of ``base``."""
    defined: dict[str, Arm] = {}
    for i, a in enumerate(table_list(doc, "arm", "arm", probs)):
        f = f"arm[{i}]"
        unknown_keys(a, ARM_KEYS, f + ".", probs)
        aname = name(a, "name", f + ".name", probs, "")
        if not aname:
            continue
        if aname in BUILTIN_ARMS:
            probs.add(f + ".name", aname, f"is a built-in arm ({', '.join(BUILTIN_ARMS)}); pick another name")
            continue
        if aname in defined:
            probs.add(f + ".name", aname, "duplicate arm name")
            continue
        own = overrides(a.get("regulator", {}), f + ".regulator", probs)
        defined[aname] = Arm(aname, tuple(sorted({**base, **own}.items())),
                             string(a, "description", f + ".description", probs))
    return defined


def _compare(doc: Mapping[str, Any], defined: dict[str, Arm], probs: Problems) -> list[str]:
    """``compare``: known arms, each once, every defined arm listed."""
    comp = doc["compare"]
    if not isinstance(comp, list) or not comp or not all(isinstance(x, str) for x in comp):
        probs.add("compare", comp, "must be a non-empty list of arm names")
        return []
    known = BUILTIN_ARMS + tuple(defined)
    for j, n in enumerate(comp):
        if n not in known:
            probs.add(f"compare[{j}]", n, "unknown arm" + did_you_mean(n, known, f"; known arms: {', '.join(known)}"))
        if comp.count(n) > 1 and comp.index(n) == j:
            probs.add("compare", comp, f"arm {n!r} listed twice")
    for n in defined:
        if n not in comp:
            probs.note("compare", f"arm {n!r} is defined in [[arm]] but not listed; list it or remove it")
    return list(comp)


# --------------------------------------------------------------------------- claim
def claim(doc: Mapping[str, Any], arm_names: list[str], probs: Problems) -> Claim | None:
    """The paper's claim and its machine-checkable checks on this scenario's arms."""
    ct = table(doc, "claim", "claim", probs)
    if ct is None:
        return None
    unknown_keys(ct, CLAIM_KEYS, "claim.", probs)
    text = string(ct, "text", "claim.text", probs, required=True)
    src = string(ct, "source", "claim.source", probs)
    checks = [_check(ch, f"claim.check[{j}]", arm_names, probs)
              for j, ch in enumerate(table_list(ct, "check", "claim.check", probs))]
    return Claim(text, src, tuple(checks))


def _check(ch: Mapping[str, Any], f: str, arm_names: list[str], probs: Problems) -> ClaimCheck:
    unknown_keys(ch, CHECK_KEYS, f + ".", probs)
    of_this = f"not an arm of this scenario ({', '.join(arm_names)})"
    carm = string(ch, "arm", f + ".arm", probs, required=True)
    if carm and arm_names and carm not in arm_names:
        probs.add(f + ".arm", carm, of_this)
    metric = string(ch, "metric", f + ".metric", probs, required=True)
    if metric and metric not in CHECKABLE_METRICS:
        hint = did_you_mean(metric, CHECKABLE_METRICS, f"; known: {', '.join(CHECKABLE_METRICS)}")
        probs.add(f + ".metric", metric, "unknown metric" + hint)
    op = string(ch, "op", f + ".op", probs, required=True)
    if op and op not in CHECK_OPS:
        probs.add(f + ".op", op, f"must be one of {', '.join(CHECK_OPS)}")
    other, value = ch.get("other_arm"), ch.get("value")
    if ("value" in ch) == ("other_arm" in ch):
        probs.note(f, "give exactly one of value or other_arm")
    if other is not None:
        if not isinstance(other, str):
            probs.add(f + ".other_arm", other, "must be a string")
            other = None
        elif arm_names and other not in arm_names:
            probs.add(f + ".other_arm", other, of_this)
    if "value" in ch and not (is_number(value) or isinstance(value, bool)):
        probs.add(f + ".value", value, "must be a number or a boolean")
    return ClaimCheck(carm, metric, op, value, other)
