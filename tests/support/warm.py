"""Run a support script (``python SCRIPT ARGS``: the FMI drivers under tests/support) in a fresh
process without a fresh interpreter's start-up.

The tests drive FMUs in processes of their own, so that a crash fails the test and not pytest:
a few hundred processes a session, each spending about 0.27 CPU s importing fmpy and numpy
before its first FMI call. :func:`run` forks each one instead from a *warm server*
(``warm_server.py``, one per pytest process, started on first use): a process that has imported
fmpy and nothing of the tests, and never loads an FMU itself. The child is a process of its
own all the same: it takes the caller's working folder, environment, arguments and stdin, and
a crash, a hang (``timeout``) or an exit code shows exactly as with :func:`subprocess.run`.

Where a fork cannot give what a new interpreter would, :func:`run` starts one: off Linux, when
the caller's environment differs from the server's in what an interpreter reads at start-up
(``PYTHON*``, ``LD_*``, the BLAS thread counts), or while another thread of this process is
using the server.
"""
from __future__ import annotations

import atexit
import json
import os
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any, Sequence

SERVER = Path(__file__).with_name("warm_server.py")
AVAILABLE = sys.platform.startswith("linux") and hasattr(os, "fork")
#: Environment variables read when an interpreter or a library starts, not later: a run that
#: changes one of them gets a new interpreter.
STARTUP_PREFIXES = ("PYTHON", "LD_", "OPENBLAS", "OMP_", "MKL_", "MALLOC_", "GLIBC_")
SERVER_START_S = 120.0

_lock = threading.Lock()
_server: "_Server | None" = None


def _startup_env(env: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in env.items() if k.startswith(STARTUP_PREFIXES)}


class _Server:
    def __init__(self) -> None:
        self.env = dict(os.environ)
        self.proc = subprocess.Popen([sys.executable, str(SERVER)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True, encoding="utf-8", errors="surrogateescape")
        ready = self._answer()
        if "ready" not in ready:
            raise RuntimeError(f"the warm server did not start: {ready}")

    def _answer(self) -> dict[str, Any]:
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            raise RuntimeError(f"the warm server ({SERVER}) died (exit {code}); its stderr is in the test's output")
        return json.loads(line)

    def ask(self, request: dict[str, Any]) -> dict[str, Any]:
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        return self._answer()

    def kill(self) -> None:
        """End the server now (its child, if any, dies with it)."""
        self.proc.kill()
        self.proc.wait()
        for pipe in (self.proc.stdin, self.proc.stdout):
            try:
                pipe.close()
            except OSError:
                pass

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc.stdout.close()


def _close() -> None:
    global _server
    if _server is not None:
        _server.close()
        _server = None


atexit.register(_close)


def run(script: Path | str, args: Sequence[Any] = (), *, input: str | None = None, timeout: float | None = None,
        env: dict[str, str] | None = None, cwd: Path | str | None = None) -> subprocess.CompletedProcess:
    """:func:`subprocess.run` of ``[sys.executable, script, *args]`` with ``capture_output=True,
    text=True``: the same result, and :class:`subprocess.TimeoutExpired` after ``timeout``."""
    global _server
    cmd = [sys.executable, str(script), *map(str, args)]
    env = dict(os.environ if env is None else env)
    cwd = os.path.abspath(cwd if cwd is not None else os.getcwd())
    if AVAILABLE and _lock.acquire(blocking=False):
        try:
            if _server is not None and _server.proc.poll() is not None:  # died between runs: close its pipes
                _server.kill()
                _server = None
            if _server is None:
                _server = _Server()
            if _startup_env(env) == _startup_env(_server.env):
                try:
                    answer = _server.ask({"script": os.path.abspath(script), "args": cmd[2:], "cwd": cwd, "env": env,
                                          "input": input, "timeout": timeout})
                except BaseException:  # dead, or its answer left unread (e.g. Ctrl-C): the next run starts another
                    _server.kill()
                    _server = None
                    raise
                if answer["timed_out"]:
                    raise subprocess.TimeoutExpired(cmd, timeout, output=answer["stdout"], stderr=answer["stderr"])
                return subprocess.CompletedProcess(cmd, answer["exit"], answer["stdout"], answer["stderr"])
        finally:
            _lock.release()
    return subprocess.run(cmd, input=input, capture_output=True, text=True, timeout=timeout, env=env, cwd=cwd)
