"""One campaign task, as it runs on a Dask worker: one sample, all its arms.

The sample's scenario file is run by a fresh ``python -m scenarios run --no-plots``
process (a crash, a leak or a pythonfmu FMU that cannot share a process touches
nothing else; the campaign's report draws the plots); the task reads the metrics back
from that run's ``summary.json``. With ``fork`` (the campaign's default on Linux,
``--no-fork-runs`` turns it off) that process is forked from the worker's warm server
(:mod:`scenarios.campaign.forkrun`: no interpreter start-up, imports and base-model check
per run) instead of started anew; on a worker that cannot fork it is started anew.
One task per sample, not per arm: the arms share the process start, the model
compilation checks and the run's CSV writing, and the sample's folder holds one normal
run output.

- The run process dies with the worker (Linux ``PR_SET_PDEATHSIG``) and sits in its
  own session (a Ctrl-C on the terminal stops the campaign, not the runs one by one).
- Each execution gets a fresh ``--out`` folder ``runs/<id>/try<k>`` (k = 1, 2, ...,
  claimed with an atomic ``mkdir``: a retry never writes over an earlier attempt) and
  its own ``TMPDIR`` under the campaign folder, removed afterwards.
- A run process killed by a signal raises :class:`RunProcessDied` (Dask's
  ``retries=`` runs the task again, bounded); a timeout or a run that reports a
  failure gives ``failed`` rows with the reason (running it again would not help).
"""
from __future__ import annotations

import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scenarios.campaign import forkrun
from scenarios.campaign.forkrun import die_with_parent

log = logging.getLogger(__name__)

#: The metrics copied from each arm of ``summary.json`` into the campaign CSV.
METRICS = ("fell", "t_fall_s", "steady_state_error_vx", "steady_state_error_vy", "settled_error_vx",
           "convergence_time_s",
           "mean_vx_last_s", "mean_vy_last_s", "max_abs_pitch_rad", "max_abs_roll_rad", "sim_s", "wall_s")
COMPLETE, FAILED = "complete", "failed"
_TAIL = 600  # characters of the run's stderr kept in a failure reason

class RunProcessDied(RuntimeError):
    """The ``scenarios run`` process was killed by a signal (Dask retries the task)."""


@dataclass(frozen=True)
class Task:
    sample: str
    scenario_file: str  # absolute path of samples/<id>.toml
    runs_dir: str  # runs/<id>: each execution claims runs/<id>/try<k>
    arms: tuple[str, ...]
    regulator: str
    fmu: str | None
    timeout_s: float
    tmp_root: str  # the campaign's scratch folder (TMPDIR of the run process)
    env: tuple[tuple[str, str], ...] = ()  # the client's settings the run must share (MENAGERIE_ROOT)
    fork: bool = False  # run forked from the worker's warm server (where it can fork), not as a new interpreter
    warm_models: tuple[str, ...] = ()  # the models that server checks (compiles) once, ahead of the runs
    controller: str = "native"  # the walking controller (run --controller)


def client_env() -> tuple[tuple[str, str], ...]:
    """The client's environment the runs must see, with paths made absolute: the Menagerie
    folder the client's model loader uses (``MENAGERIE_ROOT`` or its default), so workers
    started elsewhere (a remote scheduler's) load the same model."""
    from plant.model import menagerie_root

    root = menagerie_root()
    return (("MENAGERIE_ROOT", str(root.resolve())),) if root is not None else ()


def _claim_out(runs_dir: Path) -> Path:
    runs_dir.mkdir(parents=True, exist_ok=True)
    k = 1
    while True:
        out = runs_dir / f"try{k}"
        try:
            out.mkdir()
            return out
        except FileExistsError:
            k += 1


def run_command(task: Task, out: Path) -> list[str]:
    """``python -m scenarios run ...`` for ``task`` (from index 4: the ``run`` command's own arguments)."""
    cmd = [sys.executable, "-m", "scenarios", "run", task.scenario_file, "--out", str(out),
           "--regulator", task.regulator, "--controller", task.controller, "--no-plots"]  # the campaign's report plots the campaign
    return cmd + (["--fmu", task.fmu] if task.fmu else [])


#: Thread pools of numerical libraries: one thread per run (a worker is one core). A campaign
#: run never renders: MuJoCo skips its search for OpenGL at import (about 0.3 s a run).
_THREADS = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MUJOCO_GL": "disable"}


def run_sample(task: Task) -> dict[str, Any]:
    """Run the sample; ``{"sample", "rows": [one per arm], "task_wall_s", "run_dir"}``."""
    out = _claim_out(Path(task.runs_dir))
    Path(task.tmp_root).mkdir(parents=True, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=f"{task.sample}-", dir=task.tmp_root)
    t0 = time.perf_counter()
    try:
        code, err = (_run_forked if task.fork and forkrun.AVAILABLE else _run_process)(task, out, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    wall = time.perf_counter() - t0
    if code is None:
        why = f"timeout: the run took longer than {task.timeout_s:g} s (task_timeout_s / --task-timeout)"
        return _result(task, out, wall, {}, why)
    tail = err[-_TAIL:].strip()
    if code < 0:
        name = signal.Signals(-code).name
        raise RunProcessDied(f"sample {task.sample}: the run process was killed by {name}; stderr: {tail}")
    summary_path = out / task.sample / "summary.json"
    try:
        summary = json.loads(summary_path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        why = f"the run exited with status {code} without a readable summary.json ({exc}); stderr: {tail}"
        return _result(task, out, wall, {}, why)
    return _result(task, out, wall, summary, tail or f"exit status {code}")


def _run_process(task: Task, out: Path, tmp: str) -> tuple[int | None, str]:
    """The run as a new ``python -m scenarios run`` process: (exit status or None after
    the timeout, its stderr)."""
    env = {**os.environ, **dict(task.env), "TMPDIR": tmp, **_THREADS}
    proc = subprocess.Popen(run_command(task, out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                            preexec_fn=die_with_parent, start_new_session=True)
    try:
        _, err = proc.communicate(timeout=task.timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return None, ""
    return proc.returncode, err.decode("utf-8", "replace")


def _server_env(task: Task) -> dict[str, str]:
    """The environment of this worker's fork server for ``task`` (every run's but TMPDIR)."""
    return {**os.environ, **dict(task.env), **_THREADS}


def warm_fork_server(task: Task) -> None:
    """Start this worker's fork server for runs like ``task``'s ahead of them (the campaign
    calls it on every worker: ``client.run``); a failure leaves it to the first run. A worker
    that cannot fork starts none (its runs are new interpreters)."""
    if not forkrun.AVAILABLE:
        return
    try:
        forkrun.warm(_server_env(task), task.warm_models)
    except Exception as exc:
        log.warning("the fork server did not start ahead of the runs (%s: %s)", type(exc).__name__, exc)


def _run_forked(task: Task, out: Path, tmp: str) -> tuple[int | None, str]:
    """The run forked from this worker's warm server (:mod:`scenarios.campaign.forkrun`)."""
    stderr = Path(tmp) / "run.stderr"
    try:
        code = forkrun.run_forked(run_command(task, out)[4:], _server_env(task), {"TMPDIR": tmp}, stderr,
                                  task.timeout_s, task.warm_models)
    except EOFError as exc:
        raise RunProcessDied(f"sample {task.sample}: the fork server died during the run ({exc})") from None
    err = stderr.read_text("utf-8", "replace") if stderr.is_file() else ""
    return code, err


def arm_status(summary: dict[str, Any], arm: str) -> str:
    """``complete`` / ``failed`` / ``interrupted`` of one arm of a run's summary.

    A per-arm ``status`` is used when the summary has one; otherwise an arm with
    metrics is complete and an arm without is failed.
    """
    m = (summary.get("arms") or {}).get(arm)
    if not m:
        return FAILED
    status = m.get("status", COMPLETE)
    return COMPLETE if status in (COMPLETE, "ok") else status


def _result(task: Task, out: Path, wall: float, summary: dict[str, Any], why: str) -> dict[str, Any]:
    rows = []
    for arm in task.arms:
        status = arm_status(summary, arm)
        m = (summary.get("arms") or {}).get(arm) or {}
        row = {"arm": arm, "status": status, **{k: m.get(k) for k in METRICS}, "error": None}
        if status != COMPLETE:
            row["error"] = m.get("error") or summary.get("error") or why
        rows.append(row)
    return {"sample": task.sample, "rows": rows, "task_wall_s": wall, "run_dir": str(out / task.sample)}
