"""Campaign throughput on Dask: a real campaign with 1 and 2 local workers, against the physics.

    python benchmarks/bench_campaign.py [--samples 20] [--repeat 1] [--fmu PATH] [--json FILE]
                                        [--baseline-repo DIR]

The campaign is ``robustness_random`` (every factor of the shipped file: models, friction,
masses, COM, damping, slopes and rough terrain, pushes, a changing command) with ``--samples``
samples x its arms ``adaptive`` and ``pd_only`` (its replicas and RL-HZD left out) of 25
simulated seconds, run by the real CLI (``python -m scenarios campaign``) into a temporary
folder, with ``--workers 1`` and ``--workers 2``, interleaved ``--repeat`` times (the
fastest campaign of each counts). Printed:

- the rate per worker: simulated seconds per CPU second of the campaign and all its processes
  (the CPU time of every process on the machine while it runs, :func:`machine_cpu_s`: the CLI,
  the Dask workers, the fork servers, every task's run, forked or not; another process's too,
  so measure on a quiet machine), against bare ``mj_step`` on
  each sample's own plant (best of three, weighted by the simulated seconds run on it; target
  >= 0.8), and per wall second per worker;
- wall time of each campaign (CLI start to exit: cluster start-up included) and the
  scaling ``wall(1 worker) / wall(2 workers)`` (target >= 1.8 on 2 cores); the fixed
  cost per campaign (wall minus the tasks' wall per worker), the scaling of the task
  phase alone, and the scaling per unit of co-simulation work (on a shared machine the
  same work runs slower with two workers than with one: dividing that out estimates the
  scaling on two free cores);
- per-task overhead = the task's wall time (its ``scenarios run`` process, start to
  exit) minus the co-simulation loops of its arms (``wall_s`` in summary.json), per
  task and per arm;
- what that overhead is made of, from one ``scenarios run`` of a sample as a campaign
  task runs it (``--no-plots``), under cProfile (profiling inflates Python-heavy parts;
  read the shares, not the absolute seconds): interpreter start and imports, the
  model's check and compilation, FMU set-up, writing the time series.

Set-ups, interleaved (load from other processes hits them alike): this tree as it is
(each task's run forked from a warm server per worker, the default), this tree with
``--no-fork-runs`` (each task a new ``python -m scenarios run --no-plots`` process), and with
``--baseline-repo DIR`` the code in DIR (another checkout, e.g. ``git archive main | tar
-x -C DIR``; same interpreter and FMU), so that before/after are measured in one run.

The machine may be shared: the numbers are only as steady as its load.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import pstats
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "benchmarks"))
sys.path.insert(0, str(REPO_ROOT))

RANDOM = REPO_ROOT / "scenarios" / "campaigns" / "robustness_random.toml"
#: The arms of ``robustness_random`` the throughput campaign runs (its other nine: the replicas and RL-HZD).
RANDOM_ARMS = ("adaptive", "pd_only")
#: (file, function) under cProfile -> the part of a task it measures
PARTS = {("scenarios/lang/plantio.py", "check_plant"): "model check before the run, a compile (overhead)",
         ("scenarios/lang/plantio.py", "load_plant_model"): "plant model compilation (overhead)",
         ("scenarios/results/plots.py", "write_plots"): "plots, matplotlib (overhead)",
         ("scenarios/results/output.py", "write_timeseries"): "time series CSV (overhead)",
         ("scenarios/cosim/master.py", "run_arm"): "arms: co-simulation incl. FMU start (work)",
         ("scenarios/cosim/regulators.py", "start"): "  of which regulator start (FMU extract + instantiate)"}
#: what a run process imports (the imports of a campaign task's run, matplotlib not among them)
RUN_IMPORTS = "import scenarios.cli, scenarios.run.run_session, scenarios.cosim.master, scenarios.results.output, mujoco, fmpy, plant.sim"


def random_campaign_file(folder: Path, samples: int) -> Path:
    """``robustness_random`` with ``samples`` samples and its arms :data:`RANDOM_ARMS` only (the rest of
    the file as it is: the factors, the floors, the pushes, the commands, 25 simulated s)."""
    import re

    text = RANDOM.read_text()
    head, *arms = text.split("\n[[base.arm]]\n")
    kept = [a for a in arms if re.search(r'^name = "([^"]+)"', a, re.M).group(1) in RANDOM_ARMS]
    head = re.sub(r"^compare = \[[^\]]*\]", "compare = " + json.dumps(list(RANDOM_ARMS)), head, flags=re.M)
    head = re.sub(r"^\[replicas\]\n(?:[^\[\n].*\n)*", "", head, flags=re.M)
    # the replicas (each draw on several grounds: replicate_over's grid) left out: one run per sample
    head = re.sub(r"^(replicate_over|redraw|confirm_runs) = .*\n", "", head, flags=re.M)
    head = re.sub(r"^(\[factors\.floor_terrain_seed\].*\n(?:[^\[\n].*\n)*?)values = \[[^\]]*\]",
                  r"\1values = [1]", head, flags=re.M)
    head = re.sub(r"^samples = \d+$", f"samples = {samples}", head, flags=re.M)
    head = head.replace('name = "robustness_random"', 'name = "bench_random"')
    path = folder / "bench_random.toml"
    path.write_text("\n[[base.arm]]\n".join([head, *kept]))
    return path


def repo_env(repo: Path) -> dict[str, str]:
    """The environment that runs ``repo``'s code (its folder first on the path; also the cwd)."""
    return {**os.environ, "PYTHONPATH": str(repo)}


#: Where the CPU time of every process of this machine is counted, s per unit: cgroup v2, cgroup
#: v1 (a container's or a VM's own processes), else the kernel's count for the whole machine.
CPU_COUNTERS = (("/sys/fs/cgroup/cpu.stat", 1e-6), ("/sys/fs/cgroup/unified/cpu.stat", 1e-6),
                ("/sys/fs/cgroup/cpuacct/cpuacct.usage", 1e-9), ("/proc/stat", 1.0 / os.sysconf("SC_CLK_TCK")))


#: What the CPU seconds count, as docs/benchmarks.md says it.
CPU_COUNTED = ("every process of the machine while the campaign ran: the CLI, the Dask workers, the fork servers, "
               "the runs, and any other (see the load average)")


def machine_cpu_s() -> float:
    """CPU seconds used so far by every process this machine (or container) counts (user and
    system), from the first of :data:`CPU_COUNTERS` that can be read. A forked campaign run's
    time is counted too: no process has to wait for it (``RUSAGE_CHILDREN`` would miss the runs
    of fork servers that die with their workers)."""
    for path, unit in CPU_COUNTERS:
        try:
            text = Path(path).read_text()
        except OSError:
            continue
        if path.endswith("cpu.stat"):
            return int(dict(line.split() for line in text.splitlines())["usage_usec"]) * unit
        if path.endswith("cpuacct.usage"):
            return int(text) * unit
        user, nice, system, _idle, _iowait, irq, softirq, steal = map(int, text.split("\n")[0].split()[1:9])
        return (user + nice + system + irq + softirq + steal) * unit
    raise SystemExit("bench_campaign: no CPU counter readable (" + ", ".join(p for p, _ in CPU_COUNTERS) + ")")


def run_campaign(cfile: Path, out: Path, workers: int, fmu: str, repo: Path = REPO_ROOT,
                 extra: tuple[str, ...] = ()) -> dict:
    before = machine_cpu_s()
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "scenarios", "campaign", str(cfile), "--out", str(out),
                        "--workers", str(workers), "--fmu", fmu, *extra], capture_output=True, text=True,
                       env=repo_env(repo), cwd=repo)
    wall = time.perf_counter() - t0
    cpu = machine_cpu_s() - before
    if r.returncode != 0:
        raise SystemExit(f"campaign with {workers} worker(s) failed ({r.returncode}):\n{r.stderr}")
    with open(out / "campaign.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    tasks: dict[str, dict] = {}
    for row in rows:
        t = tasks.setdefault(row["sample"], {"task_wall_s": float(row["task_wall_s"]), "arms_wall_s": 0.0,
                                             "sim_s": 0.0})
        t["arms_wall_s"] += float(row["wall_s"])
        t["sim_s"] += float(row["sim_s"])
    overhead = [t["task_wall_s"] - t["arms_wall_s"] for t in tasks.values()]
    sim = sum(t["sim_s"] for t in tasks.values())
    arm_cpu = arm_cpu_by_sample(out)
    return {"workers": workers, "wall_s": wall, "cpu_s": cpu, "sim_s": sim, "sim_by_sample": {k: t["sim_s"] for k, t in tasks.items()},
            "rate_cpu": sim / cpu, "rate_wall_per_worker": sim / wall / workers, "tasks": len(tasks), "arms": len(rows),
            "sum_task_wall_s": sum(t["task_wall_s"] for t in tasks.values()),
            "sum_cosim_s": sum(t["arms_wall_s"] for t in tasks.values()),
            "overhead_per_task_s": sum(overhead) / len(overhead), "overhead_max_s": max(overhead),
            "arm_cpu_by_sample": arm_cpu}


#: The CPU parts of an arm's run that its summary.json records (``timings``), as the report names them.
ARM_CPU_PARTS = {"plant_s": "the plant (mj_step and the walking controller)", "loop_cpu_s": "the arms' loops",
                 "task_cpu_s": "the runs' own processes"}
#: Every part the report splits the CPU time into: those, then the whole campaign.
CPU_PARTS = {**ARM_CPU_PARTS, "campaign": "the whole campaign (every process)"}


def arm_cpu_by_sample(out: Path) -> dict[str, dict[str, float]]:
    """Per sample, the CPU seconds its arms' runs spent in each of :data:`ARM_CPU_PARTS` (from each
    sample's last try's ``summary.json``)."""
    found: dict[str, dict[str, float]] = {}
    for path in sorted((out / "runs").glob("s*/try*/*/summary.json"), key=lambda p: (p.parts[-4], int(p.parts[-3][3:]))):
        arms = json.loads(path.read_text())["arms"].values()
        found[path.parts[-2]] = {k: sum(a["timings"][k] for a in arms if "timings" in a) for k in ARM_CPU_PARTS}
    return found


def overhead_breakdown(sample: Path, folder: Path, fmu: str) -> dict:
    """One ``scenarios run`` of a sample as a campaign task runs it, under cProfile;
    seconds per part, and the imports (in a separate process)."""
    from scenarios.campaign.task import run_command
    from scenarios.run.options import DEFAULT_CONTROLLER, DEFAULT_REGULATOR

    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", RUN_IMPORTS], check=True)
    imports = time.perf_counter() - t0
    prof = folder / "run.prof"
    cmd = run_command(SimpleNamespace(scenario_file=str(sample), regulator=DEFAULT_REGULATOR, controller=DEFAULT_CONTROLLER,
                                      fmu=fmu), folder / "profiled")
    subprocess.run([sys.executable, "-m", "cProfile", "-o", str(prof), *cmd[1:]], check=True, capture_output=True)
    stats = pstats.Stats(str(prof))
    out = {"interpreter + imports (separate run)": imports}
    total = 0.0
    for (path, _, name), (_, _, _, cum, _) in stats.stats.items():
        total = max(total, cum if name == "<module>" else 0.0)
        for (suffix, func), label in PARTS.items():
            if name == func and path.endswith(suffix):
                out[label] = out.get(label, 0.0) + cum
    out["whole run under cProfile"] = total
    return out


def physics_limit(samples: Path, sim_by_sample: dict[str, float]) -> dict[str, Any]:
    """Bare ``mj_step`` (best of three) on each sample's plant (``samples``: the campaign's sample
    files) and the CPU seconds the simulated seconds run on each would take at that rate."""
    import bench_suite
    from scenarios.lang import spec

    scenarios = {name: spec.resolve_targets([str(samples / f"{name}.toml")])[0] for name in sim_by_sample}
    rates = bench_suite.physics_rates(list(scenarios.values()), 3)
    cpu = sum(sim / rates[scenarios[name].name]["rtf_cpu"] for name, sim in sim_by_sample.items())
    return {"cpu_s": cpu, "rate_cpu": sum(sim_by_sample.values()) / cpu}


def report(label: str, runs: list[dict], samples: int, physics: dict[str, Any]) -> dict:
    """Print one tree's table and ratios; return its numbers."""
    from scenarios.docs import BENCH_TARGETS

    one, two = runs
    scaling = one["wall_s"] / two["wall_s"]
    print(f"\n== {label}: {samples} samples x {len(RANDOM_ARMS)} arms x 25 s simulated")
    print(f"{'workers':>8} {'wall s':>8} {'CPU s':>8} {'sim s/CPU s':>12} {'/ bare':>7} {'sim s/wall s/worker':>20} "
          f"{'sum task s':>11} {'sum cosim s':>12} {'overhead/task s':>16}")
    for r in runs:
        r["rate_over_physics"] = r["rate_cpu"] / physics["rate_cpu"]
        print(f"{r['workers']:>8} {r['wall_s']:>8.1f} {r['cpu_s']:>8.1f} {r['rate_cpu']:>12.2f} {r['rate_over_physics']:>7.3f} "
              f"{r['rate_wall_per_worker']:>20.2f} {r['sum_task_wall_s']:>11.1f} {r['sum_cosim_s']:>12.1f} "
              f"{r['overhead_per_task_s']:>16.2f}")
    fixed = [r["wall_s"] - r["sum_task_wall_s"] / r["workers"] for r in runs]
    print(f"fixed cost per campaign (wall - sum task / workers: cluster start/close, validation, report): "
          f"{fixed[0]:.1f} s with 1 worker, {fixed[1]:.1f} s with 2; task phase alone scales "
          f"{one['sum_task_wall_s'] / (two['sum_task_wall_s'] / 2):.2f} x")
    normalised = (one["wall_s"] / one["sum_cosim_s"]) / (two["wall_s"] / two["sum_cosim_s"])
    print(f"the same co-simulation work took {two['sum_cosim_s'] / one['sum_cosim_s']:.2f} x as long with 2 workers "
          f"(1.00 on two free cores); scaling per unit of that work: {normalised:.2f} x (what two free cores "
          "would give, if every part of a task slowed alike)")
    for r in runs:  # where the CPU goes, each part against the physics of the same simulated seconds
        r["cpu_over_physics"] = {k: sum(c[k] for c in r["arm_cpu_by_sample"].values()) / physics["cpu_s"]
                                 for k in ARM_CPU_PARTS}
        r["cpu_over_physics"]["campaign"] = r["cpu_s"] / physics["cpu_s"]
        print(f"{r['workers']} worker(s), CPU s per CPU s of bare mj_step on the same simulated seconds: "
              + "; ".join(f"{CPU_PARTS[k]} {v:.2f}" for k, v in r["cpu_over_physics"].items()))
    rate = min(r["rate_over_physics"] for r in runs)
    print(f"per worker / bare mj_step (CPU) = {rate:.3f} (the lower of the two; target >= "
          f"{BENCH_TARGETS['campaign_rate']}: {'met' if rate >= BENCH_TARGETS['campaign_rate'] else 'MISSED'}); scaling wall(1)/wall(2) = {scaling:.2f} "
          f"(target >= {BENCH_TARGETS['campaign_scaling']}: {'met' if scaling >= BENCH_TARGETS['campaign_scaling'] else 'MISSED'})")
    return {"runs": runs, "scaling": scaling, "rate_over_physics": rate, "fixed_s": fixed,
            "normalised_scaling": normalised}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, default=20, help="samples of the campaign (default 20)")
    ap.add_argument("--fmu", default=None, help="the FMU (default: dist/, built if missing or stale)")
    ap.add_argument("--repeat", type=int, default=1, help="campaigns per worker count; the fastest counts")
    ap.add_argument("--baseline-repo", type=Path, default=None,
                    help="also run the campaigns with the code in this folder (before/after in one run)")
    ap.add_argument("--json", default=None, help="also write the numbers to this file")
    args = ap.parse_args(argv)
    if args.samples < 1 or args.repeat < 1:
        ap.error(f"--samples {args.samples} --repeat {args.repeat}: each must be >= 1")
    import bench_cosim
    from scenarios.cosim.fmus import ensure_fmu
    from scenarios.run.options import DEFAULT_REGULATOR

    fmu = str(Path(ensure_fmu(Path(args.fmu) if args.fmu else None, regulator=DEFAULT_REGULATOR)).resolve())
    trees = {"this tree": (REPO_ROOT, ()), "this tree, --no-fork-runs": (REPO_ROOT, ("--no-fork-runs",))}
    if args.baseline_repo is not None:
        trees = {f"baseline {args.baseline_repo}": (args.baseline_repo.resolve(), ()), **trees}
    with tempfile.TemporaryDirectory(prefix="bench_campaign_") as tmp:
        folder = Path(tmp)
        cfile = random_campaign_file(folder, args.samples)
        trials = {label: {1: [], 2: []} for label in trees}
        for k in range(args.repeat):  # interleaved: load from other processes hits every set-up and count alike
            for i, (label, (repo, extra)) in enumerate(trees.items()):
                for n in (1, 2):
                    trials[label][n].append(run_campaign(cfile, folder / f"t{i}-w{n}-{k}", n, fmu, repo, extra))
        first = folder / "t0-w1-0" / "samples"
        physics = physics_limit(first, trials[next(iter(trees))][1][0]["sim_by_sample"])
        parts = overhead_breakdown(first / "s0000.toml", folder, fmu)
    print(f"cpu_count = {os.cpu_count()}, load average {os.getloadavg()[0]:.2f} (other processes share the cores); "
          f"the fastest of {args.repeat} campaign(s) per tree and worker count")
    print(f"bare mj_step on the samples' plants: {physics['rate_cpu']:.2f} simulated s per CPU s")
    results = {label: report(label, [min(trials[label][n], key=lambda r: r["wall_s"]) for n in (1, 2)],
                             args.samples, physics) for label in trees}
    labels = list(results)
    print(f"\n{'':<48}" + "".join(f"{f'{n} worker(s)':>28}" for n in (1, 2)) + f"{'scaling':>9}")
    for label in labels:
        cells = "".join(f"{r['overhead_per_task_s']:>10.2f} s/task {r['wall_s']:>7.1f} s wall"
                        for r in results[label]["runs"])
        print(f"{label:<48}{cells}{results[label]['scaling']:>9.2f}")
    print("(overhead per task = task wall - its arms' wall_s; wall = the whole campaign, CLI start to exit)")
    print("\none task's run (this tree) under cProfile (s):")
    for k, v in sorted(parts.items(), key=lambda kv: -kv[1]):
        print(f"  {k:<55} {v:7.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps({"samples": args.samples, "arms": list(RANDOM_ARMS), "physics": physics,
                                               "cpu_counted": CPU_COUNTED,
                                               "results": results, "trials": trials, "breakdown": parts,
                                               "measured": bench_cosim.measured()}, indent=2, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
