"""``python -m scenarios``: list, validate and run scenarios, and write the report.

    python -m scenarios list
    python -m scenarios validate FILE [FILE ...]
    python -m scenarios run NAME|FILE|all|paper [...] [--model M] [--out DIR]
                            [--regulator fmu|inprocess] [--jobs N] [--fmu PATH]
                            [--duration S] [--rebuild-fmu] [--plant inprocess|fmu] [--plant-fmu PATH]
    python -m scenarios report DIR

``run`` validates every target first (all problems at once), builds the FMU at
``dist/AdaptiveVelocityRegulator.fmu`` if it is missing (fmu path), runs each
scenario x arm (``--jobs N``: in N spawned processes, each with its own FMU copy),
writes ``DIR/<name>/{timeseries.csv,summary.json,*.png}`` and prints one table row per
scenario x arm. Exit status: 0 when every run finished (whatever the verdicts),
1 when a run failed, 2 on invalid scenarios or arguments.
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import importlib.util
import logging
import multiprocessing
import os
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Sequence

from fmu_src.avr_errors import AvrError, ScenarioError

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_FMU = REPO_ROOT / "dist" / "AdaptiveVelocityRegulator.fmu"
DEFAULT_OUT = Path("runs")
SHARED_MENAGERIE = REPO_ROOT.parent / "shared" / "cassie" / "menagerie"

log = logging.getLogger("scenarios")


# --------------------------------------------------------------------------- helpers
def _setup_env() -> None:
    """Offline development: use the shared Menagerie copy unless MENAGERIE_ROOT is set."""
    if "MENAGERIE_ROOT" not in os.environ and SHARED_MENAGERIE.is_dir():
        os.environ["MENAGERIE_ROOT"] = str(SHARED_MENAGERIE)


def load_build_module():
    """The lead's ``build.py`` at the repo root (not ``import build``: PyPA's package clashes)."""
    path = REPO_ROOT / "build.py"
    if not path.is_file():
        raise AvrError(f"cannot build the FMU: {path} does not exist")
    spec = importlib.util.spec_from_file_location("avr_build", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def ensure_fmu(fmu: Path | None, *, rebuild: bool = False) -> Path:
    """The FMU to use; the default one is (re)built when missing, older than its sources
    (``fmu_src/``, ``build.py``: a stale FMU would silently run old code) or on ``rebuild``."""
    if fmu is not None:
        fmu = Path(fmu)
        if not fmu.is_file():
            raise AvrError(f"--fmu {fmu}: no such file")
        return fmu
    sources = [*(REPO_ROOT / "fmu_src").rglob("*.py"), *(REPO_ROOT / "fmu_src").rglob("*.c"), REPO_ROOT / "build.py"]
    stale = DEFAULT_FMU.is_file() and max(p.stat().st_mtime for p in sources) > DEFAULT_FMU.stat().st_mtime
    if rebuild or stale or not DEFAULT_FMU.is_file():
        log.info("building the FMU into %s%s", DEFAULT_FMU.parent, " (older than its sources)" if stale else "")
        DEFAULT_FMU.parent.mkdir(parents=True, exist_ok=True)
        return Path(load_build_module().build_fmu(DEFAULT_FMU.parent))
    return DEFAULT_FMU


def _plant(plant_fmu: str | None):
    """The ``plant`` argument of run_arm: None (in-process walker) or the CassiePlant FMU's factory."""
    if plant_fmu is None:
        return None
    from scenarios.plant_fmu import plant_factory

    return plant_factory(plant_fmu)


def _run_task(scenario, arm_name: str, regulator: str, fmu_path: str | None, plant_fmu: str | None = None):
    """One scenario x arm in a worker process (its own plant model and FMU instance)."""
    _setup_env()
    from scenarios.master import make_regulator, run_arm

    try:
        return run_arm(scenario, arm_name, make_regulator(regulator, fmu_path), plant=_plant(plant_fmu)), None
    except Exception as exc:  # report, don't kill the pool
        return None, f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"


# --------------------------------------------------------------------------- commands
def cmd_list(args) -> int:
    from scenarios import spec

    problems = []
    rows = []
    for f in spec.suite_files():
        try:
            s = spec.load_scenario(f, check_plant=False)
            rows.append((s.name, f"{s.duration_s:g}", ",".join(a.name for a in s.arms), ",".join(s.tags),
                         s.description))
        except ScenarioError as exc:
            rows.append((f.stem, "?", "?", "?", f"INVALID: {len(exc.problems)} problem(s)"))
            problems.append(str(exc))
    header = ("name", "duration_s", "arms", "tags", "description")
    widths = [max(len(header[i]), *(len(r[i]) for r in rows)) for i in range(4)] if rows else [4] * 4
    print("  ".join(h.ljust(w) for h, w in zip(header[:4], widths)) + "  " + header[4])
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r[:4], widths)) + "  " + r[4])
    for p in problems:
        print(p, file=sys.stderr)
    return 2 if problems else 0


def cmd_validate(args) -> int:
    from scenarios import spec

    status = 0
    for f in args.files:
        try:
            s = spec.load_scenario(f)
            print(f"{f}: ok ({s.name}, {s.duration_s:g} s, arms {', '.join(a.name for a in s.arms)})")
        except ScenarioError as exc:
            print(str(exc), file=sys.stderr)
            status = 2
    return status


def cmd_run(args) -> int:
    from tqdm import tqdm

    from scenarios import output, spec

    try:
        scenarios = spec.resolve_targets(args.targets)
        if args.model is not None or args.duration is not None:
            scenarios = [spec.override(s, model=args.model, duration_s=args.duration) for s in scenarios]
    except ScenarioError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    if args.jobs < 1:
        print(f"--jobs {args.jobs}: must be >= 1", file=sys.stderr)
        return 2
    fmu_path = None
    if args.regulator == "fmu":
        try:
            fmu_path = str(ensure_fmu(args.fmu, rebuild=args.rebuild_fmu))
        except Exception as exc:
            print(f"cannot get the FMU: {exc}", file=sys.stderr)
            return 1
    plant_fmu = None
    if args.plant == "fmu":
        from scenarios.plant_fmu import ensure_plant_fmu

        try:
            plant_fmu = str(ensure_plant_fmu(args.plant_fmu, rebuild=args.rebuild_fmu))
        except Exception as exc:
            print(f"cannot get the plant FMU: {exc}", file=sys.stderr)
            return 1
    out_root = Path(args.out)
    out_root.mkdir(parents=True, exist_ok=True)

    tasks = [(s, a.name) for s in scenarios for a in s.arms]
    results: dict[str, dict[str, Any]] = {s.name: {} for s in scenarios}
    errors: dict[str, list[str]] = {s.name: [] for s in scenarios}
    summaries: dict[str, dict[str, Any]] = {}
    by_name = {s.name: s for s in scenarios}
    wall0 = time.perf_counter()

    def finish(name: str) -> None:
        s = by_name[name]
        done = [results[name][a.name] for a in s.arms if a.name in results[name]]
        err = "; ".join(errors[name]) or None
        summaries[name] = output.write_results(out_root, s, args.regulator, done, error=err)

    def record(scenario, arm_name, res, err) -> None:
        if err is not None:
            errors[scenario.name].append(f"arm {arm_name}: {err.strip().splitlines()[0]}")
            log.error("%s/%s failed:\n%s", scenario.name, arm_name, err)
        else:
            results[scenario.name][arm_name] = res
        if len(results[scenario.name]) + len(errors[scenario.name]) == len(scenario.arms):
            finish(scenario.name)

    if args.jobs == 1:
        total = sum(s.n_comm_steps * len(s.arms) for s in scenarios)
        with tqdm(total=total, unit="step", desc="co-simulation", disable=None, leave=False) as bar:
            for s, arm_name in tasks:
                bar.set_postfix_str(f"{s.name}/{arm_name}")
                from scenarios.master import make_regulator, run_arm

                try:
                    res = run_arm(s, arm_name, make_regulator(args.regulator, fmu_path), progress=bar.update,
                                  plant=_plant(plant_fmu))
                    err = None
                except Exception as exc:
                    res, err = None, f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"
                if res is not None:  # the steps a fall skipped
                    bar.update(s.n_comm_steps - len(res.rows))
                record(s, arm_name, res, err)
    else:
        ctx = multiprocessing.get_context("spawn")
        with cf.ProcessPoolExecutor(max_workers=args.jobs, mp_context=ctx) as pool, \
                tqdm(total=len(tasks), unit="arm", desc="co-simulation", disable=None, leave=False) as bar:
            futures = {pool.submit(_run_task, s, a, args.regulator, fmu_path, plant_fmu): (s, a) for s, a in tasks}
            for fut in cf.as_completed(futures):
                s, a = futures[fut]
                try:
                    res, err = fut.result()
                except Exception as exc:  # the worker process died
                    res, err = None, f"{type(exc).__name__}: {exc}"
                record(s, a, res, err)
                bar.update(1)

    wall = time.perf_counter() - wall0
    ordered = [summaries[s.name] for s in scenarios if s.name in summaries]
    print(output.format_table(ordered))
    sim = sum((m.get("sim_s") or 0.0) for su in ordered for m in (su.get("arms") or {}).values())
    print(f"\n{len(scenarios)} scenario(s), {len(tasks)} arm run(s), {sim:.1f} simulated s in {wall:.1f} s wall "
          f"(--jobs {args.jobs}, regulator {args.regulator}); results in {out_root}/ "
          f"(python -m scenarios report {out_root})")
    return 1 if any(errors.values()) else 0


def cmd_report(args) -> int:
    from scenarios.report import write_report

    try:
        path = write_report(Path(args.dir))
    except FileNotFoundError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    print(path)
    return 0


# --------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m scenarios",
                                description="Closed-loop co-simulation scenarios: Cassie (MuJoCo) + the "
                                            "AdaptiveVelocityRegulator FMU.")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)")
    sub = p.add_subparsers(dest="command", required=True)

    sp = sub.add_parser("list", help="list the suite's scenarios (name, duration, arms, description)")
    sp.set_defaults(func=cmd_list)

    sp = sub.add_parser("validate", help="validate scenario files (every problem at once)")
    sp.add_argument("files", nargs="+")
    sp.set_defaults(func=cmd_validate)

    sp = sub.add_parser("run", help="run scenarios: suite names, scenario files, `all` or `paper`")
    sp.add_argument("targets", nargs="+", metavar="NAME|FILE")
    sp.add_argument("--model", default=None, help="menagerie, osu or an MJCF path (overrides the files)")
    sp.add_argument("--out", default=str(DEFAULT_OUT), help="results folder (default: runs)")
    sp.add_argument("--regulator", choices=("fmu", "inprocess"), default="fmu",
                    help="the FMU through fmpy (default) or the regulator core in-process")
    sp.add_argument("--jobs", type=int, default=1, help="parallel worker processes (default 1)")
    sp.add_argument("--fmu", type=Path, default=None, help=f"FMU file (default {DEFAULT_FMU.relative_to(REPO_ROOT)}, "
                                                          "built if missing)")
    sp.add_argument("--rebuild-fmu", action="store_true", help="rebuild the default FMU first")
    sp.add_argument("--duration", type=float, default=None, help="override every scenario's duration_s (quick runs)")
    sp.add_argument("--plant", choices=("inprocess", "fmu"), default="inprocess",
                    help="the MuJoCo plant in-process (default) or the CassiePlant FMU through fmpy")
    sp.add_argument("--plant-fmu", type=Path, default=None,
                    help="CassiePlant FMU file (default dist/CassiePlant.fmu, built if missing or stale)")
    sp.set_defaults(func=cmd_run)

    sp = sub.add_parser("report", help="write DIR/report.md over the results in DIR")
    sp.add_argument("dir")
    sp.set_defaults(func=cmd_report)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    _setup_env()
    return args.func(args)
