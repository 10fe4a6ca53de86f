"""``python -m scenarios``: list, validate and run scenarios, and write the report.

    python -m scenarios list
    python -m scenarios validate FILE [FILE ...]
    python -m scenarios run NAME|FILE|all|paper [...] [--model M] [--out DIR]
                            [--regulator fmu|native|native-fmi3|inprocess] [--jobs N] [--fmu PATH]
                            [--duration S] [--no-plots] [--rebuild-fmu] [--overwrite | --resume]
                            [--plant inprocess|fmu] [--plant-fmu PATH] [--render] [--require-pass]
    python -m scenarios report DIR
    python -m scenarios export-ssp SCENARIO [--arm ARM] [--out FILE]   (scenarios.ssp.export_ssp)

``run`` checks everything before it simulates and names every problem at once: the
scenarios (each model compiled and checked to be a Cassie), the arguments, and the
results folder (:mod:`scenarios.results.store`: results of this run's scenarios already in DIR
are refused unless ``--overwrite`` or ``--resume``; a second run on DIR is refused).
It builds the FMU at ``dist/AdaptiveVelocityRegulator.fmu`` if it is missing or stale
(fmu path), runs each scenario x arm (``--jobs N``: in N spawned processes, each with
its own FMU copy under DIR's scratch folder), writes each scenario's
``DIR/<name>/{timeseries.csv,summary.json,*.png}`` (and with ``--render`` each arm's
``<arm>.mp4`` and ``<arm>.gif``, :mod:`scenarios.results.render`) complete and then renames it into
place, and prints one table row per scenario x arm. Ctrl-C stops the run between two
steps: complete scenarios are kept, started ones are marked ``interrupted`` (or, where
earlier results existed, left as they were), one line is printed.

Exit status: 0 when every arm completed (whatever the verdicts, unless
``--require-pass``), 1 when an arm failed (it is still written and reported), 2 on
invalid scenarios, arguments or results folder (nothing simulated), 3 with
``--require-pass`` when every arm completed but a scenario's verdict is not ``pass``
(a ``miss``, or ``n/a`` for a scenario without a claim), 130 after Ctrl-C.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Sequence

from fmu_src.core.avr_errors import AvrError
from scenarios.errors import USER_ERRORS, ScenarioError
from scenarios.cosim.fmus import (REGULATOR_FMUS, REPO_ROOT, ensure_fmu, ensure_plant_fmu,
                            fmu_role_problem, fmu_version_problem)

DEFAULT_OUT = Path("runs")

log = logging.getLogger("scenarios")


# --------------------------------------------------------------------------- commands
def cmd_list(args) -> int:
    from scenarios.lang import spec

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
    from scenarios.lang import spec

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
    from scenarios.lang import spec

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
    from scenarios.results import store
    from scenarios.lang.plantio import plant_fmu_problems

    problems = []
    if args.jobs < 1:
        problems.append(f"--jobs {args.jobs}: must be >= 1")
    if args.render and args.plant == "fmu":
        problems.append("--render with --plant fmu: the CassiePlant FMU gives no MuJoCo state to render; "
                        "render with --plant inprocess (the same plant)")
    if args.fmu is not None and not Path(args.fmu).is_file():
        problems.append(f"--fmu {args.fmu}: no such file")
    elif args.fmu is not None and args.regulator in REGULATOR_FMUS:
        problems += filter(None, [fmu_version_problem(args.regulator, Path(args.fmu))
                                  or fmu_role_problem("--fmu", Path(args.fmu), "regulator")])
    if args.plant == "fmu":
        if args.plant_fmu is not None and not Path(args.plant_fmu).is_file():
            problems.append(f"--plant-fmu {args.plant_fmu}: no such file")
        elif args.plant_fmu is not None:
            problems += filter(None, [fmu_role_problem("--plant-fmu", Path(args.plant_fmu), "plant")])
        problems += [f"{s.source or s.name}: {p} (--plant fmu)" for s in scenarios for p in plant_fmu_problems(s)]
    out_root = Path(args.out)
    out = store.out_problems(out_root)
    if not out and out_root.is_dir():
        out = store.plan(out_root, scenarios, args.regulator, mode).problems
    return problems + out


def cmd_run(args) -> int:
    problems = []
    if args.render:  # before anything imports mujoco: it reads MUJOCO_GL once
        from scenarios.results.render import choose_gl_backend

        problems = choose_gl_backend()
    from scenarios.results import store
    from scenarios.run.run_session import RunSession

    mode = "overwrite" if args.overwrite else "resume" if args.resume else "new"
    scenarios, target_problems = _run_targets(args)
    problems += target_problems
    problems += _run_problems(args, scenarios, mode)
    if problems:
        return _fail(problems, 2)
    try:
        fmu_path, args.plant_fmu = _fmus(args)
    except Exception as exc:
        return _fail([str(exc)], 1)
    out_root = Path(args.out)
    try:
        with store.ResultsDir(out_root) as results_dir:
            plan = store.plan(out_root, scenarios, args.regulator, mode)  # again, now that the folder is ours
            if plan.problems:
                return _fail(plan.problems, 2)
            session = RunSession(args, results_dir, plan, fmu_path)
            session.run()
    except USER_ERRORS as exc:
        return _fail([str(exc)], 2)
    return session.report(scenarios, out_root)


def _fail(problems: list[str], status: int) -> int:
    for p in problems:
        print(p, file=sys.stderr)
    return status


def _fmus(args) -> tuple[str | None, str | None]:
    """The regulator FMU and the plant FMU the run uses (None: in-process), built if needed."""
    fmu_path = plant_fmu = None
    if args.regulator in REGULATOR_FMUS:
        try:
            fmu_path = str(ensure_fmu(args.fmu, rebuild=args.rebuild_fmu, regulator=args.regulator))
        except Exception as exc:
            raise AvrError(f"cannot get the FMU: {exc}") from exc
    if args.plant == "fmu":
        try:
            plant_fmu = str(ensure_plant_fmu(args.plant_fmu, rebuild=args.rebuild_fmu))
        except Exception as exc:
            raise AvrError(f"cannot get the plant FMU: {exc}") from exc
    return fmu_path, plant_fmu


def cmd_report(args) -> int:
    from scenarios.report import write_report

    try:
        path, problems = write_report(Path(args.dir))
    except USER_ERRORS as exc:
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
    sp.add_argument("--regulator", choices=(*REGULATOR_FMUS, "inprocess"), default="fmu",
                    help="; ".join(f"{k}: {r.help} (default file {r.default.relative_to(REPO_ROOT)})"
                                   for k, r in REGULATOR_FMUS.items())
                    + "; inprocess: the regulator core called in-process, no FMU. Default: fmu")
    sp.add_argument("--jobs", type=int, default=1, help="parallel worker processes (default 1)")
    sp.add_argument("--fmu", type=Path, default=None,
                    help="the regulator FMU file, of the --regulator's FMI version (default: the regulator's "
                         "file in dist/, built if missing or stale)")
    sp.add_argument("--rebuild-fmu", action="store_true", help="rebuild the default FMU first")
    sp.add_argument("--duration", type=float, default=None, help="override every scenario's duration_s (quick runs)")
    sp.add_argument("--no-plots", action="store_true",
                    help="write no PNG plots (time series and summary only: campaign tasks, which plot "
                         "the whole campaign themselves, or any run where ~1 s per scenario matters)")
    sp.add_argument("--plant", choices=("inprocess", "fmu"), default="inprocess",
                    help="the MuJoCo plant in-process (default) or the CassiePlant FMU through fmpy")
    sp.add_argument("--plant-fmu", type=Path, default=None,
                    help="CassiePlant FMU file (default dist/CassiePlant.fmu, built if missing or stale)")
    sp.add_argument("--render", action="store_true",
                    help="also write each arm's video, <arm>.mp4 and a small <arm>.gif, from a camera following "
                         "the pelvis (MuJoCo offscreen: MUJOCO_GL egl or osmesa; not with --plant fmu)")
    sp.add_argument("--require-pass", action="store_true",
                    help="exit 3 unless every scenario's claim verdict is pass (the README's main job: a claim "
                         "that misses is a failure, not a line in a table)")
    again = sp.add_mutually_exclusive_group()
    again.add_argument("--overwrite", action="store_true",
                       help="replace the results of this run's scenarios already in --out")
    again.add_argument("--resume", action="store_true",
                       help="keep the complete results already in --out (same set-up) and run the other scenarios")
    sp.set_defaults(func=cmd_run)

    from scenarios.campaign.cli import add_parser as add_campaign_parser

    add_campaign_parser(sub)

    from scenarios.ssp.export_ssp import add_parser as add_export_ssp_parser

    add_export_ssp_parser(sub)

    sp = sub.add_parser("report", help="write DIR/report.md over the results in DIR")
    sp.add_argument("dir")
    sp.set_defaults(func=cmd_report)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except KeyboardInterrupt:  # Ctrl-C outside the run loop, or a second one inside it
        print("interrupted: stopped at once; results of scenarios in progress were not written", file=sys.stderr)
        return 130
