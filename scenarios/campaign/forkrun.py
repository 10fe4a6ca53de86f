"""Campaign runs forked from a warm process (``campaign --fork-runs``): a fresh process per
run without a fresh interpreter's start-up.

A campaign task's run (``python -m scenarios run SAMPLE --no-plots``) spends about as
long importing numpy, MuJoCo, fmpy and the scenarios package and compiling the nominal
model for its checks as a short sample spends simulating (``benchmarks/bench_campaign.py``).
With ``--fork-runs`` each worker keeps a *fork server*: a process that has imported all
that and checked the campaign's base model once, and forks one child per run. The child
is a fresh process all the same (a pythonfmu FMU is loaded in it alone; a crash takes
nothing else with it): it starts its own session, dies with the server (Linux
``PR_SET_PDEATHSIG``), takes the task's environment (``TMPDIR``, ``MENAGERIE_ROOT``),
writes its stderr to a file and runs :func:`scenarios.run.command.main` on the run's arguments.

Protocol (one run at a time per server; a worker starts another server for a second
concurrent task): the server, started with the environment every run shares, says
``{"ready": pid}``; the client writes one JSON line ``{"argv", "env", "stderr"}`` per run
(``env``: what this run adds, e.g. its ``TMPDIR``); the server answers ``{"pid": ...}``
once the child runs, then ``{"exit": code}`` when it ends (negative: killed by that
signal). The server ends when its stdin closes, or with the thread that started it.
"""
from __future__ import annotations

import ctypes
import json
import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

try:  # Linux: the child gets SIGKILL when the thread that started it (the task) goes away
    _PRCTL = ctypes.CDLL(None, use_errno=True).prctl
except (OSError, AttributeError):  # pragma: no cover - not Linux
    _PRCTL = None
_PR_SET_PDEATHSIG = 1
#: Whether runs can be forked here: Linux (a forked child must die with its server, and fork
#: without exec is safe with these libraries only where the tests run it). Elsewhere a run that
#: asks for a fork is started as a new interpreter (:func:`scenarios.campaign.task.run_sample`).
AVAILABLE = sys.platform.startswith("linux") and hasattr(os, "fork") and _PRCTL is not None

#: What the server imports before its first fork (what a run imports, matplotlib aside).
PRELOAD = ("numpy", "mujoco", "fmpy", "fmpy.fmi2", "fmpy.fmi3", "tqdm", "plant.model", "plant.sim",
           "scenarios.run.command", "scenarios.run.run_session", "scenarios.run.runner", "scenarios.cosim.master", "scenarios.results.output",
           "scenarios.results.store", "scenarios.lang.spec", "scenarios.lang.plantio", "scenarios.cosim.regulators")
SERVER_START_S = 120.0  # a server must be ready within this time


def die_with_parent() -> None:  # runs in the child between fork and exec: no allocation-heavy work
    """Linux: this process gets SIGKILL when the thread that started it goes away."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, signal.SIGKILL)


# --------------------------------------------------------------------------- server side
def _child(request: dict[str, Any], server_pid: int) -> None:
    """In the forked child: become a fresh run process, run, exit (never returns)."""
    code = 1
    try:
        os.setsid()
        die_with_parent()
        if os.getppid() != server_pid:  # the server died before the line above
            os._exit(1)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        os.environ.update(request["env"])
        import tempfile

        tempfile.tempdir = None  # TMPDIR changed
        null = os.open(os.devnull, os.O_RDWR)
        err = os.open(request["stderr"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        for fd, target in ((0, null), (1, null), (2, err)):
            os.dup2(target, fd)
        from scenarios.run.command import main

        code = main(request["argv"])
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:  # everything is reported on the run's stderr
        import traceback

        traceback.print_exc()
    finally:
        try:
            import logging

            logging.shutdown()
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code if isinstance(code, int) else 1)


def _say(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def serve(warm_models: list[str]) -> int:
    """The server's loop (see the module docstring)."""
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    from scenarios.lang import plantio

    for model in warm_models:  # the run's check compiles the base model: once here, not in every run
        try:
            plantio._base_model_check(model, plantio._file_stamp(model))
        except Exception:  # the runs report what is wrong with the model themselves
            pass
    me = os.getpid()
    _say({"ready": me})
    for line in sys.stdin:
        request = json.loads(line)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            _child(request, me)
        _say({"pid": pid})
        _, status = os.waitpid(pid, 0)
        _say({"exit": os.waitstatus_to_exitcode(status)})
    return 0


# --------------------------------------------------------------------------- client side
class ForkServer:
    """One server process (started by :func:`warm` or :func:`run_forked`), serving one run at a time."""

    def __init__(self, env: dict[str, str], warm_models: tuple[str, ...]) -> None:
        self.key = _key(env, warm_models)
        self.proc = subprocess.Popen([sys.executable, "-m", "scenarios.campaign.forkrun", *warm_models],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     env=env, text=True, preexec_fn=die_with_parent, start_new_session=True)
        self._buffer = ""
        try:
            self.pid = self._read(SERVER_START_S)["ready"]
        except BaseException:
            self.kill()
            raise

    def _read(self, timeout: float | None) -> dict[str, Any]:
        """The server's next message; TimeoutError after ``timeout`` s; EOFError if it died."""
        deadline = None if timeout is None else time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        while "\n" not in self._buffer:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            if not select.select([fd], [], [], left)[0]:
                raise TimeoutError
            chunk = os.read(fd, 65536).decode()
            if not chunk:
                raise EOFError("the fork server ended")
            self._buffer += chunk
        line, self._buffer = self._buffer.split("\n", 1)
        return json.loads(line)

    def run(self, argv: list[str], env: dict[str, str], stderr: Path, timeout: float) -> int | None:
        """Run ``scenarios.run.command.main(argv)`` (``argv``: the ``run`` command's arguments) in a forked child; its exit code (negative: the
        signal that killed it), or None after ``timeout`` s (the child is killed)."""
        self.proc.stdin.write(json.dumps({"argv": argv, "env": env, "stderr": str(stderr)}) + "\n")
        self.proc.stdin.flush()
        child = self._read(SERVER_START_S)["pid"]
        try:
            return self._read(timeout)["exit"]
        except TimeoutError:
            try:
                os.kill(child, signal.SIGKILL)
            except ProcessLookupError:  # it ended just now (and was reaped)
                pass
            self._read(SERVER_START_S)
            return None

    def alive(self) -> bool:
        return self.proc.poll() is None

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait()

    def close(self) -> None:
        if self.proc.stdin:
            self.proc.stdin.close()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.kill()


_IDLE: list[ForkServer] = []
_LOCK = threading.Lock()


def warm(server_env: dict[str, str], warm_models: tuple[str, ...]) -> None:
    """Start a server for :func:`run_forked` calls with these arguments ahead of them."""
    server = ForkServer(server_env, warm_models)
    with _LOCK:
        _IDLE.append(server)


def _key(env: dict[str, str], warm_models: tuple[str, ...]) -> tuple:
    return tuple(sorted(env.items())), warm_models


def run_forked(argv: list[str], server_env: dict[str, str], run_env: dict[str, str], stderr: Path,
               timeout: float, warm_models: tuple[str, ...]) -> int | None:
    """:meth:`ForkServer.run` on an idle server of this worker started with ``server_env``
    (a new one when there is none); a server that failed is dropped, one that ran is kept.
    EOFError: the server died during the run."""
    key = _key(server_env, warm_models)
    with _LOCK:
        server = next((s for s in _IDLE if s.key == key and s.alive()), None)
        if server is not None:
            _IDLE.remove(server)
    if server is None:
        server = ForkServer(server_env, warm_models)
    try:
        code = server.run(argv, run_env, stderr, timeout)
    except BaseException:
        server.kill()
        raise
    with _LOCK:
        _IDLE.append(server)
    return code


if __name__ == "__main__":
    sys.exit(serve(sys.argv[1:]))
