"""Input that a run or a campaign would fail on is refused by validation, with exit 2 and
every problem named: deep nesting, files that are not regular files, huge numbers,
names too long for a folder, zero-step runs and pushes, sample counts before they are
expanded, timeouts, ranges the CassiePlant FMU enforces, FMUs of the wrong kind.
Nothing here simulates; no test leaves a traceback, a hang or a file outside tmp_path."""
from __future__ import annotations

import os
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from scenarios.lang import spec
from scenarios.campaign import spec as campaign_spec
from scenarios.cli import main as cli_main
from scenarios.errors import ScenarioError
from support.paths import REPO_ROOT
from support.plant_fmu_support import built_plant_fmu

GOOD = """name = "tiny"
duration_s = 2.0
seed = 3
[[command]]
t_s = 0.0
vx_des = 0.5
"""
CAMPAIGN = """name = "c"
samples = 8
seed = 11
base = "nominal"
duration_s = 2.0
compare = ["adaptive"]
[factors.joint_damping_scale]
dist = "uniform"
low = 0.5
high = 2.0
"""


def top(extra: str) -> str:
    """GOOD with top-level lines ``extra`` (before its [[command]] table)."""
    return GOOD.replace("[[command]]", extra + "[[command]]")


def cli(capsys, *argv) -> tuple[int, str]:
    rc = cli_main([str(a) for a in argv])
    cap = capsys.readouterr()
    return rc, cap.err


def problems_of(text: str) -> list[str]:
    with pytest.raises(ScenarioError) as info:
        spec.parse_scenario(tomllib.loads(text), source="t.toml", check_plant=False)
    return info.value.problems


def campaign_problems(text: str, base_dir: Path = REPO_ROOT) -> list[str]:
    with pytest.raises(ScenarioError) as info:
        campaign_spec.parse_campaign(tomllib.loads(text), source="c.toml", base_dir=base_dir)
    return info.value.problems


def one_with(problems: list[str], *phrases: str) -> str:
    hits = [p for p in problems if all(ph in p for ph in phrases)]
    assert hits, (phrases, problems)
    return hits[0]


# --------------------------------------------------------------------------- files
DEEP = "[" * 3000 + "]" * 3000  # tomllib recursed past Python's limit: RecursionError


@pytest.mark.parametrize("value", [DEEP, "[" * 40 + "]" * 40], ids=["beyond-the-parser", "beyond-the-format"])
def test_deep_nesting_is_one_problem_in_validate_run_and_campaign(tmp_path, capsys, value):
    f = tmp_path / "deep.toml"
    f.write_text(top(f"tags = {value}\n"))
    for argv in (["validate", f], ["run", f, "--out", tmp_path / "o", "--regulator", "inprocess"]):
        rc, err = cli(capsys, *argv)
        assert rc == 2 and "nested too deeply" in err and "Traceback" not in err, err
    c = tmp_path / "c.toml"
    c.write_text(CAMPAIGN.replace('base = "nominal"', "base = 'deep.toml'"))
    rc, err = cli(capsys, "campaign", c, "--dry-run")
    assert rc == 2 and "nested too deeply" in err, err
    c.write_text(f"description = {value}\n" + CAMPAIGN)
    rc, err = cli(capsys, "campaign", c, "--dry-run")
    assert rc == 2 and "nested too deeply" in err, err
    assert not (tmp_path / "o").exists()


def test_campaign_base_that_is_a_folder_or_a_fifo_is_refused_without_hanging(tmp_path):
    (tmp_path / "folder.toml").mkdir()
    os.mkfifo(tmp_path / "pipe.toml")  # no writer: an open() for reading would block for ever
    for base, kind in (("folder.toml", "a directory"), ("pipe.toml", "named pipe")):
        c = tmp_path / f"c_{kind[:3]}.toml"
        c.write_text(CAMPAIGN.replace('base = "nominal"', f"base = '{base}'"))
        r = subprocess.run([sys.executable, "-m", "scenarios", "campaign", str(c), "--dry-run"], capture_output=True,
                           text=True, timeout=120, cwd=REPO_ROOT)
        assert r.returncode == 2 and kind in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = subprocess.run([sys.executable, "-m", "scenarios", "validate", str(tmp_path / "pipe.toml")],
                       capture_output=True, text=True, timeout=120, cwd=REPO_ROOT)
    assert r.returncode == 2 and "named pipe (FIFO), not a scenario file" in r.stderr, r.stderr


def test_a_file_beyond_the_size_limit_is_refused_unread(tmp_path, capsys):
    from scenarios.lang.tomlfile import MAX_FILE_BYTES

    f = tmp_path / "big.toml"
    with open(f, "w") as fh:
        fh.write(GOOD)
        fh.write("# " + "x" * (MAX_FILE_BYTES + 10) + "\n")
    rc, err = cli(capsys, "validate", f)
    assert rc == 2 and "too large for a scenario file" in err


# --------------------------------------------------------------------------- values
def test_numbers_beyond_doubles_are_problems_not_overflow_errors():
    big = "9" * 400
    probs = problems_of(top(f"torso_com_offset_m = [0.0, {big}, 0.0]\ntorso_mass_kg = {big}\n")
                        .replace("duration_s = 2.0", f"duration_s = {big}"))
    one_with(probs, "duration_s = 999", "must be a finite number")
    one_with(probs, "torso_mass_kg = 999", "must be a finite number")
    one_with(probs, "torso_com_offset_m", "must be finite")
    assert all(len(p) < 300 for p in probs), probs  # huge values are shown cut
    probs = campaign_problems(CAMPAIGN.replace("[factors.joint_damping_scale]", f"""[factors.torso_mass_kg]
dist = "choice"
values = [10.0, 12.0]
weights = [1, {big}]
[factors.joint_damping_scale]"""))
    one_with(probs, "factors.torso_mass_kg.weights", "non-negative numbers")


def test_a_name_too_long_for_a_folder_is_refused_by_validate(tmp_path, capsys):
    from scenarios.lang.fields import MAX_NAME_CHARS

    long = "a" * 300
    f = tmp_path / "long.toml"
    f.write_text(GOOD.replace('"tiny"', f'"{long}"'))
    rc, err = cli(capsys, "validate", f)
    assert rc == 2 and f"is 300 characters long; at most {MAX_NAME_CHARS}" in err
    f.write_text(GOOD.replace('"tiny"', f'"{"a" * MAX_NAME_CHARS}"'))
    assert cli(capsys, "validate", f)[0] == 0
    one_with(problems_of(top(f'compare = ["{long}"]\n') + f'[[arm]]\nname = "{long}"\n'), "arm[0].name", "at most")
    one_with(campaign_problems(CAMPAIGN.replace('name = "c"', f'name = "{long}"')), "name = ", "at most")


@pytest.mark.parametrize("text,field", [
    (GOOD.replace("duration_s = 2.0", "duration_s = 1e-9"), "duration_s = 1e-09"),
    (GOOD + "[[push]]\nt_s = 0.5\nforce_n = [10.0, 0.0, 0.0]\nduration_s = 1e-9\n", "push[0].duration_s = 1e-09"),
], ids=["run", "push"])
def test_zero_step_run_or_push_is_refused(text, field):
    one_with(problems_of(text), field, "at least one communication step (0.005 s)")


def test_duration_flag_of_zero_steps_is_refused_before_running(tmp_path, capsys):
    f = tmp_path / "tiny.toml"
    f.write_text(GOOD)
    rc, err = cli(capsys, "run", f, "--duration", "1e-9", "--regulator", "inprocess", "--out", tmp_path / "o")
    assert rc == 2 and "--duration = 1e-09: must be at least one communication step" in err
    assert not (tmp_path / "o").exists()


def test_schedules_beyond_the_size_limit_are_one_problem():
    from scenarios.lang.sections import MAX_SCHEDULE_POINTS

    doc = tomllib.loads(GOOD)
    doc["push"] = [{"t_s": 0.5, "force_n": [1.0, 0.0, 0.0], "duration_s": 0.1}] * (MAX_SCHEDULE_POINTS + 1)
    with pytest.raises(ScenarioError) as info:
        spec.parse_scenario(doc, check_plant=False)
    assert info.value.problems == [f"push: {MAX_SCHEDULE_POINTS + 1} [[push]] entries; at most {MAX_SCHEDULE_POINTS}"]


# --------------------------------------------------------------------------- the plant FMU's ranges
TERRAIN = "[terrain]\nmax_height_m = 0.1\nmax_slope_deg = 10.0\nseed = {seed}\n"


def test_terrain_seed_beyond_the_plant_fmu_parameter_is_refused():
    from fmu_src.plant_fmu.fmu_core import PARAM_SPECS

    top = next(s for s in PARAM_SPECS if s.name == "terrain_seed").max
    one_with(problems_of(GOOD + TERRAIN.format(seed=2**63 - 1)), "terrain.seed = 9223372036854775807",
             f"must be in [0, {top}]", "terrain_seed")
    spec.parse_scenario(tomllib.loads(GOOD + TERRAIN.format(seed=top)), check_plant=False)


def test_pushes_that_sum_beyond_the_plant_input_are_refused():
    from fmu_src.plant_fmu.fmu_core import INPUT_SPECS

    top = next(s for s in INPUT_SPECS if s.name == "push_fy").max
    each = 2000.0  # the most one push may have; three together pass the plant's input range
    pushes = "".join(f"[[push]]\nt_s = {t}\nforce_n = [0.0, {each}, 0.0]\nduration_s = 0.2\n" for t in (1.0, 1.1, 1.15))
    assert 3 * each > top >= 2 * each
    one_with(problems_of(GOOD + pushes), "push (sum along y at t = 1.15 s) = 6000", f"[{-top:g}, {top:g}] N")
    spec.parse_scenario(tomllib.loads(GOOD + pushes.replace("1.15", "1.2")), check_plant=False)  # 2 at a time


def test_plant_fmu_run_refuses_what_the_fmu_cannot_carry(tmp_path, capsys):
    f = tmp_path / "flat.toml"
    f.write_text(GOOD + TERRAIN.format(seed=3) + "flat_radius_m = 2.0\n")
    rc, err = cli(capsys, "run", f, "--plant", "fmu", "--regulator", "inprocess", "--out", tmp_path / "o")
    assert rc == 2 and "terrain.flat_radius_m = 2.0: the CassiePlant FMU has no parameter for it" in err, err
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- campaigns
def test_samples_times_grid_beyond_the_limit_refused_before_expansion(tmp_path, capsys):
    grid = "[factors.seed]\ndist = \"grid\"\nvalues = [" + ", ".join(map(str, range(10))) + "]\n"
    text = CAMPAIGN.replace("samples = 8", "samples = 100000") + grid
    one_with(campaign_problems(text), "samples = 100000", "x 10 grid cells = 1000000 samples",
             f"at most {campaign_spec.MAX_SAMPLES}")
    two = "".join(f"[factors.{n}]\ndist = \"grid\"\nvalues = [" + ", ".join(f"{0.5 + i / 1000}" for i in range(1000))
                  + "]\n" for n in ("torso_mass_kg", "joint_damping_scale"))
    c = tmp_path / "c.toml"
    c.write_text(CAMPAIGN.replace("[factors.joint_damping_scale]\ndist = \"uniform\"\nlow = 0.5\nhigh = 2.0\n", two)
                 .replace("samples = 8", "samples = 1"))
    t0 = time.perf_counter()
    rc, err = cli(capsys, "campaign", c, "--dry-run")
    assert rc == 2 and "1000000 samples; at most" in err, err
    assert time.perf_counter() - t0 < 60  # refused before drawing 10^6 samples (that took minutes and GBs)


def test_task_timeout_beyond_what_the_waits_take_is_refused(tmp_path, capsys):
    one_with(campaign_problems("task_timeout_s = 1e308\n" + CAMPAIGN), "task_timeout_s = 1e+308",
             f"must be <= {campaign_spec.MAX_TASK_TIMEOUT_S:g}")
    c = tmp_path / "c.toml"
    c.write_text(CAMPAIGN)
    rc, err = cli(capsys, "campaign", c, "--dry-run", "--task-timeout", "1e308")
    assert rc == 2 and "--task-timeout 1e+308: must be within (0, 604800] s" in err, err


# --------------------------------------------------------------------------- FMUs of the wrong kind
def test_the_plant_fmu_as_regulator_and_the_regulator_as_plant_refused_up_front(tmp_path, tmp_path_factory, capsys,
                                                                                 built_fmu, build_module):
    plant_fmu = built_plant_fmu(tmp_path_factory, build_module)
    f = tmp_path / "tiny.toml"
    f.write_text(GOOD)
    rc, err = cli(capsys, "run", f, "--fmu", plant_fmu, "--out", tmp_path / "o")
    assert rc == 2 and "model 'CassiePlant' is not a regulator FMU" in err and "--plant-fmu" in err, err
    rc, err = cli(capsys, "run", f, "--plant", "fmu", "--plant-fmu", built_fmu, "--regulator", "inprocess",
                  "--out", tmp_path / "o")
    assert rc == 2 and "model 'AdaptiveVelocityRegulator' is not the CassiePlant FMU" in err, err
    rc, err = cli(capsys, "campaign", "smoke", "--fmu", plant_fmu, "--dry-run")
    assert rc == 2 and "is not a regulator FMU" in err, err
    assert not (tmp_path / "o").exists()
