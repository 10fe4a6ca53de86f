"""One scenario's results: ``timeseries.csv``, ``summary.json`` and the plots.

``<dir>/timeseries.csv``: the rows of every complete arm, the ``arm`` column first
(no file when no arm completed).
``<dir>/summary.json``: ``scenario``, ``model``, ``regulator``, ``path`` (the implementations the
results come from: regulator and its FMU file and SHA-256, plant, walking controller; the
results do not depend on them), the claim, ``status``,
per arm its ``status`` and, when complete, the metrics of :mod:`scenarios.results.metrics` and
its ``timings`` (where its time went, :data:`scenarios.cosim.master.TIMINGS`), the verdict of
the claim's checks, and ``timings`` of the writing (``csv_s``, ``plots_s``, their
``cpu_s``, and the ``pid`` of the process that wrote: with ``--jobs N`` a worker, see
:mod:`scenarios.run.runner`).
``<dir>/velocity.png``, ``psi.png``, ``torso.png``: :mod:`scenarios.results.plots`.
``<dir>/<arm>.mp4``, ``<arm>.gif`` (``run --render``): :mod:`scenarios.results.render`; listed
in the summary's ``videos``, the time they took in its ``timings.videos_s``.

Statuses: an arm is ``complete`` (it ran to the end or to a fall), ``failed`` (it
raised; ``error`` says why) or ``interrupted`` (stopped by Ctrl-C, or never started
because of it). A scenario is ``complete`` when every arm is, else ``failed`` when an
arm failed, else ``interrupted``. A verdict other than ``n/a`` needs every arm
complete (:func:`verdict`): an incomplete run is never a pass.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from scenarios.results import metrics
from scenarios.lang.formatting import YES_NO, is_number, show
from scenarios.results.plots import PLOTS, write_plots
from scenarios.lang.scenario import CHECK_OPS, CHECKABLE_METRICS, Scenario

log = logging.getLogger(__name__)

ARM_STATUSES = ("complete", "failed", "interrupted")
#: Every file a scenario's results folder may hold besides the videos (:func:`is_result_file`).
RESULT_FILES = ("timeseries.csv", "summary.json", *PLOTS)


def is_result_file(name: str) -> bool:
    """Whether a scenario's results folder may hold a file ``name`` (nothing else is ever
    written there): :data:`RESULT_FILES` and the arms' videos."""
    from scenarios.results.render import is_video_name

    return name in RESULT_FILES or is_video_name(name)


@dataclass(frozen=True)
class ArmOutcome:
    """How one arm ended: ``result`` (a ``master.ArmResult``) when ``complete``;
    ``error`` (one line) when ``failed``; ``started`` is false for an arm that an
    interrupt kept from starting."""

    arm: str
    status: str
    result: Any = None
    error: str | None = None
    started: bool = True

    def __post_init__(self) -> None:
        if self.status not in ARM_STATUSES or (self.status == "complete") != (self.result is not None):
            raise ValueError(f"ArmOutcome({self.arm!r}): status {self.status!r} with result {self.result!r}")


def claim_dict(scenario: Scenario) -> dict[str, Any] | None:
    if scenario.claim is None:
        return None
    return {
        "text": scenario.claim.text,
        "source": scenario.claim.source,
        "checks": [
            {"arm": c.arm, "metric": c.metric, "op": c.op, "value": c.value, "other_arm": c.other_arm}
            for c in scenario.claim.checks
        ],
    }


def scenario_header(scenario: Scenario, regulator: str) -> dict[str, Any]:
    return {
        "scenario": scenario.name,
        "description": scenario.description,
        "source": scenario.source,
        "tags": list(scenario.tags),
        "model": scenario.model,
        "regulator": regulator,
        "duration_s": scenario.duration_s,
        "comm_step_s": scenario.comm_step_s,
        "seed": scenario.seed,
        "perturbation_t_s": scenario.perturbation_t_s,
        "arm_names": [a.name for a in scenario.arms],
        "commands": [[c.t_s, c.vx_des, c.vy_des, c.yaw_rate_des] for c in scenario.commands],
        "perturbation": {
            "torso_mass_kg": scenario.torso_mass_kg,
            "torso_added_mass_kg": scenario.torso_added_mass_kg,
            "torso_com_offset_m": list(scenario.torso_com_offset_m),
            "joint_damping_scale": scenario.joint_damping_scale,
            "pushes": [{"t_s": p.t_s, "force_n": list(p.force_n), "duration_s": p.duration_s}
                       for p in scenario.pushes],
            "terrain": None if scenario.terrain is None else dataclasses.asdict(scenario.terrain),
        },
        "claim": claim_dict(scenario),
    }


def summary_commands(summary: Mapping[str, Any]) -> list[list[float]]:
    """The summary's command points as ``[t_s, vx_des, vy_des, yaw_rate_des]`` (a summary
    written before the yaw-rate command has three numbers per point: its yaw rate was 0)."""
    return [[*c, 0.0] if len(c) == 3 else list(c) for c in summary.get("commands") or []]


def build_summary(scenario: Scenario, regulator: str, outcomes: Sequence[ArmOutcome],
                  path: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """summary.json content: every arm of ``scenario`` with its status (an arm without an
    outcome is ``interrupted``, not started), metrics for the complete ones; ``path``: the
    implementations the run used (``RunOptions.path_record``), under ``path``."""
    out = scenario_header(scenario, regulator)
    if path is not None:
        out["path"] = dict(path)
    by_arm = {o.arm: o for o in outcomes}
    arms: dict[str, Any] = {}
    for arm in scenario.arms:
        o = by_arm.get(arm.name) or ArmOutcome(arm.name, "interrupted", started=False)
        entry: dict[str, Any] = {"status": o.status}
        if o.status == "complete":
            r = o.result
            entry.update(metrics.summarize_arm(r.rows, fell=r.fell, t_fall_s=r.t_fall_s,
                                               perturbation_t_s=scenario.perturbation_t_s, wall_s=r.wall_s))
            entry["fall_reason"] = r.fall_reason
            if getattr(r, "timings", None):
                entry["timings"] = dict(r.timings)
        else:
            entry["error"] = o.error
        entry["description"] = arm.description
        entry["overrides"] = {k: v for k, v in arm.overrides}
        arms[arm.name] = entry
    statuses = {a["status"] for a in arms.values()}
    out["status"] = "complete" if statuses == {"complete"} else "failed" if "failed" in statuses else "interrupted"
    errors = [f"arm {n}: {a['error']}" for n, a in arms.items() if a["status"] == "failed"]
    out["error"] = "; ".join(errors) or None
    out["arms"] = arms
    complete = [o.result for o in outcomes if o.status == "complete"]
    out["model_summary"] = complete[0].model_summary if complete else {}
    out["verdict"] = verdict(out)
    return out


def incomplete_arms(summary: Mapping[str, Any]) -> list[str]:
    """``"<arm> <status>"`` for every arm of the scenario that is not complete (or missing)."""
    arms = summary.get("arms") or {}
    names = list(summary.get("arm_names") or arms)
    out = []
    for n in names:
        status = (arms.get(n) or {}).get("status", "missing")
        if status != "complete":
            out.append(f"{n} {status}")
    return out if names else ["no arms"]


def verdict(summary: Mapping[str, Any]) -> dict[str, Any]:
    """The claim's verdict from the arms' metrics; ``n/a`` unless every arm is complete."""
    missing = incomplete_arms(summary)
    if missing:
        return {"overall": "n/a", "why": "incomplete run: " + ", ".join(missing), "checks": []}
    return evaluate_claim(summary.get("claim"), summary.get("arms") or {})


def evaluate_claim(claim: Mapping[str, Any] | None, arms: Mapping[str, Any]) -> dict[str, Any]:
    """Every check of ``claim`` against the arms' metrics; ``pass`` only if every one passes."""
    if not claim or not claim.get("checks"):
        return {"overall": "n/a", "checks": []}
    checks = [metrics.evaluate_check(c, arms) for c in claim["checks"]]
    overall = "pass" if all(c["verdict"] == "pass" for c in checks) else "miss"
    return {"overall": overall, "checks": checks}


def write_json(path: Path, data: dict[str, Any]) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=False, default=_json_default) + "\n")


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serializable: {type(o).__name__}")


def write_timeseries(path: Path, results: Sequence[Any]) -> None:
    """All arms in one CSV; the first column is ``arm``; floats round-trip exactly
    (Python's repr: the shortest text that reads back to the same double).  The columns
    are every arm's columns (the first arm's order, then any new ones); an arm without a
    column (the ``rl_hzd`` policy has no ``psi_*`` outputs) leaves its cells empty."""
    results = [r for r in results if len(r.rows)]
    with open(path, "w", newline="") as fh:
        if not results:
            fh.write("arm\n")
            return
        names = list(results[0].rows.dtype.names)
        for r in results[1:]:
            names += [n for n in r.rows.dtype.names if n not in names]
        fh.write("arm," + ",".join(names) + "\n")
        # A column equal to one already formatted (same type, same bits) takes its text: the
        # inputs are also telemetry, the offsets also Psi, the arms share t (a third of the columns).
        texts: dict[tuple[str, bytes], list[str]] = {}
        for r in results:
            prefix = r.arm + ","
            own = r.rows.dtype.names
            columns = [_memo_text(texts, r.rows[n]) if n in own else [""] * len(r.rows) for n in names]
            fh.write("".join([prefix + ",".join(cells) + "\n" for cells in zip(*columns)]))


def _memo_text(texts: dict[tuple[str, bytes], list[str]], column: np.ndarray) -> list[str]:
    key = (column.dtype.str, column.tobytes())  # C order, also for a strided field of the rows
    if key not in texts:
        texts[key] = column_text(column)
    return texts[key]


def column_text(column: np.ndarray) -> list[str]:
    """The CSV text of every value of ``column``: ``repr`` of floats, decimal integers.
    A column of few distinct values (told apart by their bits: -0.0 is not 0.0) has
    each of them formatted once."""
    bits = np.ascontiguousarray(column).view(f"u{column.dtype.itemsize}")
    distinct, index = np.unique(bits, return_inverse=True)
    if 4 * len(distinct) > len(column):
        return list(map(repr, column.tolist()))
    texts = np.array([repr(v) for v in distinct.view(column.dtype).tolist()], dtype=object)
    return texts[index].tolist()


def write_results(dest: Path, scenario: Scenario, regulator: str, outcomes: Sequence[ArmOutcome], *,
                  plots: bool = True, videos: bool = False, path: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Write csv, plots (unless ``plots`` is false: ``--no-plots``), the videos of the
    arms that carry states to render (``videos``: ``--render``) and summary (last) into
    the folder ``dest``; return the summary (its ``timings``: seconds spent writing the
    csv, the plots and the videos, the CPU time of all, the process ``pid``).

    Only complete arms have rows; the folder is meant to be a fresh one that
    :mod:`scenarios.results.store` renames into place once this returns.
    """
    dest = Path(dest)
    summary = build_summary(scenario, regulator, outcomes, path=path)
    by_arm = {o.arm: o for o in outcomes}  # the scenario's arm order, not the order the arms ended in
    ordered = [by_arm[a.name] for a in scenario.arms if a.name in by_arm]
    results = [o.result for o in ordered if o.status == "complete" and len(o.result.rows)]
    lap, cpu0 = time.perf_counter(), time.process_time()
    if results:
        write_timeseries(dest / "timeseries.csv", results)
    csv_done = time.perf_counter()
    summary["plots"] = write_plots(dest, scenario, results) if plots else []
    plots_s = time.perf_counter() - csv_done
    if videos:
        from scenarios.results.render import write_videos

        summary["videos"], videos_s = write_videos(dest, scenario, results)
    summary["timings"] = {"csv_s": csv_done - lap, "plots_s": plots_s, "cpu_s": time.process_time() - cpu0,
                          "pid": os.getpid(), **({"videos_s": videos_s} if videos else {})}
    write_json(dest / "summary.json", summary)
    return summary


def table_rows(summary: Mapping[str, Any]) -> list[dict[str, Any]]:
    """One row per arm for the CLI and report, with the arm's status (``missing`` when
    the summary lacks it); a scenario without arms gives one row (arm ``-``)."""
    arms = summary.get("arms") or {}
    names = list(summary.get("arm_names") or arms)
    scenario = summary.get("scenario")
    if not names:
        return [{"scenario": scenario, "arm": "-", "status": summary.get("status", "missing"),
                 "error": summary.get("error")}]
    rows = []
    for arm_name in names:
        m = arms.get(arm_name) or {"status": "missing"}
        rows.append({**m, "scenario": scenario, "arm": arm_name, "status": m.get("status", "missing")})
    return rows


def fmt(v: Any, digits: int = 3) -> str:
    """A table cell: ``digits`` decimals, yes/no, ``-`` for a missing value."""
    return show(v, f".{digits}f", none="-", bools=YES_NO, quote=False)


#: (summary key, column header, decimals) of the table printed by the CLI and the report.
TABLE_COLUMNS = (
    ("scenario", "scenario", 0), ("arm", "arm", 0), ("fell", "fell", 0), ("t_fall_s", "t_fall_s", 2),
    ("steady_state_error_vx", "sse_vx", 3), ("steady_state_error_vy", "sse_vy", 3),
    ("steady_state_error_vy_stride", "sse_vy2", 3), ("steady_state_error_yaw_rate", "sse_yaw", 3),
    ("convergence_time_s", "t_conv_s", 2), ("wall_s", "wall_s", 1), ("realtime_factor", "rtf", 2),
)


def format_table(summaries: Sequence[dict[str, Any]]) -> str:
    """A plain-text table, one row per scenario x arm (failed arms and scenarios say so)."""
    header = [h for _, h, _ in TABLE_COLUMNS] + ["verdict"]
    lines = []
    for s in summaries:
        overall = verdict(s).get("overall", "n/a")
        for row in table_rows(s):
            if row.get("status") != "complete":
                cells = [fmt(row.get("scenario")), fmt(row.get("arm"))] + [""] * (len(TABLE_COLUMNS) - 2)
                cells[2] = f"{row.get('status')}: {str(row.get('error') or '')[:60]}"
                lines.append(cells + [overall])
                continue
            lines.append([fmt(row.get(k), d) for k, _, d in TABLE_COLUMNS] + [overall])
    widths = [max([len(header[i])] + [len(line[i]) for line in lines]) for i in range(len(header))]
    out = ["  ".join(h.ljust(w) for h, w in zip(header, widths)), "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.ljust(w) for c, w in zip(line, widths)).rstrip() for line in lines]
    return "\n".join(out)


# --------------------------------------------------------------------------- reading summary.json back
class _Kind:
    """One rule of :data:`SUMMARY_SCHEMA`: ``ok(value)`` and what is allowed, in words."""

    def __init__(self, ok: Any, allowed: str, items: Any = None, keys: Mapping[str, Any] | None = None,
                 required: tuple[str, ...] = ()) -> None:
        self.ok, self.allowed, self.items, self.keys, self.required = ok, allowed, items, keys, required


def _finite(v: Any) -> bool:
    """A JSON number (not a bool) that is a finite double: an int beyond the doubles'
    range cannot be formatted as one, NaN and infinities are no measurement."""
    if not is_number(v):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _num(ge: float | None = None, gt: float | None = None) -> _Kind:
    """A finite number, ``>= ge`` or ``> gt`` if given."""
    if ge is not None:
        return _Kind(lambda v: _finite(v) and v >= ge, f"a finite number >= {ge:g}")
    if gt is not None:
        return _Kind(lambda v: _finite(v) and v > gt, f"a finite number > {gt:g}")
    return _Kind(_finite, "a finite number")


NUM = _num()
INT = _Kind(lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer")
STR = _Kind(lambda v: isinstance(v, str), "a string")
BOOL = _Kind(lambda v: isinstance(v, bool), "true or false")
ANY_OBJECT = _Kind(lambda v: isinstance(v, dict), "an object")


def _opt(kind: _Kind) -> _Kind:
    return _Kind(lambda v: v is None or kind.ok(v), kind.allowed + " or null", kind.items, kind.keys, kind.required)


def _one_of(*values: Any) -> _Kind:
    return _Kind(lambda v: any(v == x and type(v) is type(x) for x in values),
                 "one of " + ", ".join(json.dumps(x) for x in values))


def _list(item: _Kind) -> _Kind:
    return _Kind(lambda v: isinstance(v, list), "a list", items=item)


def _obj(*required: str, **keys: _Kind) -> _Kind:
    """An object: the ``required`` keys must be there, every key in ``keys`` of its kind."""
    return _Kind(lambda v: isinstance(v, dict), "an object", keys=keys, required=required)


def _map(item: _Kind) -> _Kind:
    return _Kind(lambda v: isinstance(v, dict) and all(isinstance(k, str) for k in v), "an object", items=item)


_METRIC = _Kind(lambda v: v is None or isinstance(v, bool) or _finite(v), "a finite number, true/false or null")
_VEC3 = _Kind(lambda v: isinstance(v, list) and len(v) == 3 and all(map(_finite, v)), "a list of 3 finite numbers")
_TIME = _num(ge=0.0)
#: Each metric's kind: errors, times and extents are >= 0 (null: not measured).
_METRICS = {**{k: _METRIC for k in CHECKABLE_METRICS}, "fell": _opt(BOOL),
            **{k: _opt(_num(ge=0.0)) for k in ("t_fall_s", "steady_state_error_vx", "steady_state_error_vy",
                                                "steady_state_error_vy_stride", "steady_state_error_yaw_rate",
                                                "run_error_vx", "convergence_time_s", "max_abs_pitch_rad",
                                                "max_abs_roll_rad", "wall_s", "realtime_factor", "sim_s")}}
_ARM = _obj("status", status=_one_of(*ARM_STATUSES), error=_opt(STR), fall_reason=_opt(STR), **_METRICS,
            level_errors_vx=_list(_obj("t_s", "vx_des", t_s=_TIME, vx_des=NUM, error_vx=_opt(_num(ge=0.0)))))
#: What the CLI and the report read from a summary.json, key by key (the required ones
#: first), with the ranges the writer's values have; any other key may be missing, but
#: not wrong.
SUMMARY_SCHEMA = _obj(
    "scenario", "status", "arm_names", "arms",
    scenario=STR, description=_opt(STR), source=_opt(STR), tags=_list(STR), model=STR, regulator=STR,
    duration_s=_num(gt=0.0), comm_step_s=_num(gt=0.0), seed=INT, perturbation_t_s=_TIME, arm_names=_list(STR),
    commands=_list(_Kind(lambda v: isinstance(v, list) and len(v) in (3, 4) and all(map(_finite, v))
                         and v[0] >= 0,
                         "a list [t_s, vx_des, vy_des, yaw_rate_des] of finite numbers, t_s >= 0 (older runs: "
                         "no yaw_rate_des)")),
    perturbation=_obj(torso_mass_kg=_opt(_num(gt=0.0)), torso_added_mass_kg=_opt(NUM), torso_com_offset_m=_VEC3,
                      joint_damping_scale=_num(ge=0.0),
                      pushes=_list(_obj("t_s", "force_n", "duration_s", t_s=_TIME, force_n=_VEC3,
                                        duration_s=_num(gt=0.0))),
                      terrain=_opt(_obj("max_height_m", "max_slope_deg", "seed", max_height_m=_num(gt=0.0),
                                        max_slope_deg=_num(gt=0.0), seed=INT, size_m=_num(gt=0.0),
                                        flat_radius_m=_num(ge=0.0)))),
    claim=_opt(_obj(text=STR, source=_opt(STR), checks=_list(_obj("arm", "metric", "op",
        arm=STR, metric=_one_of(*CHECKABLE_METRICS), op=_one_of(*CHECK_OPS),
        value=_METRIC, other_arm=_opt(STR))))),
    status=_one_of("complete", "failed", "interrupted"), error=_opt(STR), arms=_map(_ARM),
    model_summary=_obj(pelvis_mass_kg=_opt(_num(gt=0.0)), pelvis_com_m=_opt(_VEC3), total_mass_kg=_num(gt=0.0)),
    verdict=ANY_OBJECT, plots=_list(_one_of(*PLOTS)),
    path=_obj(regulator=STR, plant=STR, controller=STR, regulator_fmu=_opt(STR), regulator_fmu_sha256=_opt(STR),
              plant_fmu=_opt(STR), plant_fmu_sha256=_opt(STR)),
    videos=_list(_Kind(lambda v: isinstance(v, str) and is_result_file(v) and v not in RESULT_FILES,
                       "a file name <arm>.mp4 or <arm>.gif")),
)


def _check(value: Any, kind: _Kind, where: str, problems: list[str]) -> None:
    if not kind.ok(value):
        problems.append(f"{where} = {_quoted(value)}: must be {kind.allowed}")
        return
    if kind.keys is not None and isinstance(value, dict):
        problems.extend(f"{where}.{k}: required" if where else f"{k}: required"
                        for k in kind.required if k not in value)
        for k, sub in kind.keys.items():
            if k in value:
                _check(value[k], sub, f"{where}.{k}" if where else k, problems)
    if kind.items is not None and isinstance(value, (list, dict)):
        pairs = value.items() if isinstance(value, dict) else enumerate(value)
        for k, item in pairs:
            _check(item, kind.items, f"{where}.{k}" if isinstance(value, dict) else f"{where}[{k}]", problems)


def _quoted(value: Any) -> str:
    """``value`` as JSON, cut to 60 characters."""
    try:
        return json.dumps(value)[:60]
    except (ValueError, RecursionError):  # an int Python does not write (> 4300 digits), a deep value
        return f"(a {type(value).__name__} that cannot be shown)"


def summary_problems(data: Any) -> list[str]:
    """Every way ``data`` (a parsed summary.json) is not what this package writes and
    reads, each naming its key; [] when it can be reported. Per-arm statuses must be
    present: a summary without them (or written by an older version) is not a result."""
    if not isinstance(data, dict):
        return [f"the top level must be an object, not {type(data).__name__}"]
    if data.get("status") == "ok":
        return ['written by an older version of this tool (status "ok", no status per arm): run it again']
    problems: list[str] = []
    _check(data, SUMMARY_SCHEMA, "", problems)
    if not problems and data["status"] == "complete" and incomplete_arms(data):
        problems.append(f"status = \"complete\", but not every arm is: {', '.join(incomplete_arms(data))}")
    return problems
