"""Per-step cost of the adaptive velocity regulator vs nengo 4.1 on the same networks.

Run ``python benchmarks/bench_regulator.py [--steps N] [--neurons N] [--rounds R]``.
Prints, for each measured path, the median and 90th percentile wall time of one step
(µs) and the ratio nengo / path of the medians, all measured in the same run.

Paths: one ``setup_*(inputs, dt, n_neurons)`` function each, registered in ``PATHS``.
A setup builds its model, runs ``WARMUP`` steps and returns a *stepper*: a callable
``stepper(k)`` that performs step ``k`` (k = 0, 1, 2, ... with input ``inputs[WARMUP +
k]``); if the stepper has a ``close()`` attribute it is called at the end.

* ``setup_regulator_step``: ``Regulator.step`` (in-process co-simulation path),
* ``setup_pure_step``: the pure ``step`` function, state threaded by hand,
* ``setup_pd_only``: ``step`` with ``adaptation_enabled = False`` (floor: no networks),
* ``setup_fmu``: the built FMU through fmpy's ``FMU2Slave``: per step ``setReal`` of the
  eight Real inputs, ``setInteger`` of ``step_index``, ``doStep`` and ``getReal`` of all
  fourteen outputs (what a co-simulation master does each communication step); the FMU is
  built by ``build.py`` into a temporary folder first,
* ``setup_native_fmu``: the same calls on the native FMI 2.0 FMU (C, ``fmu_src/native``),
* ``measure_c_host``: the native FMU in a plain C host (``tests/support/native/fmi2_host.c``), the
  same set+doStep+get per step timed in C; run after the interleaved paths,
* ``setup_nengo``: ``nengo.Simulator.step()`` of three LIFRate ensembles (2-, 2- and
  4-dimensional, n_neurons each) with the core's encoders/gains/biases, input and error
  Nodes and PES-learning ``neurons -> output`` connections (2, 2 and 3 outputs): the
  same network work as the regulator, without the PD terms and saturation.

The machine may be shared, so the paths are measured *interleaved*: ``rounds`` rounds,
each running a block of ``steps / rounds`` consecutive steps of every path in turn, so
that load changes hit all paths alike.  Every call is timed individually with
``time.perf_counter_ns``, the garbage collector disabled during the timed blocks.
"""
from __future__ import annotations

import argparse
import gc
import sys
import time
from pathlib import Path

import numpy as np

try:
    from fmu_src.core.avr_core import Regulator
    from fmu_src.core.avr_params import RegulatorInputs, RegulatorParams
    from fmu_src.core.avr_network import build_networks
    from fmu_src.core.avr_regulator import initial_state, step
except ImportError:  # run from a checkout without the editable install
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from fmu_src.core.avr_core import Regulator
    from fmu_src.core.avr_params import RegulatorInputs, RegulatorParams
    from fmu_src.core.avr_network import build_networks
    from fmu_src.core.avr_regulator import initial_state, step

DT = 0.005  # s, a typical co-simulation communication step
WARMUP = 200


def make_inputs(n_steps: int, seed: int = 0) -> list[RegulatorInputs]:
    """A seeded random walk of plausible walking inputs (python floats), the step
    index advancing every 60 calls (~0.3 s per walking step at dt = 5 ms)."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0.0, 1.0, (n_steps, 8)), axis=0)
    walk *= np.array([0.01, 0.005, 0.002, 0.001, 0.002, 0.002, 0.02, 0.02])
    walk += np.array([0.6, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0])
    return [RegulatorInputs(*map(float, row), step_index=k // 60)
            for k, row in enumerate(walk)]


def _params(n_neurons: int, **changes) -> RegulatorParams:
    return RegulatorParams(n_neurons=n_neurons, **changes)


def _time_block(stepper, start: int, count: int) -> np.ndarray:
    """Time ``stepper(k)`` for k in [start, start + count) individually; µs per call."""
    out = np.empty(count)
    clock = time.perf_counter_ns
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        for i in range(count):
            t0 = clock()
            stepper(start + i)
            out[i] = clock() - t0
    finally:
        if was_enabled:
            gc.enable()
    return out / 1000.0


def setup_regulator_step(inputs, dt, n_neurons):
    reg = Regulator(_params(n_neurons))
    for u in inputs[:WARMUP]:
        reg.step(u, dt)
    timed = inputs[WARMUP:]
    return lambda k: reg.step(timed[k], dt)


def _setup_step(inputs, dt, params):
    nets = build_networks(params)
    box = [initial_state(params, nets)]
    for u in inputs[:WARMUP]:
        box[0] = step(box[0], u, dt, params, nets)[0]
    timed = inputs[WARMUP:]

    def stepper(k):
        box[0] = step(box[0], timed[k], dt, params, nets)[0]

    return stepper


def setup_pure_step(inputs, dt, n_neurons):
    return _setup_step(inputs, dt, _params(n_neurons))


def setup_pd_only(inputs, dt, n_neurons):
    return _setup_step(inputs, dt, _params(n_neurons, adaptation_enabled=False))


def setup_nengo(inputs, dt, n_neurons):
    import nengo  # test/benchmark dependency only

    from fmu_src.core.reference.nengo_model import build_reference  # the model the cross-check test uses

    model, _ = build_reference(_params(n_neurons), inputs, dt)
    sim = nengo.Simulator(model, dt=dt, progress_bar=False, optimize=True)
    for _ in range(WARMUP):
        sim.step()

    def stepper(k):
        sim.step()

    stepper.close = sim.close
    return stepper


def _setup_fmu(inputs, dt, n_neurons, build):
    """A stepper over the FMI 2.0 FMU that ``build(folder)`` makes (fmpy's FMU2Slave)."""
    import tempfile

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS

    tmp = tempfile.TemporaryDirectory(prefix="bench_fmu_")
    fmu_path = build(Path(tmp.name))
    md = read_model_description(str(fmu_path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu_path), unzipdir=tmp.name + "/x"),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    fmu.instantiate()
    fmu.setInteger([vr["n_neurons"]], [n_neurons])
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    reals = [s.name for s in INPUT_SPECS if s.type == "Real"]
    real_vrs, index_vr = [vr[n] for n in reals], [vr["step_index"]]
    out_vrs = [vr[s.name] for s in OUTPUT_SPECS]

    def stepper(k, offset=0):
        u = inputs[offset + k]
        fmu.setReal(real_vrs, [getattr(u, n) for n in reals])
        fmu.setInteger(index_vr, [u.step_index])
        fmu.doStep((offset + k) * dt, dt)
        return fmu.getReal(out_vrs)

    for k in range(WARMUP):
        stepper(k)

    def close():
        fmu.terminate()
        fmu.freeInstance()
        tmp.cleanup()

    timed = lambda k: stepper(k, offset=WARMUP)  # noqa: E731
    timed.close = close
    return timed


def _build_module():
    from scenarios.cosim.fmus import load_build_module

    return load_build_module()


def setup_fmu(inputs, dt, n_neurons):
    return _setup_fmu(inputs, dt, n_neurons, _build_module().build_fmu)


def setup_native_fmu(inputs, dt, n_neurons):
    return _setup_fmu(inputs, dt, n_neurons, lambda out: _build_module().build_native_fmu(2, out))


def measure_c_host(inputs, dt, n_neurons, repeats: int = 5) -> float | None:
    """Median µs of one set+doStep+get of the native FMI 2.0 FMU in a plain C host
    (tests/support/native/fmi2_host.c, -O2), over ``repeats`` passes of the timed inputs; None
    without a C compiler."""
    import shutil
    import subprocess
    import tempfile
    import zipfile

    from fmpy import read_model_description

    from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS

    root = Path(__file__).resolve().parents[1]
    cc = shutil.which("cc")
    if cc is None or dt != DT:
        return None
    with tempfile.TemporaryDirectory(prefix="bench_c_host_") as tmp:
        tmp = Path(tmp)
        fmu = _build_module().build_native_fmu(2, tmp)
        md = read_model_description(str(fmu))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        lib = tmp / "native.so"
        lib.write_bytes(zipfile.ZipFile(fmu).read("binaries/linux64/AdaptiveVelocityRegulatorNative.so"))
        host = tmp / "fmi2_host"
        subprocess.run([cc, "-std=c99", "-O2", f"-I{root / 'fmu_src' / 'fmi' / 'third_party' / 'fmi2'}",
                        str(root / "tests" / "support" / "native" / "fmi2_host.c"), "-o", str(host), "-ldl"], check=True)
        lines = [f"P {vr['n_neurons']} I {n_neurons}",
                 "I " + " ".join(str(vr[s.name]) for s in INPUT_SPECS),
                 f"O {len(OUTPUT_SPECS)} " + " ".join(str(vr[s.name]) for s in OUTPUT_SPECS)]
        lines += ["S " + " ".join(repr(float(getattr(u, s.name))) for s in INPUT_SPECS) for u in inputs]
        (tmp / "script.txt").write_text("\n".join(lines) + "\n")
        out = subprocess.run([str(host), str(lib), md.guid, str(tmp / "script.txt"), str(repeats)],
                             capture_output=True, text=True, check=True).stdout.split()
    return float(out[out.index("median_us") + 1])


#: (label, setup); the nengo reference must keep the label "nengo".
PATHS = [
    ("Regulator.step", setup_regulator_step),
    ("FMU via fmpy (set+doStep+get)", setup_fmu),
    ("native FMU via fmpy", setup_native_fmu),
    ("pure step()", setup_pure_step),
    ("step(), adaptation off", setup_pd_only),
    ("nengo", setup_nengo),
]


def summarize(samples_us: np.ndarray) -> tuple[float, float]:
    """(median, 90th percentile) in µs."""
    return float(np.median(samples_us)), float(np.percentile(samples_us, 90))


def measure(paths=None, n_steps: int = 3000, n_neurons: int = 1000, dt: float = DT,
            rounds: int = 10, seed: int = 0) -> dict[str, np.ndarray]:
    """Per-step samples (µs) of every path, measured interleaved in ``rounds``."""
    paths = PATHS if paths is None else paths
    inputs = make_inputs(n_steps + WARMUP, seed)
    block = max(1, n_steps // rounds)
    steppers = [(label, setup(inputs, dt, n_neurons)) for label, setup in paths]
    samples = {label: [] for label, _ in steppers}
    try:
        for r in range(rounds):
            for label, stepper in steppers:
                samples[label].append(_time_block(stepper, r * block, block))
    finally:
        for _, stepper in steppers:
            close = getattr(stepper, "close", None)
            if close is not None:
                close()
    return {label: np.concatenate(v) for label, v in samples.items()}


def run(paths=None, **kwargs) -> dict[str, tuple[float, float]]:
    """label -> (median µs, p90 µs); keyword arguments as :func:`measure`."""
    return {label: summarize(s) for label, s in measure(paths, **kwargs).items()}


def format_table(results: dict[str, tuple[float, float]], n_neurons: int,
                 dt: float = DT) -> str:
    ref = results.get("nengo", (float("nan"),))[0]
    lines = [f"per-step wall time, 3 networks x {n_neurons} LIFRate neurons "
             f"(dt = {dt * 1e3:g} ms)",
             f"{'path':<31}{'median µs':>11}{'p90 µs':>10}{'nengo/this':>12}"]
    for label, (med, p90) in results.items():
        lines.append(f"{label:<31}{med:>11.1f}{p90:>10.1f}{ref / med:>11.2f}x")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000, help="timed steps per path")
    ap.add_argument("--neurons", type=int, default=1000, help="neurons per network")
    ap.add_argument("--rounds", type=int, default=10, help="interleaving rounds")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    results = run(n_steps=args.steps, n_neurons=args.neurons, rounds=args.rounds,
                  seed=args.seed)
    c_host = measure_c_host(make_inputs(args.steps + WARMUP, args.seed), DT, args.neurons)
    if c_host is not None:  # measured right after the interleaved paths (no p90: the host reports the median)
        results["native FMU in a C host"] = (c_host, float("nan"))
    print(format_table(results, args.neurons))
    return 0


if __name__ == "__main__":
    sys.exit(main())
