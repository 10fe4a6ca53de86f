"""``python -m scenarios run --no-plots`` (what campaign tasks run: the campaign's report
plots the campaign, so each task skips matplotlib and its three PNGs, ~1 s of a task):
the same time series and metrics as a run with plots, nothing else missing."""
import json
import subprocess
import sys
from pathlib import Path

from scenarios.campaign import task as task_mod
from support.paths import REPO_ROOT

NOMINAL = REPO_ROOT / "scenarios" / "suite" / "nominal.toml"


def run(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "scenarios", "run", "nominal", "--regulator", "inprocess",
                           "--duration", "0.5", "--out", str(out), *extra],
                          capture_output=True, text=True, cwd=REPO_ROOT)  # MENAGERIE_ROOT may be relative


def test_no_plots_writes_the_same_results_without_pngs(tmp_path):
    with_plots, without = tmp_path / "plots", tmp_path / "no_plots"
    for out, extra in ((with_plots, ()), (without, ("--no-plots",))):
        proc = run(out, *extra)
        assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (with_plots / "nominal").iterdir()) == [
        "psi.png", "summary.json", "timeseries.csv", "torso.png", "velocity.png"]
    assert sorted(p.name for p in (without / "nominal").iterdir()) == ["summary.json", "timeseries.csv"]
    a, b = (json.loads((d / "nominal" / "summary.json").read_text()) for d in (with_plots, without))
    assert a["plots"] == ["velocity.png", "psi.png", "torso.png"] and b["plots"] == []
    assert b["status"] == "complete"
    for arm in ("adaptive", "pd_only"):
        drop = ("wall_s", "realtime_factor", "timings")
        assert {k: v for k, v in a["arms"][arm].items() if k not in drop} == \
               {k: v for k, v in b["arms"][arm].items() if k not in drop}
    assert (with_plots / "nominal" / "timeseries.csv").read_bytes() == (without / "nominal" / "timeseries.csv").read_bytes()


def test_a_campaign_task_runs_without_plots(tmp_path):
    sample = tmp_path / "s0000.toml"
    sample.write_text(NOMINAL.read_text().replace("duration_s = 40.0", "duration_s = 0.5").replace(
        'name = "nominal"', 'name = "s0000"'))
    t = task_mod.Task(sample="s0000", scenario_file=str(sample), runs_dir=str(tmp_path / "runs" / "s0000"),
                      arms=("adaptive", "pd_only"), regulator="inprocess", fmu=None, timeout_s=300.0,
                      tmp_root=str(tmp_path / "tmp"), env=task_mod.client_env())
    result = task_mod.run_sample(t)
    assert [r["status"] for r in result["rows"]] == ["complete", "complete"], result
    assert sorted(p.name for p in Path(result["run_dir"]).iterdir()) == ["summary.json", "timeseries.csv"]
