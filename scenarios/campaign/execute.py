"""Running a campaign on Dask: the cluster, the tasks, the progress bar, the rows.

A ``LocalCluster`` (worker processes, one thread each) or an existing scheduler by
address runs one task per sample (:func:`scenarios.campaign.task.run_sample`). Each
finished task's rows go to ``campaign.csv`` at once (nothing is held only in memory);
Ctrl-C or SIGTERM loses at most the tasks in flight; a task whose worker dies is run
again up to ``retries`` times (``distributed.scheduler.allowed-failures`` of the local
cluster; an existing scheduler keeps its own setting) and a task whose run process is
killed likewise (Dask's ``retries=``); after that it is recorded as failed with the
reason.

The local cluster binds everything it opens (scheduler, nannies, workers, dashboard) to
127.0.0.1 (:data:`LOCAL_HOST`): nothing of a local campaign is reachable from the network;
``dashboard_address`` (``--dashboard-address``) exposes the dashboard on purpose.  The
dashboard's URL is printed when the cluster is up.

An existing scheduler is given by address (``--scheduler tcp://HOST:PORT`` or
``tls://HOST:PORT``) or by Dask's scheduler file (``--scheduler-file FILE``, as written by
``dask scheduler --scheduler-file``, dask-jobqueue or dask-mpi).  The connection uses Dask's own
configuration: TLS credentials from ``distributed.comm.tls.*`` (e.g.
``DASK_DISTRIBUTED__COMM__TLS__CA_FILE``, ``..._CLIENT__CERT``, ``..._CLIENT__KEY``), the connect
timeout from ``distributed.comm.timeouts.connect``.  A scheduler that cannot be reached, is not
a Dask scheduler or has no worker is :class:`ConnectionFailed` (one line).  The workers must see
the campaign folder, the repository and the FMU at the same paths as the client (a shared file
system) and run the same environment.
"""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from scenarios.campaign import task as task_mod
from scenarios.campaign.spec import Campaign
from scenarios.campaign.store import CampaignDir
from scenarios.run.options import DEFAULT_CONTROLLER, DEFAULT_REGULATOR

log = logging.getLogger(__name__)

WORKER_WAIT_S = 60.0  # an existing scheduler must have a worker within this time
#: Where the local cluster listens: this machine only.
LOCAL_HOST = "127.0.0.1"
#: The local cluster's dashboard: this machine, a free port (``--dashboard-address`` exposes it).
DEFAULT_DASHBOARD = f"{LOCAL_HOST}:0"
#: How the local cluster's dashboard address starts its line on stderr.
DASHBOARD_LINE = "Dask dashboard: "


class ConnectionFailed(Exception):
    """The scheduler given cannot be used (unreachable, not a Dask scheduler, no worker); one line
    naming the option and the address."""


class CampaignInterrupted(Exception):
    """Ctrl-C / SIGTERM: the rows written so far stay; ``--resume`` continues."""

    def __init__(self, done: int, remaining: int):
        super().__init__(f"{done} task(s) done, {remaining} not")
        self.done, self.remaining = done, remaining


@dataclass
class RunOptions:
    workers: int | None = None  # LocalCluster size (default: CPU count)
    scheduler: str | None = None  # or an existing scheduler's address
    scheduler_file: str | None = None  # or Dask's scheduler file of one
    dashboard_address: str = DEFAULT_DASHBOARD  # the local cluster's dashboard
    regulator: str = DEFAULT_REGULATOR
    controller: str = DEFAULT_CONTROLLER
    fmu: str | None = None
    timeout_s: float | None = None  # per task; default from the campaign
    retries: int | None = None  # default from the campaign
    progress: bool | None = None  # tqdm's disable=None: on a terminal only
    fork_runs: bool = True  # each run forked from the worker's warm server (scenarios.campaign.forkrun), where it can fork


@dataclass
class Tally:
    total: int
    done: int = 0
    failed: int = 0  # tasks with at least one failed arm

    @property
    def remaining(self) -> int:
        return self.total - self.done


def default_timeout_s(campaign: Campaign) -> float:
    """Two minutes of start-up plus 10 wall seconds per simulated second of every arm."""
    if campaign.task_timeout_s is not None:
        return campaign.task_timeout_s
    return 120.0 + 10.0 * float(campaign.base_doc["duration_s"]) * len(campaign.arm_names())


@contextlib.contextmanager
def _scratch_env(tmp_dir: Path) -> Iterator[None]:
    """TMPDIR (and Python's tempfile) under the campaign folder while the cluster lives."""
    tmp_dir.mkdir(parents=True, exist_ok=True)
    old = os.environ.get("TMPDIR")
    os.environ["TMPDIR"] = str(tmp_dir)
    tempfile.tempdir = None
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("TMPDIR", None)
        else:
            os.environ["TMPDIR"] = old
        tempfile.tempdir = None


def _verbose() -> bool:
    """Whether the campaign logs at INFO (``-v``): then Dask's own logs stay as they are."""
    return log.isEnabledFor(logging.INFO)


class SyncCancelBugFilter(logging.Filter):
    """Drops one known Dask error, tornado's log of it: a Ctrl-C that lands while the client waits
    in ``distributed.utils.sync`` before sync's coroutine has started makes sync's ``cancel``
    callback raise NameError (its ``future`` is not assigned yet: there was nothing to cancel).
    The campaign reports the interrupt in one line itself; every other record passes."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if not isinstance(exc, NameError) or exc.__traceback__ is None:
            return True
        tb = exc.__traceback__
        while tb.tb_next is not None:
            tb = tb.tb_next
        code = tb.tb_frame.f_code
        return not (code.co_name == "cancel" and Path(code.co_filename).parts[-2:] == ("distributed", "utils.py"))


def _filter_sync_cancel_bug() -> None:
    """Install :class:`SyncCancelBugFilter` on tornado's callback logger, once per process."""
    tlog = logging.getLogger("tornado.application")
    if not any(isinstance(f, SyncCancelBugFilter) for f in tlog.filters):
        tlog.addFilter(SyncCancelBugFilter())


@contextlib.contextmanager
def _quiet_dask() -> Iterator[None]:
    """Dask logs every connection at INFO: keep its errors only, unless we are verbose (-v); and
    never the traceback of a known Dask error on Ctrl-C (:class:`SyncCancelBugFilter`)."""
    _filter_sync_cancel_bug()
    dlog = logging.getLogger("distributed")
    old = dlog.level
    if not _verbose():
        dlog.setLevel(logging.ERROR)
    try:
        yield
    finally:
        dlog.setLevel(old)


def _worker_log_level() -> int:
    """The local cluster's workers log only what kills them, unless we are verbose (-v): every
    task failure and worker death already reaches the campaign's rows with its reason, and a
    worker's heartbeat that outlives the scheduler on Ctrl-C is not an error of the run."""
    return logging.ERROR if _verbose() else logging.CRITICAL


def scheduler_file_problem(path: str | Path) -> str | None:
    """What is wrong with ``--scheduler-file path`` (Dask's JSON file with the scheduler's
    ``address``), or None."""
    import json

    flag = f"--scheduler-file {path}"
    if Path(path).is_dir():
        return f"{flag}: is a folder, not a Dask scheduler file"
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        return f"{flag}: cannot read: {exc.strerror or exc}"
    except ValueError as exc:
        return f"{flag}: not a Dask scheduler file (JSON with the scheduler's address): {exc}"
    if not isinstance(doc, dict) or not isinstance(doc.get("address"), str):
        return f"{flag}: not a Dask scheduler file: no \"address\""
    return None


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0]}" if text else type(exc).__name__


def _where(opts: RunOptions) -> str:
    return f"--scheduler-file {opts.scheduler_file}" if opts.scheduler_file else f"--scheduler {opts.scheduler}"


async def _identity(address: str, timeout_s: float) -> Any:
    """What the server at ``address`` says it is (Dask's ``identity`` call), with Dask's security
    configuration (``distributed.comm.tls.*``)."""
    import asyncio

    from distributed.comm import connect
    from distributed.security import Security

    comm = await connect(address, timeout=timeout_s, **Security().get_connection_args("client"))
    try:
        await comm.write({"op": "identity", "reply": True})
        return await asyncio.wait_for(comm.read(), timeout_s)
    finally:
        comm.abort()


def check_scheduler(opts: RunOptions) -> None:
    """ConnectionFailed (one line) unless the scheduler of ``opts`` (``scheduler`` or
    ``scheduler_file``) answers as a Dask scheduler within Dask's connect timeout
    (``distributed.comm.timeouts.connect``).  A ``distributed.Client`` waits forever on a server
    that accepts the connection but never answers as Dask does (e.g. an HTTP server)."""
    import asyncio
    import json

    import dask
    from dask.utils import parse_timedelta

    timeout_s = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), "s")
    address = opts.scheduler
    if opts.scheduler_file:
        problem = scheduler_file_problem(opts.scheduler_file)
        if problem:
            raise ConnectionFailed(problem)
        address = json.loads(Path(opts.scheduler_file).read_text(encoding="utf-8"))["address"]
    try:
        reply = asyncio.run(asyncio.wait_for(_identity(address, timeout_s), 2 * timeout_s))
    except asyncio.TimeoutError:
        raise ConnectionFailed(f"{_where(opts)}: {address} gave no Dask answer within {2 * timeout_s:g} s "
                               "(not a Dask scheduler?)") from None
    except Exception as exc:  # noqa: BLE001 - unreachable, refused, not Dask, TLS: all one line
        raise ConnectionFailed(f"{_where(opts)}: cannot connect to a Dask scheduler at {address}: "
                               f"{_one_line(exc)}") from None
    kind = reply.get("type") if isinstance(reply, dict) else type(reply).__name__
    if kind != "Scheduler":
        raise ConnectionFailed(f"{_where(opts)}: {address} is not a Dask scheduler (it answers as {kind})")


def _connect(opts: RunOptions) -> Any:
    """A Client on the existing scheduler with a worker; ConnectionFailed (one line) otherwise."""
    from distributed import Client

    check_scheduler(opts)
    where = _where(opts)
    try:  # security and the connect timeout: Dask's configuration (distributed.comm.*)
        client = Client(opts.scheduler, scheduler_file=opts.scheduler_file)
    except Exception as exc:  # noqa: BLE001
        raise ConnectionFailed(f"{where}: cannot connect to a Dask scheduler: {_one_line(exc)}") from None
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except Exception as exc:  # noqa: BLE001
        client.close(timeout=10)
        raise ConnectionFailed(f"{where}: no worker joined the scheduler within {WORKER_WAIT_S:g} s "
                               f"({_one_line(exc)})") from None
    return client


@contextlib.contextmanager
def open_client(opts: RunOptions, cdir: CampaignDir, retries: int) -> Iterator[Any]:
    """A ``distributed.Client`` on a new LocalCluster or on the scheduler of ``opts``; closed on exit."""
    import dask
    from distributed import Client, LocalCluster

    settings = {"temporary-directory": str(cdir.dask_dir.resolve()), "distributed.scheduler.allowed-failures": retries,
                "distributed.scheduler.worker-saturation": 1.0}  # queued tasks: see submit_and_collect
    with dask.config.set(settings), _scratch_env(cdir.tmp_dir.resolve()), _quiet_dask():
        if opts.scheduler or opts.scheduler_file:
            client = _connect(opts)
            try:
                log.info("scheduler %s: %d worker(s); its own allowed-failures applies to worker deaths",
                         client.scheduler.address, len(client.scheduler_info()["workers"]))
                yield client
            finally:
                client.close(timeout=10)
            return
        n = opts.workers or os.cpu_count() or 1
        # the worker processes inherit an ignored SIGINT: a Ctrl-C on the terminal reaches the
        # whole process group, but only this process acts on it (and closes the cluster)
        with _signal(signal.SIGINT, signal.SIG_IGN):
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host=LOCAL_HOST,
                                   dashboard_address=opts.dashboard_address,
                                   local_directory=str(cdir.dask_dir.resolve()), silence_logs=_worker_log_level())
        try:
            client = Client(cluster)
            print(f"{DASHBOARD_LINE}{client.dashboard_link}", file=sys.stderr)
            try:
                yield client
            finally:
                client.close(timeout=10)
        finally:
            cluster.close(timeout=20)


def _failed_rows(t: task_mod.Task, why: str) -> dict[str, Any]:
    rows = [{"arm": a, "status": task_mod.FAILED, "error": why} for a in t.arms]
    return {"sample": t.sample, "rows": rows, "task_wall_s": None, "run_dir": None}


def _failure_reason(exc: BaseException, retries: int) -> str:
    """One line: the exception's type and first sentence, and the retries spent."""
    first = str(exc).strip().splitlines()[0].split(". ")[0] if str(exc).strip() else ""
    return f"{type(exc).__name__} after {retries} retr{'y' if retries == 1 else 'ies'}: {first}"


def _record(cdir: CampaignDir, values: dict[str, Any], result: dict[str, Any]) -> bool:
    """Append one task's rows; True when every arm is complete."""
    run_dir = result.get("run_dir")
    rel = os.path.relpath(run_dir, cdir.root) if run_dir else None
    rows = [{"sample": result["sample"], **values, **r, "task_wall_s": result.get("task_wall_s"), "run_dir": rel}
            for r in result["rows"]]
    cdir.append(rows)
    return all(r["status"] == task_mod.COMPLETE for r in result["rows"])


@contextlib.contextmanager
def _signal(sig: int, handler) -> Iterator[None]:
    """``handler`` for ``sig`` inside the block (main thread only: elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(sig, handler)
    try:
        yield
    finally:
        signal.signal(sig, old)


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def _collect(fut, t: task_mod.Task, cdir: CampaignDir, values: dict[str, Any], retries: int) -> bool:
    """Write the rows of one finished task; True when every arm is complete."""
    try:
        result = fut.result()
    except Exception as exc:  # the worker died `retries` times, or the run process was killed
        result = _failed_rows(t, _failure_reason(exc, retries))
    fut.release()  # a result held by a worker that dies later is not computed again
    ok = _record(cdir, values, result)
    if not ok:
        log.warning("sample %s: %s", t.sample, next(r["error"] for r in result["rows"] if r.get("error")))
    return ok


def submit_and_collect(client, tasks: list[task_mod.Task], values: dict[str, dict], cdir: CampaignDir,
                       retries: int, progress: bool | None, desc: str) -> Tally:
    """Submit every task, write rows as they finish; raise CampaignInterrupted on Ctrl-C."""
    from distributed import as_completed
    from tqdm import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    tally = Tally(total=len(tasks))
    by_key = {f"campaign-{cdir.fingerprint[:8]}-{t.sample}": t for t in tasks}
    # one graph (map, not a submit per task): the scheduler queues the tasks and sends a worker
    # only as many as it has threads, so a worker that dies takes only its running task along
    pending = as_completed(client.map(task_mod.run_sample, list(by_key.values()), key=list(by_key),
                                      retries=retries, pure=False))
    disable = None if progress is None else not progress  # None: on a terminal only
    try:
        with tqdm(total=len(tasks), unit="sample", desc=desc, disable=disable, file=sys.stderr,
                  dynamic_ncols=True) as bar, logging_redirect_tqdm():
            bar.set_postfix(done=0, failed=0, remaining=tally.total)
            for fut in pending:
                t = by_key[fut.key]
                tally.failed += not _collect(fut, t, cdir, values[t.sample], retries)
                tally.done += 1
                bar.set_postfix(done=tally.done, failed=tally.failed, remaining=tally.remaining, refresh=False)
                bar.update(1)
    except KeyboardInterrupt:
        raise CampaignInterrupted(tally.done, tally.remaining) from None
    return tally


def make_tasks(campaign: Campaign, cdir: CampaignDir, todo: list[str], opts: RunOptions,
               fmu: str | None) -> list[task_mod.Task]:
    timeout = opts.timeout_s if opts.timeout_s is not None else default_timeout_s(campaign)
    return [task_mod.Task(sample=sid, scenario_file=str(cdir.sample_file(sid).resolve()),
                          runs_dir=str((cdir.runs_dir / sid).resolve()), arms=tuple(campaign.arm_names()),
                          regulator=opts.regulator, controller=opts.controller, fmu=fmu, timeout_s=timeout,
                          tmp_root=str(cdir.tmp_dir.resolve()), env=task_mod.client_env(), fork=opts.fork_runs,
                          warm_models=(str(campaign.base_doc.get("model") or "menagerie"),))
            for sid in todo]


def run(campaign: Campaign, cdir: CampaignDir, values: dict[str, dict], opts: RunOptions,
        fmu: str | None) -> Tally:
    """Run the samples of ``cdir`` that are not complete yet."""
    done = cdir.complete_samples()
    todo = [sid for sid in cdir.texts if sid not in done]
    log.info("%d of %d samples complete, %d to run", len(done), len(cdir.texts), len(todo))
    if not todo:
        return Tally(total=0)
    retries = opts.retries if opts.retries is not None else campaign.retries
    tasks = make_tasks(campaign, cdir, todo, opts, fmu)
    t0 = time.perf_counter()
    with _signal(signal.SIGTERM, _raise_interrupt), _signal(signal.SIGINT, signal.getsignal(signal.SIGINT)):
        with open_client(opts, cdir, retries) as client:
            if opts.fork_runs:  # every worker's fork server imports while the others do
                client.run(task_mod.warm_fork_server, tasks[0])
            try:
                tally = submit_and_collect(client, tasks, values, cdir, retries, opts.progress,
                                           f"campaign {campaign.name}")
            except CampaignInterrupted:
                # closing the cluster takes a moment: a second Ctrl-C must not cut it short
                if threading.current_thread() is threading.main_thread():
                    signal.signal(signal.SIGINT, signal.SIG_IGN)
                raise
    log.info("campaign %s: %d task(s) in %.1f s", campaign.name, len(tasks), time.perf_counter() - t0)
    return tally
