"""Closed-loop co-simulation speed: simulated seconds per wall second, in one run.

    python benchmarks/bench_cosim.py [--duration 10] [--repeat 3] [--fmu PATH] [--suite] [--json FILE] [--no-system]

Measured on the same machine in the same process, one after the other:

- ``bare mj_step``: ``mujoco.mj_step`` on the nominal model from ``home``, no
  controller (the physics alone; the robot falls, which does not slow MuJoCo down);
- ``plant only``: the master loop (``scenarios.cosim.master.run_arm``) with a regulator path
  that returns zero offsets: walker + nominal controller + the loop's bookkeeping
  (without the regulator the walker may fall early: its rate is over the part run);
- ``in-process``: the same loop with the regulator core called directly;
- ``FMU``: the same loop through the built FMU (fmpy);
- ``native FMU``: the same loop through the native FMI 2.0 FMU (C, ``fmu_src/native``) via
  the master's own FMU path (``scenarios.cosim.master.FmuRegulator`` takes any FMI 2.0 FMU);
- ``native FMU + C controller``: the same with the walker's C controller (``CassieWalker(controller=
  "native")``): the run's default path (target: >= 0.8 x bare mj_step);
- ``lean loop``: ``plant.sim.CassieWalker`` stepped directly with zero offsets and with the
  native FMU called through its raw C functions (``LeanNativeFmu``): what the FMU itself
  adds to a closed loop, without the master's per-step Python bookkeeping.
- with the plant as an FMU too (:func:`system_loop`): libcosim running ``CassieAVR.ssp``
  and our master with ``--plant fmu`` (target: libcosim >= 0.5 x bare mj_step).

Each closed-loop figure is the best of ``--repeat`` runs of ``--duration`` simulated
seconds of the ``nominal`` scenario (``adaptive`` arm), start-up (FMU extraction and
instantiation) included; the three paths are interleaved so that load from other
processes hits them alike, and rates are given per CPU second of this process (the
ratios use these: on a shared machine wall time mostly measures the neighbours) and
per wall second. Targets: FMU wall <= 1.2 x in-process wall; FMU closed loop
>= 0.5 x the bare mj_step rate; native FMU closed loop >= 0.9 x the plant-only rate. ``--suite`` also times ``python -m scenarios run all
--jobs 2`` (minutes).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Mapping

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))

from scenarios.cosim import master  # noqa: E402
from scenarios.docs import BENCH_TARGETS  # noqa: E402
from scenarios.lang import spec  # noqa: E402
from ctypes import c_double as c_double_t  # noqa: E402
from scenarios.cosim.regulators import FmuRegulator, InProcessRegulator, RegulatorPath
from scenarios.lang.scenario import Scenario


class ZeroRegulator(RegulatorPath):
    """A regulator path that outputs zeros: the plant-only baseline of the same loop."""

    kind = "zero"

    def __init__(self) -> None:
        from fmu_src.core.avr_specs import OUTPUT_SPECS

        self._outputs = tuple(s.name for s in OUTPUT_SPECS)
        self._zeros = {n: 0.0 for n in self._outputs}

    def output_names(self) -> tuple[str, ...]:
        return self._outputs

    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None:
        pass

    def step(self, t: float, h: float, inputs: Mapping[str, Any]) -> dict[str, float]:
        return dict(self._zeros)

    def close(self) -> None:
        pass


def measured() -> dict[str, Any]:
    """Where and when a benchmark ran (for docs/data/benchmarks/): the commit, the date, the
    machine, and the load averages over 1, 5 and 15 minutes at the end of the run."""
    from scenarios.docs import measured_here

    return {**measured_here(), "cpu_count": os.cpu_count(), "load_average": [round(x, 2) for x in os.getloadavg()]}


def bare_mj_step(seconds: float, model=None) -> dict[str, float]:
    """Simulated s per wall s (and per CPU s) of mj_step alone on ``model`` (a compiled
    Cassie; default the nominal model)."""
    import mujoco

    from plant.model import load_model

    model = load_model("menagerie") if model is None else model
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    n = int(round(seconds / model.opt.timestep))
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        mujoco.mj_step(model, data)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    sim = n * model.opt.timestep
    return {"sim_s": sim, "wall_s": wall, "cpu_s": cpu, "rtf": sim / wall, "rtf_cpu": sim / cpu}


def closed_loop_all(scenario: Scenario, makers: dict[str, Any], repeat: int, plant=None) -> dict[str, dict[str, float]]:
    """Best of ``repeat`` runs per regulator path, the paths interleaved (fair under load); ``plant``:
    ``run_arm``'s plant factory (None: the walker with the Python controller)."""
    from scenarios.lang.plantio import load_plant_model

    model, summary = load_plant_model(scenario)
    best: dict[str, dict[str, float]] = {}
    for _ in range(repeat):
        for key, make in makers.items():
            c0 = time.process_time()
            r = master.run_arm(scenario, "adaptive", make(), model=model, model_summary=summary, plant=plant)
            cpu = time.process_time() - c0
            # without a regulator the walker may fall: the rate is over the simulated part
            m = {"sim_s": r.sim_s, "wall_s": r.wall_s, "cpu_s": cpu, "rtf": r.sim_s / r.wall_s,
                 "rtf_cpu": r.sim_s / cpu, "fell_at_s": r.t_fall_s}
            if key not in best or m["rtf_cpu"] > best[key]["rtf_cpu"]:
                best[key] = m
    return best


def regulator_step_cost(make, n: int = 2000) -> float:
    """Wall seconds per regulator step alone (no plant), start-up excluded."""
    reg = make()
    reg.start({}, 0.0, n * 0.005)
    inputs = {"vx": 0.3, "vy": 0.01, "vx_des": 0.5, "vy_des": 0.0, "pitch": 0.01, "roll": -0.01,
              "pitch_rate": 0.1, "roll_rate": -0.1, "step_index": 0}
    try:
        t0 = time.perf_counter()
        for k in range(n):
            inputs["step_index"] = k // 60
            reg.step(k * 0.005, 0.005, inputs)
        return (time.perf_counter() - t0) / n
    finally:
        reg.close()


class LeanNativeFmu:
    """The native FMI 2.0 FMU called straight through its C functions (ctypes, preallocated
    buffers, status checked), for the lean loop below: what the FMU itself adds to a closed
    loop, without the master's per-step bookkeeping.  ``step(inputs, dt)`` as the core's."""

    def __init__(self, fmu_path: Path) -> None:
        from ctypes import c_double, c_int

        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave, fmi2ValueReference

        from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS

        md = read_model_description(str(fmu_path))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        self._dir = extract(str(fmu_path))  # a new temporary folder: removed by close()
        self._fmu = FMU2Slave(guid=md.guid, unzipDirectory=self._dir,
                              modelIdentifier=md.coSimulation.modelIdentifier, instanceName="lean")
        self._fmu.instantiate()
        self._fmu.setupExperiment(startTime=0.0)
        self._fmu.enterInitializationMode()
        self._fmu.exitInitializationMode()
        self._reals = [s.name for s in INPUT_SPECS if s.type == "Real"]
        self._outputs = [s.name for s in OUTPUT_SPECS]
        self._vr_in = (fmi2ValueReference * 8)(*[vr[n] for n in self._reals])
        self._vr_index = (fmi2ValueReference * 1)(vr["step_index"])
        self._vr_out = (fmi2ValueReference * len(self._outputs))(*[vr[n] for n in self._outputs])
        self._in, self._index = (c_double * 8)(), (c_int * 1)()
        self._out = (c_double * len(self._outputs))()
        dll = self._fmu.dll  # the raw C functions: no Python wrapper per call
        self._set_real, self._set_integer = dll.fmi2SetReal, dll.fmi2SetInteger
        self._do_step, self._get_real = dll.fmi2DoStep, dll.fmi2GetReal
        self._comp, self._t = self._fmu.component, 0.0

    def step(self, inputs, dt: float) -> dict[str, float]:
        for i, name in enumerate(self._reals):
            self._in[i] = getattr(inputs, name)
        self._index[0] = inputs.step_index
        status = (self._set_real(self._comp, self._vr_in, 8, self._in)
                  | self._set_integer(self._comp, self._vr_index, 1, self._index)
                  | self._do_step(self._comp, c_double_t(self._t), c_double_t(dt), 1)
                  | self._get_real(self._comp, self._vr_out, len(self._outputs), self._out))
        if status:
            raise RuntimeError(f"native FMU call failed (status {status}) at t = {self._t}")
        self._t += dt
        return dict(zip(self._outputs, self._out))

    def close(self) -> None:
        self._fmu.terminate()
        self._fmu.freeInstance()  # also unloads the library
        shutil.rmtree(self._dir)


class LeanZero:
    """Zero offsets with the same ``step(inputs, dt)``: the lean loop's plant-only baseline."""

    def __init__(self) -> None:
        from fmu_src.core.avr_specs import OUTPUT_SPECS

        self._zeros = {s.name: 0.0 for s in OUTPUT_SPECS}

    def step(self, inputs, dt: float) -> dict[str, float]:
        return dict(self._zeros)

    def close(self) -> None:
        pass


def lean_loop(makers: dict[str, Any], seconds: float, repeat: int) -> dict[str, dict[str, float]]:
    """CPU s per simulated s of ``plant.sim`` walking at 0.5 m/s with each regulator (5 ms
    communication step, 10 plant steps each), best of ``repeat``, interleaved."""
    from plant.model import load_model
    from plant.sim import CassieWalker
    from scenarios.cosim.inprocess import apply_regulator

    model = load_model("menagerie")
    best: dict[str, dict[str, float]] = {}
    for _ in range(repeat):
        for key, make in makers.items():
            walker, reg = CassieWalker(model), make()
            walker.set_command(0.5, 0.0)
            c0 = time.process_time()
            for _ in range(int(round(seconds / 0.005))):
                apply_regulator(walker, reg, 0.005)
                walker.advance(10)
            cpu = time.process_time() - c0
            reg.close()
            m = {"sim_s": seconds, "cpu_s": cpu, "rtf_cpu": seconds / cpu, "fell": walker.fell()}
            if key not in best or m["rtf_cpu"] > best[key]["rtf_cpu"]:
                best[key] = m
    return best


def ensure_fmu(path: str | None, folder: Path, native: bool = False) -> Path:
    """``path``, or the FMU (the pythonfmu one, or the native FMI 2.0 one) built into ``folder``."""
    if path:
        return Path(path)
    out = Path(folder)
    from scenarios.cosim.fmus import load_build_module

    build = load_build_module()
    return Path(build.build_native_fmu(2, out) if native else build.build_fmu(out))


def build_system(fmu: Path, out: Path) -> tuple[Path, Path]:
    """The plant FMU and CassieAVR.ssp in ``out`` (before any FMU is loaded: pythonfmu's builder must be
    the installed package, not an FMU's copy of it)."""
    from scenarios.cosim.fmus import load_build_module

    build = load_build_module()
    plant_fmu = Path(build.build_plant_fmu(out))
    return plant_fmu, build.build_ssp(out, plant_fmu, fmu)


def system_loop(scenario: Scenario, fmu: Path, plant_fmu: Path, ssp: Path, repeat: int) -> dict[str, Any]:
    """The loop with the plant as an FMU too (issue 10), best of ``repeat``, interleaved:

    - ``libcosim_ssp``: libcosim running ``CassieAVR.ssp`` (both FMUs, 5 ms Jacobi steps in
      its worker threads), ``execution.step(n)`` in one call, nothing observed;
    - ``master_plant_fmu``: our master with ``--plant fmu`` (Gauss-Seidel, fmpy).
    Rates per CPU second of the process (all threads) and per wall second; the command is
    the scenario's first (0.5 m/s for ``nominal``), the plant nominal.
    """
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    from scenarios.cosim.plant_fmu import plant_factory
    from scenarios.lang.plantio import load_plant_model

    log_output_level(CosimLogLevel.ERROR)
    model, summary = load_plant_model(scenario)
    n = scenario.n_comm_steps
    best: dict[str, dict[str, float]] = {}
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        execution = CosimExecution.from_ssp_file(str(ssp))
        ok = execution.step(n)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        del execution
        runs = {"libcosim_ssp": {"sim_s": n * scenario.comm_step_s, "wall_s": wall, "cpu_s": cpu, "ok": ok}}
        c0 = time.process_time()
        r = master.run_arm(scenario, "adaptive", FmuRegulator(fmu), model=model, model_summary=summary,
                           plant=plant_factory(plant_fmu))
        runs["master_plant_fmu"] = {"sim_s": r.sim_s, "wall_s": r.wall_s, "cpu_s": time.process_time() - c0,
                                    "ok": not r.fell}
        for key, m in runs.items():
            m.update(rtf=m["sim_s"] / m["wall_s"], rtf_cpu=m["sim_s"] / m["cpu_s"])
            if key not in best or m["rtf_cpu"] > best[key]["rtf_cpu"]:
                best[key] = m
    return best


def master_vs_c_host(scenario: Scenario, folder: Path, repeat: int) -> dict[str, dict[str, float]]:
    """Our master against the plain C host on the same two FMUs (the native CassiePlant and the
    native regulator, FMI 2.0), the same communication step, the same command, best of ``repeat``
    (interleaved):

    - ``c_host``: ``tests/support/native/fmi2_loop_host.c`` (the loop in C: set, doStep, get, each
      step's outputs printed), CPU time of its loop as it measures it (initialization excluded);
    - ``master``: :func:`scenarios.cosim.master.run_arm` with ``--plant fmu`` on the native plant FMU
      and the native regulator FMU (fmpy), CPU time of its communication steps (``loop_cpu_s``:
      extraction and initialization excluded, as in the C host); ``master_arm``: the same run's
      CPU time as a whole (FMU extraction and initialization included).
    """
    import re

    import build
    from fmpy import extract

    from scenarios.cosim.plant_fmu import plant_factory
    from scenarios.lang.plantio import load_plant_model

    sys.path.insert(0, str(REPO_ROOT / "tests"))
    from native.test_native_plant import H, _loop_script
    from support.native_support import CC, FMI2_INCLUDE, NATIVE_DIR, compile_c

    plant_fmu, reg_fmu = Path(build.build_native_plant_fmu(2, folder)), Path(build.build_native_fmu(2, folder))
    plant_dir = Path(extract(str(plant_fmu), unzipdir=str(folder / "plant")))
    reg_dir = Path(extract(str(reg_fmu), unzipdir=str(folder / "regulator")))
    host = compile_c(CC, [NATIVE_DIR / "fmi2_loop_host.c"], folder / "host", "-std=c99", "-O2", f"-I{FMI2_INCLUDE}",
                     "-ldl")
    n, h = scenario.n_comm_steps, scenario.comm_step_s
    vx_des = scenario.command_at_step(0)[0]
    script, _ = _loop_script(plant_fmu, plant_dir, reg_fmu, reg_dir, n, vx_des)
    steps_line = f"T {H!r} {n}\n"
    if steps_line not in script:
        raise SystemExit(f"the C host's script has no line {steps_line!r}: tests/native/test_native_plant.py changed")
    (folder / "loop.txt").write_text(script.replace(steps_line, f"T {h!r} {n}\n"))
    model, summary = load_plant_model(scenario)
    best: dict[str, dict[str, float]] = {}
    for _ in range(repeat):
        proc = subprocess.run(["env", "-i", str(host), str(folder / "loop.txt")], capture_output=True, text=True,
                              check=True)
        runs = {"c_host": {"sim_s": n * h, "cpu_s": float(re.search(r"cpu time ([0-9.]+) s", proc.stderr).group(1))}}
        c0 = time.process_time()
        r = master.run_arm(scenario, "adaptive", FmuRegulator(reg_fmu), model=model, model_summary=summary,
                           plant=plant_factory(plant_fmu, unpack_dir=folder))
        runs["master_arm"] = {"sim_s": r.sim_s, "cpu_s": time.process_time() - c0}
        runs["master"] = {"sim_s": r.sim_s, "cpu_s": r.timings["loop_cpu_s"]}
        for key, m in runs.items():
            m["rtf_cpu"] = m["sim_s"] / m["cpu_s"]
            if key not in best or m["rtf_cpu"] > best[key]["rtf_cpu"]:
                best[key] = m
    return best


def print_system_loop(res: dict[str, Any]) -> None:
    bare = res["bare_mj_step"]
    print("closed loop with the plant as an FMU (CassiePlant + AdaptiveVelocityRegulator)")
    for key, label, target in (("libcosim_ssp", "libcosim, CassieAVR.ssp", 0.5),
                               ("master_plant_fmu", "our master, --plant fmu", None)):
        m = res["system"][key]
        ratio = m["rtf_cpu"] / bare["rtf_cpu"]
        res["ratios"][f"{key}_rate_over_bare_mj_step"] = ratio
        verdict = "" if target is None else f"  (target >= {target:.2f}: {'met' if ratio >= target else 'MISSED'})"
        print(f"  {label:25s} {m['rtf_cpu']:8.2f} sim s/CPU s {m['rtf']:8.2f} sim s/wall s   "
              f"{ratio:.3f} x bare mj_step (CPU){verdict}{'' if m['ok'] else '  [run failed or fell]'}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds per closed-loop run")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--fmu", default=None, help="FMU file (default: build one into a temp folder)")
    ap.add_argument("--native-fmu", default=None, help="native FMI 2.0 FMU file (default: build one)")
    ap.add_argument("--suite", action="store_true", help="also time `run all --jobs 2` (minutes)")
    ap.add_argument("--json", default=None, help="write the numbers to this file")
    ap.add_argument("--no-system", action="store_true", help="skip the plant-FMU rows (libcosim SSP, --plant fmu)")
    args = ap.parse_args(argv)

    built = tempfile.TemporaryDirectory(prefix="bench_cosim_")
    fmu = ensure_fmu(args.fmu, Path(built.name))
    native_fmu = ensure_fmu(args.native_fmu, Path(built.name), native=True)
    system_dir = None if args.no_system else tempfile.TemporaryDirectory(prefix="bench_system_")
    system_files = None if system_dir is None else build_system(fmu, Path(system_dir.name))
    scenario = spec.override(spec.resolve_targets(["nominal"])[0], duration_s=args.duration)
    res: dict[str, Any] = {"duration_s": args.duration, "repeat": args.repeat, "fmu": str(fmu)}
    bare = [bare_mj_step(min(args.duration, 5.0)) for _ in range(args.repeat)]
    res["bare_mj_step"] = max(bare, key=lambda m: m["rtf_cpu"])
    res.update(closed_loop_all(scenario, {
        "plant_only": ZeroRegulator,
        "inprocess": InProcessRegulator,
        "fmu": lambda: FmuRegulator(fmu),
        "native_fmu": lambda: FmuRegulator(native_fmu),
    }, args.repeat))
    from plant.sim import CassieWalker

    c_walker = lambda scenario, model: CassieWalker(model, controller="native")  # noqa: E731
    res["native_fmu_c_controller"] = closed_loop_all(scenario, {"native_fmu": lambda: FmuRegulator(native_fmu)},
                                                     args.repeat, plant=c_walker)["native_fmu"]
    res["regulator_step_us"] = {
        "inprocess": 1e6 * regulator_step_cost(InProcessRegulator),
        "fmu": 1e6 * regulator_step_cost(lambda: FmuRegulator(fmu)),
        "native_fmu": 1e6 * regulator_step_cost(lambda: FmuRegulator(native_fmu)),
    }
    t0 = time.perf_counter()
    reg = FmuRegulator(fmu)
    reg.start({}, 0.0, 1.0)
    reg.close()
    res["fmu_startup_s"] = time.perf_counter() - t0
    res["ratios"] = {  # per simulated second, CPU time (the machine is shared: wall time is noisy)
        "fmu_over_inprocess": res["inprocess"]["rtf_cpu"] / res["fmu"]["rtf_cpu"],
        "inprocess_over_plant_only": res["plant_only"]["rtf_cpu"] / res["inprocess"]["rtf_cpu"],
        "fmu_rate_over_bare_mj_step": res["fmu"]["rtf_cpu"] / res["bare_mj_step"]["rtf_cpu"],
        "plant_only_rate_over_bare_mj_step": res["plant_only"]["rtf_cpu"] / res["bare_mj_step"]["rtf_cpu"],
        "fmu_over_inprocess_wall": res["inprocess"]["rtf"] / res["fmu"]["rtf"],
        "native_fmu_rate_over_plant_only": res["native_fmu"]["rtf_cpu"] / res["plant_only"]["rtf_cpu"],
        "native_fmu_c_controller_over_bare_mj_step": (res["native_fmu_c_controller"]["rtf_cpu"]
                                                      / res["bare_mj_step"]["rtf_cpu"]),
    }
    res["lean_loop"] = lean_loop({"plant_only": LeanZero, "native_fmu": lambda: LeanNativeFmu(native_fmu)},
                                 args.duration, args.repeat)
    r_lean = res["lean_loop"]["native_fmu"]["rtf_cpu"] / res["lean_loop"]["plant_only"]["rtf_cpu"]
    res["ratios"]["lean_native_fmu_rate_over_plant_only"] = r_lean
    if system_dir is not None:
        with system_dir:
            res["system"] = system_loop(scenario, fmu, *system_files, args.repeat)
        with tempfile.TemporaryDirectory(prefix="bench_c_host_") as tmp:
            res["c_host"] = master_vs_c_host(scenario, Path(tmp), args.repeat)
    if args.suite:
        with tempfile.TemporaryDirectory(prefix="bench_suite_") as out:
            t0 = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "scenarios", "run", "all", "--jobs", "2", "--out", out,
                                   "--fmu", str(fmu)], cwd=REPO_ROOT, capture_output=True, text=True)
            res["suite_jobs2_wall_s"] = time.perf_counter() - t0
            res["suite_returncode"] = proc.returncode
            res["suite_table"] = proc.stdout

    r = res["ratios"]
    print(f"closed loop, {args.duration:g} simulated s, best of {args.repeat} interleaved runs")
    print("                        sim s / CPU s   sim s / wall s")
    b = res["bare_mj_step"]
    print(f"  bare mj_step          {b['rtf_cpu']:10.2f}   {b['rtf']:10.2f}")
    for key, label in (("plant_only", "plant only (zero)"), ("inprocess", "in-process regulator"),
                       ("fmu", "FMU regulator"), ("native_fmu", "native FMU regulator"),
                       ("native_fmu_c_controller", "native FMU + C ctrl")):
        m = res[key]
        fell = f"  (fell at {m['fell_at_s']:.2f} s)" if m["fell_at_s"] is not None else ""
        print(f"  {label:21s} {m['rtf_cpu']:10.2f}   {m['rtf']:10.2f}   {m['sim_s']:.2f} simulated s{fell}")
    print(f"regulator step alone: in-process {res['regulator_step_us']['inprocess']:.1f} us, "
          f"FMU {res['regulator_step_us']['fmu']:.1f} us, native FMU {res['regulator_step_us']['native_fmu']:.1f} us; "
          f"FMU start-up {res['fmu_startup_s'] * 1e3:.0f} ms")
    ok1 = r["fmu_over_inprocess"] <= 1.2
    ok2 = r["fmu_rate_over_bare_mj_step"] >= 0.5
    print(f"FMU / in-process CPU per simulated s  {r['fmu_over_inprocess']:.3f}  (target <= 1.20: "
          f"{'met' if ok1 else 'MISSED'}; by wall {r['fmu_over_inprocess_wall']:.3f})")
    print(f"FMU rate / bare mj_step rate          {r['fmu_rate_over_bare_mj_step']:.3f}  (target >= 0.50: "
          f"{'met' if ok2 else 'MISSED'})")
    ok3 = r["native_fmu_rate_over_plant_only"] >= 0.9
    print(f"native FMU rate / plant-only rate     {r['native_fmu_rate_over_plant_only']:.3f}  (target >= 0.90: "
          f"{'met' if ok3 else 'MISSED'})")
    print(f"native FMU + C controller (the run's default path) / bare mj_step  "
          f"{r['native_fmu_c_controller_over_bare_mj_step']:.3f}  (target >= 0.80)")
    lean = res["lean_loop"]
    print(f"lean loop (plant.sim + the FMU's C functions, no master): plant only {lean['plant_only']['rtf_cpu']:.2f}, "
          f"native FMU {lean['native_fmu']['rtf_cpu']:.2f} sim s / CPU s: ratio "
          f"{r['lean_native_fmu_rate_over_plant_only']:.3f} (target >= 0.90: "
          f"{'met' if r['lean_native_fmu_rate_over_plant_only'] >= 0.9 else 'MISSED'})")
    print(f"plant-only rate / bare mj_step rate   {r['plant_only_rate_over_bare_mj_step']:.3f}; "
          f"in-process / plant-only CPU per simulated s {r['inprocess_over_plant_only']:.3f}")
    if "system" in res:
        print_system_loop(res)
    if "c_host" in res:
        host, ours = res["c_host"]["c_host"], res["c_host"]["master"]
        r["master_over_c_host"] = ours["rtf_cpu"] / host["rtf_cpu"]
        target = BENCH_TARGETS["master_over_c_host"]
        print(f"the native plant FMU + native regulator FMU, the loop (initialization excluded): the plain C host "
              f"{host['rtf_cpu']:.2f}, our master {ours['rtf_cpu']:.2f} sim s / CPU s: master / C host "
              f"{r['master_over_c_host']:.3f} (target >= {target}: {'met' if r['master_over_c_host'] >= target else 'MISSED'})"
              f"; our master's whole arm (extraction and initialization included) "
              f"{res['c_host']['master_arm']['rtf_cpu']:.2f} sim s / CPU s")
    if "suite_jobs2_wall_s" in res:
        print(f"suite `run all --jobs 2`: {res['suite_jobs2_wall_s']:.1f} s wall (exit {res['suite_returncode']})")
    built.cleanup()
    if args.json:
        res["measured"] = measured()
        Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
