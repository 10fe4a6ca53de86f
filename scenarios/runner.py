"""Running scenario x arm tasks, in this process or in spawned workers, and stopping them.

Stopping is cooperative: :class:`StopFlag` is set (from the CLI's SIGINT handler) and the
master loop asks it before every communication step (``run_arm(stop=...)``), so an arm
ends between two steps, its FMU terminated and freed, never inside a call. Workers
ignore SIGINT themselves (a Ctrl-C on a terminal reaches the whole process group) and
watch a shared event instead. Each task ends as an :class:`~scenarios.output.ArmOutcome`:
complete, failed (with the first line of the error; the traceback is logged) or
interrupted.
"""
from __future__ import annotations

import concurrent.futures as cf
import logging
import multiprocessing
import signal
import traceback
from pathlib import Path
from typing import Any, Callable, Sequence

from scenarios.output import ArmOutcome
from scenarios.spec import Scenario

log = logging.getLogger(__name__)

Task = tuple[Scenario, str]
_WORKER_STOP: Any = None  # the shared event, in a worker process


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


def run_task(scenario: Scenario, arm: str, regulator: str, fmu_path: str | None, unpack_dir: str | None,
             stop: Callable[[], bool], progress: Callable[[int], None] | None = None,
             plant_fmu: str | None = None) -> ArmOutcome:
    """One scenario x arm (its own plant model and regulator instance) as an outcome; the plant
    in-process, or the CassiePlant FMU at ``plant_fmu`` (``--plant fmu``)."""
    from scenarios.master import make_regulator, run_arm

    if stop():
        return ArmOutcome(arm, "interrupted", started=False)
    try:
        reg = make_regulator(regulator, fmu_path, unpack_dir=unpack_dir)
        plant = None
        if plant_fmu is not None:
            from scenarios.plant_fmu import plant_factory

            plant = plant_factory(plant_fmu, unpack_dir=unpack_dir)
        return ArmOutcome(arm, "complete", result=run_arm(scenario, arm, reg, progress=progress, stop=stop,
                                                          plant=plant))
    except KeyboardInterrupt:
        return ArmOutcome(arm, "interrupted")
    except Exception as exc:  # one arm's failure is reported, the run goes on
        first = f"{type(exc).__name__}: {exc}".strip().splitlines()[0]
        return ArmOutcome(arm, "failed", error=first + "\n" + traceback.format_exc(limit=4))


def _init_worker(event: Any) -> None:
    global _WORKER_STOP
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides; see the module doc
    _WORKER_STOP = event


def _worker_task(scenario: Scenario, arm: str, regulator: str, fmu_path: str | None,
                 unpack_dir: str | None, plant_fmu: str | None = None) -> ArmOutcome:
    return run_task(scenario, arm, regulator, fmu_path, unpack_dir, _WORKER_STOP.is_set, plant_fmu=plant_fmu)


def run_tasks(tasks: Sequence[Task], *, regulator: str, fmu_path: str | None, unpack_dir: Path | None, jobs: int,
              stop: StopFlag, on_outcome: Callable[[Scenario, ArmOutcome], None],
              progress: Callable[[int], None] | None = None, plant_fmu: str | None = None) -> None:
    """Run every task (``jobs`` > 1: in that many spawned processes) and hand each outcome
    to ``on_outcome`` in the calling thread; after a stop, the tasks not run are
    reported interrupted (not started). ``progress(n)``: communication steps done
    (``jobs == 1``) or arms done (``jobs > 1``)."""
    unpack = None if unpack_dir is None else str(unpack_dir)
    if jobs == 1:
        for s, arm in tasks:
            out = run_task(s, arm, regulator, fmu_path, unpack, stop, progress, plant_fmu=plant_fmu)
            if progress is not None and out.status == "complete":
                progress(s.n_comm_steps - len(out.result.rows))  # the steps a fall skipped
            on_outcome(s, _first_line(s, out))
        return
    _run_pool(tasks, regulator, fmu_path, unpack, jobs, stop, on_outcome, progress, plant_fmu)


def _run_pool(tasks, regulator, fmu_path, unpack, jobs, stop, on_outcome, progress, plant_fmu=None) -> None:
    ctx = multiprocessing.get_context("spawn")
    stop.event = ctx.Event()
    if stop.requested:
        stop.event.set()
    pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_init_worker,
                                  initargs=(stop.event,))
    futures = {pool.submit(_worker_task, s, a, regulator, fmu_path, unpack, plant_fmu): (s, a) for s, a in tasks}
    pending = set(futures)
    try:
        while pending and not stop.requested:
            done, pending = cf.wait(pending, timeout=0.5, return_when=cf.FIRST_COMPLETED)
            for fut in done:
                _deliver(fut, futures[fut], on_outcome, progress)
        pool.shutdown(wait=True, cancel_futures=True)  # after a stop, workers end within a step
    except KeyboardInterrupt:  # a second Ctrl-C: do not wait for the workers
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            proc.terminate()
        raise
    finally:
        stop.event = None
    for fut in futures:
        if fut in pending:
            _deliver(fut, futures[fut], on_outcome, progress)


def _deliver(fut: cf.Future, task: Task, on_outcome, progress) -> None:
    s, arm = task
    if fut.cancelled():
        out = ArmOutcome(arm, "interrupted", started=False)
    else:
        try:
            out = fut.result()
        except Exception as exc:  # the worker process died
            out = ArmOutcome(arm, "failed", error=f"{type(exc).__name__}: {exc}")
    if progress is not None:
        progress(1)
    on_outcome(s, _first_line(s, out))


def _first_line(scenario: Scenario, out: ArmOutcome) -> ArmOutcome:
    """Log a failure's traceback; keep its first line for the summary."""
    if out.status != "failed" or not out.error:
        return out
    first, _, rest = out.error.partition("\n")
    if rest:
        log.error("%s/%s failed:\n%s", scenario.name, out.arm, rest)
    return ArmOutcome(out.arm, "failed", error=first)
