"""Benchmark: bare ``mj_step`` vs plant + nominal controller, in the same run.

``python benchmarks/bench_plant.py [--source menagerie|osu] [--seconds 10]``

* bare: ``mujoco.mj_step`` of the unmodified model from the ``home`` keyframe with
  zero motor commands, in chunks of 20 steps (``nstep``), for the same simulated
  time as the walker, restarting from ``home`` whenever the (uncontrolled) robot
  has fallen (pelvis < 0.6 m) so that the contact load stays comparable;
* walker: :class:`plant.sim.CassieWalker` walking at 0.5 m/s from rest with the
  regulator core ``fmu_src.core.avr_core`` (adaptation off, default gains) called
  in-process every 10 ms (``advance(20)``) through
  :func:`plant.sim.apply_regulator`, including the regulator and telemetry calls
  the co-simulation makes.

Prints simulated seconds per wall second for both, their ratio (target >= 0.5),
and the Python controller rate.  Best of ``--repeat`` runs (machine is shared).
"""
from __future__ import annotations

import argparse
import time

import mujoco

from fmu_src.core.avr_core import Regulator
from scenarios.gaits.make_gaits import COMM_STEPS, PD_ONLY_PARAMS
from plant.model import load_model
from plant.sim import CassieWalker
from scenarios.cosim.inprocess import apply_regulator


def bench_bare(model, sim_s: float) -> float:
    d = mujoco.MjData(model)
    key = model.key("home").id
    mujoco.mj_resetDataKeyframe(model, d, key)
    n = int(round(sim_s / model.opt.timestep))
    t0 = time.perf_counter()
    done = 0
    while done < n:
        mujoco.mj_step(model, d, nstep=20)
        done += 20
        if d.qpos[2] < 0.6:
            mujoco.mj_resetDataKeyframe(model, d, key)
    return sim_s / (time.perf_counter() - t0)


def bench_walker(model, sim_s: float) -> tuple[float, bool]:
    w = CassieWalker(model)
    w.set_command(0.5, 0.0)
    reg = Regulator(PD_ONLY_PARAMS)
    dt_s = COMM_STEPS * w.SIM_DT_S
    t0 = time.perf_counter()
    while w.time_s < sim_s - 1e-9:
        apply_regulator(w, reg, dt_s)
        w.advance(COMM_STEPS)
        w.telemetry()
    return w.time_s / (time.perf_counter() - t0), w.fell()


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__)
    ap.add_argument("--source", default="menagerie")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args(argv)
    model = load_model(a.source)
    bare = max(bench_bare(model, a.seconds) for _ in range(a.repeat))
    runs = [bench_walker(model, a.seconds) for _ in range(a.repeat)]
    walker = max(r[0] for r in runs)
    sub = CassieWalker(model).params.control_substeps
    print(f"model: {a.source}, simulated {a.seconds:.0f} s, best of {a.repeat}")
    print(f"bare mj_step         : {bare:6.2f} sim-s/wall-s ({1e6 * model.opt.timestep / bare:.0f} us/step)")
    print(f"plant + controller   : {walker:6.2f} sim-s/wall-s (fell: {any(r[1] for r in runs)})")
    print(f"ratio                : {walker / bare:6.2f} (target >= 0.5)")
    print(f"python controller    : every {sub} plant steps = {1.0 / (sub * model.opt.timestep):.0f} Hz; "
          f"joint PD inside MuJoCo at {1.0 / model.opt.timestep:.0f} Hz")


if __name__ == "__main__":
    main()
