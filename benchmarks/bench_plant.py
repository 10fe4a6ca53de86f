"""Benchmark: bare ``mj_step`` vs plant + nominal controller, in the same run.

``python benchmarks/bench_plant.py [--source menagerie|osu] [--seconds 10] [--controller python|native]``

* bare: ``mujoco.mj_step`` of the unmodified model from the ``home`` keyframe with
  zero motor commands, in chunks of 20 steps (``nstep``), for the same simulated
  time as the walker, restarting from ``home`` whenever the (uncontrolled) robot
  has fallen (pelvis < 0.6 m) so that the contact load stays comparable;
* walker: :class:`plant.sim.CassieWalker` walking at 0.5 m/s from rest with the
  regulator core ``fmu_src.core.avr_core`` (adaptation off, default gains) called
  in-process every 10 ms (``advance(20)``) through
  :func:`plant.sim.apply_regulator`, including the regulator and telemetry calls
  the co-simulation makes;
* the walk's own physics: ``mj_step`` alone, restarted from the walker's state at each of
  its communication steps (positions, velocities, warm start, the controller's motor
  commands and servo gains as they were) for that step's plant steps: what the physics of
  this walk costs without the controller, the regulator or Python around it (the contacts
  of walking, not those of a robot that falls from ``home``).

Prints simulated seconds per wall second for each, the walker's ratio to both (target
>= 0.5 of bare), and the controller's rate.  Best of ``--repeat`` runs (machine is shared).
"""
from __future__ import annotations

import argparse
import copy
import time

import mujoco
import numpy as np

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


#: What a communication step's state holds for :func:`bench_walk_physics` (the controller's
#: motor commands included: mjSTATE_INTEGRATION has ctrl and the warm start).
STATE = mujoco.mjtState.mjSTATE_INTEGRATION


def bench_walker(model, sim_s: float, controller: str = "python",
                 states: list | None = None) -> tuple[float, bool]:
    """The walker's rate; with ``states``, also each communication step's state before it
    (recording it is not timed)."""
    w = CassieWalker(model, controller=controller)
    w.set_command(0.5, 0.0)
    reg = Regulator(PD_ONLY_PARAMS)
    dt_s = COMM_STEPS * w.SIM_DT_S
    size = mujoco.mj_stateSize(w.model, STATE)
    elapsed = 0.0
    while w.time_s < sim_s - 1e-9:
        if states is not None:
            state = np.empty(size)
            mujoco.mj_getState(w.model, w.data, state, STATE)
            states.append((state, w.model.actuator_biasprm.copy()))
        t0 = time.perf_counter()
        apply_regulator(w, reg, dt_s)
        w.advance(COMM_STEPS)
        w.telemetry()
        elapsed += time.perf_counter() - t0
    return w.time_s / elapsed, w.fell()


def bench_walk_physics(model, states: list) -> float:
    """``mj_step`` alone from each recorded state for one communication step; simulated s per wall s."""
    m = copy.copy(model)  # the servo gains below are the controller's; the caller's model stays as it is
    d = mujoco.MjData(m)
    elapsed = 0.0
    for state, bias in states:
        m.actuator_biasprm[:] = bias
        mujoco.mj_setState(m, d, state, STATE)
        t0 = time.perf_counter()
        mujoco.mj_step(m, d, nstep=COMM_STEPS)
        elapsed += time.perf_counter() - t0
    return len(states) * COMM_STEPS * m.opt.timestep / elapsed


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__)
    ap.add_argument("--source", default="menagerie")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--controller", choices=("python", "native"), default="python",
                    help="the walking controller (native: the C controller, the run's default)")
    a = ap.parse_args(argv)
    model = load_model(a.source)
    bare = max(bench_bare(model, a.seconds) for _ in range(a.repeat))
    states: list = []
    runs = [bench_walker(model, a.seconds, a.controller, states if i == 0 else None) for i in range(a.repeat)]
    walker = max(r[0] for r in runs)
    walk = max(bench_walk_physics(model, states) for _ in range(a.repeat))
    sub = CassieWalker(model).params.control_substeps
    print(f"model: {a.source}, simulated {a.seconds:.0f} s, best of {a.repeat}, the {a.controller} controller")
    print(f"bare mj_step         : {bare:6.2f} sim-s/wall-s ({1e6 * model.opt.timestep / bare:.0f} us/step)")
    print(f"the walk's mj_step   : {walk:6.2f} sim-s/wall-s ({walk / bare:.2f} x bare)")
    print(f"plant + controller   : {walker:6.2f} sim-s/wall-s (fell: {any(r[1] for r in runs)})")
    print(f"ratio                : {walker / bare:6.2f} of bare (target >= 0.5), {walker / walk:.2f} of the walk's mj_step")
    print(f"controller           : every {sub} plant steps = {1.0 / (sub * model.opt.timestep):.0f} Hz; "
          f"joint PD inside MuJoCo at {1.0 / model.opt.timestep:.0f} Hz")


if __name__ == "__main__":
    main()
