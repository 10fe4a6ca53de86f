"""The command line: ``python -m fmu_src.fmi.conformance PATH.fmu [--report junit.xml] [--json out.json]``
(also installed as ``fmi-conformance``).  Exit status 0 when every check passes (skips allowed),
1 when one fails, 2 on bad input (not an FMU, no binary for this platform, a bad option)."""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from fmu_src.fmi.conformance import report
from fmu_src.fmi.conformance.checks import CHECKS, GROUPS
from fmu_src.fmi.conformance.model import BadInput, Fmu, extract
from fmu_src.fmi.conformance.runner import run_all

#: option -> (lowest allowed value, highest allowed value)
RANGES = {"timeout": (1, 86400), "steps": (3, 100000), "cycles": (2, 100000), "flips": (0, 1_000_000),
          "max_growth_kib": (0, 1 << 30), "seed": (0, 2**63 - 1)}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fmi-conformance", description="Dynamic FMI 2.0/3.0 co-simulation conformance "
                                "check: the model description, every function in every state, argument and "
                                "FMU-state fuzzing, life cycle; every dynamic check group in a child process.")
    p.add_argument("fmu", type=Path, help="the .fmu file (or an extracted FMU folder)")
    p.add_argument("--report", type=Path, metavar="JUNIT_XML", help="write a JUnit XML report here")
    p.add_argument("--json", type=Path, metavar="JSON", help="write a JSON report here")
    p.add_argument("--only", action="append", default=[], metavar="CHECK_OR_GROUP",
                   help=f"run only these checks or groups (repeatable; groups: {', '.join(GROUPS)})")
    p.add_argument("--timeout", type=float, default=120.0, help="time limit of each child process, s (default 120)")
    p.add_argument("--steps", type=int, default=10, help="communication steps per run, at least 3 (default 10)")
    p.add_argument("--step", type=float, default=None,
                   help="communication step size, s (default: the DefaultExperiment's stepSize, else 1e-3)")
    p.add_argument("--cycles", type=int, default=20, help="instantiate/free cycles of lifecycle.memory (default 20)")
    p.add_argument("--max-growth-kib", type=float, default=16.0,
                   help="resident memory growth per instantiate/free cycle (after the first half of the cycles, "
                        "a garbage collection and malloc_trim) that fails lifecycle.memory, KiB (default 16)")
    p.add_argument("--flips", type=int, default=64, help="single-bit flips of a serialized state (default 64)")
    p.add_argument("--seed", type=int, default=0, help="seed of the inputs and of the flipped bits (default 0)")
    return p


def validate(args) -> list[str]:
    """Every problem with the options, at once."""
    problems = []
    for name, (low, high) in RANGES.items():
        value = getattr(args, name)
        if not low <= value <= high:
            problems.append(f"--{name.replace('_', '-')} {value:g}: allowed range [{low}, {high}]")
    if args.step is not None and not 0 < args.step < float("inf"):
        problems.append(f"--step {args.step:g}: must be a finite number > 0")
    known = {c.id for c in CHECKS} | set(GROUPS)
    problems += [f"--only {name}: no such check or group (groups: {', '.join(GROUPS)})"
                 for name in args.only if name not in known]
    return problems


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    problems = validate(args)
    if problems:
        print("fmi-conformance: " + "; ".join(problems), file=sys.stderr)
        return 2
    options = {"timeout": args.timeout, "steps": args.steps, "step": args.step, "cycles": args.cycles,
               "flips": args.flips, "max_growth_kib": args.max_growth_kib, "seed": args.seed}
    with tempfile.TemporaryDirectory(prefix="fmi_conformance_") as tmp:
        try:
            fmu = Fmu(extract(args.fmu, Path(tmp)))
        except BadInput as exc:
            print(f"fmi-conformance: {exc}", file=sys.stderr)
            return 2
        results = run_all(fmu, options, tuple(args.only))
    name = args.fmu.name
    print("\n".join(report.lines(name, fmu.version, results)))
    if args.report:
        report.write(args.report, report.junit(name, fmu.version, results))
    if args.json:
        report.write(args.json, json.dumps(report.to_json(name, fmu.version, results), indent=2) + "\n")
    return 1 if any(r.status == "fail" for r in results) else 0
