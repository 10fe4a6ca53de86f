"""Benchmark: the compiled Cassie controller and the native CassiePlant FMU against bare ``mj_step``,
in the same run (issue 23's rows).

``python benchmarks/bench_native_plant.py [--seconds 10] [--repeat 3]``

* bare: ``mujoco.mj_step`` of the nominal model from ``home`` (``bench_cosim.bare_mj_step``), CPU time;
* controller update: one ``NominalController.update`` (Python) and one ``cc_update`` (C, through
  ctypes) on the same walking state, mean over 2000 calls;
* plant with the compiled controller, no regulator: ``CassieWalker``'s stepping (``mj_step`` every
  0.5 ms, the controller every 2 ms) with the C controller, walking at 0.5 m/s, CPU time;
* loop: the native plant FMU and the native regulator FMU (FMI 2.0) in the plain C host
  ``tests/support/native/fmi2_loop_host.c``, 10 ms steps at 0.5 m/s, the loop's CPU time as the host
  measures it (initialization excluded).

Prints each rate in simulated seconds per CPU second and its ratio to bare ``mj_step``.  Best of
``--repeat`` runs (the machine is shared).  Builds the FMUs and the host in a temporary folder.
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]

from benchmarks.bench_cosim import bare_mj_step  # noqa: E402
from plant.model import load_model  # noqa: E402
from plant.native.native_ctrl import NativeController, NativeLibrary, build_library  # noqa: E402
from plant.sim import CassieWalker  # noqa: E402


def update_costs(native: NativeLibrary, n: int = 2000) -> tuple[float, float]:
    """Mean seconds of one Python and one C controller update on the same walking state."""
    walker = CassieWalker(load_model("menagerie"))
    walker.set_command(0.5, 0.0)
    c = NativeController(native, walker.physics, walker.params)
    c.set_command(0.5, 0.0, walker.gaits)
    walker.advance(4000)  # walking
    t0 = time.process_time()
    for _ in range(n):
        walker.controller.update()
    py = (time.process_time() - t0) / n
    t0 = time.process_time()
    for _ in range(n):
        c.update()
    return py, (time.process_time() - t0) / n


def plant_with_c_controller(native: NativeLibrary, seconds: float) -> float:
    """Simulated s per CPU s of the walker's stepping with the C controller (no regulator)."""
    walker = CassieWalker(load_model("menagerie"))
    c = NativeController(native, walker.physics, walker.params)
    c.set_command(0.5, 0.0, walker.gaits)
    phys, sub = walker.physics, walker.params.control_substeps
    blocks = int(round(seconds / walker.SIM_DT_S)) // sub
    t0 = time.process_time()
    for _ in range(blocks):
        phys.step(sub)
        c.update()
    cpu = time.process_time() - t0
    assert c.step_index > 5, "the walker must walk"
    return blocks * sub * walker.SIM_DT_S / cpu


def native_loop(tmp: Path, seconds: float):
    """Build the native loop in ``tmp``; a function running it once that returns simulated s per CPU s."""
    import build
    from fmpy import extract
    from native.test_native_plant import H, _loop_script
    from support.native_support import CC, FMI2_INCLUDE, NATIVE_DIR, compile_c

    plant = build.build_native_plant_fmu(2, tmp)
    regulator = build.build_native_fmu(2, tmp)
    plant_dir = Path(extract(str(plant), unzipdir=str(tmp / "plant")))
    reg_dir = Path(extract(str(regulator), unzipdir=str(tmp / "regulator")))
    host = compile_c(CC, [NATIVE_DIR / "fmi2_loop_host.c"], tmp / "host", "-std=c99", "-O2", f"-I{FMI2_INCLUDE}", "-ldl")
    steps = int(round(seconds / H))
    script, _ = _loop_script(plant, plant_dir, regulator, reg_dir, steps, 0.5)
    (tmp / "loop.txt").write_text(script)

    def run() -> float:
        proc = subprocess.run(["env", "-i", str(host), str(tmp / "loop.txt")], capture_output=True, text=True,
                              check=True)
        cpu = float(re.search(r"cpu time ([0-9.]+) s", proc.stderr).group(1))
        return steps * H / cpu

    return run


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_native_plant_") as tmp:
        tmp = Path(tmp)
        native = NativeLibrary(build_library(tmp / "ctrl"))
        loop = native_loop(tmp, args.seconds)
        bare = max(bare_mj_step(min(args.seconds, 5.0))["rtf_cpu"] for _ in range(args.repeat))
        py, c = min(update_costs(native) for _ in range(args.repeat))
        plant = max(plant_with_c_controller(native, args.seconds) for _ in range(args.repeat))
        loop_rate = max(loop() for _ in range(args.repeat))
    print(f"bare mj_step: {bare:.2f} simulated s per CPU s")
    print(f"controller update: Python {py * 1e6:.1f} us, C (through ctypes) {c * 1e6:.2f} us, {py / c:.0f}x")
    print(f"plant with the compiled controller, no regulator: {plant:.2f} s/s = {plant / bare:.3f} x bare mj_step")
    print(f"native plant FMU + native regulator FMU in the C host: {loop_rate:.2f} s/s = {loop_rate / bare:.3f} x bare")
    return 0


if __name__ == "__main__":
    sys.exit(main())
