"""Where the main job's wall time goes: the suite against the physics and the loop, in one run.

    python benchmarks/bench_suite.py [TARGET ...] [--jobs 2] [--duration S] [--fmu PATH]
                                     [--regulator fmu|native] [--controller python|native]
                                     [--repeat 3] [--compare DIR] [--keep DIR] [--json FILE]
                                     [--code CHECKOUT] [--no-plots]

``TARGET``: what ``python -m scenarios run`` takes (default ``all``, the whole suite;
``--duration 8`` makes a quick representative run of every scenario). Measured in this
one run, one after the other:

- the physics limit: bare ``mj_step`` (``bench_cosim.bare_mj_step``: the model from
  ``home``, no controller) on every distinct plant of the targets, terrain included,
  best of ``--repeat``; the limit is that rate times ``--jobs`` processes, weighted by
  the simulated seconds run on each plant;
- the loop benchmark (``bench_cosim.closed_loop_all``: ``run_arm`` through the FMU,
  10 simulated s, best of ``--repeat``) on the flat nominal plant and, when a target
  has terrain, on its terrain, on the path the suite takes (``--regulator``, ``--controller``:
  the run's defaults, the native regulator FMU and the C walking controller; ``--regulator fmu
  --controller python`` is the reference path);
- the suite: ``python -m scenarios run TARGET... --jobs N`` in a subprocess: its wall
  time, the CPU time of it and its workers (``RUSAGE_CHILDREN``), and from each
  ``summary.json`` every arm's ``timings`` (``scenarios.cosim.master.TIMINGS``; start-up =
  worker start for its first arm, model, walker, regulator start) and each
  scenario's writing (csv, plots, their CPU time, and which process wrote).

Rates are given per wall second and per CPU second: on a shared machine wall time
mostly measures the neighbours, and each arm's ``rtf`` is compared with the loop
benchmark on its own kind of floor. ``--compare DIR`` checks every ``timeseries.csv``
byte for byte and the metrics of every ``summary.json`` against an earlier run.
``--no-plots`` runs the suite with ``run --no-plots`` (the plots cost the difference from
a run with them). ``--code CHECKOUT`` runs the suite of another checkout (e.g. ``git
archive`` of the commit before) against the same yardsticks: a before/after on one
machine state (a version without ``timings`` gets totals and per-arm ``rtf`` only).
"""
from __future__ import annotations

import argparse
import json
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "benchmarks"))
sys.path.insert(0, str(REPO_ROOT))

import bench_cosim  # noqa: E402
from scenarios.docs import BENCH_TARGETS  # noqa: E402
from scenarios.lang import spec  # noqa: E402
from scenarios.lang.plantio import load_plant_model  # noqa: E402
from scenarios.cosim.regulators import FmuRegulator
from scenarios.lang.scenario import Scenario

#: summary.json keys that differ between runs of the same thing (time, where the file was).
VOLATILE_ARM_KEYS = ("wall_s", "realtime_factor", "timings", "status")
VOLATILE_TOP_KEYS = ("source", "timings", "status", "error", "regulator", "path")  # path: not the results


def floor_kind(scenario: Scenario) -> str:
    return "terrain" if scenario.terrain is not None else "flat"


# --------------------------------------------------------------------------- the yardsticks
def physics_rates(scenarios: list[Scenario], repeat: int) -> dict[str, dict[str, float]]:
    """Bare mj_step on each scenario's compiled plant (measured once per distinct plant),
    best of ``repeat`` by CPU rate, by scenario name."""
    plants = {s.name: load_plant_model(s, shared=True)[0] for s in scenarios}
    best: dict[int, dict[str, float]] = {}
    for _ in range(repeat):
        for model in {id(m): m for m in plants.values()}.values():
            m = bench_cosim.bare_mj_step(3.0, model)
            if id(model) not in best or m["rtf_cpu"] > best[id(model)]["rtf_cpu"]:
                best[id(model)] = m
    return {name: best[id(model)] for name, model in plants.items()}


def loop_rates(scenarios: list[Scenario], fmu: Path, repeat: int, controller: str = "python") -> dict[str, dict[str, float]]:
    """The FMU loop benchmark on the flat nominal plant and on each terrain of the targets, with
    the walking controller ``controller``."""
    from plant.sim import CassieWalker

    plant = None if controller == "python" else lambda scenario, model: CassieWalker(model, controller=controller)
    benches = {"flat": spec.resolve_targets(["nominal"])[0]}
    benches.update({"terrain": s for s in scenarios if s.terrain is not None})
    out = {}
    for kind, s in benches.items():
        short = spec.override(s, duration_s=10.0)
        out[kind] = bench_cosim.closed_loop_all(short, {"fmu": lambda: FmuRegulator(fmu)}, repeat, plant=plant)["fmu"]
    return out


# --------------------------------------------------------------------------- the suite
def run_suite(targets: list[str], jobs: int, fmu: Path, out: Path, duration: float | None,
              code: Path = REPO_ROOT, path: tuple[str, ...] = ()) -> dict[str, Any]:
    """``python -m scenarios run`` (of the checkout ``code``, with the ``path`` options) in a
    subprocess: wall, CPU of it and its workers, its output."""
    cmd = [sys.executable, "-m", "scenarios", "run", *targets, "--jobs", str(jobs), "--out", str(out),
           "--fmu", str(fmu), *path]
    if duration is not None:
        cmd += ["--duration", str(duration)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=code, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        raise SystemExit(f"the suite failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    found = re.search(r"simulated s in ([0-9.]+) s wall", proc.stdout)
    return {"wall_s": wall, "cpu_s": cpu, "tasks_wall_s": float(found.group(1)) if found else None,
            "table": proc.stdout}


def read_arms(out: Path, scenarios: list[Scenario]) -> tuple[list[dict[str, Any]], dict[str, dict]]:
    """Every arm's metrics and timings, and each scenario's writing timings, from summary.json."""
    arms, writes = [], {}
    for s in scenarios:
        summary = json.loads((out / s.name / "summary.json").read_text())
        writes[s.name] = summary.get("timings") or {}
        for name, m in summary["arms"].items():
            arms.append({"scenario": s.name, "arm": name, "floor": floor_kind(s), **m})
    return arms, writes


def startup_s(t: dict[str, float]) -> float:
    """Worker start (its first arm only), model, walker and regulator start."""
    return t.get("worker_startup_s", 0.0) + t["model_s"] + t["walker_s"] + t["regulator_start_s"]


# --------------------------------------------------------------------------- comparing with an earlier run
def compare_runs(new: Path, old: Path, scenarios: list[Scenario], skip: tuple[str, ...] = ()) -> list[str]:
    """Differences: timeseries.csv bytes, and every summary.json key of ``old`` except the
    volatile ones (wall time, statuses added later, the source path, timings) and ``skip``."""
    problems = []
    for s in scenarios:
        a, b = new / s.name, old / s.name
        if (a / "timeseries.csv").read_bytes() != (b / "timeseries.csv").read_bytes():
            problems.append(f"{s.name}: timeseries.csv differs")
        sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
        for key, value in sb.items():
            if key == "arms":
                for arm, mb in value.items():
                    ma = sa["arms"].get(arm, {})
                    diff = [k for k in mb if k not in VOLATILE_ARM_KEYS and ma.get(k) != mb[k]]
                    problems += [f"{s.name}/{arm}: {k} {ma.get(k)!r} != {mb[k]!r}" for k in diff]
            elif key not in VOLATILE_TOP_KEYS + skip and sa.get(key) != value:
                problems.append(f"{s.name}: {key} differs")
    return problems


# --------------------------------------------------------------------------- report
def arm_rates(a: dict[str, Any], loops: dict[str, dict[str, float]]) -> dict[str, float | None]:
    """An arm's rtf (summary.json: simulated s per s of run_arm) and its CPU rate, each also
    over the loop benchmark on the same floor; the CPU ones None without timings."""
    loop, t = loops[a["floor"]], a.get("timings")
    cpu = a["sim_s"] / t["cpu_s"] if t else None
    return {"rtf": a["realtime_factor"], "rtf_loop": a["realtime_factor"] / loop["rtf"],
            "cpu": cpu, "cpu_loop": None if cpu is None else cpu / loop["rtf_cpu"]}


def suite_figures(res: dict[str, Any], jobs: int) -> dict[str, Any]:
    """Totals: the suite's rate against the physics limit and the loop limit (wall and CPU)."""
    arms, phys, loops, suite = res["arms"], res["physics"], res["loop"], res["suite"]
    timed = all(a.get("timings") for a in arms)
    sim = sum(a["sim_s"] for a in arms)
    limit = {key: sum(a["sim_s"] / rates[a[pick]][rate] for a in arms)
             for key, rates, pick, rate in (("physics_cpu", phys, "scenario", "rtf_cpu"),
                                            ("physics_wall", phys, "scenario", "rtf"),
                                            ("loop_cpu", loops, "floor", "rtf_cpu"), ("loop_wall", loops, "floor", "rtf"))}
    out: dict[str, Any] = {
        "sim_s": sim, "wall_s": suite["wall_s"], "cpu_s": suite["cpu_s"],
        "physics_limit_wall_s": limit["physics_wall"] / jobs,
        "physics_fraction": limit["physics_wall"] / jobs / suite["wall_s"],
        "physics_fraction_cpu": limit["physics_cpu"] / suite["cpu_s"],
        "loop_limit_wall_s": limit["loop_wall"] / jobs, "loop_fraction": limit["loop_wall"] / jobs / suite["wall_s"],
        "loop_fraction_cpu": limit["loop_cpu"] / suite["cpu_s"],
        "lowest_rtf_loop": min(arm_rates(a, loops)["rtf_loop"] for a in arms),
    }
    if timed:
        arm_cpu = sum(a["timings"]["task_cpu_s"] for a in arms)
        worker_cpu = sum(a["timings"].get("worker_startup_cpu_s", 0.0) for a in arms)
        writes = res["writes"].values()
        write_cpu = sum(w.get("cpu_s", 0.0) for w in writes)
        out.update(arms_cpu_s=arm_cpu, worker_startup_cpu_s=worker_cpu, writing_cpu_s=write_cpu,
                   rest_cpu_s=suite["cpu_s"] - arm_cpu - worker_cpu - write_cpu,
                   writers=sorted({"parent" if w.get("pid") not in res["worker_pids"] else "workers"
                                   for w in writes}),
                   csv_s=sum(w.get("csv_s", 0.0) for w in writes), plots_s=sum(w.get("plots_s", 0.0) for w in writes),
                   last_arm_end_s=max(a["timings"]["ended_s"] for a in arms),
                   lowest_cpu_loop=min(arm_rates(a, loops)["cpu_loop"] for a in arms))
    return out


def print_arms(res: dict[str, Any]) -> None:
    print("per arm (s; start = worker start for its first arm + model + walker + regulator start; other = the "
          "loop's sensing and bookkeeping; rtf = simulated s per s of run_arm, wall and CPU; /loop = over the loop "
          "benchmark on the same floor)")
    print(f"{'scenario/arm':34s} {'sim':>5s} {'start':>6s} {'loop':>6s} {'reg':>6s} {'plant':>6s} {'rec':>5s} "
          f"{'other':>5s} {'cpu':>6s} {'rtf':>5s} {'/loop':>5s} {'rtfCPU':>6s} {'/loop':>5s} {'began':>6s}")
    for a in sorted(res["arms"], key=lambda a: (a.get("timings") or {}).get("started_s", 0.0)):
        r, t = arm_rates(a, res["loop"]), a.get("timings")
        name = f"{a['scenario']}/{a['arm']}"
        if not t:  # results of a version without timings
            print(f"{name:34s} {a['sim_s']:5.0f} {'':55s} {r['rtf']:5.2f} {r['rtf_loop']:5.2f}")
            continue
        other = t["loop_s"] - t["regulator_s"] - t["plant_s"] - t["record_s"]
        print(f"{name:34s} {a['sim_s']:5.0f} {startup_s(t):6.2f} {t['loop_s']:6.2f} {t['regulator_s']:6.2f} "
              f"{t['plant_s']:6.2f} {t['record_s']:5.2f} {other:5.2f} {t['cpu_s']:6.2f} {r['rtf']:5.2f} "
              f"{r['rtf_loop']:5.2f} {r['cpu']:6.2f} {r['cpu_loop']:5.2f} {t['started_s']:6.1f}")


def print_summary(res: dict[str, Any], jobs: int) -> None:
    f = res["figures"]
    print("\nyardsticks (this run):")
    for kind, m in res["loop"].items():
        print(f"  loop benchmark, FMU, {kind:7s} floor: {m['rtf_cpu']:6.2f} sim s / CPU s  {m['rtf']:6.2f} / wall s")
    rates = sorted(res["physics"].items(), key=lambda kv: kv[1]["rtf_cpu"])
    print(f"  bare mj_step: {rates[0][1]['rtf_cpu']:.2f} ({rates[0][0]}) .. {rates[-1][1]['rtf_cpu']:.2f} "
          f"({rates[-1][0]}) sim s / CPU s")
    no_plots = "" if res["plots"] else " --no-plots"
    print(f"\nsuite, --jobs {jobs}, --regulator {res['regulator']} --controller {res['controller']}{no_plots}: "
          f"{f['sim_s']:.0f} simulated s in {f['wall_s']:.1f} s wall (the tasks: "
          f"{res['suite']['tasks_wall_s']} s), {f['cpu_s']:.1f} CPU s in all its processes")
    if "arms_cpu_s" in f:
        print(f"  CPU: arms {f['arms_cpu_s']:.1f} s, worker start-up {f['worker_startup_cpu_s']:.1f} s, writing the "
              f"results {f['writing_cpu_s']:.1f} s (in the {' and '.join(f['writers'])}; wall: csv {f['csv_s']:.1f} s, "
              f"plots {f['plots_s']:.1f} s), the rest (the parent: start, checks, handing out work) "
              f"{f['rest_cpu_s']:.1f} s; the last arm ended {f['last_arm_end_s']:.1f} s after the tasks began")
    print(f"  physics limit ({jobs} x bare mj_step): {f['physics_limit_wall_s']:.1f} s wall -> the suite at "
          f"{f['physics_fraction']:.2f} of it (by CPU time: {f['physics_fraction_cpu']:.2f}; target >= {BENCH_TARGETS['suite']})")
    print(f"  loop limit ({jobs} x loop benchmark): {f['loop_limit_wall_s']:.1f} s wall -> the suite at "
          f"{f['loop_fraction']:.2f} of it (by CPU time: {f['loop_fraction_cpu']:.2f})")
    cpu = f" (by CPU time: {f['lowest_cpu_loop']:.2f})" if "lowest_cpu_loop" in f else ""
    print(f"  lowest arm rtf / loop benchmark: {f['lowest_rtf_loop']:.2f}{cpu} (target >= 0.80)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n\n")[0])
    ap.add_argument("targets", nargs="*", default=["all"], help="what `run` takes (default: all)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--duration", type=float, default=None, help="override every scenario's duration (quick run)")
    ap.add_argument("--fmu", default=None, help="FMU file (default: build one of --regulator's kind into a temp folder)")
    ap.add_argument("--regulator", choices=("fmu", "native"), default="native",
                    help="the regulator FMU's kind (default native, the run's default)")
    ap.add_argument("--controller", choices=("python", "native"), default="native",
                    help="the walking controller (default native, the run's default)")
    ap.add_argument("--repeat", type=int, default=3, help="best of N for the yardsticks")
    ap.add_argument("--compare", type=Path, default=None, help="an earlier results folder: bit-identity check")
    ap.add_argument("--keep", type=Path, default=None, help="write the results here (default: a temp folder)")
    ap.add_argument("--json", default=None, help="write the numbers to this file")
    ap.add_argument("--code", type=Path, default=REPO_ROOT,
                    help="run the suite of this checkout instead (e.g. the code before, for a before/after)")
    ap.add_argument("--no-plots", action="store_true", help="run the suite with `run --no-plots`")
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="bench_suite_") as tmp:
        res = measure(args, Path(tmp))
    res["figures"] = suite_figures(res, args.jobs)
    print_arms(res)
    print_summary(res, args.jobs)
    if args.compare is not None:
        print(f"\ncompared with {args.compare}: " + ("every timeseries.csv and summary.json metric identical"
                                                     if not res["compare"] else "\n  ".join(res["compare"])))
    if args.json:
        res["measured"] = bench_cosim.measured()
        Path(args.json).write_text(json.dumps(res, indent=2, default=str) + "\n")
    return 1 if res.get("compare") else 0


def measure(args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    """The yardsticks and the suite (its results in ``--keep`` or under ``tmp``, the FMU built there)."""
    fmu = bench_cosim.ensure_fmu(args.fmu, tmp, native=args.regulator == "native")
    path = ("--regulator", args.regulator, "--controller", args.controller) + (("--no-plots",) if args.no_plots else ())
    scenarios = spec.resolve_targets(args.targets)
    if args.duration is not None:
        scenarios = [spec.override(s, duration_s=args.duration) for s in scenarios]
    res: dict[str, Any] = {"targets": args.targets, "jobs": args.jobs, "duration": args.duration,
                           "regulator": args.regulator, "controller": args.controller, "plots": not args.no_plots}
    res["physics"] = physics_rates(scenarios, args.repeat)
    res["loop"] = loop_rates(scenarios, fmu, args.repeat, args.controller)
    out = args.keep or tmp / "runs"
    res["suite"] = run_suite(args.targets, args.jobs, fmu, out, args.duration, args.code, path)
    res["arms"], res["writes"] = read_arms(out, scenarios)
    res["worker_pids"] = sorted({(a.get("timings") or {}).get("pid") for a in res["arms"]} - {None})
    if args.compare is not None:
        res["compare"] = compare_runs(out, args.compare, scenarios, ("plots",) if args.no_plots else ())
    return res


if __name__ == "__main__":
    sys.exit(main())
