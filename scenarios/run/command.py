"""The ``run`` command: ``python -m scenarios run NAME|FILE|all|paper [...]`` (see
:mod:`scenarios.cli` for the whole command line and the exit statuses).

:func:`add_parser` puts it under the top command line; :func:`main` runs it alone on its own
arguments (the campaigns' fork server does, :mod:`scenarios.campaign.forkrun`). Its options
become one :class:`~scenarios.run.options.RunOptions` (:func:`run`), checked with the scenarios
and the results folder before anything is simulated, every problem named at once.
"""
from __future__ import annotations

import argparse

from scenarios.lang.cmdline import Parser
import logging
import sys
from pathlib import Path
from typing import Sequence

from fmu_src.core.avr_errors import AvrError
from fmu_src.core.avr_profiles import PROFILES
from scenarios.cosim.fmus import REGULATOR_FMUS, REPO_ROOT, ensure_fmu, ensure_plant_fmu
from scenarios.errors import USER_ERRORS, ScenarioError
from scenarios.run.options import (CONTROLLERS, DEFAULT_CONTROLLER, DEFAULT_OUT, DEFAULT_REGULATOR, PLANTS,
                                   REGULATORS, RunOptions)


def add_arguments(sp: argparse.ArgumentParser) -> None:
    """The ``run`` command's arguments on ``sp``."""
    sp.add_argument("targets", nargs="+", metavar="NAME|FILE")
    sp.add_argument("--model", default=None, help="menagerie, osu or an MJCF path (overrides the files)")
    sp.add_argument("--out", default=str(DEFAULT_OUT), help="results folder (default: runs)")
    sp.add_argument("--regulator", choices=REGULATORS, default=None,
                    help="; ".join(f"{k}: {r.help} (default file {r.default.relative_to(REPO_ROOT)})"
                                   for k, r in REGULATOR_FMUS.items())
                    + f"; inprocess: the regulator core called in-process, no FMU. Default: the kind of the --fmu "
                      f"file, else {DEFAULT_REGULATOR} (every path gives the same bits)")
    sp.add_argument("--controller", choices=CONTROLLERS, default=None,
                    help="the nominal walking controller of the in-process plant: python (plant/controller.py) or "
                         "native (the same operations in C, plant/native/, built once under build/native_ctrl/ "
                         f"with cc). Default: {DEFAULT_CONTROLLER} (python with --plant fmu, whose FMU carries "
                         "its own); both give the same bits")
    sp.add_argument("--jobs", type=int, default=1, help="parallel worker processes (default 1)")
    sp.add_argument("--fmu", type=Path, default=None,
                    help="the regulator FMU file, of the --regulator's FMI version (default: the regulator's "
                         "file in dist/, built if missing or stale)")
    sp.add_argument("--rebuild-fmu", action="store_true", help="rebuild the default FMU first")
    sp.add_argument("--duration", type=float, default=None, help="override every scenario's duration_s (quick runs)")
    sp.add_argument("--profile", default=None, metavar="NAME",
                    help=f"every regulator arm starts from the named profile ({', '.join(PROFILES)}; "
                         "dist/profiles/NAME.ssv) instead of the FMU's defaults; the files' own values stay on top")
    sp.add_argument("--no-plots", action="store_true",
                    help="write no PNG plots (time series and summary only: campaign tasks, which plot "
                         "the whole campaign themselves, or any run where ~1 s per scenario matters)")
    sp.add_argument("--plant", choices=PLANTS, default="inprocess",
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


def add_parser(sub) -> None:
    """The ``run`` sub-command under the top command line's ``sub``."""
    sp = sub.add_parser("run", help="run scenarios: suite names, scenario files, `all` or `paper`")
    add_arguments(sp)
    sp.set_defaults(func=lambda args: run(RunOptions.from_args(args)))


def main(argv: Sequence[str] | None = None) -> int:
    """``run`` alone: ``argv`` holds its arguments (``-v`` for more log output), not the word ``run``."""
    p = Parser(prog="python -m scenarios run")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)")
    add_arguments(p)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING - 10 * min(args.verbose, 2),
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return run(RunOptions.from_args(args))
    except KeyboardInterrupt:  # a second Ctrl-C inside the run loop
        print("interrupted: stopped at once; results of scenarios in progress were not written", file=sys.stderr)
        return 130


def run(options: RunOptions) -> int:
    """Check everything, run, report; the exit status (see :mod:`scenarios.cli`)."""
    problems = []
    if options.render:  # before anything imports mujoco: it reads MUJOCO_GL once
        from scenarios.results.render import choose_gl_backend

        problems = choose_gl_backend()
    from scenarios.results import store
    from scenarios.run.run_session import RunSession

    scenarios, target_problems = _targets(options)
    problems += target_problems
    problems += options.problems() + _problems(options, scenarios)
    if problems:
        return _fail(problems, 2)
    try:
        options = _with_fmus(options)
    except Exception as exc:
        return _fail([str(exc)], 1)
    try:
        with store.ResultsDir(options.out) as results_dir:
            plan = store.plan(options.out, scenarios, options.regulator, options.mode)  # again, now that the folder is ours
            if plan.problems:
                return _fail(plan.problems, 2)
            session = RunSession(options.with_unpack_dir(results_dir.fmu_dir), results_dir, plan)
            session.run()
    except USER_ERRORS as exc:
        return _fail([str(exc)], 2)
    return session.report(scenarios, options.out)


def _targets(options: RunOptions) -> tuple[list, list[str]]:
    """The validated scenarios of the run (with --model/--duration) and every problem of them."""
    from scenarios.lang import spec

    try:
        scenarios = spec.resolve_targets(list(options.targets))
    except ScenarioError as exc:
        return [], [str(exc)]
    if options.model is None and options.duration_s is None and options.profile is None:
        return scenarios, []
    problems = spec.override_problems(model=options.model, duration_s=options.duration_s)
    if problems:  # the values themselves: once, as command-line errors
        return scenarios, problems
    out = []
    for s in scenarios:
        try:
            out.append(spec.override(s, model=options.model, duration_s=options.duration_s, profile=options.profile))
        except ScenarioError as exc:
            problems.append(str(exc))
    return out, problems


def _problems(options: RunOptions, scenarios: list) -> list[str]:
    """Everything the run would fail on before simulating, beyond the options and the scenarios
    themselves: scenarios the plant FMU cannot run, and the results folder."""
    from scenarios.lang.plantio import plant_fmu_problems
    from scenarios.results import store

    problems = []
    if options.plant == "fmu":
        problems += [f"{s.source or s.name}: {p} (--plant fmu)" for s in scenarios for p in plant_fmu_problems(s)]
    out = store.out_problems(options.out)
    if not out and options.out.is_dir():
        out = store.plan(options.out, scenarios, options.regulator, options.mode).problems
    return problems + out


def _fail(problems: list[str], status: int) -> int:
    for p in problems:
        print(p, file=sys.stderr)
    return status


def _with_fmus(options: RunOptions) -> RunOptions:
    """``options`` with the regulator FMU and the plant FMU the run uses (None: in-process), built if needed."""
    fmu = plant_fmu = None
    if options.regulator in REGULATOR_FMUS:
        try:
            fmu = ensure_fmu(options.fmu, rebuild=options.rebuild_fmu, regulator=options.regulator)
        except Exception as exc:
            raise AvrError(f"cannot get the FMU: {exc}") from exc
    if options.plant == "fmu":
        try:
            plant_fmu = ensure_plant_fmu(options.plant_fmu, rebuild=options.rebuild_fmu)
        except Exception as exc:
            raise AvrError(f"cannot get the plant FMU: {exc}") from exc
    controller_lib = None
    if options.controller == "native" and options.plant == "inprocess":
        from plant.native.native_ctrl import cached_library_path
        from plant.sim import NATIVE_CACHE

        try:
            controller_lib = cached_library_path(NATIVE_CACHE)
        except Exception as exc:
            raise AvrError(f"--controller native: cannot build the C walking controller: {exc}; "
                           "--controller python runs the same controller in Python (the same results)") from exc
    return options.with_fmus(None if fmu is None else Path(fmu),
                             None if plant_fmu is None else Path(plant_fmu)).with_controller_lib(controller_lib)
