"""The results of ``python -m scenarios run`` survive failures, re-runs, concurrent runs and Ctrl-C;
``validate``/``run`` refuse up front whatever ``run`` would fail on; ``report`` trusts no file.

Runs are short (0.5-2 simulated s) and use the in-process regulator unless the FMU is the
point (Ctrl-C inside FMU calls, FMU copies in the temp folder, an FMU that cannot load).
The CLI runs in this process (``cli.main``) where that is enough, and as a real
subprocess where signals, the temp folder or a killed process are the point.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from scenarios.cli import main as cli_main
from support.scenario_support import scenario_file
from support.paths import REPO_ROOT

# long enough that it is still running when the test interrupts it (about 6 s per arm here)
SLOW_S = 60.0


def cli(capsys, *argv) -> tuple[int, str, str]:
    rc = cli_main([str(a) for a in argv])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too) with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def summary(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())


@pytest.fixture(scope="module")
def broken_fmu(built_fmu, tmp_path_factory) -> Path:
    """The real FMU with its shared libraries replaced by junk: it reads, but cannot be loaded."""
    src = Path(built_fmu)
    dst = tmp_path_factory.mktemp("broken") / src.name
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename.startswith("binaries/"):
                data = b"not a shared library"
            zout.writestr(item, data)
    return dst


# --------------------------------------------------------------------------- defect 6: nothing lost or overwritten
def test_rerun_refused_failed_rerun_keeps_results_overwrite_replaces_whole_folder(tmp_path, capsys, broken_fmu):
    f = scenario_file(tmp_path, "keep", arms=("adaptive", "pd_only"))
    out = tmp_path / "out"
    rc, _, err = cli(capsys, "run", f, "--out", out, "--regulator", "inprocess")
    assert rc == 0, err
    before = snapshot(out)
    assert set(before) == {"keep/timeseries.csv", "keep/summary.json", "keep/velocity.png", "keep/psi.png",
                           "keep/torso.png"}

    # a plain re-run is refused before simulating: nothing changes
    rc, _, err = cli(capsys, "run", f, "--out", out, "--regulator", "inprocess")
    assert rc == 2 and "already holds results" in err and "--overwrite" in err and "--resume" in err, err
    assert snapshot(out) == before

    # a re-run that fails (the FMU cannot load) does not replace the good results
    rc, stdout, err = cli(capsys, "run", f, "--out", out, "--fmu", broken_fmu, "--overwrite")
    assert rc == 1 and "Traceback" not in stdout, err
    assert "failed" in stdout and "earlier results" in err and "were kept" in err
    assert snapshot(out) == before

    # a complete re-run with --overwrite replaces the whole folder: no file of the old one survives
    rc, _, err = cli(capsys, "run", f, "--out", out, "--regulator", "inprocess", "--overwrite", "--duration", "1.0")
    assert rc == 0, err
    after = snapshot(out)
    assert set(after) == set(before)
    s = summary(out / "keep")
    assert s["duration_s"] == 1.0 and s["status"] == "complete"
    assert set(s["plots"]) == {"velocity.png", "psi.png", "torso.png"}
    assert len((out / "keep" / "timeseries.csv").read_text().splitlines()) == 1 + 2 * 200


def test_two_files_with_one_name_refused_naming_both(tmp_path, capsys):
    a = scenario_file(tmp_path, "same", file="a.toml")
    b = scenario_file(tmp_path, "same", file="b.toml")
    out = tmp_path / "out"
    rc, _, err = cli(capsys, "run", a, b, "--out", out, "--regulator", "inprocess")
    assert rc == 2 and str(a) in err and str(b) in err and "unique" in err, err
    assert not out.exists()
    rc, _, err = cli(capsys, "validate", a, b)
    assert rc == 2 and str(a) in err and str(b) in err, err
    rc, _, err = cli(capsys, "run", a, a, "--out", out, "--regulator", "inprocess")  # one file twice: refused
    assert rc == 2 and "'same': named twice on the command line" in err and not out.exists(), err


def test_scenario_folder_taken_by_a_file_refused_before_simulating(tmp_path, capsys):
    first, second = scenario_file(tmp_path, "first"), scenario_file(tmp_path, "second")
    out = tmp_path / "out"
    out.mkdir()
    (out / "second").write_text("a file where the folder would go")
    (out / "notes").mkdir()  # folders of others are left alone
    for again in ((), ("--overwrite",)):
        rc, _, err = cli(capsys, "run", first, second, "--out", out, "--regulator", "inprocess", *again)
        assert rc == 2 and f"{out / 'second'} is a file" in err and "Traceback" not in err, err
        assert sorted(p.name for p in out.iterdir()) == ["notes", "second"]  # nothing simulated, nothing written


def test_folder_with_foreign_files_never_replaced(tmp_path, capsys):
    f = scenario_file(tmp_path, "mine")
    out = tmp_path / "out"
    (out / "mine").mkdir(parents=True)
    (out / "mine" / "thesis.tex").write_text("not ours")
    for again in ((), ("--overwrite",)):
        rc, _, err = cli(capsys, "run", f, "--out", out, "--regulator", "inprocess", *again)
        assert rc == 2 and "thesis.tex" in err, err
        assert snapshot(out) == {"mine/thesis.tex": b"not ours"}


def test_resume_keeps_complete_results_and_reruns_the_others(tmp_path, capsys, broken_fmu):
    done, todo = scenario_file(tmp_path, "done"), scenario_file(tmp_path, "todo")
    out = tmp_path / "out"
    assert cli(capsys, "run", done, "--out", out, "--regulator", "inprocess")[0] == 0
    rc, _, err = cli(capsys, "run", todo, "--out", out, "--fmu", broken_fmu)
    assert rc == 1 and summary(out / "todo")["status"] == "failed", err
    kept = snapshot(out / "done")

    rc, stdout, err = cli(capsys, "run", done, todo, "--out", out, "--regulator", "inprocess", "--resume")
    assert rc == 0, err
    assert "1 kept as complete (--resume)" in stdout
    assert snapshot(out / "done") == kept
    assert summary(out / "todo")["status"] == "complete"

    # complete results of another set-up are not silently kept
    rc, _, err = cli(capsys, "run", done, "--out", out, "--regulator", "inprocess", "--resume", "--duration", "1.0")
    assert rc == 2 and "another set-up" in err and "duration_s" in err, err
    assert snapshot(out / "done") == kept


def test_second_run_on_one_out_refused_and_a_killed_runs_lock_and_scratch_do_not_block(tmp_path, capsys, built_fmu):
    slow = scenario_file(tmp_path, "slow", duration_s=SLOW_S)
    quick = scenario_file(tmp_path, "quick")
    out = tmp_path / "out"
    first = subprocess.Popen([sys.executable, "-m", "scenarios", "run", str(slow), "--out", str(out),
                              "--fmu", str(built_fmu)], cwd=REPO_ROOT, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: any(out.glob(".run-*/fmu/fmu-*")), first)  # it is simulating
        rc, _, err = cli(capsys, "run", quick, "--out", out, "--regulator", "inprocess")
        assert rc == 2 and f"another run (pid {first.pid})" in err, err
        assert not (out / "quick").exists()
    finally:
        first.kill()  # SIGKILL: no clean-up at all; the OS drops its flock
        first.wait(timeout=60)
    assert (out / ".lock").exists() and any(out.glob(".run-*"))  # what the killed run left
    rc, _, err = cli(capsys, "run", quick, "--out", out, "--regulator", "inprocess")
    assert rc == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["quick"]  # its scratch folder and lock are gone


def test_a_write_cut_short_changes_nothing_and_a_killed_swap_is_repaired(tmp_path):
    from scenarios.results.store import REPLACED_TAG, ResultsDir

    out = tmp_path / "out"
    (out / "kept").mkdir(parents=True)
    (out / "kept" / "summary.json").write_text("old")

    def half_then_ctrl_c(folder: Path) -> None:
        (folder / "timeseries.csv").write_text("arm,t\n")
        raise KeyboardInterrupt

    with ResultsDir(out) as rd:
        staged = rd.stage("kept")  # as a run writes a scenario: staged, committed only when complete
        with pytest.raises(KeyboardInterrupt):
            half_then_ctrl_c(staged)
        rd.discard("kept")
        assert snapshot(out / "kept") == {"summary.json": b"old"}
        assert list((rd.scratch / "stage").iterdir()) == []
    # a run killed between its two renames: the old folder is aside, the new one not in place
    (out / "kept").rename(out / f".kept{REPLACED_TAG}12345")
    (out / "done").mkdir()
    (out / f".done{REPLACED_TAG}12345").mkdir()  # killed after the second rename: the new one stays
    with ResultsDir(out):
        pass
    assert sorted(p.name for p in out.iterdir()) == ["done", "kept"]
    assert snapshot(out / "kept") == {"summary.json": b"old"}


# --------------------------------------------------------------------------- defect 7: Ctrl-C
def wait_for(predicate, proc: subprocess.Popen, timeout: float = 180.0) -> None:
    t0 = time.monotonic()
    while not predicate():
        assert proc.poll() is None, f"the run ended early (exit {proc.returncode})"
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.05)


def start_run(args: list, tmp_path: Path) -> tuple[subprocess.Popen, Path, Path]:
    """``python -m scenarios run ...`` in its own process group, with its own TMPDIR."""
    tmpdir = tmp_path / "systmp"
    tmpdir.mkdir()
    err = tmp_path / "stderr.txt"
    proc = subprocess.Popen([sys.executable, "-m", "scenarios", "run", *map(str, args)], cwd=REPO_ROOT,
                            env={**os.environ, "TMPDIR": str(tmpdir)}, stdout=subprocess.DEVNULL,
                            stderr=open(err, "w"), start_new_session=True)
    return proc, tmpdir, err


def assert_clean_exit_130(proc: subprocess.Popen, err: Path, tmpdir: Path, out: Path) -> str:
    assert proc.wait(timeout=120) == 130
    text = err.read_text()
    assert "Traceback" not in text and len(text.strip().splitlines()) == 1, text
    deadline = time.monotonic() + 10
    while True:  # every process of the run is gone (workers, resource tracker)
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        assert time.monotonic() < deadline, "processes of the run are still alive"
        time.sleep(0.1)
    assert list(tmpdir.iterdir()) == []
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []  # no lock, no scratch folder
    return text


def test_ctrl_c_with_two_jobs_stops_workers_keeps_complete_flags_started(tmp_path, built_fmu):
    quick = scenario_file(tmp_path, "quick")
    slow = scenario_file(tmp_path, "slow", duration_s=SLOW_S, arms=("adaptive", "pd_only"))
    out = tmp_path / "out"
    # three workers: the arms go longest first, so with two the quick arm would wait for a slow one
    proc, tmpdir, err = start_run([quick, slow, "--out", out, "--fmu", built_fmu, "--jobs", "3"], tmp_path)
    wait_for(lambda: (out / "quick" / "summary.json").exists(), proc)
    time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
    text = assert_clean_exit_130(proc, err, tmpdir, out)
    assert text.startswith("interrupted: 1 of 2 scenario(s) complete") and "--resume" in text

    q = summary(out / "quick")
    assert q["status"] == "complete" and q["arms"]["adaptive"]["status"] == "complete"
    assert len((out / "quick" / "timeseries.csv").read_text().splitlines()) == 1 + 100
    s = summary(out / "slow")  # started: flagged, never half-written
    assert s["status"] == "interrupted" and s["verdict"]["overall"] == "n/a"
    statuses = {a: m["status"] for a, m in s["arms"].items()}
    assert set(statuses) == {"adaptive", "pd_only"} and "interrupted" in statuses.values()
    complete = {a for a, st in statuses.items() if st == "complete"}
    csv = out / "slow" / "timeseries.csv"
    assert ({ln.split(",", 1)[0] for ln in csv.read_text().splitlines()[1:]} if csv.exists() else set()) == complete


def test_ctrl_c_during_an_overwrite_leaves_the_previous_results_intact(tmp_path, capsys, built_fmu):
    slow = scenario_file(tmp_path, "slow", duration_s=SLOW_S)
    out = tmp_path / "out"
    assert cli(capsys, "run", slow, "--out", out, "--regulator", "inprocess", "--duration", "1.0")[0] == 0
    before = snapshot(out)
    proc, tmpdir, err = start_run([slow, "--out", out, "--fmu", built_fmu, "--overwrite"], tmp_path)
    wait_for(lambda: any(out.glob(".run-*/fmu/fmu-*")), proc)  # the FMU is unpacked: the arm runs
    time.sleep(1.0)
    os.kill(proc.pid, signal.SIGINT)
    text = assert_clean_exit_130(proc, err, tmpdir, out)
    assert "slow left as before" in text
    assert snapshot(out) == before


# --------------------------------------------------------------------------- defect 8: validation up front
BAD_MODELS = {
    "unclosed.xml": "<mujoco><worldbody>",
    "massless.xml": '<mujoco><worldbody><body><joint type="hinge"/></body></worldbody></mujoco>',
    "box.xml": '<mujoco><worldbody><body><freejoint/><geom size=".1"/></body></worldbody></mujoco>',
    "passwd.xml": '<mujoco><include file="/etc/passwd"/></mujoco>',
    "bomb.xml": ('<?xml version="1.0"?>\n<!DOCTYPE m [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;">'
                 '<!ENTITY c "&b;&b;&b;&b;&b;&b;">]>\n<mujoco model="&c;"><worldbody/></mujoco>'),
}


def bad_scenario_files(folder: Path) -> dict[str, str]:
    """file -> a phrase its problem must contain."""
    for name, text in BAD_MODELS.items():
        (folder / name).write_text(text)
    expected = {}
    for name, phrase in (("unclosed.xml", "not well-formed"), ("massless.xml", "cannot compile"),
                         ("box.xml", "not the Cassie model"), ("passwd.xml", "/etc/passwd"),
                         ("bomb.xml", "DTD or entity")):
        stem = name[:-4]
        expected[str(scenario_file(folder, stem, model=name))] = phrase
    empty = folder / "empty_command.toml"
    empty.write_text(scenario_file(folder, "empty_command").read_text().replace(
        "[[command]]\nt_s = 0.0\nvx_des = 0.5\n", "command = []\n"))
    expected[str(empty)] = "command: required"
    (folder / "latin1.toml").write_bytes('name = "caf\xe9"\n'.encode("latin-1"))
    expected[str(folder / "latin1.toml")] = "not UTF-8"
    (folder / "folder.toml").mkdir()
    expected[str(folder / "folder.toml")] = "is a directory"
    (folder / "loop.toml").symlink_to("loop.toml")  # unreadable whoever runs the test (root too)
    expected[str(folder / "loop.toml")] = "cannot read"
    return expected


def test_validate_names_every_problem_at_once_without_traceback(tmp_path, capsys):
    expected = bad_scenario_files(tmp_path)
    good = scenario_file(tmp_path, "fine")
    rc, stdout, err = cli(capsys, "validate", good, *expected)
    assert rc == 2 and "Traceback" not in err
    assert f"{good}: ok" in stdout
    for file, phrase in expected.items():
        block = err.split(file, 1)
        assert len(block) == 2, f"{file} not named:\n{err}"
        assert phrase in block[1].split("problem(s)", 2)[1][:2000], (file, phrase, err)


def test_run_refuses_the_same_before_simulating(tmp_path, capsys):
    expected = bad_scenario_files(tmp_path)
    out = tmp_path / "out"
    rc, _, err = cli(capsys, "run", *expected, "--out", out, "--regulator", "inprocess")
    assert rc == 2 and "Traceback" not in err
    for file, phrase in expected.items():
        assert file in err and phrase in err, (file, phrase)
    assert not out.exists()


@pytest.mark.parametrize("where", ["proc", "file", "under_file"])
def test_out_that_cannot_be_written_refused_up_front(tmp_path, capsys, where):
    f = scenario_file(tmp_path, "x")
    (tmp_path / "a_file").write_text("x")
    out = {"proc": Path("/proc/cassie_avr_results"), "file": tmp_path / "a_file",
           "under_file": tmp_path / "a_file" / "sub"}[where]
    rc, _, err = cli(capsys, "run", f, "--out", out, "--regulator", "inprocess")
    assert rc == 2 and f"--out {out}" in err and "Traceback" not in err, err
    assert (tmp_path / "a_file").read_text() == "x"


# --------------------------------------------------------------------------- defect 9: the report trusts no file
def test_report_names_a_summary_of_the_wrong_shape(tmp_path, capsys):
    for name, data in (("listed", []), ("armless", {"scenario": "armless", "status": "complete",
                                                    "arm_names": ["adaptive"], "arms": []})):
        (tmp_path / name).mkdir()
        (tmp_path / name / "summary.json").write_text(json.dumps(data))
    rc, stdout, err = cli(capsys, "report", tmp_path)
    assert rc == 2 and "Traceback" not in err, err
    assert str(tmp_path / "listed" / "summary.json") in err and "top level must be an object" in err
    assert str(tmp_path / "armless" / "summary.json") in err and "arms = []: must be an object" in err
    text = (tmp_path / "report.md").read_text()
    assert "invalid" in text and "**pass**" not in text


def test_report_never_passes_a_run_with_missing_or_incomplete_arms(tmp_path, capsys):
    f = scenario_file(tmp_path, "both", arms=("adaptive", "pd_only"))
    out = tmp_path / "out"
    assert cli(capsys, "run", f, "--out", out, "--regulator", "inprocess")[0] == 0
    assert cli(capsys, "report", out)[0] == 0
    assert "| [both](#both) |" in (out / "report.md").read_text()
    assert "**pass**" in (out / "report.md").read_text()

    path = out / "both" / "summary.json"
    good = json.loads(path.read_text())
    bad = json.loads(path.read_text())
    del bad["arms"]["pd_only"]  # a missing arm; the stored verdict still says pass
    path.write_text(json.dumps(bad))
    rc, _, err = cli(capsys, "report", out)
    assert rc == 2 and "not every arm is: pd_only missing" in err, err
    assert "**pass**" not in (out / "report.md").read_text()

    bad = json.loads(json.dumps(good))  # consistent, but an arm failed: no verdict, whatever is stored
    bad["status"], bad["error"] = "failed", "arm pd_only: boom"
    bad["arms"]["pd_only"] = {"status": "failed", "error": "boom"}
    path.write_text(json.dumps(bad))
    assert cli(capsys, "report", out)[0] == 0
    text = (out / "report.md").read_text()
    assert "**pass**" not in text and "incomplete run: pd_only failed" in text


# --------------------------------------------------------------------------- defect 10: no FMU copies in the temp folder
def test_an_fmu_that_cannot_load_leaves_no_copy_and_the_working_folder_as_it_was(tmp_path, broken_fmu):
    from scenarios.cosim.regulators import FmuRegulator

    cwd = os.getcwd()
    reg = FmuRegulator(broken_fmu)
    try:
        with pytest.raises(Exception, match="Failed to load shared library"):
            reg.start({}, 0.0, 1.0)
        assert os.getcwd() == cwd  # fmpy 0.3 stays in binaries/linux64 when loading fails
    finally:
        os.chdir(cwd)
        reg.close()
    reg = FmuRegulator(broken_fmu, unpack_dir=tmp_path)
    with pytest.raises(Exception, match="Failed to load shared library"):
        reg.start({}, 0.0, 1.0)
    assert len(list(tmp_path.iterdir())) == 1  # the copy lives under unpack_dir until close()
    reg.close()
    assert list(tmp_path.iterdir()) == []


def test_no_fmu_copies_left_in_the_system_temp_folder(tmp_path, built_fmu, broken_fmu):
    tmpdir = tmp_path / "systmp"
    tmpdir.mkdir()
    f = scenario_file(tmp_path, "t", arms=("adaptive", "pd_only"))
    for fmu, jobs, rc in ((broken_fmu, "1", 1), (built_fmu, "2", 0)):  # a start that fails, then workers
        proc = subprocess.run([sys.executable, "-m", "scenarios", "run", str(f), "--out", str(tmp_path / f"o{jobs}"),
                               "--fmu", str(fmu), "--jobs", jobs], cwd=REPO_ROOT, capture_output=True, text=True,
                              env={**os.environ, "TMPDIR": str(tmpdir)}, timeout=300)
        assert proc.returncode == rc, proc.stderr
        assert list(tmpdir.iterdir()) == [], (fmu, sorted(p.name for p in tmpdir.iterdir()))


def test_require_pass_exits_3_on_a_claim_that_misses_and_0_when_every_claim_passes(tmp_path, capsys):
    """`run --require-pass` (the README's main job): every arm completes in both runs; a claim
    that misses (a standing robot claimed to fall) gives exit 3 naming the scenario, where
    plain `run` gives 0; a claim that passes gives 0."""
    ok = scenario_file(tmp_path, "stands")
    misses = scenario_file(tmp_path, "claims_a_fall")
    misses.write_text(misses.read_text().replace("value = false", "value = true"))
    rc, _, err = cli(capsys, "run", ok, misses, "--regulator", "inprocess", "--out", tmp_path / "plain", "--no-plots")
    assert rc == 0, err
    rc, _, err = cli(capsys, "run", ok, misses, "--regulator", "inprocess", "--out", tmp_path / "strict",
                     "--no-plots", "--require-pass")
    assert rc == 3, err
    assert "claims_a_fall: miss" in err and "stands" not in err.split("--require-pass:")[1]
    rc, _, err = cli(capsys, "run", ok, "--regulator", "inprocess", "--out", tmp_path / "good", "--no-plots",
                     "--require-pass")
    assert rc == 0, err
