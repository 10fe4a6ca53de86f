"""Scenario files: TOML parsed into frozen dataclasses, validated before anything runs.

A scenario file describes one closed-loop experiment: how long, which model, the
communication step, a piecewise-constant velocity and yaw-rate command schedule, plant
perturbations (torso mass, torso COM offset, joint damping, pushes, terrain),
regulator parameter overrides (by FMU variable name), the arms to compare
(e.g. ``adaptive`` vs ``pd_only``) and the paper's claim with machine-checkable
checks for the report.

The file is read by section parsers (:mod:`scenarios.lang.sections`) into the model of
:mod:`scenarios.lang.scenario`. Each rule is checked in one place: regulator overrides by the
regulator core (``params_from_overrides``), perturbation and terrain ranges by the
plant (``Perturbation.problems``); the time grid, the schedule and the arms here.
Every problem in a file is collected and reported at once (``ScenarioError.problems``),
each naming its field, e.g. ``push[1].duration_s = -0.1: must be > 0``; a file that
cannot be read (missing, not a regular file, larger than 16 MiB, not UTF-8, nested
too deeply: :mod:`scenarios.lang.tomlfile`) is one problem naming it. Scenario
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
    vx_des = 0.5                    # m/s, heading frame, |vx_des| <= 2
    vy_des = 0.0                    # m/s, heading frame, |vy_des| <= 1 (optional, 0)
    yaw_rate_des = 0.0              # rad/s, positive turns left, |yaw_rate_des| <= 1 (optional, 0);
                                    # the plant's only: the regulator has no yaw-rate input

    [[push]]                        # constant world-frame force on the pelvis
    t_s = 2.5
    force_n = [30.0, 0.0, 0.0]
    duration_s = 0.1

    [terrain]                       # the field spans [-size_m, size_m]^2; no ground outside
    max_height_m = 0.4
    max_slope_deg = 20.0
    seed = 3
    size_m = 20.0                   # optional
    flat_radius_m = 1.0             # optional: the flat start patch around the origin, m

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
from pathlib import Path
from typing import Any, Mapping

from scenarios.lang import plantio
from scenarios.lang import sections
from scenarios.errors import ScenarioError
from scenarios.lang.fields import Problems, did_you_mean, number
from scenarios.lang.scenario import (Scenario)
from scenarios.lang.sections import resolve_model
from scenarios.lang.tomlfile import depth_problem, read_toml

SUITE_DIR = Path(__file__).resolve().parents[1] / "suite"
#: A suite name typed on the command line is offered as "did you mean" from this similarity.
TARGET_HINT_CUTOFF = 0.5


def parse_scenario(doc: Mapping[str, Any], source: str | None = None, *, base_dir: Path | None = None,
                   check_plant: bool = True) -> Scenario:
    """Validate a parsed TOML document; raise ScenarioError listing every problem.

    ``base_dir`` resolves a relative model path (the scenario file's folder).
    ``check_plant`` also checks what loading the plant would fail on (needs mujoco): the
    model parses safely, compiles and is a Cassie, and the perturbation is valid on it
    (:func:`scenarios.lang.plantio.check_plant`).
    """
    too_deep = depth_problem(doc)  # before any reader walks the values
    if too_deep:
        raise ScenarioError([too_deep], source=source)
    probs = Problems()
    head, grid = sections.header(doc, base_dir, probs)
    plant = sections.perturbation(doc, probs)
    profile = sections.command_profile(doc, grid, probs)
    drawn = sections.random_pushes(doc, grid, probs)
    grid_ok = grid.ok and grid.duration is not None
    if "command_profile" in doc:
        cmds = sections.profile_commands(profile, grid) if profile is not None and grid_ok else ()
    else:
        cmds = sections.commands(doc, grid, probs)
    pushes = sections.pushes(doc, grid, probs)
    if drawn is not None and grid_ok:
        pushes += sections.drawn_pushes(drawn, grid)
    schedule = {"commands": cmds, "pushes": pushes, "command_profile": profile, "random_pushes": drawn,
                "events": sections.events(doc, grid, plant, probs)}
    arms, arm_names = sections.arms(doc, head["seed"], probs)
    claim = sections.claim(doc, arm_names, probs)
    scenario = None
    if not probs.items:
        scenario = Scenario(**head, **plant, **schedule, arms=arms, claim=claim, source=source)
        for field, value, why in plantio.plant_input_problems(scenario):
            probs.add(field, value, why)
        if check_plant and not probs.items:
            _check_plant(scenario, probs)
    if probs.items:
        raise ScenarioError(probs.items, source=source)
    return scenario


def _check_plant(scenario: Scenario, probs: Problems) -> None:
    """What loading the plant would fail on (the model compiles and is a Cassie, the
    perturbation is valid on it): :func:`scenarios.lang.plantio.check_plant`."""
    for field, problem in plantio.check_plant(scenario):
        probs.note(field, problem)


def override_problems(*, model: str | None = None, duration_s: float | None = None,
                      base_dir: Path | None = None) -> list[str]:
    """The problems of the command-line values ``--model`` and ``--duration`` themselves, named by
    their flags: whatever the scenario, so a command reports them once, not under each file."""
    probs = Problems()
    if model is not None:
        resolve_model(model, base_dir or Path.cwd(), probs, field="--model")
    if duration_s is not None:
        number({"duration_s": duration_s}, "duration_s", "--duration", probs, gt=0.0, le=sections.MAX_DURATION_S)
    return probs.items


def override(scenario: Scenario, *, model: str | None = None, duration_s: float | None = None,
             profile: str | None = None, base_dir: Path | None = None, check_plant: bool = True) -> Scenario:
    """The scenario with another model, duration and/or regulator profile (CLI flags), re-checked
    (a new model is compiled and checked as in :func:`parse_scenario` unless ``check_plant`` is
    false).  ``profile``: every regulator arm starts from that profile's values
    (``fmu_src.core.avr_profiles``) instead of the FMU's defaults; the file's own values stay on top.
    ScenarioError without a source for a bad value (:func:`override_problems`), with the
    scenario's source for what the value does to this scenario (its grid, its plant)."""
    found = override_problems(model=model, duration_s=duration_s, base_dir=base_dir)
    if found:
        raise ScenarioError(found)
    probs = Problems()
    changes: dict[str, Any] = {}
    if profile is not None:
        arms = sections.arms_with_profile(scenario.arms, profile, "--profile", probs)
        if arms is not None:
            changes["arms"] = arms
    if model is not None:
        changes["model"] = resolve_model(model, base_dir or Path.cwd())
    if duration_s is not None:
        sections.Grid(scenario.comm_step_s, True, float(duration_s)).check_span(float(duration_s), "--duration", probs)
        changes["duration_s"] = float(duration_s)
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
    doc = read_toml(path, "scenario file")
    return parse_scenario(doc, source=str(path), base_dir=path.parent, check_plant=check_plant)


def suite_files() -> list[Path]:
    return sorted(SUITE_DIR.glob("*.toml"))


def _suite_name_problem(s: Scenario) -> str | None:
    """A suite scenario's name is its file's stem (the name finds the file, and names the output folder)."""
    stem = Path(s.source).stem
    return None if s.name == stem else f"{Path(s.source).name}: name = {s.name!r}: must equal the file name ({stem!r})"


def load_suite(*, check_plant: bool = True) -> list[Scenario]:
    """Every suite file, validated; all problems of all files in one ScenarioError."""
    scenarios, problems = [], []
    for f in suite_files():
        try:
            scenarios.append(load_scenario(f, check_plant=check_plant))
        except ScenarioError as exc:
            problems.extend(f"{f.name}: {p}" for p in exc.problems)
    problems += [q for s in scenarios if (q := _suite_name_problem(s))]
    scenarios, clashes = distinct([(s.source, s) for s in scenarios])
    if problems or clashes:
        raise ScenarioError(problems + clashes, source=str(SUITE_DIR))
    return scenarios


def distinct(named: list[tuple[str, Scenario]]) -> tuple[list[Scenario], list[str]]:
    """The scenarios of ``named`` ((target as given, scenario) pairs) and a problem for every
    scenario named twice (the same file, suite name, or one inside ``all``/``paper`` and named
    again: it would run twice into one output folder) and for every name two different files
    share (the name is the output folder: one would be lost)."""
    first: dict[str, tuple[int, str, Scenario]] = {}
    unique, problems = [], []
    for i, (target, s) in enumerate(named):
        j, other_target, other = first.setdefault(s.name, (i, target, s))
        if j == i:
            unique.append(s)
        elif other is s or _same_file(other.source, s.source):
            by = f"{other_target!r} and {target!r}" if other_target != target else f"{target!r} twice"
            problems.append(f"{s.name!r}: named twice on the command line (by {by}); name each scenario once")
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
    scenario once. ScenarioError lists every problem (invalid files, unknown names, a
    scenario named twice, two files with one name). A suite name reads its own file only
    (a suite scenario's name is its file's stem); ``all`` and ``paper`` read the whole suite."""
    out: list[tuple[str, Scenario]] = []
    problems: list[str] = []
    suite: list[Scenario] | None = None
    by_stem = {f.stem: f for f in suite_files()}
    for t in targets:
        p = Path(t)
        if t.endswith(".toml") or p.exists():
            try:
                out.append((t, load_scenario(p, check_plant=check_plant)))
            except ScenarioError as exc:
                problems.extend(f"{t}: {q}" for q in exc.problems)
            continue
        if t in by_stem:
            try:
                s = load_scenario(by_stem[t], check_plant=check_plant)
            except ScenarioError as exc:
                problems.extend(f"suite: {by_stem[t].name}: {q}" for q in exc.problems)
                continue
            bad = _suite_name_problem(s)
            if bad:
                problems.append(f"suite: {bad}")
            else:
                out.append((t, s))
            continue
        if t not in ("all", "paper"):
            hint = did_you_mean(t, [*by_stem, "all", "paper"], "", cutoff=TARGET_HINT_CUTOFF)
            problems.append(f"{t!r}: no such scenario in the suite or file{hint}")
            continue
        if suite is None:
            try:
                suite = load_suite(check_plant=check_plant)
            except ScenarioError as exc:
                problems.extend(f"suite: {q}" for q in exc.problems)
                suite = []
        out.extend((t, s) for s in suite if t == "all" or "paper" in s.tags)
    unique, clashes = distinct(out)
    if problems or clashes:
        raise ScenarioError(problems + clashes)
    return unique
