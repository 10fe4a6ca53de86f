"""Campaign files: TOML parsed into a frozen :class:`Campaign`, every problem at once.

Layout (every key below is known; anything else is an error)::

    name = "robustness"             # [a-z0-9][a-z0-9_-]*
    description = "..."
    extends = "robustness"          # optional: a built-in campaign or a campaign file
                                    # (relative to this file) this one is laid over: its
                                    # tables merge key by key (a factor's table, one with
                                    # dist, replaces the parent's whole), any other value
                                    # and every array replace; name is then required
    drop = ["replicas", "base.arm"] # optional, with extends: the parent's keys (dotted
                                    # paths) removed before this file is laid over
    default_variant = "ramp"        # with [variants]: the variant run without --variant
    base = "nominal"                # a suite scenario name, a scenario file (relative to
                                    # this file), or an inline [base] table (a scenario)
    duration_s = 30.0               # optional: replaces the base's duration_s
    compare = ["adaptive", "pd_only"]   # optional: replaces the base's arms
    samples = 60                    # random draws; a grid multiplies them (at most 100,000 in all)
    seed = 2026                     # every draw comes from it (same seed, same samples)
    task_timeout_s = 600.0          # optional: one sample (all arms), at most a week; default
                                    # from the duration
    retries = 2                     # optional (0-10, default 2): re-runs of a task whose
                                    # worker or run process died
    metric = "settled_error_vx"     # optional: the error the paired verdicts compare,
                                    # steady_state_error_vx (default) or settled_error_vx

    [replicas]                      # optional: the verdicts' two arms (the first two of
    adaptive = ["adaptive_k2"]      # compare), each with as many replica arms, paired by
    pd_only = ["pd_only_k2"]        # position: the verdicts judge per-sample outcomes
    replicate_over = "floor_terrain_seed"   # optional, instead of [replicas]: a grid factor;
                                    # the verdicts judge each random draw over its cells
                                    # (e.g. the same robot on five grounds), paired by cell
    redraw = ["random_pushes_seed"] # optional, with replicate_over: random factors drawn
                                    # anew on each of its values (a nuisance of every
                                    # replica, e.g. the pushes); its first value keeps the
                                    # draws it has without redraw
    confirm_runs = 20               # optional, with replicate_over over integer values: every
                                    # draw the "never" reading lists is run again on this
                                    # many fresh values of that factor (the largest + 1,
                                    # + 2, ...; redraw factors drawn anew), the verdicts'
                                    # two arms only; the verdict then holds when no listed
                                    # draw's fresh runs show the first arm falling more
                                    # (see scenarios.campaign.analysis.confirmation)

    [variants.ramp]                 # optional: named variants of one study, each a table
    seed = 2032                     # of overrides laid over the rest of the file (as
    [variants.default_rule]         # extends lays a file over its parent; drop as there)
    seed = 2036                     # and chosen by --variant NAME (default_variant without
    drop = ["base.regulator"]       # it); the effective campaign is named NAME_VARIANT

    [factors.torso_mass_kg]         # see scenarios.campaign.factors for the names
    dist = "uniform"                # uniform | lhs: low, high (+ step); randint: low, high
    low = 10.33                     # (integers, inclusive); choice: values (+ weights);
    high = 25.0                     # grid: values (every value x every random draw)

Factors with ``dist = "lhs"`` are drawn together as one Latin hypercube of ``samples``
points. ``step`` rounds uniform/lhs draws to ``low + k*step`` (push times default to
the base's communication step). The base with each factor at its extreme values is
checked by the scenario validator before any sample is drawn, so a range the scenario
format does not allow is reported once, against the factor.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from scenarios.errors import ScenarioError
from scenarios.lang import spec as scenario_spec
from scenarios.campaign import factors as fx
from scenarios.campaign import tomlw
from scenarios.campaign.catalog import CAMPAIGN_DIR, builtin_campaigns, variant_names
from scenarios.lang.fields import (NAME_PATTERN, NAME_RE, Problems, as_finite, did_you_mean, integer, name as name_field,
                                   number, string, unknown_keys)
from scenarios.lang.formatting import show
from scenarios.lang.scenario import BUILTIN_MODELS, DEFAULT_COMM_STEP_S
from scenarios.lang.sections import resolve_model
from scenarios.lang.tomlfile import depth_problem, read_toml

TOP_KEYS = ("name", "description", "extends", "drop", "default_variant", "variants", "base", "duration_s",
            "compare", "samples", "seed", "task_timeout_s", "retries", "factors", "metric", "replicas",
            "replicate_over", "redraw", "confirm_runs")
#: What a ``[variants.NAME]`` table may give: the campaign's own keys (its name is the file's
#: with ``_NAME``), and ``drop``.
VARIANT_KEYS = tuple(k for k in TOP_KEYS if k not in ("name", "extends", "default_variant", "variants"))
#: The errors the paired verdicts may compare (columns of campaign.csv), the default first.
VERDICT_METRICS = ("steady_state_error_vx", "settled_error_vx")
DISTS = ("uniform", "lhs", "randint", "choice", "grid")
DIST_KEYS = {"uniform": ("dist", "low", "high", "step"), "lhs": ("dist", "low", "high", "step"),
             "randint": ("dist", "low", "high"), "choice": ("dist", "values", "weights"),
             "grid": ("dist", "values")}
#: Most samples (random draws x grid cells) a campaign may have.
MAX_SAMPLES = 100_000
#: Longest task_timeout_s / --task-timeout, s: a week, well above the default of the
#: longest sample (120 s + 10 s per simulated s of each arm: 30 h for 3 arms of 3600 s)
#: and below what the waits accept (poll(2) takes at most 2**31 - 1 ms, 24.8 days).
MAX_TASK_TIMEOUT_S = 7 * 24 * 3600.0
MAX_RETRIES = 10
DEFAULT_RETRIES = 2
#: Most fresh runs ``confirm_runs`` gives each listed draw.
MAX_CONFIRM_RUNS = 1000
#: Longest chain of ``extends`` (a campaign over a campaign over ...).
MAX_EXTENDS = 8


@dataclass(frozen=True)
class Factor:
    name: str
    kind: str
    dist: str
    low: Any = None
    high: Any = None
    step: float | None = None
    values: tuple = ()
    weights: tuple[float, ...] | None = None

    def extremes(self) -> list[Any]:
        """The values the scenario validator must accept for every draw to be valid."""
        return [self.low, self.high] if self.dist in ("uniform", "lhs", "randint") else list(self.values)


@dataclass(frozen=True)
class Campaign:
    name: str
    description: str
    base_ref: str  # the suite name, file path or "inline"
    base_doc: Mapping[str, Any]  # the scenario document every sample starts from (read only)
    base_dir: Path  # resolves the base's relative paths
    samples: int
    seed: int
    factors: tuple[Factor, ...]
    retries: int = DEFAULT_RETRIES
    task_timeout_s: float | None = None
    source: str | None = None
    comm_step_s: float = field(default=DEFAULT_COMM_STEP_S)
    metric: str = VERDICT_METRICS[0]  # the error the paired verdicts compare
    replicas: tuple[tuple[str, tuple[str, ...]], ...] = ()  # (arm, its replica arms) for the verdicts
    replicate_over: str | None = None  # a grid factor whose cells are the verdicts' replicas
    redraw: tuple[str, ...] = ()  # random factors drawn anew on each value of replicate_over
    resolved_text: str | None = None  # with extends or variants: the whole campaign as one file (the run folder's copy)
    confirm_runs: int = 0  # fresh runs of each draw the "never" reading lists (0: no confirmation stage)
    variant: str | None = None  # the [variants.NAME] table applied (None: the file has none)

    def analysis_settings(self) -> dict[str, Any]:
        """What the campaign's report needs beyond the rows (written into campaign.json)."""
        over = None
        if self.replicate_index is not None:
            over = {"factor": self.replicate_over, "draws": self.samples,
                    "cells": [len(f.values) for f in self.grid], "index": self.replicate_index,
                    "redraw": list(self.redraw)}
        return {"seed": self.seed, "metric": self.metric,
                "replicas": {arm: list(more) for arm, more in self.replicas}, "replicate_over": over,
                "confirm_runs": self.confirm_runs}

    @property
    def grid(self) -> tuple[Factor, ...]:
        return tuple(f for f in self.factors if f.dist == "grid")

    @property
    def replicate_index(self) -> int | None:
        """The position of ``replicate_over`` among the grid factors (None without it)."""
        if self.replicate_over is None:
            return None
        return [f.name for f in self.grid].index(self.replicate_over)

    @property
    def n_samples(self) -> int:
        """Random draws x the grid's cells."""
        return self.samples * math.prod(len(f.values) for f in self.grid)

    def arm_names(self) -> list[str]:
        return list(self.base_doc.get("compare") or ["adaptive"])


# --------------------------------------------------------------------------- factors
def _check_values(tab: Mapping[str, Any], f: str, kind: str, probs: Problems) -> tuple:
    values = tab.get("values")
    if "values" not in tab:
        probs.note(f + ".values", "required")
        return ()
    if not isinstance(values, list) or not values:
        probs.add(f + ".values", values, "must be a non-empty list")
        return ()
    ok = True
    for j, v in enumerate(values):
        if not fx.value_ok(kind, v):
            probs.add(f"{f}.values[{j}]", v, f"must be {fx.KIND_HINT[kind]}")
            ok = False
    if ok and len({repr(v) for v in values}) != len(values):
        probs.add(f + ".values", values, "has duplicates")
    return tuple(values) if ok else ()


def _check_weights(tab: Mapping[str, Any], f: str, n: int, probs: Problems) -> tuple | None:
    if "weights" not in tab:
        return None
    w = tab["weights"]
    good = isinstance(w, list) and all(as_finite(x) is not None and x >= 0 for x in w)
    if not good or len(w) != n or sum(w) <= 0:
        probs.add(f + ".weights", w, f"must be {n} non-negative numbers (one per value) with a positive sum")
        return None
    return tuple(float(x) for x in w)


def _check_range(tab, f, kind, dist, probs) -> tuple[Any, Any, float | None]:
    if dist == "randint" or kind == "integer":
        if dist in ("uniform", "lhs"):
            probs.add(f + ".dist", dist, "an integer factor takes randint, choice or grid")
            return None, None, None
        low = integer(tab, "low", f + ".low", probs, required=True)
        high = integer(tab, "high", f + ".high", probs, required=True)
        if low is not None and high is not None and low > high:
            probs.add(f + ".high", high, f"must be >= low = {low}")
        return low, high, None
    low = number(tab, "low", f + ".low", probs, required=True)
    high = number(tab, "high", f + ".high", probs, required=True)
    if low is not None and high is not None and not low < high:
        probs.add(f + ".high", high, f"must be > low = {show(low)}")
    step = number(tab, "step", f + ".step", probs, gt=0.0)
    return low, high, step


def parse_factor(name: str, tab: Any, probs: Problems) -> Factor | None:
    f = f"factors.{name}"
    kind = fx.lookup(name)
    if kind is None:
        hint = did_you_mean(name, fx.known_names(), f"; known: {', '.join(fx.FACTORS)}, regulator.<param>, "
                                                     "link_mass_scale.<body>")
        probs.note(f, "unknown factor" + hint)
        return None
    if not isinstance(tab, dict):
        probs.add(f, tab, "must be a table ([factors.NAME] with dist = ...)")
        return None
    dist = string(tab, "dist", f + ".dist", probs, required=True)
    if dist not in DISTS:
        if dist:
            probs.add(f + ".dist", dist, f"must be one of {', '.join(DISTS)}")
        return None
    unknown_keys(tab, DIST_KEYS[dist], f + ".", probs)
    if dist in ("choice", "grid"):
        values = _check_values(tab, f, kind.kind, probs)
        weights = _check_weights(tab, f, len(values), probs) if dist == "choice" else None
        return Factor(name, kind.kind, dist, values=values, weights=weights) if values else None
    if kind.kind not in ("number", "integer"):
        probs.add(f + ".dist", dist, f"a {kind.kind} factor takes choice or grid")
        return None
    low, high, step = _check_range(tab, f, kind.kind, dist, probs)
    return Factor(name, kind.kind, dist, low=low, high=high, step=step) if low is not None and high is not None else None


# --------------------------------------------------------------------------- base scenario
def _read_toml(path: Path, what: str) -> dict[str, Any]:
    return read_toml(path, what)


def _resolve_base(raw: Any, base_dir: Path, probs: Problems) -> tuple[str, dict | None, Path]:
    """(reference, scenario document, folder its relative paths resolve against)."""
    if isinstance(raw, dict):
        return "inline", copy.deepcopy(raw), base_dir
    if not isinstance(raw, str) or not raw:
        probs.add("base", raw, "must be a suite scenario name, a scenario file or an inline [base] table")
        return "", None, base_dir
    path = (base_dir / raw) if not Path(raw).is_absolute() else Path(raw)
    if raw.endswith(".toml") or path.exists() or path.is_symlink():
        try:
            return str(path), _read_toml(path, "scenario file"), path.parent
        except ScenarioError as exc:
            for p in exc.problems:
                probs.add("base", raw, p if not p.startswith("file not found") else f"no such scenario file ({path})")
        return raw, None, base_dir
    suite = {p.stem: p for p in scenario_spec.suite_files()}
    if raw not in suite:
        hint = did_you_mean(raw, suite, f"; suite: {', '.join(suite)}", cutoff=scenario_spec.TARGET_HINT_CUTOFF)
        probs.add("base", raw, "no such suite scenario" + hint)
        return raw, None, base_dir
    return raw, _read_toml(suite[raw], "scenario file"), suite[raw].parent


def _base_document(doc: Mapping[str, Any], name: str, base_dir: Path, probs: Problems) -> tuple[str, dict | None]:
    """The base scenario with the campaign's duration/compare on top, checked as a scenario."""
    ref, base, bdir = _resolve_base(doc.get("base"), base_dir, probs)
    if base is None:
        return ref, None
    base.setdefault("name", name)
    base.pop("claim", None)  # a campaign measures distributions, not the base's claim
    for key in ("duration_s", "compare"):
        if key in doc:
            base[key] = copy.deepcopy(doc[key])
    model = base.get("model")
    if isinstance(model, str) and model not in BUILTIN_MODELS:
        base["model"] = resolve_model(model, bdir)  # samples live elsewhere
    try:
        scenario = scenario_spec.parse_scenario(base, source="base", base_dir=bdir)
    except ScenarioError as exc:
        for p in exc.problems:
            probs.note("base", p)
        return ref, None
    base.setdefault("compare", [a.name for a in scenario.arms])
    base.setdefault("comm_step_s", scenario.comm_step_s)
    return ref, base


def _probe_factors(factors: list[Factor], base: dict, base_dir: Path, probs: Problems) -> None:
    """Each factor at each extreme value on the base: the scenario rules, reported per factor."""
    for f in factors:
        kind = fx.lookup(f.name)
        for v in f.extremes():
            doc = copy.deepcopy(base)
            why = kind.apply(doc, copy.deepcopy(v))
            if why:
                probs.note(f"factors.{f.name}", why)
                break
            try:
                scenario_spec.parse_scenario(doc, base_dir=base_dir)
            except ScenarioError as exc:
                for p in exc.problems:
                    probs.add(f"factors.{f.name}", v, f"gives an invalid scenario: {p}")


# --------------------------------------------------------------------------- campaign
def _flatten_regulator(raw: dict[str, Any]) -> dict[str, Any]:
    """``[factors.regulator.learning_rate]`` (a nested table in TOML) as ``regulator.learning_rate``."""
    out: dict[str, Any] = {}
    for name, tab in raw.items():
        if name == "regulator" and isinstance(tab, dict) and "dist" not in tab:
            out.update({f"{fx.REGULATOR_PREFIX}{k}": v for k, v in tab.items()})
        elif f"{name}." == fx.LINK_MASS_PREFIX and isinstance(tab, dict) and "dist" not in tab:
            out.update({f"{fx.LINK_MASS_PREFIX}{k}": v for k, v in tab.items()})
        else:
            out[name] = tab
    return out


def _verdict_metric(doc: Mapping[str, Any], probs: Problems) -> str:
    metric = doc.get("metric", VERDICT_METRICS[0])
    if metric not in VERDICT_METRICS:
        probs.add("metric", metric, f"must be one of {', '.join(VERDICT_METRICS)}")
        return VERDICT_METRICS[0]
    return metric


def _replicate_over(doc: Mapping[str, Any], factors: Sequence[Factor], probs: Problems) -> str | None:
    """``replicate_over``: a grid factor of the campaign (at least two values). Every random
    draw runs once per value of it; the verdicts take those runs as the draw's replicas,
    paired by value (the first value's sample names the draw). Not with ``[replicas]``."""
    raw = doc.get("replicate_over")
    if raw is None:
        return None
    grid = [f.name for f in factors if f.dist == "grid" and len(f.values) >= 2]
    allowed = f"a grid factor of at least two values ({', '.join(grid) or 'none here'})"
    if not isinstance(raw, str) or raw not in grid:
        probs.add("replicate_over", raw, f"must name {allowed}")
        return None
    if doc.get("replicas") is not None:
        probs.add("replicate_over", raw, "give [replicas] or replicate_over, not both")
        return None
    return raw


def _redraw(doc: Mapping[str, Any], factors: Sequence[Factor], over: str | None, probs: Problems) -> tuple[str, ...]:
    """``redraw``: random factors of the campaign (uniform, randint or choice; an ``lhs``
    factor shares one hypercube with the others and cannot be drawn alone) drawn anew on
    every value of ``replicate_over`` but the first, so that each replica of a draw also
    sees its own nuisance (e.g. its own pushes on a flat floor, where the ground alone
    would repeat one walk). Only with ``replicate_over``."""
    raw = doc.get("redraw")
    if raw is None:
        return ()
    random = [f.name for f in factors if f.dist in ("uniform", "randint", "choice")]
    allowed = f"the campaign's uniform, randint or choice factors ({', '.join(random) or 'none here'})"
    if not isinstance(raw, list) or not raw or not all(isinstance(n, str) for n in raw):
        probs.add("redraw", raw, f"must be a list of {allowed}")
        return ()
    if "replicate_over" not in doc:
        probs.add("redraw", raw, "redraws factors per value of replicate_over: give replicate_over too")
        return ()
    out = []
    for n in raw:
        if n not in random:
            probs.add("redraw", n, f"must be one of {allowed}")
        elif n in out:
            probs.add("redraw", n, "is listed twice")
        else:
            out.append(n)
    return tuple(out) if over is not None else ()


def _confirm_runs(doc: Mapping[str, Any], factors: Sequence[Factor], over: str | None,
                  arms: Sequence[str] | None, probs: Problems) -> int:
    """``confirm_runs``: how many fresh runs each draw the "never falls where b walks"
    reading lists gets in the confirmation stage (1 to :data:`MAX_CONFIRM_RUNS`). The fresh
    runs are new values of ``replicate_over``, counting on from its largest, so that factor
    must hold integers (e.g. ``floor_terrain_seed``); the verdicts' two arms run them."""
    raw = doc.get("confirm_runs")
    if raw is None:
        return 0
    runs = integer(doc, "confirm_runs", "confirm_runs", probs, ge=1)
    if runs is None:
        return 0
    if runs > MAX_CONFIRM_RUNS:
        probs.add("confirm_runs", runs, f"must be <= {MAX_CONFIRM_RUNS}")
        return 0
    if "replicate_over" not in doc:
        probs.add("confirm_runs", runs, "runs listed draws on fresh values of replicate_over: give replicate_over too")
        return 0
    if arms is not None and len(arms) < 2:
        probs.add("confirm_runs", runs, f"confirms the verdicts of the first two arms of compare; compare has {len(arms)}")
        return 0
    if over is None:
        return 0
    factor = next(f for f in factors if f.name == over)
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in factor.values):
        probs.add("confirm_runs", runs, f"the fresh runs take the values after the largest of replicate_over = "
                                        f"{over!r}; its values {list(factor.values)} are not all integers")
        return 0
    return runs


def _replicas(doc: Mapping[str, Any], arms: Sequence[str] | None,
              probs: Problems) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """``[replicas]``: ``ARM = [replica arms]``. The verdicts of the first two arms of
    ``compare`` take each with its replicas: replica i of the first pairs with replica i of
    the second on every sample (both lists the same length); a replica is an arm of
    ``compare`` that runs the same controller under a nuisance change (a gain, a seed)."""
    raw = doc.get("replicas")
    if raw is None:
        return ()
    if not isinstance(raw, dict) or not raw:
        probs.add("replicas", raw, "must be a table ARM = [replica arms, ...]")
        return ()
    known = set(arms or ())
    before = len(probs.items)
    seen: dict[str, str] = {}
    out = []
    for arm, more in raw.items():
        where = f"replicas.{arm}"
        if arms is not None and arm not in known:
            probs.add(where, arm, f"is not an arm of compare ({', '.join(arms)})")
        if not isinstance(more, list) or not more or not all(isinstance(m, str) for m in more):
            probs.add(where, more, "must be a non-empty list of arm names")
            continue
        for m in more:
            if arms is not None and m not in known:
                probs.add(where, m, f"is not an arm of compare ({', '.join(arms)})")
            elif m in raw or m in seen or m == arm:
                probs.add(where, m, f"is already {'an arm with replicas' if m in raw or m == arm else 'a replica'}")
            seen[m] = arm
        out.append((arm, tuple(more)))
    groups = dict(out)
    if arms is not None and len(arms) >= 2 and len(probs.items) == before:  # the lists are sound
        a, b = arms[0], arms[1]
        na, nb = len(groups.get(a, ())), len(groups.get(b, ()))
        if na != nb:
            probs.add("replicas", {a: na, b: nb},
                      f"the verdicts pair {a}'s replicas with {b}'s: give both the same number")
        if any(arm not in (a, b) for arm in groups):
            probs.add("replicas", list(groups), f"only the verdicts' arms ({a}, {b}) take replicas")
        if a in seen or b in seen:
            probs.add("replicas", [a, b], "the verdicts' arms cannot be replicas of another arm")
    return tuple(out)


def parse_campaign(doc: Mapping[str, Any], source: str | None = None, *, base_dir: Path | None = None,
                   variant: str | None = None) -> Campaign:
    """Validate a parsed campaign document (with ``variant``: that one of its
    ``[variants]``, else its ``default_variant``); raise ScenarioError listing every problem."""
    base_dir = base_dir or Path.cwd()
    too_deep = depth_problem(doc)  # before any reader walks or copies the values
    if too_deep:
        raise ScenarioError([too_deep], source=source)
    probs = Problems()
    resolved = []  # what was resolved into the one document
    if "extends" in doc or "drop" in doc:
        resolved.append(f"extends = {doc.get('extends')!r}")
        doc, base_dir = extended(doc, base_dir, probs)
    if not probs.items and ("variants" in doc or "default_variant" in doc or variant is not None):
        doc, variant = with_variant(doc, variant, probs)
        resolved.append(f"variant {variant!r}")
    if probs.items:
        raise ScenarioError(probs.items, source=source)
    resolved_text = None
    if resolved:
        resolved_text = f"# {source or 'a campaign'} ({', '.join(resolved)}), resolved into one file\n" + tomlw.dumps(doc)
    unknown_keys(doc, TOP_KEYS, "", probs)
    name = name_field(doc, "name", "name", probs, " (it names samples)")
    description = string(doc, "description", "description", probs)
    samples = integer(doc, "samples", "samples", probs, required=True, ge=1)
    if samples is not None and samples > MAX_SAMPLES:
        probs.add("samples", samples, f"must be <= {MAX_SAMPLES}")
    seed = integer(doc, "seed", "seed", probs, required=True, ge=0)
    retries = integer(doc, "retries", "retries", probs, default=DEFAULT_RETRIES, ge=0)
    if retries is not None and retries > MAX_RETRIES:
        probs.add("retries", retries, f"must be <= {MAX_RETRIES}")
    timeout = number(doc, "task_timeout_s", "task_timeout_s", probs, gt=0.0, le=MAX_TASK_TIMEOUT_S)
    if "base" not in doc:
        probs.note("base", "required: a suite scenario name, a scenario file or an inline [base] table")
    ref, base = _base_document(doc, name or "campaign", base_dir, probs) if "base" in doc else ("", None)

    factors: list[Factor] = []
    raw = doc.get("factors", {})
    if not isinstance(raw, dict) or not raw:
        probs.add("factors", raw, "must be a table of at least one [factors.NAME]")
        raw = {}
    for fname, tab in _flatten_regulator(raw).items():
        factor = parse_factor(fname, tab, probs)
        if factor is not None:
            factors.append(factor)
    grid_cells = math.prod(len(f.values) for f in factors if f.dist == "grid")
    if samples is not None and samples * grid_cells > MAX_SAMPLES:  # before anything is drawn or expanded
        probs.add("samples", samples, f"x {grid_cells} grid cells = {samples * grid_cells} samples; at most "
                                      f"{MAX_SAMPLES} in all")
    if "terrain" in raw and any(n.startswith("terrain_") for n in raw):
        probs.note("factors.terrain", "give the terrain factor or terrain_* factors, not both")
    metric = _verdict_metric(doc, probs)
    arms = list(base.get("compare") or ["adaptive"]) if base is not None else None
    replicas = _replicas(doc, arms, probs)
    replicate_over = _replicate_over(doc, factors, probs)
    redraw = _redraw(doc, factors, replicate_over, probs)
    confirm_runs = _confirm_runs(doc, factors, replicate_over, arms, probs)
    if base is not None and not probs.items:
        _probe_factors(factors, base, base_dir, probs)
        if confirm_runs:  # the confirmation stage's last fresh value, checked like a factor's extremes
            over = next(f for f in factors if f.name == replicate_over)
            _probe_factors([Factor(over.name, over.kind, "grid", values=(max(over.values) + confirm_runs,))],
                           base, base_dir, probs)
    if probs.items:
        raise ScenarioError(probs.items, source=source)
    order = fx.apply_order([f.name for f in factors])
    factors.sort(key=lambda f: order.index(f.name))
    return Campaign(name, description, ref, base, base_dir, samples, seed, tuple(factors), retries, timeout,
                    source, float(base["comm_step_s"]), metric, replicas, replicate_over, redraw, resolved_text,
                    confirm_runs, variant)


def _lay_over(parent: Mapping[str, Any], child: Mapping[str, Any], under_factors: bool = False) -> dict[str, Any]:
    """``child`` laid over ``parent``: tables merge key by key, a factor's table (under
    ``factors``, one with ``dist``) and every other value replace."""
    out = copy.deepcopy(dict(parent))
    for k, v in child.items():
        whole = under_factors and isinstance(v, dict) and "dist" in v
        if isinstance(v, dict) and isinstance(out.get(k), dict) and not whole:
            out[k] = _lay_over(out[k], v, under_factors or k == "factors")
        else:
            out[k] = copy.deepcopy(v)
    return out


def extended(doc: Mapping[str, Any], base_dir: Path, probs: Problems,
             chain: tuple[Path, ...] = ()) -> tuple[dict[str, Any], Path]:
    """A campaign document with its ``extends`` resolved: the parent (itself resolved) with
    ``doc`` laid over it, and the folder the result's ``base`` resolves against (the file
    that gave ``base``). Problems go to ``probs``."""
    raw = doc.get("extends")
    own = {k: v for k, v in doc.items() if k not in ("extends", "drop")}
    if raw is None:
        if "drop" in doc:
            probs.add("drop", doc["drop"], "removes keys of the campaign this one extends: give extends too")
        return own, base_dir
    if not isinstance(raw, str) or not raw:
        probs.add("extends", raw, "must be a built-in campaign name or a campaign file")
        return own, base_dir
    if "name" not in doc:
        probs.note("extends", "a campaign that extends another gives its own name")
    path, why = _campaign_path(raw, base_dir)
    if path is None:
        probs.add("extends", raw, why)
        return own, base_dir
    key = path.resolve()
    if key in chain or len(chain) >= MAX_EXTENDS:
        shown = " -> ".join(p.name for p in (*chain, key))
        probs.add("extends", raw, f"{'extends itself' if key in chain else 'too long a chain'}: {shown} "
                                  f"(at most {MAX_EXTENDS} files)")
        return own, base_dir
    try:
        parent = _read_toml(path, "campaign file")
    except ScenarioError as exc:
        for p in exc.problems:
            probs.add("extends", raw, p)
        return own, base_dir
    parent, parent_dir = extended(parent, path.parent, probs, (*chain, key))
    _drop(parent, doc.get("drop", []), raw, probs)
    return _lay_over(parent, own), (base_dir if "base" in own else parent_dir)


def with_variant(doc: Mapping[str, Any], variant: str | None, probs: Problems) -> tuple[dict[str, Any], str | None]:
    """The campaign ``doc`` with one of its ``[variants.NAME]`` tables applied: ``variant``,
    or the file's ``default_variant`` when None. The variant's ``drop`` keys are removed from
    the rest of the file, then its other keys laid over it (as ``extends`` lays a file over
    its parent); the result is named ``<name>_<variant>`` (its run folder, its samples' tag)
    and has no variants. Returns (that document, the variant's name); problems go to ``probs``."""
    own = {k: copy.deepcopy(v) for k, v in doc.items() if k not in ("variants", "default_variant")}
    raw, default = doc.get("variants"), doc.get("default_variant")
    label = repr(doc["name"]) if isinstance(doc.get("name"), str) else "this campaign"
    if raw is None:
        if "default_variant" in doc:
            probs.add("default_variant", default, "names one of the [variants.NAME] tables: give them too")
        if variant is not None:
            probs.add("variant", variant, f"{label} has no variants (no [variants.NAME] tables)")
        return own, None
    if not isinstance(raw, dict) or not raw or not all(isinstance(t, dict) for t in raw.values()):
        probs.add("variants", raw, "must be a table of [variants.NAME] tables, each the overrides of one variant")
        return own, None
    for name in raw:
        if not NAME_RE.match(name):
            probs.add(f"variants.{name}", name, f"the name must match {NAME_PATTERN} (it names the campaign)")
    listed = ", ".join(variant_names(doc))
    if "default_variant" not in doc:
        probs.note("default_variant", f"required with [variants]: the variant run without one named ({listed})")
    elif default not in raw:
        probs.add("default_variant", default, f"must name one of the variants: {listed}")
    if variant is not None and variant not in raw:
        probs.add("variant", variant, f"no such variant of {label}{did_you_mean(variant, raw, '')}; variants: {listed}")
        return own, None
    chosen = default if variant is None else variant
    if chosen not in raw:
        return own, None
    table = raw[chosen]
    unknown_keys(table, VARIANT_KEYS, f"variants.{chosen}.", probs)
    if "drop" in table:
        _drop(own, table["drop"], label, probs, field=f"variants.{chosen}.drop")
    out = _lay_over(own, {k: v for k, v in table.items() if k != "drop"})
    if isinstance(out.get("name"), str):
        out["name"] = f"{out['name']}_{chosen}"
    return out, chosen


def _drop(parent: dict[str, Any], paths: Any, parent_name: str, probs: Problems, field: str = "drop") -> None:
    """Remove each dotted key of ``paths`` from ``parent`` (in place); a path that is not a
    key of it is a problem (named ``field``)."""
    if not isinstance(paths, list) or not all(isinstance(p, str) and p for p in paths):
        probs.add(field, paths, f"must be a list of {parent_name}'s keys (dotted, e.g. \"base.arm\")")
        return
    for dotted in paths:
        *outer, last = dotted.split(".")
        table = parent
        for k in outer:
            table = table.get(k) if isinstance(table, dict) else None
        if not isinstance(table, dict) or last not in table:
            probs.add(field, dotted, f"is not a key of {parent_name}")
            continue
        del table[last]


def load_campaign(path: str | Path, variant: str | None = None) -> Campaign:
    path = Path(path)
    doc = _read_toml(path, "campaign file")
    return parse_campaign(doc, source=str(path), base_dir=path.parent, variant=variant)


def _campaign_path(target: str, base_dir: Path | None = None) -> tuple[Path | None, str]:
    """(the file, "") for a campaign file path (relative to ``base_dir`` if given) or a
    built-in campaign name; (None, why) for neither."""
    path = base_dir / target if base_dir is not None and not Path(target).is_absolute() else Path(target)
    if target.endswith(".toml") or path.exists():
        return path, ""
    names = builtin_campaigns()
    if target in names:
        return CAMPAIGN_DIR / f"{target}.toml", ""
    hint = did_you_mean(target, names, f"; built-in: {', '.join(names)}", cutoff=scenario_spec.TARGET_HINT_CUTOFF)
    return None, "no such campaign file or built-in campaign" + hint


def resolve_campaign(target: str) -> Path:
    """A built-in campaign name (``robustness``, ``smoke``) or a campaign file path."""
    path, why = _campaign_path(target)
    if path is None:
        raise ScenarioError([f"{target!r}: {why}"])
    return path
