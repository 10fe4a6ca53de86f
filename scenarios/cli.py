"""``python -m scenarios``: list, validate and run scenarios, and write the report.

    python -m scenarios list
    python -m scenarios validate FILE [FILE ...]
    python -m scenarios run NAME|FILE|all|paper [...] [--model M] [--out DIR]
                            [--regulator fmu|native|native-fmi3|inprocess] [--jobs N] [--fmu PATH]
                            [--duration S] [--profile paper|default|robust] [--no-plots] [--rebuild-fmu]
                            [--overwrite | --resume]
                            [--plant inprocess|fmu] [--plant-fmu PATH] [--render] [--require-pass]
    python -m scenarios report DIR
    python -m scenarios export-ssp SCENARIO [--arm ARM] [--profile NAME] [--out FILE]   (scenarios.ssp.export_ssp)

``run`` (:mod:`scenarios.run.command`, its options one :class:`scenarios.run.options.RunOptions`)
checks everything before it simulates and names every problem at once: the
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

from scenarios.lang.cmdline import Parser
import logging
import sys
from pathlib import Path
from typing import Sequence

from scenarios.errors import USER_ERRORS, ScenarioError

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
            loaded.append((f, spec.load_scenario(f)))
        except ScenarioError as exc:
            problems.append(str(exc))
    unique, clashes = spec.distinct(loaded)
    for s in unique:
        print(f"{s.source}: ok ({s.name}, {s.duration_s:g} s, arms {', '.join(a.name for a in s.arms)})")
    problems += clashes
    for p in problems:
        print(p, file=sys.stderr)
    return 2 if problems else 0


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
    p = Parser(prog="python -m scenarios",
                                description="Closed-loop co-simulation scenarios: Cassie (MuJoCo) + the "
                                            "AdaptiveVelocityRegulator FMU.")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)")
    sub = p.add_subparsers(dest="command", required=True)

    sp = sub.add_parser("list", help="list the suite's scenarios (name, duration, arms, description)")
    sp.set_defaults(func=cmd_list)

    sp = sub.add_parser("validate", help="validate scenario files (every problem at once)")
    sp.add_argument("files", nargs="+")
    sp.set_defaults(func=cmd_validate)

    from scenarios.run.command import add_parser as add_run_parser

    add_run_parser(sub)

    from scenarios.campaign.cli import add_parser as add_campaign_parser

    add_campaign_parser(sub)

    from scenarios.ssp.export_ssp import add_parser as add_export_ssp_parser

    add_export_ssp_parser(sub)

    from scenarios.docs import add_parser as add_docs_parser

    add_docs_parser(sub)

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
