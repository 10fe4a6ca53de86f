"""Forked campaign runs (the default; ``--no-fork-runs`` turns them off): each sample's run
forked from a warm server per worker (:mod:`scenarios.campaign.forkrun`), real processes and a
real Dask cluster throughout.

- a task forked from a server: the same run folder as a task run as a new interpreter,
  the server reused by the next task, its stderr kept in a failure's reason;
- a forked run killed by a signal: ``RunProcessDied`` (Dask retries the task); the
  server killed during a run: the same; a timeout kills the run, the server goes on;
- the smoke campaign with ``--no-fork-runs`` (new interpreters) on 2 workers: the same CSV
  apart from the timings as the session's, forked by default; where a worker cannot fork, a
  task's run is a new interpreter.
"""
from __future__ import annotations

import csv
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import psutil

import pytest

from scenarios.campaign import forkrun
from scenarios.campaign import task as task_mod
from scenarios.campaign.execute import DASHBOARD_LINE
from scenarios.campaign.store import TIMING_COLUMNS
from support.paths import MODEL_ENV, REPO_ROOT
from support.smoke_campaign import CLI, SMOKE, run_campaign, smoke_run

NOMINAL = REPO_ROOT / "scenarios" / "suite" / "nominal.toml"


def sample_task(tmp_path: Path, sid: str, duration: float = 0.5, **kw) -> task_mod.Task:
    tmp_path.mkdir(parents=True, exist_ok=True)
    sample = tmp_path / f"{sid}.toml"
    sample.write_text(NOMINAL.read_text().replace("duration_s = 40.0", f"duration_s = {duration!r}").replace(
        'name = "nominal"', f'name = "{sid}"'))
    fields = dict(sample=sid, scenario_file=str(sample), runs_dir=str(tmp_path / "runs" / sid),
                  arms=("adaptive", "pd_only"), regulator="inprocess", fmu=None, timeout_s=300.0,
                  tmp_root=str(tmp_path / "tmp"), env=task_mod.client_env(), fork=True, warm_models=("menagerie",))
    return task_mod.Task(**{**fields, **kw})


@pytest.fixture
def servers():
    """This process's fork servers, closed afterwards (they are per worker process)."""
    yield forkrun._IDLE
    while forkrun._IDLE:
        forkrun._IDLE.pop().close()


def test_a_forked_task_writes_the_same_run_and_reuses_its_server(tmp_path, servers):
    forked = task_mod.run_sample(sample_task(tmp_path, "s0000"))
    assert [r["status"] for r in forked["rows"]] == ["complete", "complete"], forked
    assert len(servers) == 1
    server = servers[0]
    again = task_mod.run_sample(sample_task(tmp_path, "s0001"))
    assert servers == [server] and server.alive()  # the same warm server ran the second task
    plain = task_mod.run_sample(sample_task(tmp_path / "plain", "s0000", fork=False))
    for a, b in zip(forked["rows"], plain["rows"]):
        assert {k: v for k, v in a.items() if k != "wall_s"} == {k: v for k, v in b.items() if k != "wall_s"}
    assert (Path(forked["run_dir"]) / "timeseries.csv").read_bytes() == \
           (Path(plain["run_dir"]) / "timeseries.csv").read_bytes()
    assert sorted(p.name for p in Path(again["run_dir"]).iterdir()) == ["summary.json", "timeseries.csv"]
    assert list((tmp_path / "tmp").iterdir()) == []  # each run's TMPDIR removed


def test_a_failing_forked_run_reports_its_stderr(tmp_path, servers):
    t = sample_task(tmp_path, "s0000", fmu=str(tmp_path / "missing.fmu"), regulator="fmu")
    result = task_mod.run_sample(t)
    assert all(r["status"] == "failed" for r in result["rows"])
    assert "missing.fmu: no such file" in result["rows"][0]["error"]


def _kill_when_running(pick, sig=signal.SIGKILL) -> threading.Thread:
    """In the background: wait for the forked run (``pick(server)`` gives the process to
    kill) to have run for 1 s, then send it ``sig``."""
    def kill():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            for s in list(forkrun._IDLE) + list(_BUSY):
                kids = psutil.Process(s.proc.pid).children()
                if kids and time.time() - kids[0].create_time() > 1.0:
                    os.kill(pick(s.proc.pid, kids[0].pid), sig)
                    return
            time.sleep(0.05)
    thread = threading.Thread(target=kill, daemon=True)
    thread.start()
    return thread


_BUSY: list = []  # the server under test while it runs (run_forked takes it off the idle list)


@pytest.mark.parametrize("victim", ["run", "server"])
def test_a_killed_forked_run_or_server_is_a_dead_run_process(tmp_path, servers, victim):
    forkrun.warm(task_mod._server_env(sample_task(tmp_path, "w")), ("menagerie",))
    _BUSY[:] = list(servers)
    try:
        killer = _kill_when_running(lambda server, run: run if victim == "run" else server)
        with pytest.raises(task_mod.RunProcessDied) as err:
            task_mod.run_sample(sample_task(tmp_path, "s0000", duration=20.0))
        killer.join(5)
    finally:
        _BUSY.clear()
    assert ("killed by SIGKILL" if victim == "run" else "fork server died") in str(err.value)
    if victim == "server":
        assert servers == []  # dropped: the next task starts a new one


def test_a_forked_run_past_its_timeout_is_killed_and_the_server_goes_on(tmp_path, servers):
    # 40 s of walking takes >= 2.5 s of wall even at the physics' limit here (~16 simulated s per
    # wall s): a 1 s timeout always cuts it (a 20 s run under 3 s finished in time on a quiet machine)
    result = task_mod.run_sample(sample_task(tmp_path, "s0000", duration=40.0, timeout_s=1.0))
    assert all(r["status"] == "failed" and r["error"].startswith("timeout: ") for r in result["rows"])
    assert len(servers) == 1 and servers[0].alive() and psutil.Process(servers[0].proc.pid).children() == []
    again = task_mod.run_sample(sample_task(tmp_path, "s0001"))
    assert [r["status"] for r in again["rows"]] == ["complete", "complete"]


def test_smoke_campaign_with_new_interpreters_gives_the_same_rows(tmp_path, tmp_path_factory, built_fmu):
    """The session's smoke campaign (support.smoke_campaign: forked runs, the default) again with
    ``--no-fork-runs``: each run a new interpreter."""
    _, forked_out, forked = smoke_run(tmp_path_factory, built_fmu)
    assert forked.returncode == 0, forked.stderr
    got = {}
    out = tmp_path / "new"
    r = run_campaign([SMOKE, "--out", out, "--workers", 2, "--no-plots", "--no-fork-runs"], tmp_path, built_fmu)
    assert r.returncode == 0, r.stderr
    assert not (out / ".tmp").exists() and not (out / ".dask").exists() and not list((tmp_path / "systemp").iterdir())
    for mode, folder in (("new", out), ("fork", forked_out)):
        with open(folder / "campaign.csv", newline="") as fh:
            got[mode] = [{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in csv.DictReader(fh)]
    assert len(got["new"]) == 8 and all(row["status"] == "complete" for row in got["new"])
    assert got["new"] == got["fork"]


def test_the_cli_forks_runs_by_default_and_no_fork_runs_turns_it_off():
    from scenarios.campaign.cli import run_options
    from scenarios.cli import build_parser

    def options(*args):
        return run_options(build_parser().parse_args(["campaign", "smoke", "--out", "x", *args]))
    assert options().fork_runs is forkrun.AVAILABLE is True  # Linux
    assert options("--no-fork-runs").fork_runs is False
    assert options("--fork-runs").fork_runs is True


def test_a_task_that_asks_for_a_fork_where_none_is_possible_runs_a_new_interpreter(tmp_path, monkeypatch, servers):
    """A worker that cannot fork (not Linux) runs the task's run as a new interpreter: the same run."""
    monkeypatch.setattr(forkrun, "AVAILABLE", False)
    task_mod.warm_fork_server(sample_task(tmp_path, "s0000"))
    result = task_mod.run_sample(sample_task(tmp_path, "s0000"))
    assert [r["status"] for r in result["rows"]] == ["complete", "complete"], result
    assert servers == []  # no server was started, ahead of the run or for it


def test_interrupt_with_fork_runs_kills_the_runs_then_resume_finishes(tmp_path, built_fmu):
    """Ctrl-C as a terminal sends it (SIGINT to the CLI's process group): exit 130, no
    server or forked run left alive; ``--resume`` runs only what was not complete."""
    env = {**os.environ, "MENAGERIE_ROOT": MODEL_ENV["MENAGERIE_ROOT"]}  # the loader's default, absolute
    out = tmp_path / "out"
    args = [str(SMOKE), "--out", str(out), "--workers", "2", "--fmu", str(built_fmu), "--fork-runs", "--no-plots"]
    cli = subprocess.Popen(CLI + args, env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while not ((out / "campaign.csv").is_file() and len(_rows(out)) >= 2):
            assert time.monotonic() < deadline, "no sample finished"
            time.sleep(0.1)
        forked = [p for p in psutil.Process(cli.pid).children(recursive=True)
                  if "scenarios.campaign.forkrun" in _cmdline(p)]  # the servers and their runs
        os.killpg(cli.pid, signal.SIGINT)
        _, err = cli.communicate(timeout=60)
    finally:
        if cli.poll() is None:
            cli.kill()
            cli.wait()
    lines = [line for line in err.strip().splitlines() if not line.startswith(DASHBOARD_LINE)]
    assert cli.returncode == 130 and lines[0].startswith("interrupted: "), err
    assert forked
    psutil.wait_procs(forked, timeout=30)
    assert not [p for p in forked if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    before = _rows(out)
    done = {x["sample"] for x in before}
    r = subprocess.run(CLI + args + ["--resume"], env=env, cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    after = _rows(out)
    assert sorted((x["sample"], x["arm"]) for x in after) == [(f"s{i:04d}", a) for i in range(4)
                                                             for a in ("adaptive", "pd_only")]
    assert [x for x in after if x["sample"] in done] == before  # not run again
    assert all(len(list((out / "runs" / s).glob("try*"))) == 1 for s in done)
    assert not (out / ".tmp").exists() and not (out / ".dask").exists()


def _cmdline(p: psutil.Process) -> list[str]:
    """``p``'s command line; [] for a process that has just ended (a zombie run not yet
    reaped by its server, or one already gone): it is no longer running either way."""
    try:
        return p.cmdline()
    except (psutil.ZombieProcess, psutil.NoSuchProcess):
        return []


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "campaign.csv", newline="") as fh:
        return list(csv.DictReader(fh))
