"""Campaigns on real Dask clusters, through the real CLI (no mocks; a few seconds each).

- the smoke campaign on a LocalCluster: rows = samples x arms, all complete; twice
  (2 workers, then 1) gives the same CSV apart from the timing columns; nothing lands
  in the system temp folder and the scratch folders are gone;
- a scheduler and a worker started as separate processes (``dask scheduler``,
  ``dask worker`` from this interpreter's folder), the campaign submitted by address;
- a worker killed (SIGKILL) in the middle of a sample: the campaign completes, every
  row exactly once; with ``--retries 0`` that sample is recorded as failed with the reason;
- SIGINT to the CLI, then ``--resume``: no sample run twice, none lost;
- a per-task timeout gives failed rows saying so.
"""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from scenarios.campaign.execute import DASHBOARD_LINE
from scenarios.campaign.store import TIMING_COLUMNS
from support.smoke_campaign import CLI, SMOKE, WAIT_S, campaign_env, run_campaign
from support.smoke_campaign import smoke_run as shared_smoke_run

BIN = Path(sys.executable).parent


def campaign_file(tmp_path: Path, samples: int) -> Path:
    """The smoke campaign with ``samples`` random draws (x 2 speeds)."""
    text = SMOKE.read_text().replace("samples = 2\n", f"samples = {samples}\n")
    path = tmp_path / f"smoke{samples}.toml"
    path.write_text(text)
    return path


def rows(out: Path) -> list[dict[str, str]]:
    with open(out / "campaign.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def without_timing(rs):
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rs]


def tries(out: Path) -> dict[str, int]:
    """How many executions each sample had (runs/<id>/try<k>)."""
    return {d.name: len(list(d.glob("try*"))) for d in sorted((out / "runs").iterdir())}


def assert_clean(tmp_path: Path, out: Path) -> None:
    assert list((tmp_path / "systemp").iterdir()) == []
    assert not (out / ".tmp").exists() and not (out / ".dask").exists()


def wait_for(predicate, what: str, timeout: float = WAIT_S):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


def running_runs(pid: int) -> list[psutil.Process]:
    """The `scenarios run` processes below process ``pid``."""
    out = []
    for p in psutil.Process(pid).children(recursive=True):
        try:
            cmd = p.cmdline()
        except psutil.Error:
            continue
        if "scenarios" in cmd and "run" in cmd:
            out.append(p)
    return out


def gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(15)


# --------------------------------------------------------------------------- local cluster
@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory, built_fmu):
    return shared_smoke_run(tmp_path_factory, built_fmu)  # once per session: test_campaign_fork reads it too


def test_smoke_campaign_local_cluster(smoke_run):
    tmp, out, r = smoke_run
    assert r.returncode == 0, r.stderr
    rs = rows(out)
    assert [(x["sample"], x["arm"]) for x in rs] == [(f"s{i:04d}", a) for i in range(4) for a in ("adaptive", "pd_only")]
    assert all(x["status"] == "complete" and x["fell"] == "false" and float(x["sim_s"]) == 2.0 for x in rs)
    assert {x["vx_des"] for x in rs} == {"0.3", "0.5"}
    assert tries(out) == {f"s{i:04d}": 1 for i in range(4)}
    summary = json.loads((out / rs[0]["run_dir"] / "summary.json").read_text())
    assert summary["arms"]["adaptive"]["steady_state_error_vx"] == float(rs[0]["steady_state_error_vx"])
    for f in ("campaign.md", "fall_rate.png", "errors.png", "factors.png", "paired.png", "speeds.png", "samples/s0003.toml"):
        assert (out / f).is_file(), f
    assert "| adaptive | 4 | 0 | 0/4 = 0 %" in (out / "campaign.md").read_text()
    assert_clean(tmp, out)
    # `scenarios report` over the folder holding the campaign lists it with its table
    r = subprocess.run([sys.executable, "-m", "scenarios", "report", str(tmp)], capture_output=True, text=True,
                       timeout=120, env=campaign_env(tmp))
    assert r.returncode == 0, r.stderr
    assert "## Campaigns\n\n### [out](out/campaign.md)" in (tmp / "report.md").read_text()


def test_same_seed_same_csv_apart_from_timings(smoke_run, tmp_path, built_fmu):
    _, first, _ = smoke_run
    out = tmp_path / "again"
    r = run_campaign([SMOKE, "--out", out, "--workers", 1, "--no-plots"], tmp_path, built_fmu)
    assert r.returncode == 0, r.stderr
    assert without_timing(rows(out)) == without_timing(rows(first))
    # --no-plots: the report's text, no plot (`scenarios report` writes them later)
    assert (out / "campaign.md").is_file() and not list(out.glob("*.png")) and ".png" not in (out / "campaign.md").read_text()
    assert rows(out) != rows(first)  # the timings differ: two real runs, not a copy
    assert_clean(tmp_path, out)


# --------------------------------------------------------------------------- existing scheduler
def test_campaign_on_a_scheduler_and_worker_started_as_processes(smoke_run, tmp_path, built_fmu):
    _, first, _ = smoke_run
    env = campaign_env(tmp_path)
    sched_file = tmp_path / "scheduler.json"
    procs = []
    try:
        procs.append(subprocess.Popen([BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                                       "--no-dashboard", "--scheduler-file", sched_file], env=env, cwd=tmp_path,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        address = wait_for(lambda: sched_file.is_file() and json.loads(sched_file.read_text() or "{}").get("address"),
                           "the scheduler file", 60)
        procs.append(subprocess.Popen([BIN / "dask", "worker", address, "--nthreads", "1", "--nworkers", "1",
                                       "--no-dashboard", "--local-directory", tmp_path / "worker"], env=env,
                                      cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        out = tmp_path / "out"
        r = run_campaign([SMOKE, "--out", out, "--scheduler", address, "--no-plots"], tmp_path, built_fmu)
        assert r.returncode == 0, r.stderr
        assert without_timing(rows(out)) == without_timing(rows(first))
    finally:
        for p in reversed(procs):
            stop(p)
    assert not (tmp_path / "out" / ".tmp").exists()


# --------------------------------------------------------------------------- faults
def _sample_of(run: psutil.Process) -> str:
    cmd = run.cmdline()
    if "run" not in cmd:  # it has just ended: a terminated process's command line is empty
        raise psutil.NoSuchProcess(run.pid)
    return Path(cmd[cmd.index("run") + 1]).stem


def _kill_a_busy_worker(cli: subprocess.Popen, out: Path) -> tuple[str, int]:
    """SIGKILL a worker process in the middle of a sample; (sample, pid of its run process).

    The worker picked has finished a sample before (it holds that result: it must not be
    computed again) and its current run started less than 1 s ago (a smoke sample takes
    ~3 s): the kill lands in the middle of the run, not as it ends.
    """
    worker_of: dict[str, int] = {}  # sample -> the worker process that ran it

    def victim():
        for run in running_runs(cli.pid):
            try:
                worker_of.setdefault(_sample_of(run), run.parent().pid)
                young = time.time() - run.create_time() < 1.0
            except psutil.Error:
                continue
            finished = {r["sample"] for r in rows(out)} if (out / "campaign.csv").is_file() else set()
            if young and any(worker_of.get(s) == run.parent().pid for s in finished):
                return run
        return None
    run = wait_for(victim, "a worker with a finished sample starting another one")
    sample = _sample_of(run)
    os.kill(run.parent().pid, signal.SIGKILL)
    return sample, run.pid


#: The killed-worker campaign's random draws (x 2 speeds: twice as many samples).
DRAWS = 4


@pytest.mark.parametrize("retries", [2, 0])
def test_killed_worker_mid_campaign(retries, tmp_path, built_fmu):
    out = tmp_path / "out"
    # 4 draws x 2 speeds: each worker starts three samples after its first, so a loaded machine
    # (the first row lands late) still leaves a run younger than 1 s to catch
    # runs as new interpreters, children of the workers (a forked run's parent is its server:
    # test_campaign_fork.py kills servers and forked runs)
    args = [campaign_file(tmp_path, DRAWS), "--out", out, "--workers", 2, "--retries", retries, "--fmu", built_fmu,
            "--no-plots", "--no-fork-runs"]
    cli = subprocess.Popen(CLI + [str(a) for a in args], env=campaign_env(tmp_path), cwd=tmp_path,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        killed, run_pid = _kill_a_busy_worker(cli, out)
        _, err = cli.communicate(timeout=WAIT_S)
    finally:
        stop(cli)
    wait_for(lambda: gone(run_pid), "the killed worker's run process to die", 30)
    rs = rows(out)
    assert sorted((x["sample"], x["arm"]) for x in rs) == [(f"s{i:04d}", a) for i in range(2 * DRAWS)
                                                          for a in ("adaptive", "pd_only")]  # each once
    others = [x for x in rs if x["sample"] != killed]
    assert all(x["status"] == "complete" for x in others), [(x["sample"], x["error"]) for x in rs]
    mine = [x for x in rs if x["sample"] == killed]
    if retries:
        assert cli.returncode == 0, err
        assert all(x["status"] == "complete" for x in mine), mine
        assert tries(out) == {f"s{i:04d}": 2 if f"s{i:04d}" == killed else 1 for i in range(2 * DRAWS)}, (killed, err)
    else:
        assert cli.returncode == 1, err
        assert all(x["status"] == "failed" and x["error"].startswith("KilledWorker after 0 retries") for x in mine), mine
    assert_clean(tmp_path, out)


def test_interrupt_then_resume_runs_every_sample_once(tmp_path, built_fmu):
    """Ctrl-C as a terminal sends it: SIGINT to the whole process group (CLI and workers); the
    runs as new interpreters (test_campaign_fork.py interrupts forked ones), the resume forked."""
    out = tmp_path / "out"
    cfile = campaign_file(tmp_path, 3)
    cli = subprocess.Popen(CLI + [str(cfile), "--out", str(out), "--workers", "1", "--fmu", str(built_fmu), "--no-plots",
                                  "--no-fork-runs"],
                           env=campaign_env(tmp_path), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           start_new_session=True)
    try:
        wait_for(lambda: (out / "campaign.csv").is_file() and len(rows(out)) >= 2, "the first sample's rows")
        in_flight = running_runs(cli.pid)
        os.killpg(cli.pid, signal.SIGINT)
        _, err = cli.communicate(timeout=60)
    finally:
        stop(cli)
    assert cli.returncode == 130, err
    lines = [line for line in err.strip().splitlines() if not line.startswith(f"{DASHBOARD_LINE}http://127.0.0.1:")]
    assert len(lines) == 1, err  # the dashboard's address, then one line: no worker tracebacks
    assert lines[0].startswith("interrupted: ") and "--resume" in lines[0]
    for p in in_flight:
        wait_for(lambda: gone(p.pid), "the runs in flight to stop", 30)
    before = rows(out)
    done = {x["sample"] for x in before}
    assert 1 <= len(done) < 6 and all(x["status"] == "complete" for x in before)

    r = run_campaign([cfile, "--out", out, "--workers", 2, "--resume", "--no-plots"], tmp_path, built_fmu)
    assert r.returncode == 0, r.stderr
    after = rows(out)
    assert sorted((x["sample"], x["arm"]) for x in after) == [(f"s{i:04d}", a) for i in range(6)
                                                             for a in ("adaptive", "pd_only")]
    assert all(x["status"] == "complete" for x in after)
    assert [x for x in after if x["sample"] in done] == before  # timings too: not run again
    assert all(tries(out)[s] == 1 for s in done)
    assert_clean(tmp_path, out)


def test_task_timeout_recorded_as_failed(tmp_path, built_fmu):
    out = tmp_path / "out"
    r = run_campaign([SMOKE, "--out", out, "--workers", 1, "--task-timeout", 0.2, "--no-plots"], tmp_path, built_fmu)
    assert r.returncode == 1
    rs = rows(out)
    assert len(rs) == 8 and all(x["status"] == "failed" and x["error"].startswith("timeout: ") for x in rs)
    assert_clean(tmp_path, out)
