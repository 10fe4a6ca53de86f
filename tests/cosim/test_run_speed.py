"""The main job without needless overhead (issue 14), and nothing the user gets changed by it.

- the arms go to the workers longest first (terrain weighted), equal costs in file order;
- each arm reports where its time went (``timings`` in summary.json, never in the CSV);
- with ``--jobs N`` the results are written by the workers, not the process that runs them;
- rows are recorded into a preallocated table of doubles: the same rows as the
  structured assignment per step;
- timeseries.csv is written column-wise: the same bytes as the writer before
  (``np.savetxt`` of ``repr``), on a real run and on the awkward doubles;
- each distinct plant is compiled once per process and shared.

Speed itself is measured by ``benchmarks/bench_suite.py``, not here.
"""
from __future__ import annotations

import dataclasses
import io
import json
import os
from pathlib import Path

import numpy as np
import pytest

from scenarios.cosim import master
from scenarios.results import output
from scenarios.run import runner
from scenarios.lang import spec
from scenarios.cli import main as cli_main
from scenarios.lang.plantio import load_plant_model
from scenarios.run.options import RunOptions
from scenarios.cosim.regulators import InProcessRegulator
from scenarios.lang.scenario import CommandPoint, Push, Scenario


def suite(name: str, duration_s: float | None = None) -> Scenario:
    s = spec.resolve_targets([name])[0]
    return s if duration_s is None else spec.override(s, duration_s=duration_s)


def scenario_file(folder: Path, name: str, duration_s: float) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(f'name = "{name}"\nduration_s = {duration_s}\nseed = 1\ncompare = ["adaptive", "pd_only"]\n'
                    '[[command]]\nt_s = 0.0\nvx_des = 0.5\n')
    return path


# --------------------------------------------------------------------------- scheduling
def test_longest_first_orders_arms_by_cost_terrain_weighted_ties_in_file_order():
    push, nominal, terrain, redundancy = (suite(n) for n in ("push_fwd_30n", "nominal", "terrain_uneven",
                                                            "redundancy_hip_zero"))
    assert terrain.duration_s == nominal.duration_s  # terrain ranks above nominal by its weight only
    tasks = [(s, a.name) for s in (push, nominal, terrain, redundancy) for a in s.arms]
    ordered = runner.longest_first(tasks)
    assert [(s.name, a) for s, a in ordered] == [
        ("redundancy_hip_zero", "adaptive"), ("redundancy_hip_zero", "hip_zero"),
        ("terrain_uneven", "adaptive"), ("terrain_uneven", "pd_only"),
        ("nominal", "adaptive"), ("nominal", "pd_only"),
        ("push_fwd_30n", "adaptive"), ("push_fwd_30n", "pd_only")]
    assert runner.arm_cost(terrain) == runner.TERRAIN_COST * runner.arm_cost(nominal)


def test_two_jobs_start_the_longest_arms_first_and_report_their_timings(tmp_path, capsys):
    short = scenario_file(tmp_path, "short", 0.5)  # first in file order
    long = scenario_file(tmp_path, "long", 1.5)
    out = tmp_path / "out"
    assert cli_main(["run", str(short), str(long), "--out", str(out), "--regulator", "inprocess",
                     "--jobs", "2"]) == 0
    capsys.readouterr()
    arms = {(n, a): m for n in ("short", "long")
            for a, m in json.loads((out / n / "summary.json").read_text())["arms"].items()}
    began = {k: m["timings"]["started_s"] for k, m in arms.items()}
    # two workers take the two long arms; a short one starts only when a long one has ended
    assert max(began[("long", "adaptive")], began[("long", "pd_only")]) < min(began[("short", a)]
                                                                          for a in ("adaptive", "pd_only"))
    first_ended = min(arms[("long", a)]["timings"]["ended_s"] for a in ("adaptive", "pd_only"))
    assert min(began[("short", a)] for a in ("adaptive", "pd_only")) >= first_ended
    for m in arms.values():
        t = m["timings"]
        assert set(master.TIMINGS) <= set(t) and all(t[k] >= 0 for k in master.TIMINGS)
        assert t["loop_s"] >= t["regulator_s"] + t["plant_s"] + t["record_s"]
        assert t["ended_s"] > t["started_s"] and isinstance(t["pid"], int)
    # each worker says once what starting it cost, with its first arm
    assert sum("worker_startup_s" in m["timings"] for m in arms.values()) == 2
    workers = {m["timings"]["pid"] for m in arms.values()}
    assert len(workers) == 2 and os.getpid() not in workers
    for n in ("short", "long"):
        written = json.loads((out / n / "summary.json").read_text())["timings"]
        assert set(written) == {"csv_s", "plots_s", "cpu_s", "pid"}
        assert written["pid"] in workers  # written by a worker: this process never competes with the arms
        columns = (out / n / "timeseries.csv").read_text().splitlines()[0].split(",")
        assert not [c for c in columns if c.endswith("_s") or "timing" in c]  # timings never in the CSV


def test_jobs_run_in_the_workers_and_their_values_and_errors_come_back(tmp_path):
    s = suite("nominal", 0.2)
    got = {}

    def on_outcome(scenario, outcome):  # each arm's outcome asks for one job
        if outcome.arm == "adaptive":
            return runner.Job(os.getpid, (), lambda value, error: got.update(pid=(value, error)))
        return runner.Job(os.listdir, (str(tmp_path / "missing"),), lambda value, error: got.update(ls=(value, error)))

    runner.run_tasks([(s, "adaptive"), (s, "pd_only")], RunOptions(regulator="inprocess", jobs=2),
                     stop=runner.StopFlag(), on_outcome=on_outcome)
    pid, error = got["pid"]
    assert error is None and isinstance(pid, int) and pid != os.getpid()
    value, error = got["ls"]
    assert value is None and isinstance(error, FileNotFoundError)


# --------------------------------------------------------------------------- recording
def test_recorder_gives_the_rows_of_a_structured_assignment_per_step():
    dtype = master._row_dtype(("a", "b"), {}, {"i": 3, "x": 1.5, "flag": True})
    values = [(0.0, 0.5, -0.0, 0.3, 1.0, 2.0, 3.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 7, np.float64(1e-310),
               float("nan"), 2 ** 40, np.float32(0.1), True),
              (0.005, 0.5, 0.0, -0.3, 1.0, 2.0, 3.0, float("inf"), -1e300, 5e-324, 0.4, 0.5, 0.6, -8, 0.1 + 0.2,
               float("-inf"), -(2 ** 52), 1e16, False)]
    expected = np.zeros(3, dtype=dtype)
    rec = master._Recorder(3, dtype)
    for k, row in enumerate(values):
        expected[k] = row
        rec.table[k] = row
    got = rec.rows(2)
    assert got.dtype == dtype and got.tobytes() == expected[:2].tobytes()


# --------------------------------------------------------------------------- the CSV
def savetxt_writer(path: Path, results) -> None:
    """output.write_timeseries as it was before issue 14 (the reference for the bytes)."""
    results = [r for r in results if len(r.rows)]
    with open(path, "w", newline="") as fh:
        names = results[0].rows.dtype.names
        fh.write("arm," + ",".join(names) + "\n")
        for r in results:
            fmts = ["%d" if r.rows.dtype[n].kind in "iu" else "%r" for n in names]
            buf = io.StringIO()
            table = np.empty((len(r.rows), len(names)), dtype=object)
            for j, n in enumerate(names):
                table[:, j] = r.rows[n].tolist()
            np.savetxt(buf, table, fmt=fmts, delimiter=",")
            fh.writelines(r.arm + "," + line + "\n" for line in buf.getvalue().splitlines())


def test_timeseries_csv_bytes_equal_the_previous_writer_on_a_real_run(tmp_path):
    s = dataclasses.replace(suite("compare_fixed_speed", 1.0),
                            commands=(CommandPoint(0.0, 0.5, 0.0), CommandPoint(0.5, 0.3, 0.1)),
                            pushes=(Push(0.6, (20.0, -5.0, 0.0), 0.1),))
    results = master.run_scenario(s, "inprocess")
    odd = results[1].rows.copy()  # the awkward doubles, in columns of few and of many distinct values
    odd["push_fx"][:3] = -0.0  # -0.0 among 0.0: told apart by bits
    odd["cmd_vy_des"][-4:] = [float("nan"), float("inf"), float("-inf"), 5e-324]
    odd["tel_pelvis_x"][:6] = [1e16, 1e-5, 0.1 + 0.2, -1e300, 123456789.0, 2.0 ** -1074]
    odd["in_step_index"][:2] = [2 ** 53, -(2 ** 40)]
    results.append(dataclasses.replace(results[1], arm="odd", rows=odd))
    output.write_timeseries(tmp_path / "new.csv", results)
    savetxt_writer(tmp_path / "old.csv", results)
    new, old = (tmp_path / "new.csv").read_bytes(), (tmp_path / "old.csv").read_bytes()
    assert new == old
    assert b",-0.0," in new and b",nan," in new and b",1e+16," in new and b",5e-324," in new
    back = np.genfromtxt(tmp_path / "new.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    sel = back[back["arm"] == "odd"]
    for name in odd.dtype.names:  # and it reads back to the same values (NaN where NaN)
        assert np.array_equal(sel[name], odd[name], equal_nan=odd.dtype[name].kind == "f"), name


# --------------------------------------------------------------------------- shared plant models
def test_each_distinct_plant_is_compiled_once_per_process_and_runs_the_same():
    nominal, pushed = suite("nominal", 0.2), suite("push_fwd_30n", 0.2)
    heavy = suite("compare_staircase", 0.2)  # torso_added_mass_kg: needs the nominal model's own mass
    a, sa = load_plant_model(nominal, shared=True)
    b, _ = load_plant_model(pushed, shared=True)
    c, sc = load_plant_model(heavy, shared=True)
    assert a is b  # one plant (pushes are applied by the master, not compiled in), one compiled model
    assert c is not a and sc["pelvis_mass_kg"] == pytest.approx(sa["pelvis_mass_kg"] + 5.0)
    fresh, fresh_summary = load_plant_model(heavy)
    assert fresh is not c and fresh_summary == sc
    shared_run = master.run_arm(heavy, "adaptive", InProcessRegulator(), model=c, model_summary=sc)
    fresh_run = master.run_arm(heavy, "adaptive", InProcessRegulator(), model=fresh,
                               model_summary=fresh_summary)
    assert shared_run.rows.tobytes() == fresh_run.rows.tobytes()
    again, _ = load_plant_model(heavy, shared=True)
    assert again is c  # a walker works on its own copy: the shared model is never changed


@pytest.mark.parametrize("value", [0.0, -0.0, float("nan"), 1e16, 5e-324])
def test_a_column_of_one_value_is_written_as_repr_would(value):
    col = np.full(50, value)
    assert output.column_text(col) == [repr(value)] * 50
    ints = np.arange(50, dtype=np.int64) // 25 - 2 ** 40
    assert output.column_text(ints) == [repr(int(v)) for v in ints]
