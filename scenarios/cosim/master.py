"""The co-simulation master: the MuJoCo Cassie plant closed around the regulator.

One loop (:func:`run_arm`) drives the plant and a
:class:`~scenarios.cosim.regulators.RegulatorPath` (the FMU, or the core in-process: see
:mod:`scenarios.cosim.regulators`; both give bit-identical trajectories for the same
scenario and seed).

Per communication step ``k`` (time ``t = t0 + k*h`` from the integer counter; never
``t += h``): the command schedule and the pushes in force over ``[t, t+h)`` are applied
to the plant (pushes switch on communication-step boundaries only), the plant is
sensed, the regulator steps from ``t`` by ``h`` and its six ``delta_*`` outputs go to
the walker, which then advances ``h / SIM_DT_S`` plant steps. A fall stops the run
(``t_fall_s`` = end of the step in which it was detected).

The result is a numpy structured array, one row per communication step: ``t``,
``cmd_vx_des``, ``cmd_vy_des``, ``cmd_yaw_rate_des``, ``push_fx/fy/fz``, ``in_<input>`` (the sensed
regulator inputs), ``out_<output>`` (every FMU output) and ``tel_<key>`` (the
walker's telemetry), all sampled at ``t`` (outputs: computed at ``t``, applied over
the step).
"""
from __future__ import annotations

import logging
import math
import operator
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from plant.constants import OFFSET_NAMES
from plant.interface import REGULATOR_INPUT_NAMES, Plant
from scenarios.errors import CosimError, ScenarioError
from scenarios.cosim.regulators import RegulatorPath, arm_regulator
from scenarios.lang.scenario import Arm, Scenario

log = logging.getLogger(__name__)

#: Regulator inputs sensed on the plant (vx_des/vy_des come from the command schedule; its
#: yaw_rate_des goes to the plant only: the regulator has no such input).
SENSED_INPUTS = REGULATOR_INPUT_NAMES
#: Progress is reported every this many communication steps.
PROGRESS_EVERY = 200
#: The data flow within a communication step: ``gauss-seidel`` (the default: sense the plant,
#: step the regulator, apply its offsets over the same step) or ``jacobi`` (as the SSP masters
#: libcosim, fmpy and Ecos: the offsets applied over step k are the regulator's outputs at
#: t_k, computed from the plant's outputs at t_(k-1); the offsets act one step later).
EXCHANGES = ("gauss-seidel", "jacobi")
#: How close ``h / sim_dt`` must be to a whole number (in plant steps).
WHOLE_STEPS_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class ArmResult:
    """One arm of one scenario: the trajectory and how the run ended.

    ``timings``: where the arm's time went, seconds (:data:`TIMINGS`); reported in
    summary.json, never part of the trajectory.
    """

    scenario: str
    arm: str
    regulator: str
    model: str
    rows: np.ndarray
    fell: bool
    t_fall_s: float | None
    fall_reason: str | None
    wall_s: float
    model_summary: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    track: Any = None  # the states to render (``run --render``: scenarios.results.render.StateTrack)

    @property
    def sim_s(self) -> float:
        if len(self.rows) == 0:
            return 0.0
        h = float(self.rows["t"][1] - self.rows["t"][0]) if len(self.rows) > 1 else 0.0
        return float(self.rows["t"][-1]) + h


#: The phases :func:`run_arm` times (wall seconds, ``time.perf_counter``), and its CPU time.
TIMINGS = {
    "model_s": "compiling the plant model (0 when it was passed in)",
    "walker_s": "building the walker on it",
    "regulator_start_s": "starting the regulator (FMU: extract, instantiate, initialize)",
    "loop_s": "every communication step, the three below included",
    "loop_cpu_s": "CPU time of the process over every communication step",
    "regulator_s": "the regulator's steps",
    "plant_s": "the plant's steps (physics and nominal controller)",
    "record_s": "storing each step's row",
    "finish_s": "closing the regulator, building the rows",
    "cpu_s": "CPU time of the process over all of the above",
}


def plant_steps_per_comm(h: float, sim_dt: float) -> int:
    """``h / sim_dt`` as an int; ScenarioError unless it is a whole number >= 1."""
    n = h / sim_dt
    if not (math.isfinite(n) and n >= 1 - 1e-9 and abs(n - round(n)) < WHOLE_STEPS_TOL):
        raise ScenarioError([f"comm_step_s = {h:g}: must be a whole multiple of the plant step {sim_dt:g} s"])
    return int(round(n))


def _row_dtype(outputs: tuple[str, ...], sensed: Mapping[str, Any], telemetry: Mapping[str, Any]) -> np.dtype:
    fields: list[tuple[str, Any]] = [("t", "f8"), ("cmd_vx_des", "f8"), ("cmd_vy_des", "f8"),
                                     ("cmd_yaw_rate_des", "f8"), ("push_fx", "f8"), ("push_fy", "f8"),
                                     ("push_fz", "f8")]
    for n in SENSED_INPUTS:
        fields.append((f"in_{n}", "i8" if n == "step_index" else "f8"))
    fields += [(f"out_{n}", "f8") for n in outputs]
    for k, v in telemetry.items():
        is_int = isinstance(v, (int, np.integer)) and not isinstance(v, bool)
        fields.append((f"tel_{k}", "i8" if is_int else "f8"))
    return np.dtype(fields)


class _Recorder:
    """The rows in a table of doubles preallocated for every step (one store per step),
    turned into the structured array at the end. Integer columns (step counters) are
    whole numbers far below 2**53: a double holds them exactly."""

    def __init__(self, n_steps: int, dtype: np.dtype) -> None:
        self.dtype = dtype
        self.table = np.empty((n_steps, len(dtype.names)))

    def rows(self, n: int) -> np.ndarray:
        rows = np.empty(n, dtype=self.dtype)
        for j, name in enumerate(self.dtype.names):
            rows[name] = self.table[:n, j]
        return rows


@dataclass
class _Steps:
    """What the communication steps of one arm produced (filled in as they run)."""

    recorder: _Recorder | None = None
    done: int = 0
    fell: bool = False
    t_fall: float | None = None
    reason: str | None = None
    timings: dict = field(default_factory=dict)


def run_arm(scenario: Scenario, arm: Arm | str, regulator: RegulatorPath, *,
            progress: Callable[[int], None] | None = None, model=None, model_summary: dict | None = None,
            stop: Callable[[], bool] | None = None,
            plant: Callable[[Scenario, Any], Plant] | None = None,
            recorder: Callable[[int, float, Plant], None] | None = None,
            exchange: str = "gauss-seidel") -> ArmResult:
    """Run one arm of ``scenario`` closed-loop; return its trajectory (nothing printed).

    ``progress(n)`` is called with the number of communication steps done since the
    last call (for a progress bar). ``model`` may pass an already compiled plant model
    (it is only read: a fresh walker is built on it). ``stop()`` is asked before every
    communication step; when it answers true the run ends with ``KeyboardInterrupt``
    (a cooperative Ctrl-C: raised here, never inside the FMU). The regulator is closed
    whatever happens. ``plant(scenario, model)`` makes the walker instead of
    ``CassieWalker(model)`` (``scenarios.cosim.plant_fmu``: the plant FMU); either is a
    :class:`plant.interface.Plant`, closed at the end. ``recorder(k, t, walker)`` is called at every
    communication step before the plant advances (``run --render``:
    :class:`scenarios.results.render.StateRecorder`; its ``track()`` goes into the result).
    The result's ``timings`` say where the time went (:data:`TIMINGS`).
    ``exchange``: :data:`EXCHANGES` (``"jacobi"``: the SSP masters' order).
    """
    from plant.sim import CassieWalker

    from scenarios.lang.plantio import load_plant_model

    if exchange not in EXCHANGES:
        raise ValueError(f"exchange = {exchange!r}: must be one of {', '.join(EXCHANGES)}")
    if isinstance(arm, str):
        arm = scenario.arm(arm)
    cpu0, lap = time.process_time(), time.perf_counter()
    timings = {"model_s": 0.0}
    if model is None:
        model, model_summary = load_plant_model(scenario)
        lap = _lap(timings, "model_s", lap)
    walker: Plant = CassieWalker(model) if plant is None else plant(scenario, model)  # its own copy of the model
    n_plant = plant_steps_per_comm(scenario.comm_step_s, float(walker.SIM_DT_S))
    outputs = regulator.output_names()
    missing = [n for n in OFFSET_NAMES if n not in outputs]
    if missing:
        raise CosimError(f"the regulator has no output(s) {', '.join(missing)}")
    steps = _Steps()
    wall0 = lap = _lap(timings, "walker_s", lap)
    try:
        regulator.start(arm.overrides_dict(), 0.0, scenario.n_comm_steps * scenario.comm_step_s)
        lap = _lap(timings, "regulator_start_s", lap)
        loop_cpu0 = time.process_time()
        _run_steps(scenario, arm, walker, regulator, n_plant, steps, progress, stop, recorder, exchange)
        timings["loop_cpu_s"] = time.process_time() - loop_cpu0
        lap = _lap(timings, "loop_s", lap)
    finally:
        regulator.close()
        walker.close()
    if progress is not None and steps.done % PROGRESS_EVERY:
        progress(steps.done % PROGRESS_EVERY)
    rows = steps.recorder.rows(steps.done) if steps.recorder is not None else np.zeros(0, dtype=[("t", "f8")])
    _lap(timings, "finish_s", lap)
    wall = time.perf_counter() - wall0
    timings.update(steps.timings, cpu_s=time.process_time() - cpu0)
    return ArmResult(scenario=scenario.name, arm=arm.name, regulator=regulator.kind, model=scenario.model,
                     rows=rows, fell=steps.fell, t_fall_s=steps.t_fall, fall_reason=steps.reason, wall_s=wall,
                     model_summary=dict(model_summary or {}), timings=timings,
                     track=None if recorder is None else recorder.track())


def _lap(timings: dict[str, float], key: str, since: float) -> float:
    """Add the time since ``since`` to ``timings[key]``; return now."""
    now = time.perf_counter()
    timings[key] = timings.get(key, 0.0) + (now - since)
    return now


def _run_steps(scenario: Scenario, arm: Arm, walker: Plant, regulator: RegulatorPath, n_plant: int, steps: _Steps,
               progress: Callable[[int], None] | None, stop: Callable[[], bool] | None,
               recorder: Callable[[int, float, Any], None] | None = None, exchange: str = "gauss-seidel") -> None:
    """The communication steps of :func:`run_arm` (see the module docstring), into ``steps``."""
    h, t0, n_steps = scenario.comm_step_s, 0.0, scenario.n_comm_steps
    outputs = regulator.output_names()
    # per step, numbers in fixed orders (no names): the plant's signals (regulator inputs, then
    # telemetry), the regulator's inputs (MASTER_INPUTS) and outputs, the offsets (OFFSET_NAMES)
    n_sensed = len(SENSED_INPUTS)  # MASTER_INPUTS: these, then vx_des and vy_des
    offsets_of = operator.itemgetter(*(outputs.index(n) for n in OFFSET_NAMES))
    signals, step_values, set_offsets = walker.signals, regulator.step_values, walker.set_offset_values
    command_at, push_at, advance, fell = scenario.command_at_step, scenario.push_force_at_step, walker.advance, walker.fell
    pushed_bodies, events = scenario.pushed_bodies, scenario.events
    clock = time.perf_counter
    command: tuple[float, float, float] | None = None
    force = (0.0, 0.0, 0.0)
    table = None
    reg_s = plant_s = record_s = 0.0
    # Jacobi: the offsets in force over step k are the regulator's outputs at t_k, computed
    # in step k-1; at t0 its outputs' start values, 0 for every regulator output.
    held = [0.0] * len(outputs) if exchange == "jacobi" else None
    body_forces: dict[str, tuple[float, float, float]] = {}
    running = {"torso_com_offset_m": scenario.torso_com_offset_m, "joint_damping_scale": scenario.joint_damping_scale}
    try:
        for k in range(n_steps):
            if stop is not None and stop():
                raise KeyboardInterrupt(f"{scenario.name}/{arm.name} stopped at t = {t0 + k * h:g} s")
            t = t0 + k * h
            cmd = command_at(k)
            if cmd != command:
                walker.set_command(*cmd)
                command = cmd
            f = push_at(k)
            if f != force:
                walker.set_pelvis_force(np.array(f, dtype=float))
                force = f
            if pushed_bodies:
                body_forces = _apply_body_forces(scenario, walker, k, body_forces)
            if events:
                running = _apply_events(scenario, walker, k, running)
            sensed = signals()
            inputs = (*sensed[:n_sensed - 1], int(sensed[n_sensed - 1]), cmd[0], cmd[1])  # step_index last: an int
            c0 = clock()
            out = step_values(t, h, inputs)
            if held is not None:
                out, held = held, out
            c1 = clock()
            set_offsets(offsets_of(out))
            if table is None:
                steps.recorder = _Recorder(n_steps, _row_dtype(outputs, walker.regulator_inputs(), walker.telemetry()))
                table = steps.recorder.table
            c2 = clock()
            table[k] = (t, *cmd, *f, *inputs[:n_sensed], *out, *sensed[n_sensed:])
            if recorder is not None:
                recorder(k, t, walker)
            c3 = clock()
            advance(n_plant)
            c4 = clock()
            reg_s += c1 - c0
            record_s += c3 - c2
            plant_s += c4 - c3
            steps.done += 1
            if progress is not None and (steps.done % PROGRESS_EVERY == 0):
                progress(PROGRESS_EVERY)
            if fell():
                steps.fell, steps.t_fall = True, t0 + (k + 1) * h
                steps.reason = walker.fall_reason or None
                log.info("%s/%s: fell at t = %.3f s (%s)", scenario.name, arm.name, steps.t_fall, steps.reason)
                break
    finally:
        steps.timings.update(regulator_s=reg_s, plant_s=plant_s, record_s=record_s)


def _apply_body_forces(scenario: Scenario, walker, k: int, before: dict) -> dict:
    """Set the forces on the pushed bodies other than the pelvis over step ``k`` (zero on a
    body whose pushes ended); return them."""
    now = scenario.body_forces_at_step(k)
    if now != before:
        for body in scenario.pushed_bodies:
            walker.set_body_force(body, np.array(now.get(body, (0.0, 0.0, 0.0)), dtype=float))
    return now


def _apply_events(scenario: Scenario, walker, k: int, running: dict) -> dict:
    """The scenario's events at step ``k`` on the walker's model: each value replaces the
    scenario's (``running``: the COM offset and damping scale in force, which the walker
    changes by a shift and a factor)."""
    for event in scenario.events_at_step(k):
        change: dict[str, Any] = {}
        if event.torso_mass_kg is not None:
            change["torso_mass_kg"] = event.torso_mass_kg
        if event.torso_com_offset_m is not None:
            change["torso_com_shift_m"] = tuple(n - o for n, o in zip(event.torso_com_offset_m,
                                                                     running["torso_com_offset_m"]))
            running = {**running, "torso_com_offset_m": event.torso_com_offset_m}
        if event.joint_damping_scale is not None:  # the start scale is > 0 (sections.events)
            change["damping_factor"] = event.joint_damping_scale / running["joint_damping_scale"]
            running = {**running, "joint_damping_scale": event.joint_damping_scale}
        if event.floor_friction is not None:
            change["floor_friction"] = event.floor_friction
        walker.change_plant(**change)
        log.debug("%s: event at t = %g s: %s", scenario.name, event.t_s, change)
    return running


def run_scenario(scenario: Scenario, regulator: str = "fmu", *, fmu_path: str | Path | None = None,
                 arms: tuple[str, ...] | None = None, progress: Callable[[int], None] | None = None,
                 plant: Callable[[Scenario, Any], Plant] | None = None,
                 exchange: str = "gauss-seidel") -> list[ArmResult]:
    """Every arm of ``scenario`` (or those named in ``arms``), each on a fresh plant and regulator."""
    from scenarios.lang.plantio import load_plant_model

    model, summary = load_plant_model(scenario)
    results = []
    for arm in scenario.arms:
        if arms is not None and arm.name not in arms:
            continue
        results.append(run_arm(scenario, arm, arm_regulator(arm, regulator, fmu_path), progress=progress,
                               model=model, model_summary=summary, plant=plant, exchange=exchange))
    return results
