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
                                CommandPoint, Push, Terrain)
from fmu_src.core.avr_params import params_from_overrides
from fmu_src.core.avr_specs import PARAM_SPECS

TOP_KEYS = (
    "name", "description", "tags", "duration_s", "model", "comm_step_s", "seed",
    "perturbation_t_s", "torso_mass_kg", "torso_added_mass_kg", "torso_com_offset_m",
    "joint_damping_scale", "compare", "command", "push", "terrain", "regulator", "arm", "claim",
)
COMMAND_KEYS = ("t_s", "vx_des", "vy_des", "yaw_rate_des")
PUSH_KEYS = ("t_s", "force_n", "duration_s")
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


def resolve_model(model: str, base_dir: Path | None, probs: Problems | None = None) -> str:
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
        if t is not None and vx is not None and vy is not None and yaw_rate is not None:
            out.append(CommandPoint(t, vx, vy, yaw_rate))
    ts = [c.get("t_s") for c in tables]
    if ts and ts[0] != 0 and is_number(ts[0]):
        probs.add("command[0].t_s", ts[0], "the first command must be at t_s = 0")
    for i in range(1, len(ts)):
        if is_number(ts[i]) and is_number(ts[i - 1]) and not ts[i] > ts[i - 1]:
            probs.add(f"command[{i}].t_s", ts[i], f"must be > command[{i - 1}].t_s = {show(ts[i - 1])} (increasing)")
    return tuple(out)


def pushes(doc: Mapping[str, Any], grid: Grid, probs: Problems) -> tuple[Push, ...]:
    """Constant pelvis forces on the communication grid, within the run."""
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
        if t is not None and force is not None and dur is not None:
            out.append(Push(t, force, dur))
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


# --------------------------------------------------------------------------- regulator and arms
def regulator_param_specs() -> dict[str, Any]:
    """The regulator core's PARAM_SPECS by name (VarSpec: name, type, default, min, max, ...)."""
    return {spec.name: spec for spec in PARAM_SPECS}


def overrides(raw: Any, field: str, probs: Problems) -> dict[str, Any]:
    """FMU parameter overrides checked by the regulator core, one by one so each problem
    names its field (``field.name``; ``name`` alone for top-level keys, ``field = ""``);
    returns the core's normalised values of the good ones."""
    if not isinstance(raw, dict):
        probs.add(field, raw, "must be a table of FMU parameter overrides")
        return {}
    known = regulator_param_specs()
    out: dict[str, Any] = {}
    for key, v in raw.items():
        f = f"{field}.{key}" if field else key
        if key not in known:
            probs.note(f, "unknown regulator parameter" + did_you_mean(key, known, "; see the FMU's parameters "
                                                                               "(PARAM_SPECS)"))
            continue
        try:
            out[key] = getattr(params_from_overrides({key: v}), key)
        except ParameterError as exc:
            for p in exc.problems:
                _core_problem(f, key, v, p, probs)
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
