"""Running scenario x arm tasks, in this process or in spawned workers, and stopping them.

Stopping is cooperative: :class:`StopFlag` is set (from the CLI's SIGINT handler) and the
master loop asks it before every communication step (``run_arm(stop=...)``), so an arm
ends between two steps, its FMU terminated and freed, never inside a call. Workers
ignore SIGINT themselves (a Ctrl-C on a terminal reaches the whole process group) and
watch a shared event instead. Each task ends as an :class:`~scenarios.results.output.ArmOutcome`:
complete, failed (with the first line of the error; the traceback is logged) or
interrupted.

With ``jobs`` > 1 the arms go to the workers longest first (:func:`longest_first`), so
that no long arm is left running alone at the end, and what follows an outcome (the
CLI writes a scenario's results once its arms are in) runs in a worker as a
:class:`Job`, ahead of the arms still waiting: this process only hands out work, so it
never takes a core from an arm. A worker imports the heavy modules
once, before its first arm, and every process compiles each distinct plant once
(``load_plant_model(shared=True)``). A complete arm's ``timings``
(:data:`scenarios.cosim.master.TIMINGS`) also say how long getting its model took
(``model_s``), the CPU time of the whole task (``task_cpu_s``), when it started and
ended (``started_s``, ``ended_s``: s since the tasks began) and in which process
(``pid``); a worker's first complete arm carries what starting that worker cost
(``worker_startup_s`` since the pool was made, ``worker_startup_cpu_s``).
"""
from __future__ import annotations

import collections
import concurrent.futures as cf
import logging
import multiprocessing
import os
import signal
import time
import traceback
from dataclasses import dataclass
from typing import Any, Callable, Sequence

from scenarios.lang.scenario import Scenario
from scenarios.results.output import ArmOutcome
from scenarios.run.options import RunOptions

log = logging.getLogger(__name__)

Task = tuple[Scenario, str]
_WORKER: dict[str, Any] = {}  # in a worker process: the stop event, the tasks' clock origin, its start-up cost

#: Cost per simulated second of a plant on a height field relative to a flat floor, for
#: the order of the arms only: MuJoCo's contacts with the terrain and compiling it
#: (benchmarks/bench_suite.py prints every arm's CPU time; measured 1.35-1.45 on the suite).
TERRAIN_COST = 1.5


def arm_cost(scenario: Scenario) -> float:
    """The expected cost of one arm of ``scenario``: its communication steps, times
    :data:`TERRAIN_COST` on terrain."""
    return scenario.n_comm_steps * (TERRAIN_COST if scenario.terrain is not None else 1.0)


def longest_first(tasks: Sequence[Task]) -> list[Task]:
    """``tasks`` by :func:`arm_cost`, the longest first (equal costs keep their order)."""
    return sorted(tasks, key=lambda task: -arm_cost(task[0]))


class StopFlag:
    """Set once to stop the run. :meth:`set` only assigns an attribute and sets an
    ``multiprocessing.Event`` nobody else in this process waits on: safe in a signal
    handler. Calling the flag answers whether a stop was requested."""

    def __init__(self) -> None:
        self.requested = False
        self.event: Any = None  # the workers' event, while a pool runs

    def set(self) -> None:
        self.requested = True
        if self.event is not None:
            self.event.set()

    def __call__(self) -> bool:
        return self.requested


def run_task(scenario: Scenario, arm: str, options: RunOptions, stop: Callable[[], bool],
             progress: Callable[[int], None] | None = None, origin: float | None = None) -> ArmOutcome:
    """One scenario x arm (its own plant and regulator instance) as an outcome, run as
    ``options`` say: the regulator (``regulator``, ``fmu``), the plant in-process or the
    CassiePlant FMU at ``plant_fmu`` (``plant == "fmu"``), both extracted under ``unpack_dir``,
    the ``exchange`` order, and with ``render`` the states to render in the result
    (:class:`scenarios.results.render.StateRecorder`). A complete arm's timings say when it
    ran (s since ``origin``, a ``perf_counter``)."""
    from scenarios.cosim.regulators import arm_regulator
    from scenarios.cosim.master import run_arm
    from scenarios.lang.plantio import load_plant_model

    if stop():
        return ArmOutcome(arm, "interrupted", started=False)
    started, cpu0 = time.perf_counter(), time.process_time()
    unpack = None if options.unpack_dir is None else str(options.unpack_dir)
    try:
        model, summary = load_plant_model(scenario, shared=True)
        model_s = time.perf_counter() - started
        fmu = None if options.fmu is None else str(options.fmu)
        reg = arm_regulator(scenario.arm(arm), options.regulator, fmu, unpack_dir=unpack)
        plant = None
        if options.plant == "fmu":
            from scenarios.cosim.plant_fmu import plant_factory

            plant = plant_factory(options.plant_fmu, unpack_dir=unpack)
        elif options.controller == "native":
            plant = _native_walker(options.controller_lib)
        recorder = None
        if options.render:
            from scenarios.results.render import StateRecorder

            recorder = StateRecorder(scenario.comm_step_s)
        result = run_arm(scenario, arm, reg, progress=progress, stop=stop, model=model, model_summary=summary,
                         plant=plant, recorder=recorder, exchange=options.exchange)
    except KeyboardInterrupt:
        return ArmOutcome(arm, "interrupted")
    except Exception as exc:  # one arm's failure is reported, the run goes on
        first = f"{type(exc).__name__}: {exc}".strip().splitlines()[0]
        return ArmOutcome(arm, "failed", error=first + "\n" + traceback.format_exc(limit=4))
    base = started if origin is None else origin
    result.timings.update(model_s=model_s, task_cpu_s=time.process_time() - cpu0, started_s=started - base,
                          ended_s=time.perf_counter() - base, pid=os.getpid())
    return ArmOutcome(arm, "complete", result=result)


def _native_walker(controller_lib) -> Callable[[Scenario, Any], Any]:
    """A plant factory for ``run_arm``: the in-process walker with the C controller, the
    library at ``controller_lib`` (None: built under ``plant.sim.NATIVE_CACHE``) loaded once per process."""
    from plant.native.native_ctrl import cached_library_path, load_library
    from plant.sim import NATIVE_CACHE, CassieWalker

    native = load_library(controller_lib if controller_lib is not None else cached_library_path(NATIVE_CACHE))
    return lambda scenario, model: CassieWalker(model, controller="native", native_library=native)


def _init_worker(event: Any, origin: float) -> None:
    """Ignore SIGINT (the parent decides; see the module doc), import what every arm
    needs, and note what starting this worker cost."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _WORKER.update(stop=event, origin=origin)
    import fmpy.fmi2  # noqa: F401
    import mujoco  # noqa: F401
    import plant.sim  # noqa: F401
    import scenarios.cosim.master  # noqa: F401
    _WORKER["startup"] = {"worker_startup_s": time.perf_counter() - origin,
                          "worker_startup_cpu_s": time.process_time()}


def _worker_task(scenario: Scenario, arm: str, options: RunOptions) -> ArmOutcome:
    out = run_task(scenario, arm, options, _WORKER["stop"].is_set, origin=_WORKER["origin"])
    if out.status == "complete" and "startup" in _WORKER:  # reported once, with the first complete arm
        out.result.timings.update(_WORKER.pop("startup"))
    return out


@dataclass(frozen=True)
class Job:
    """Work that follows outcomes (writing a scenario's results): ``fn(*args)``, in a
    worker ahead of the arms still waiting (so that this process never competes with
    the arms for a core), or in this process with ``jobs == 1`` and after a stop;
    ``done(value, error)`` then gets, in the calling thread, what it returned or the
    exception it raised."""

    fn: Callable[..., Any]
    args: tuple
    done: Callable[[Any, BaseException | None], None]


OnOutcome = Callable[[Scenario, ArmOutcome], "Job | None"]


def run_tasks(tasks: Sequence[Task], options: RunOptions, *, stop: StopFlag, on_outcome: OnOutcome,
              progress: Callable[[int], None] | None = None) -> None:
    """Run every task as ``options`` say (``options.jobs`` > 1: in that many spawned processes,
    longest first) and hand each outcome to ``on_outcome`` in the calling thread, which may
    answer a :class:`Job` to run; after a stop, the tasks not run are reported interrupted (not
    started). ``progress(n)``: communication steps done (``jobs == 1``) or arms done
    (``jobs > 1``)."""
    if options.jobs == 1:
        origin = time.perf_counter()
        for s, arm in tasks:
            out = run_task(s, arm, options, stop, progress, origin)
            if progress is not None and out.status == "complete":
                progress(s.n_comm_steps - len(out.result.rows))  # the steps a fall skipped
            _run_here(on_outcome(s, _first_line(s, out)))
        return
    _Pool(options.jobs, stop, on_outcome, progress).run(longest_first(tasks), (options,))


def _run_here(job: Job | None) -> None:
    if job is None:
        return
    try:
        value = job.fn(*job.args)
    except Exception as exc:
        job.done(None, exc)
    else:
        job.done(value, None)


class _Pool:
    """Spawned workers kept busy with at most one item each: the next is a waiting
    :class:`Job` if any, else the next arm (so a job never waits behind queued arms)."""

    def __init__(self, jobs: int, stop: StopFlag, on_outcome: OnOutcome, progress) -> None:
        self.jobs, self.stop, self.on_outcome, self.progress = jobs, stop, on_outcome, progress
        self.waiting: collections.deque[Job] = collections.deque()
        self.running: dict[cf.Future, Task | Job] = {}

    def run(self, tasks: list[Task], arm_args: tuple) -> None:
        ctx = multiprocessing.get_context("spawn")
        stop = self.stop
        stop.event = ctx.Event()
        if stop.requested:
            stop.event.set()
        pool = cf.ProcessPoolExecutor(max_workers=self.jobs, mp_context=ctx, initializer=_init_worker,
                                      initargs=(stop.event, time.perf_counter()))
        arms = collections.deque(tasks)
        try:
            while not stop.requested and self._fill(pool, arms, arm_args):
                done, _ = cf.wait(self.running, timeout=0.5, return_when=cf.FIRST_COMPLETED)
                for fut in done:
                    self._deliver(fut, self.running.pop(fut))
            pool.shutdown(wait=True, cancel_futures=True)  # after a stop, workers end within a step
        except KeyboardInterrupt:  # a second Ctrl-C: do not wait for the workers
            pool.shutdown(wait=False, cancel_futures=True)
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                proc.terminate()
            raise
        finally:
            stop.event = None
        for fut, item in list(self.running.items()):  # ended or cancelled during the shutdown
            self._deliver(fut, item)
        for s, arm in arms:
            self._add(self.on_outcome(s, ArmOutcome(arm, "interrupted", started=False)))
        while self.waiting:  # the pool is gone: what is left runs here
            _run_here(self.waiting.popleft())

    def _fill(self, pool: cf.ProcessPoolExecutor, arms: collections.deque, arm_args: tuple) -> bool:
        """Give every idle worker the next item; true while anything runs."""
        while len(self.running) < self.jobs and (self.waiting or arms):
            if self.waiting:
                job = self.waiting.popleft()
                self.running[pool.submit(job.fn, *job.args)] = job
            else:
                s, a = arms.popleft()
                self.running[pool.submit(_worker_task, s, a, *arm_args)] = (s, a)
        return bool(self.running)

    def _add(self, job: Job | None) -> None:
        if job is not None:
            self.waiting.append(job)

    def _deliver(self, fut: cf.Future, item: Task | Job) -> None:
        if isinstance(item, Job):
            if fut.cancelled():
                self.waiting.append(item)
                return
            error = fut.exception()
            item.done(None if error else fut.result(), error)
            return
        s, arm = item
        if fut.cancelled():
            out = ArmOutcome(arm, "interrupted", started=False)
        else:
            try:
                out = fut.result()
            except Exception as exc:  # the worker process died
                out = ArmOutcome(arm, "failed", error=f"{type(exc).__name__}: {exc}")
        if self.progress is not None:
            self.progress(1)
        self._add(self.on_outcome(s, _first_line(s, out)))


def _first_line(scenario: Scenario, out: ArmOutcome) -> ArmOutcome:
    """Log a failure's traceback; keep its first line for the summary."""
    if out.status != "failed" or not out.error:
        return out
    first, _, rest = out.error.partition("\n")
    if rest:
        log.error("%s/%s failed:\n%s", scenario.name, out.arm, rest)
    return ArmOutcome(out.arm, "failed", error=first)
