"""The results folder of ``run --out DIR``: one run at a time, nothing half-written, nothing lost.

- ``DIR/.lock``: a run holds an exclusive ``flock`` on it while it uses DIR; the OS
  releases it when the process dies (a killed run leaves no stale lock). A second run
  on DIR is refused.
- ``DIR/.run-<pid>/``: the run's scratch folder: FMU copies (``fmu/``) and each
  scenario's folder while it is being written (``stage/<name>/``). Removed when the run
  ends; a killed run's scratch folder is removed by the next run.
- ``DIR/<name>/``: a scenario's results, renamed into place only once complete. A
  folder it replaces is first renamed to ``DIR/.<name>.replaced-<pid>`` and deleted
  after; a run that dies between the two renames has its old folder put back by the
  next run.

:func:`plan` decides, before anything is simulated, which scenarios run, and lists
every problem: a scenario folder taken by a file or holding files this package does
not write, results that would be replaced without ``overwrite``, complete results of a
different set-up under ``resume``.
"""
from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import shutil
import signal
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

from fmu_src.core.avr_errors import AvrError
from scenarios.results import output
from scenarios.lang.scenario import Scenario

log = logging.getLogger(__name__)

MODES = ("new", "overwrite", "resume")
LOCK_NAME = ".lock"
SCRATCH_PREFIX = ".run-"
REPLACED_TAG = ".replaced-"
#: The summary keys that fix what a scenario simulates (resume keeps results only if equal).
SETUP_KEYS = ("model", "regulator", "duration_s", "comm_step_s", "seed", "perturbation_t_s", "arm_names",
              "commands", "perturbation")


# --------------------------------------------------------------------------- planning
@dataclass
class Plan:
    """``run``: the scenarios to simulate; ``replace``: names whose folder they replace;
    ``kept``: summaries of complete results kept as they are (resume); ``problems``."""

    run: list[Scenario] = field(default_factory=list)
    replace: set[str] = field(default_factory=set)
    kept: list[dict[str, Any]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def out_problems(root: Path) -> list[str]:
    """Why ``root`` cannot be a results folder, without creating anything."""
    if root.is_symlink() and not root.exists():
        return [f"--out {root}: a dangling symbolic link"]
    if root.exists():
        if not root.is_dir():
            return [f"--out {root}: exists and is not a folder"]
        if not os.access(root, os.W_OK | os.X_OK):
            return [f"--out {root}: the folder is not writable"]
        return []
    parent = root.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        return [f"--out {root}: {parent} is not a folder"]
    if not os.access(parent, os.W_OK | os.X_OK):
        return [f"--out {root}: cannot create it, {parent} is not writable"]
    return []


def read_summary(path: Path) -> tuple[dict[str, Any] | None, list[str]]:
    """A summary.json and its problems (:func:`scenarios.results.output.summary_problems`)."""
    from scenarios.errors import ScenarioError
    from scenarios.lang.tomlfile import depth_problem, read_regular_file

    try:
        data = json.loads(read_regular_file(path, "summary.json").decode("utf-8"))
    except ScenarioError as exc:  # not a regular file, or too large
        return None, list(exc.problems)
    except (OSError, UnicodeDecodeError) as exc:
        return None, [f"cannot read: {getattr(exc, 'strerror', None) or exc}"]
    except json.JSONDecodeError as exc:
        return None, [f"not valid JSON: {exc}"]
    except ValueError as exc:  # an integer of more than 4300 digits
        return None, [f"a value Python does not read: {exc}"]
    except RecursionError:
        return None, ["not readable: nested too deeply"]
    too_deep = depth_problem(data)
    if too_deep:
        return None, [too_deep]
    problems = output.summary_problems(data)
    return (None if problems else data), problems


def setup_of(summary: dict[str, Any]) -> dict[str, Any]:
    """What a summary's scenario simulated: :data:`SETUP_KEYS` and each arm's overrides."""
    arms = summary.get("arms") or {}
    return {**{k: summary.get(k) for k in SETUP_KEYS}, "commands": output.summary_commands(summary),
            "overrides": {n: (a or {}).get("overrides") for n, a in arms.items()}}


def scenario_setup(scenario: Scenario, regulator: str) -> dict[str, Any]:
    """:func:`setup_of` the summary this run would write for ``scenario`` (JSON-normalised)."""
    header = output.scenario_header(scenario, regulator)
    arms = {a.name: {"overrides": dict(a.overrides)} for a in scenario.arms}
    return json.loads(json.dumps(setup_of({**header, "arms": arms})))


def _existing(root: Path, name: str) -> tuple[str, Any]:
    """What ``root/name`` holds: ("absent"|"empty", None), ("blocked", why),
    ("results", (summary or None, problems))."""
    path = root / name
    if not path.exists() and not path.is_symlink():
        return "absent", None
    if path.is_symlink() or not path.is_dir():
        return "blocked", f"{path} is a file, not a scenario folder; move it away or choose another --out"
    try:
        entries = sorted(os.listdir(path))
    except OSError as exc:
        return "blocked", f"{path}: cannot list it ({exc.strerror})"
    foreign = [e for e in entries if not output.is_result_file(e) or not (path / e).is_file()]
    if foreign:
        return "blocked", (f"{path} holds files this tool does not write ({', '.join(foreign[:5])}); "
                           "move them away or choose another --out")
    if not entries:
        return "empty", None
    return "results", read_summary(path / "summary.json")


def plan(root: Path, scenarios: Sequence[Scenario], regulator: str, mode: str) -> Plan:
    """What a run of ``scenarios`` into ``root`` does in ``mode`` (one of :data:`MODES`)."""
    if mode not in MODES:
        raise ValueError(f"mode = {mode!r}: must be one of {', '.join(MODES)}")
    p = Plan()
    existing: list[str] = []
    for s in scenarios:
        state, info = _existing(root, s.name)
        if state == "blocked":
            p.problems.append(info)
            continue
        if state == "results":
            summary, _problems = info
            if mode == "new":
                existing.append(s.name)
                continue
            if mode == "resume" and summary is not None and summary["status"] == "complete":
                before, now = setup_of(summary), scenario_setup(s, regulator)
                if before == now:
                    p.kept.append(summary)
                    continue
                diff = ", ".join(k for k in now if before.get(k) != now[k])
                p.problems.append(f"{root / s.name} holds complete results of another set-up (differs in {diff}); "
                                  "--overwrite replaces them, or choose another --out")
                continue
        if state != "absent":
            p.replace.add(s.name)
        p.run.append(s)
    if existing:
        shown = ", ".join(existing[:6]) + (f" and {len(existing) - 6} more" if len(existing) > 6 else "")
        p.problems.append(f"--out {root} already holds results of {len(existing)} scenario(s) of this run "
                          f"({shown}); --overwrite replaces them, --resume keeps the complete ones and runs the "
                          "rest, or choose another --out")
    return p


# --------------------------------------------------------------------------- the folder in use
class ResultsDir:
    """``with ResultsDir(root) as rd:``: create ``root``, take its lock, repair what a
    killed run left, and give a scratch folder; everything is released on exit."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.scratch = self.root / f"{SCRATCH_PREFIX}{os.getpid()}"
        self._lock_fd: int | None = None

    @property
    def fmu_dir(self) -> Path:
        """Where FMUs are extracted during the run (removed with the scratch folder)."""
        return self.scratch / "fmu"

    def __enter__(self) -> "ResultsDir":
        try:
            self.root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise AvrError(f"--out {self.root}: cannot create the folder: {exc.strerror or exc}") from None
        self._lock_fd = _lock(self.root / LOCK_NAME)
        try:
            self._repair()
            self.fmu_dir.mkdir(parents=True)
            (self.scratch / "stage").mkdir()
        except OSError as exc:
            self.__exit__(None, None, None)
            raise AvrError(f"--out {self.root}: cannot write into it: {exc.strerror or exc}") from None
        return self

    def __exit__(self, *exc: Any) -> None:
        shutil.rmtree(self.scratch, ignore_errors=True)
        if self._lock_fd is not None:
            _unlock(self.root / LOCK_NAME, self._lock_fd)
            self._lock_fd = None

    def _repair(self) -> None:
        """Remove dead runs' scratch folders; put back a folder a dead run had renamed aside."""
        for entry in sorted(self.root.iterdir()):
            name = entry.name
            if name.startswith(SCRATCH_PREFIX) and entry.is_dir():
                log.info("removing %s (left by a run that was killed)", entry)
                shutil.rmtree(entry, ignore_errors=True)
            elif name.startswith(".") and REPLACED_TAG in name and entry.is_dir():
                original = self.root / name[1:name.rindex(REPLACED_TAG)]
                if original.exists() or original.is_symlink():
                    shutil.rmtree(entry, ignore_errors=True)
                else:
                    log.warning("restoring %s (a killed run had moved it aside)", original)
                    os.rename(entry, original)

    def stage(self, name: str) -> Path:
        """A fresh staging folder for ``name``'s results, to fill (in any process) and then
        :meth:`commit` or :meth:`discard`."""
        staged = self.scratch / "stage" / name
        staged.mkdir()
        return staged

    def discard(self, name: str) -> None:
        shutil.rmtree(self.scratch / "stage" / name, ignore_errors=True)

    def commit(self, name: str, *, replace: bool) -> None:
        """Rename the staged folder of ``name`` to ``root/name`` (one step to a user: SIGINT
        and SIGTERM wait). An existing ``root/name`` is replaced only when ``replace`` is
        true; otherwise the staged folder is discarded and AvrError raised."""
        staged = self.scratch / "stage" / name
        final = self.root / name
        aside = self.root / f".{name}{REPLACED_TAG}{os.getpid()}"
        with _signals_deferred():
            if final.exists() or final.is_symlink():
                if not replace:
                    self.discard(name)
                    raise AvrError(f"{final} appeared while the run was writing; not replaced")
                os.rename(final, aside)
            os.rename(staged, final)
        shutil.rmtree(aside, ignore_errors=True)


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """SIGINT/SIGTERM wait until the block is done (the renames are one step to a user)."""
    sigs = {signal.SIGINT, signal.SIGTERM}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _lock(path: Path) -> int:
    """An exclusive flock on ``path`` (created if needed); AvrError naming the holder if
    another process has it. Retries when ``path`` was replaced between open and lock."""
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise AvrError(f"--out {path.parent}: cannot create its lock file: {exc.strerror or exc}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            if exc.errno not in (errno.EAGAIN, errno.EACCES):
                raise AvrError(f"--out {path.parent}: cannot lock {path}: {exc.strerror}") from None
            raise AvrError(f"--out {path.parent}: another run (pid {holder}) is using this folder; wait for it to "
                           "end or choose another --out") from None
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            return fd
        os.close(fd)  # the holder removed it as we opened it: lock the new one


def _unlock(path: Path, fd: int) -> None:
    """Remove the lock file while holding it (a waiter re-checks the inode), then release."""
    try:
        os.unlink(path)
    except OSError:
        pass
    os.close(fd)
