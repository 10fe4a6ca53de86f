"""``report`` never raises on any summary.json: a tampered file is listed as invalid,
naming what is wrong (exit 2), and the schema checks types and ranges (``fell = NaN``,
``duration_s = -1`` are not results). A property test mutates a real summary (from a
short in-process run with terrain, a push, two command levels and a claim) at random
places with random JSON values; explicit cases cover NaN, negative durations, wrong
types, deep nesting, huge integers and a summary.json that is not a file."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from scenarios import report
from scenarios.results import output
from scenarios.cli import main as cli_main
from support.paths import REPO_ROOT

SCENARIO = """name = "tampered"
duration_s = 1.0
seed = 1
compare = ["adaptive", "pd_only"]
[[command]]
t_s = 0.0
vx_des = 0.3
[[command]]
t_s = 0.5
vx_des = 0.4
[[push]]
t_s = 0.2
force_n = [20.0, 0.0, 0.0]
duration_s = 0.1
[terrain]
max_height_m = 0.02
max_slope_deg = 5.0
seed = 4
size_m = 5.0
[claim]
text = "it stands"
[[claim.check]]
arm = "adaptive"
metric = "fell"
op = "=="
value = false
[[claim.check]]
arm = "adaptive"
metric = "steady_state_error_vx"
op = "<="
other_arm = "pd_only"
"""


@pytest.fixture(scope="module")
def real_summary(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("tampered")
    f = folder / "tampered.toml"
    f.write_text(SCENARIO)
    assert cli_main(["run", str(f), "--regulator", "inprocess", "--no-plots", "--out", str(folder / "runs")]) == 0
    data = json.loads((folder / "runs" / "tampered" / "summary.json").read_text())
    assert output.summary_problems(data) == []
    return data


def paths(value, prefix=()) -> list[tuple]:
    """Every key path into ``value`` (the root excluded)."""
    out = []
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for k, v in items:
        out.append(prefix + (k,))
        out += paths(v, prefix + (k,))
    return out


def report_of(folder: Path, text: str) -> tuple[str, list[str]]:
    """Write ``text`` as folder/x/summary.json and run the report over it (it must not raise)."""
    (folder / "x").mkdir(exist_ok=True)
    (folder / "x" / "summary.json").write_text(text)
    path, problems = report.write_report(folder)
    return path.read_text(), problems


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**400, 10**400) | st.floats() | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12)
DEEP = "DEEP-NESTING-HERE"


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_report_never_raises_on_a_tampered_summary(real_summary, tmp_path, data):
    summary = json.loads(json.dumps(real_summary))
    where = data.draw(st.sampled_from(paths(summary)))
    parent = summary
    for k in where[:-1]:
        parent = parent[k]
    action = data.draw(st.sampled_from(["replace", "delete", "deep"]))
    if action == "delete":
        del parent[where[-1]]
    else:
        parent[where[-1]] = DEEP if action == "deep" else data.draw(json_values)
    text = json.dumps(summary).replace(json.dumps(DEEP), "[" * 5000 + "1" + "]" * 5000)
    page, problems = report_of(tmp_path, text)
    assert "## x" in page
    if problems:  # listed as invalid, naming the file
        assert problems[0].startswith(f"invalid {tmp_path / 'x' / 'summary.json'}: ")


def test_nan_negative_and_wrong_types_are_named(real_summary, tmp_path):
    cases = {("arms", "adaptive", "fell"): (math.nan, "arms.adaptive.fell = NaN: must be true or false or null"),
             ("duration_s",): (-1, "duration_s = -1: must be a finite number > 0"),
             ("arms", "adaptive", "wall_s"): (-3.0, "arms.adaptive.wall_s = -3.0: must be a finite number >= 0"),
             ("perturbation", "torso_mass_kg"): (10**400, "perturbation.torso_mass_kg = 1000000000"),
             ("arms", "pd_only", "t_fall_s"): (math.inf, "arms.pd_only.t_fall_s = Infinity"),
             ("arms", "adaptive", "level_errors_vx"): (7, "arms.adaptive.level_errors_vx = 7: must be a list"),
             ("commands",): ({"t_s": 0}, "commands = {\"t_s\": 0}: must be a list"),
             ("claim", "checks", 0, "value"): ("no", "claim.checks[0].value = \"no\": must be a finite number")}
    for where, (value, phrase) in cases.items():
        summary = json.loads(json.dumps(real_summary))
        parent = summary
        for k in where[:-1]:
            parent = parent[k]
        parent[where[-1]] = value
        page, problems = report_of(tmp_path, json.dumps(summary))
        assert len(problems) == 1 and phrase in problems[0], (where, problems)


@pytest.mark.parametrize("text,phrase", [
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ('{"scenario": "x", "seed": ' + "9" * 5000 + "}", "Python does not read"),
    ('{"scenario": "x", "duration_s": 1e999}', "duration_s = Infinity"),
    ("NaN", "the top level must be an object"),
])
def test_unreadable_json_is_one_problem(tmp_path, text, phrase):
    _, problems = report_of(tmp_path, text)
    assert len(problems) == 1 and phrase in problems[0], problems


def test_a_summary_that_is_a_fifo_or_a_folder_is_named_without_hanging(tmp_path):
    (tmp_path / "p").mkdir()
    os.mkfifo(tmp_path / "p" / "summary.json")  # no writer: reading it would block for ever
    (tmp_path / "d" / "summary.json").mkdir(parents=True)
    r = subprocess.run([sys.executable, "-m", "scenarios", "report", str(tmp_path)], capture_output=True, text=True,
                       timeout=120, cwd=REPO_ROOT)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "is a named pipe (FIFO), not a summary.json" in r.stderr and "is a directory" in r.stderr, r.stderr
