"""``python -m scenarios``: list, validate and run scenarios, and write the report.

    python -m scenarios list
    python -m scenarios validate FILE [FILE ...]
    python -m scenarios run NAME|FILE|all|paper [...] [--model M] [--out DIR]
                            [--regulator fmu|native|inprocess] [--jobs N] [--fmu PATH]
                            [--duration S] [--rebuild-fmu] [--overwrite | --resume]
                            [--plant inprocess|fmu] [--plant-fmu PATH]
    python -m scenarios report DIR

``run`` checks everything before it simulates and names every problem at once: the
scenarios (each model compiled and checked to be a Cassie), the arguments, and the
results folder (:mod:`scenarios.store`: results of this run's scenarios already in DIR
are refused unless ``--overwrite`` or ``--resume``; a second run on DIR is refused).
It builds the FMU at ``dist/AdaptiveVelocityRegulator.fmu`` if it is missing or stale
(fmu path), runs each scenario x arm (``--jobs N``: in N spawned processes, each with
its own FMU copy under DIR's scratch folder), writes each scenario's
``DIR/<name>/{timeseries.csv,summary.json,*.png}`` complete and then renames it into
place, and prints one table row per scenario x arm. Ctrl-C stops the run between two
steps: complete scenarios are kept, started ones are marked ``interrupted`` (or, where
earlier results existed, left as they were), one line is printed.

Exit status: 0 when every arm completed (whatever the verdicts), 1 when an arm failed
(it is still written and reported), 2 on invalid scenarios, arguments or results
folder (nothing simulated), 130 after Ctrl-C.
"""
from __future__ import annotations

import argparse
import importlib.util
import logging
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Any, Sequence

from fmu_src.avr_errors import AvrError
from scenarios.errors import ScenarioError

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_FMU = REPO_ROOT / "dist" / "AdaptiveVelocityRegulator.fmu"
DEFAULT_NATIVE_FMU = REPO_ROOT / "dist" / "AdaptiveVelocityRegulatorNative_fmi2.fmu"
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


def ensure_fmu(fmu: Path | None, *, rebuild: bool = False, native: bool = False) -> Path:
    """The FMU to use: ``fmu`` if given, else the default one (the pythonfmu FMU, or with
    ``native`` the native FMI 2.0 FMU), (re)built when missing, older than its sources
    (``fmu_src/``, ``build.py``: a stale FMU would silently run old code) or on ``rebuild``."""
    if fmu is not None:
        fmu = Path(fmu)
        if not fmu.is_file():
            raise AvrError(f"--fmu {fmu}: no such file")
        return fmu
    default = DEFAULT_NATIVE_FMU if native else DEFAULT_FMU
    sources = [p for ext in ("py", "c", "h") for p in (REPO_ROOT / "fmu_src").rglob(f"*.{ext}")] + [REPO_ROOT / "build.py"]
    stale = default.is_file() and max(p.stat().st_mtime for p in sources) > default.stat().st_mtime
    if rebuild or stale or not default.is_file():
        log.info("building %s%s", default, " (older than its sources)" if stale else "")
        default.parent.mkdir(parents=True, exist_ok=True)
        build = load_build_module()
        return Path(build.build_native_fmu(2, default.parent) if native else build.build_fmu(default.parent))
    return default


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

    loaded, problems = [], []
    for f in args.files:
        try:
            loaded.append(spec.load_scenario(f))
        except ScenarioError as exc:
            problems.append(str(exc))
    unique, clashes = spec.distinct(loaded)
    for s in unique:
        print(f"{s.source}: ok ({s.name}, {s.duration_s:g} s, arms {', '.join(a.name for a in s.arms)})")
    problems += clashes
    for p in problems:
        print(p, file=sys.stderr)
    return 2 if problems else 0


def _run_targets(args) -> tuple[list, list[str]]:
    """The validated scenarios of ``run`` (with --model/--duration) and every problem of them."""
    from scenarios import spec

    try:
        scenarios = spec.resolve_targets(args.targets)
    except ScenarioError as exc:
        return [], [str(exc)]
    if args.model is None and args.duration is None:
        return scenarios, []
    out, problems = [], []
    for s in scenarios:
        try:
            out.append(spec.override(s, model=args.model, duration_s=args.duration))
        except ScenarioError as exc:
            problems.append(str(exc))
    return out, problems


def _run_problems(args, scenarios: list, mode: str) -> list[str]:
    """Everything ``run`` would fail on before simulating, beyond the scenarios themselves."""
    from scenarios import store

    problems = []
    if args.jobs < 1:
        problems.append(f"--jobs {args.jobs}: must be >= 1")
    if args.fmu is not None and not Path(args.fmu).is_file():
        problems.append(f"--fmu {args.fmu}: no such file")
    out_root = Path(args.out)
    out = store.out_problems(out_root)
    if not out and out_root.is_dir():
        out = store.plan(out_root, scenarios, args.regulator, mode).problems
    return problems + out


def cmd_run(args) -> int:
    from scenarios import store

    mode = "overwrite" if args.overwrite else "resume" if args.resume else "new"
    scenarios, problems = _run_targets(args)
    problems += _run_problems(args, scenarios, mode)
    if problems:
        for p in problems:
            print(p, file=sys.stderr)
        return 2
    fmu_path = None
    if args.regulator in ("fmu", "native"):
        try:
            fmu_path = str(ensure_fmu(args.fmu, rebuild=args.rebuild_fmu, native=args.regulator == "native"))
        except Exception as exc:
            print(f"cannot get the FMU: {exc}", file=sys.stderr)
            return 1
    if args.plant == "fmu":
        from scenarios.plant_fmu import ensure_plant_fmu

        try:
            args.plant_fmu = str(ensure_plant_fmu(args.plant_fmu, rebuild=args.rebuild_fmu))
        except Exception as exc:
            print(f"cannot get the plant FMU: {exc}", file=sys.stderr)
            return 1
    else:
        args.plant_fmu = None
    out_root = Path(args.out)
    try:
        with store.ResultsDir(out_root) as results_dir:
            plan = store.plan(out_root, scenarios, args.regulator, mode)  # again, now that the folder is ours
            if plan.problems:
                for p in plan.problems:
                    print(p, file=sys.stderr)
                return 2
            session = _RunSession(args, results_dir, plan, fmu_path)
            session.run()
    except AvrError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    return session.report(scenarios, out_root)


class _RunSession:
    """One ``run``: the tasks, their outcomes, each scenario published once all its arms end."""

    def __init__(self, args, results_dir, plan, fmu_path: str | None) -> None:
        from scenarios.runner import StopFlag

        self.args, self.results_dir, self.plan, self.fmu_path = args, results_dir, plan, fmu_path
        self.stop = StopFlag()
        self.outcomes: dict[str, dict[str, Any]] = {s.name: {} for s in plan.run}
        self.summaries: dict[str, dict[str, Any]] = {s["scenario"]: s for s in plan.kept}
        self.left_as_were: list[str] = []
        self.write_errors: list[str] = []
        self.wall_s = 0.0

    def run(self) -> None:
        from tqdm import tqdm

        from scenarios import runner

        tasks = [(s, a.name) for s in self.plan.run for a in s.arms]
        jobs = min(self.args.jobs, max(1, len(tasks)))
        if jobs == 1:
            bar = tqdm(total=sum(s.n_comm_steps for s, _ in tasks), unit="step", desc="co-simulation",
                       disable=None, leave=False)
        else:
            bar = tqdm(total=len(tasks), unit="arm", desc="co-simulation", disable=None, leave=False)
        wall0 = time.perf_counter()
        with bar, _sigint_sets(self.stop):
            runner.run_tasks(tasks, regulator=self.args.regulator, fmu_path=self.fmu_path,
                             unpack_dir=self.results_dir.fmu_dir, jobs=jobs, stop=self.stop,
                             on_outcome=self.on_outcome, progress=bar.update, plant_fmu=self.args.plant_fmu)
        self.wall_s = time.perf_counter() - wall0

    def on_outcome(self, scenario, outcome):
        got = self.outcomes[scenario.name]
        got[outcome.arm] = outcome
        if len(got) == len(scenario.arms):
            return self.finish(scenario, list(got.values()))
        return None

    def finish(self, scenario, outcomes: list):
        """The job that writes the scenario's folder (staged, renamed into place when it is
        done: :meth:`published`), or None. Only complete results replace earlier ones: a
        failed or interrupted scenario leaves an existing folder as it was."""
        from scenarios import output, runner

        if not any(o.started for o in outcomes):
            return None  # an interrupt kept every arm from starting: nothing to say on disk
        replace = scenario.name in self.plan.replace
        if replace and any(o.status != "complete" for o in outcomes):
            self.left_as_were.append(scenario.name)
            if not self.stop.requested:  # for the table and the exit status
                self.summaries[scenario.name] = output.build_summary(scenario, self.args.regulator, outcomes)
            return None
        try:
            staged = self.results_dir.stage(scenario.name)
        except OSError as exc:
            self.write_errors.append(f"{scenario.name}: results not written: {exc}")
            return None
        return runner.Job(output.write_results, (staged, scenario, self.args.regulator, outcomes),
                          partial(self.published, scenario.name, replace))

    def published(self, name: str, replace: bool, summary, error: BaseException | None) -> None:
        """Rename the written folder into place, or say why it was not written."""
        if error is None:
            try:
                self.results_dir.commit(name, replace=replace)
                self.summaries[name] = summary
                return
            except (OSError, AvrError) as exc:  # e.g. the disk is full: the other scenarios go on
                error = exc
        if not isinstance(error, (OSError, AvrError)):
            log.error("%s: writing the results failed", name, exc_info=error)
        self.results_dir.discard(name)
        self.write_errors.append(f"{name}: results not written: {error}")

    def report(self, scenarios: list, out_root: Path) -> int:
        """Print the table (or, after Ctrl-C, one line); the exit status."""
        from scenarios import output

        ordered = [self.summaries[s.name] for s in scenarios if s.name in self.summaries]
        if self.stop.requested:
            line = _interrupted_line(scenarios, self.summaries, self.left_as_were, out_root)
            print(line + "".join(f"; {e}" for e in self.write_errors), file=sys.stderr)
            return 130
        print(output.format_table(ordered))
        for name in self.left_as_were:
            print(f"{name}: this run's results are {self.summaries[name]['status']}; the earlier results in "
                  f"{out_root / name} were kept", file=sys.stderr)
        for err in self.write_errors:
            print(err, file=sys.stderr)
        n_arms = sum(len(s.arms) for s in self.plan.run)
        sim = sum((m.get("sim_s") or 0.0) for s in self.plan.run if s.name in self.summaries
                  for m in self.summaries[s.name]["arms"].values())
        kept = f"{len(self.plan.kept)} kept as complete (--resume), " if self.plan.kept else ""
        print(f"\n{len(scenarios)} scenario(s), {kept}{n_arms} arm run(s), {sim:.1f} simulated s in "
              f"{self.wall_s:.1f} s wall (--jobs {self.args.jobs}, regulator {self.args.regulator}); results in "
              f"{out_root}/ (python -m scenarios report {out_root})")
        failed = self.write_errors or any(su["status"] != "complete" for su in ordered)
        return 1 if failed else 0


def _interrupted_line(scenarios: list, summaries: dict, left_as_were: list[str], out_root: Path) -> str:
    status = {n: s["status"] for n, s in summaries.items()}
    complete = sum(1 for s in scenarios if status.get(s.name) == "complete")
    flagged = sorted(n for n, st in status.items() if st != "complete")
    parts = [f"{complete} of {len(scenarios)} scenario(s) complete in {out_root}/"]
    if flagged:
        parts.append(f"{', '.join(flagged)} marked incomplete")
    if left_as_were:
        parts.append(f"{', '.join(left_as_were)} left as before")
    return f"interrupted: {'; '.join(parts)}; run again with --resume to finish"


@contextmanager
def _sigint_sets(stop):
    """While inside: the first SIGINT sets ``stop`` (the run ends cleanly between steps),
    a second one raises KeyboardInterrupt (stop at once)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if stop.requested:
            raise KeyboardInterrupt
        stop.set()

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def cmd_report(args) -> int:
    from scenarios.report import write_report

    try:
        path, problems = write_report(Path(args.dir))
    except AvrError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{args.dir}: cannot write report.md: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(path)
    for p in problems:
        print(p, file=sys.stderr)
    return 2 if problems else 0


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
    sp.add_argument("--regulator", choices=("fmu", "native", "inprocess"), default="fmu",
                    help="the pythonfmu FMU through fmpy (default), the native (C) FMI 2.0 FMU through fmpy, "
                         "or the regulator core in-process")
    sp.add_argument("--jobs", type=int, default=1, help="parallel worker processes (default 1)")
    sp.add_argument("--fmu", type=Path, default=None, help=f"FMU file (default {DEFAULT_FMU.relative_to(REPO_ROOT)}, "
                                                          "built if missing)")
    sp.add_argument("--rebuild-fmu", action="store_true", help="rebuild the default FMU first")
    sp.add_argument("--duration", type=float, default=None, help="override every scenario's duration_s (quick runs)")
    sp.add_argument("--plant", choices=("inprocess", "fmu"), default="inprocess",
                    help="the MuJoCo plant in-process (default) or the CassiePlant FMU through fmpy")
    sp.add_argument("--plant-fmu", type=Path, default=None,
                    help="CassiePlant FMU file (default dist/CassiePlant.fmu, built if missing or stale)")
    again = sp.add_mutually_exclusive_group()
    again.add_argument("--overwrite", action="store_true",
                       help="replace the results of this run's scenarios already in --out")
    again.add_argument("--resume", action="store_true",
                       help="keep the complete results already in --out (same set-up) and run the other scenarios")
    sp.set_defaults(func=cmd_run)

    from scenarios.campaign.cli import add_parser as add_campaign_parser

    add_campaign_parser(sub)

    sp = sub.add_parser("report", help="write DIR/report.md over the results in DIR")
    sp.add_argument("dir")
    sp.set_defaults(func=cmd_report)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    _setup_env()
    try:
        return args.func(args)
    except KeyboardInterrupt:  # Ctrl-C outside the run loop, or a second one inside it
        print("interrupted: stopped at once; results of scenarios in progress were not written", file=sys.stderr)
        return 130
