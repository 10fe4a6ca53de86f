"""Seeded draws of a campaign's factors, and the concrete scenario of each sample.

Every factor draws from its own generator, seeded by (campaign seed, factor name): adding
or reordering factors leaves the other factors' draws unchanged; the ``lhs`` factors
share one generator (seed, ``"lhs"``) and one Latin hypercube. Sample ``i`` is grid cell
``i // samples`` (grid factors in file order, the last varying fastest) with random draw
``i % samples``: every grid cell sees the same random draws (paired comparisons), except
the campaign's ``redraw`` factors, drawn anew on each value ``k`` > 0 of its
``replicate_over`` factor from the generator (campaign seed, ``"NAME@k"``). The
confirmation stage (:func:`confirmation`) continues that factor's values, so its draws
come from streams the campaign itself never used.
"""
from __future__ import annotations

import copy
import dataclasses
import itertools
import json
import tomllib
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from scenarios.errors import ScenarioError
from scenarios.lang import spec as scenario_spec
from scenarios.campaign import factors as fx
from scenarios.campaign import tomlw
from scenarios.campaign.spec import Campaign, Factor


@dataclass(frozen=True)
class Sample:
    id: str
    index: int
    values: dict[str, Any]  # factor name -> drawn value, in the campaign's factor order


def rng_for(seed: int, name: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(name.encode())]))


def latin_hypercube(rng: np.random.Generator, n: int, d: int) -> np.ndarray:
    """``n`` points in [0, 1)^d, exactly one in each of the ``n`` strata of every axis."""
    u = np.empty((n, d))
    for j in range(d):
        u[:, j] = (rng.permutation(n) + rng.random(n)) / n
    return u


def _snap(values: np.ndarray, f: Factor, step: float | None) -> list[float]:
    if step is None:
        return [float(v) for v in values]
    k = np.round((values - f.low) / step)
    snapped = f.low + k * step
    snapped = np.where(snapped > f.high + 1e-12, snapped - step, snapped)
    return [round(float(v), 12) for v in snapped]


def _step(f: Factor, campaign: Campaign) -> float | None:
    return f.step if f.step is not None else campaign.comm_step_s if f.name in fx.TIME_FACTORS else None


def _draw_factor(f: Factor, campaign: Campaign, n: int, stream: str | None = None) -> list[Any]:
    rng = rng_for(campaign.seed, stream or f.name)
    if f.dist == "uniform":
        return _snap(rng.uniform(f.low, f.high, n), f, _step(f, campaign))
    if f.dist == "randint":
        return [int(v) for v in rng.integers(f.low, f.high, n, endpoint=True)]
    p = None if f.weights is None else np.asarray(f.weights) / sum(f.weights)
    return [copy.deepcopy(f.values[i]) for i in rng.choice(len(f.values), size=n, p=p)]


def draw(campaign: Campaign) -> list[Sample]:
    """Every sample of the campaign, in order (deterministic in the campaign's seed)."""
    n = campaign.samples
    columns: dict[str, list[Any]] = {}
    for f in campaign.factors:
        if f.dist in ("uniform", "randint", "choice"):
            columns[f.name] = _draw_factor(f, campaign, n)
    lhs = [f for f in campaign.factors if f.dist == "lhs"]
    if lhs:
        u = latin_hypercube(rng_for(campaign.seed, "lhs"), n, len(lhs))
        for j, f in enumerate(lhs):
            columns[f.name] = _snap(f.low + u[:, j] * (f.high - f.low), f, _step(f, campaign))
    grid = campaign.grid
    over = campaign.replicate_index
    redrawn: dict[int, dict[str, list[Any]]] = {}  # value index k > 0 of replicate_over -> its columns
    if over is not None and campaign.redraw:
        by_name = {f.name: f for f in campaign.factors}
        redrawn = {k: {name: _draw_factor(by_name[name], campaign, n, f"{name}@{k}") for name in campaign.redraw}
                   for k in range(1, len(grid[over].values))}
    width = max(4, len(str(campaign.n_samples - 1)))
    samples = []
    for c, cell in enumerate(itertools.product(*(range(len(f.values)) for f in grid))):
        fixed = {f.name: copy.deepcopy(f.values[j]) for f, j in zip(grid, cell)}
        cols = {**columns, **redrawn.get(cell[over], {})} if over is not None else columns
        for r in range(n):
            i = c * n + r
            drawn = {**{k: col[r] for k, col in cols.items()}, **fixed}
            values = {f.name: drawn[f.name] for f in campaign.factors}
            samples.append(Sample(f"s{i:0{width}d}", i, values))
    return samples


#: Suffix of the confirmation stage's campaign name (its samples' tags and descriptions).
CONFIRM_SUFFIX = "_confirm"


def _draw_key(index: int, campaign: Campaign) -> tuple[tuple[int, ...], int, int]:
    """(grid cell without ``replicate_over``, random draw, value index of ``replicate_over``)
    of sample ``index``: a draw is the same robot on every value of that factor."""
    n, over = campaign.samples, campaign.replicate_index
    cell = np.unravel_index(index // n, [len(f.values) for f in campaign.grid])
    return tuple(int(c) for j, c in enumerate(cell) if j != over), index % n, int(cell[over])


def confirmation(campaign: Campaign, listed: list[str]) -> tuple[Campaign, list[Sample], dict[str, str]]:
    """The confirmation stage of a campaign with ``confirm_runs``: every draw of ``listed``
    (named by its sample on the first value of ``replicate_over``, as the verdicts name it)
    on ``confirm_runs`` fresh values of that factor, the largest value + 1, + 2, ... Each
    fresh run keeps the draw's factors, except the ``redraw`` factors, drawn anew on each
    fresh value (streams ``NAME@k`` with k past the campaign's values: no run repeats a
    walk of the campaign). The stage runs the verdicts' two arms (the first two of
    ``compare``).

    Returns (the stage as a campaign, its samples ``DRAW_cJ``: fresh run J of draw DRAW,
    {stage sample id: listed draw})."""
    over = campaign.replicate_index
    if not campaign.confirm_runs or over is None:
        raise ValueError(f"campaign {campaign.name!r} has no confirmation stage (confirm_runs with replicate_over)")
    factor = campaign.grid[over]
    first = len(factor.values)
    fresh = tuple(max(factor.values) + 1 + j for j in range(campaign.confirm_runs))
    longer = dataclasses.replace(factor, values=factor.values + fresh)
    pair = campaign.arm_names()[:2]
    base = {**copy.deepcopy(dict(campaign.base_doc)), "compare": pair}
    if "arm" in base:  # the scenario format refuses an [[arm]] that compare does not list
        base["arm"] = [arm for arm in base["arm"] if arm.get("name") in pair]
        if not base["arm"]:
            del base["arm"]
    stage = dataclasses.replace(campaign, name=campaign.name + CONFIRM_SUFFIX, base_doc=base, confirm_runs=0,
                                factors=tuple(longer if f is factor else f for f in campaign.factors))
    names = {}
    for sid in listed:
        index = int(sid[1:])
        cell, r, k = _draw_key(index, campaign)
        if k != 0 or index >= campaign.n_samples:
            raise ValueError(f"{sid} does not name a draw of {campaign.name!r} (its sample on the first value of "
                             f"{factor.name})")
        names[(cell, r)] = sid
    samples, of = [], {}
    width = len(str(campaign.confirm_runs))
    for s in draw(stage):
        cell, r, k = _draw_key(s.index, stage)
        if k >= first and (cell, r) in names:
            d = names[(cell, r)]
            sid = f"{d}_c{k - first + 1:0{width}d}"  # the draw's fresh run 1, 2, ...
            samples.append(dataclasses.replace(s, id=sid))
            of[sid] = d
    return stage, samples, of


def format_value(v: Any) -> Any:
    """A factor value for a CSV cell: numbers as they are, tables/lists as compact JSON."""
    if isinstance(v, (dict, list)):
        return json.dumps(v, separators=(",", ":"), sort_keys=True)
    return v


def sample_document(campaign: Campaign, sample: Sample) -> dict[str, Any]:
    """The base scenario with the sample's factor values applied."""
    doc = copy.deepcopy(dict(campaign.base_doc))
    for name, value in sample.values.items():
        why = fx.lookup(name).apply(doc, copy.deepcopy(value))
        if why:  # parse_campaign probed every factor on the base: a bug if it shows here
            raise ScenarioError([f"factors.{name}: {why}"], source=campaign.source)
    settings = ", ".join(f"{k} = {format_value(v)}" for k, v in sample.values.items())
    doc["name"] = sample.id
    doc["description"] = f"campaign {campaign.name}, sample {sample.id}: {settings}"
    doc["tags"] = ["campaign", campaign.name]
    return doc


def sample_text(campaign: Campaign, sample: Sample) -> str:
    header = (f"Generated by `python -m scenarios campaign` (campaign {campaign.name!r}, seed {campaign.seed}, "
              f"sample {sample.index + 1} of {campaign.n_samples}).\n"
              f"Re-run it alone, from the campaign folder: python -m scenarios run samples/{sample.id}.toml")
    return tomlw.dumps(sample_document(campaign, sample), header=header)


def build_samples(campaign: Campaign, samples: list[Sample] | None = None) -> dict[str, str]:
    """``{sample id: scenario file text}`` of ``samples`` (default: :func:`draw`), each
    text checked by the scenario loader.

    Raises ScenarioError listing every problem of every sample (``sNNNN: field = ...``).
    """
    texts: dict[str, str] = {}
    problems: list[str] = []
    for sample in draw(campaign) if samples is None else samples:
        text = sample_text(campaign, sample)
        try:
            scenario_spec.parse_scenario(tomllib.loads(text), source=sample.id, base_dir=campaign.base_dir)
        except ScenarioError as exc:
            problems.extend(f"{sample.id}: {p}" for p in exc.problems)
        texts[sample.id] = text
    if problems:
        raise ScenarioError(problems, source=campaign.source)
    return texts
