"""The CommandSource FMU (fmu_src/command_source/): FMI 2.0 and FMI 3.0 from one C source,
built as build.py builds them, driven by fmpy in a subprocess (tests/support/command_source_driver.py).

* Both versions play a schedule the same way: at a communication point t the outputs hold
  the last row with time <= t, whether t is k * h or computed from integer nanoseconds.
* A bad schedule fails the instantiation (NULL), its log message naming the file, the
  line and the field; a start time before the first row fails the initialization.
* Every call the FMI state machine forbids, every set, every call of a function the FMU
  does not provide returns Error (never OK), logs why, crashes nothing and changes
  nothing: the legal calls after it give the outputs they give without it.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from fmpy import extract, read_model_description

from fmu_src.command_source import build_command_source as cs
from support import warm
from support.paths import SUPPORT_DIR

DRIVER = SUPPORT_DIR / "command_source_driver.py"
OK, ERROR = 0, 3
H = 0.005
#: A schedule with switching times on the 5 ms grid and off it (1.0123 s).
ROWS = ((0.0, (0.5, 0.0, 0.0, 0.0, 0.0, 0.0)), (0.01, (0.3, 0.1, 0.2, 30.0, 0.0, 0.0)),
        (0.02, (0.3, 0.1, 0.2, 0.0, -5.0, 1.5)), (0.0123 + 1.0, (-0.25, 0.0, -0.1, 0.0, 0.0, 0.0)))


def _schedule(rows=ROWS) -> str:
    return cs.schedule_csv((t, dict(zip(cs.NAMES, values))) for t, values in rows)


@pytest.fixture(scope="module", params=[2, 3], ids=["fmi2", "fmi3"])
def fmi(request):
    return request.param


@pytest.fixture(scope="module")
def built(tmp_path_factory, command_sources):
    """Both versions as build.py builds them (conftest.py), with :data:`ROWS` as their schedule."""
    out = tmp_path_factory.mktemp("command_source")
    return {v: cs.with_schedule(command_sources[v], _schedule(), out / f"scheduled_fmi{v}.fmu") for v in (2, 3)}


@pytest.fixture
def fmu_dir(built, fmi, tmp_path):
    """The FMU unzipped into a fresh folder (a test may edit its schedule)."""
    return Path(extract(str(built[fmi]), unzipdir=str(tmp_path / "fmu")))


def drive(fmu_dir: Path, fmi: int, calls: list) -> dict:
    proc = warm.run(DRIVER, [fmu_dir, fmi, json.dumps(calls)], timeout=120)
    assert proc.returncode == 0, f"the host process failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _expected(t: float) -> list[float]:
    """The last row of ROWS at or before t (relative tolerance 1e-9, the FMU's)."""
    values = ROWS[0][1]
    for row_t, row_values in ROWS:
        if t >= row_t - 1e-9 * max(1.0, abs(row_t)):
            values = row_values
    return list(values)


ALL = list(range(len(cs.NAMES)))
START = [["instantiate"], ["setup", 0.0], ["enter"], ["exit"]]


# ---- one source, two FMI versions ------------------------------------------------------------
def test_both_versions_are_valid_fmus_of_the_same_variables(built):
    from fmpy.validation import validate_fmu

    mds = {v: read_model_description(str(built[v]), validate=True) for v in (2, 3)}
    for v, md in mds.items():
        assert validate_fmu(str(built[v])) == [], v
        outputs = [(x.name, x.valueReference, x.unit) for x in md.modelVariables if x.causality == "output"]
        assert outputs == [(name, vr, unit) for vr, (name, unit, _) in enumerate(cs.OUTPUTS)], v
    assert [(x.name, x.causality) for x in mds[3].modelVariables if x.causality == "independent"] == [
        ("time", "independent")]
    assert mds[2].fmiVersion == "2.0" and mds[3].fmiVersion == "3.0"


@pytest.mark.parametrize("clock", ["k*h", "integer ns"])
def test_plays_the_schedule_at_every_communication_point(fmu_dir, fmi, clock):
    """1.2 s in 5 ms steps; t from k * h, or as libcosim computes it (integer nanoseconds)."""
    n = 240
    times = [k * H for k in range(n + 1)] if clock == "k*h" else [k * 5_000_000 * 1e-9 for k in range(n + 1)]
    calls = START + [["get", ALL]]
    for k in range(n):
        calls += [["step", times[k], times[k + 1] - times[k]], ["get", ALL]]
    out = drive(fmu_dir, fmi, calls + [["terminate"], ["free"]])
    gets = [r for c, r in zip(calls, out["results"]) if c[0] == "get"]
    assert gets == [_expected(t) for t in times]
    assert all(r in (OK, None) or isinstance(r, list) for r in out["results"]) and None not in out["results"]
    assert gets[202] == list(ROWS[2][1]) and gets[203] == list(ROWS[3][1])  # the row at 1.0123 s: from 1.015 s


def test_fmi3_time_is_the_end_of_the_last_step(fmu_dir, fmi):
    if fmi == 2:
        pytest.skip("FMI 2.0 has no independent variable to get")
    out = drive(fmu_dir, 3, START + [["get", [6]], ["step", 0.0, H], ["step", H, H], ["get", [6]]])
    assert out["results"][4:] == [[0.0], OK, OK, [2 * H]]


# ---- bad schedules: each problem named -------------------------------------------------------
HEADER = cs.HEADER
BAD_SCHEDULES = {
    "missing": (None, "cannot open the schedule"),
    "wrong header": ("time,vx_des,vy_des\n0,0.5,0\n", 'line 1: the header must be "' + HEADER + '"'),
    "no rows": (HEADER + "\n", "has no rows"),
    "not a number": (HEADER + "\n0,0.5,0,0,0,0,0\n1,0.5,abc,0,0,0,0\n", 'line 3: vy_des = "abc" is not a finite number'),
    "nan": (HEADER + "\n0,0.5,0,0,nan,0,0\n", 'line 2: push_fx = "nan" is not a finite number'),
    "infinite time": (HEADER + "\ninf,0.5,0,0,0,0,0\n", 'line 2: time = "inf" is not a finite number'),
    "too few columns": (HEADER + "\n0,0.5,0,0,0,0\n", "line 2: 7 comma-separated numbers expected"),
    "too many columns": (HEADER + "\n0,0.5,0,0,0,0,0,1\n", "line 2: 7 comma-separated numbers expected"),
    "empty field": (HEADER + "\n0,0.5,,0,0,0,0\n", 'line 2: vy_des = "" is not a finite number'),
    "time not increasing": (HEADER + "\n0,0.5,0,0,0,0,0\n0,0.3,0,0,0,0,0\n",
                            "line 3: time = 0 s must be after the previous row's 0 s"),
    "time going back": (HEADER + "\n1,0.5,0,0,0,0,0\n0.5,0.3,0,0,0,0,0\n",
                        "line 3: time = 0.5 s must be after the previous row's 1 s"),
    "line too long": (HEADER + "\n0,0.5,0,0,0,0," + "0" * 5000 + "\n", "line 2: longer than 4094 characters"),
    # FMI log messages are UTF-8: the file's bytes are shown escaped, not copied
    "not UTF-8": ("\xff\xfe garbage\n", 'line 1: the header must be "' + HEADER + '", not "\\xff\\xfe garbage"'),
    "not UTF-8 number": (HEADER + "\n0,0.5,0,0,0,0,\xb5\n", 'line 2: push_fz = "\\xb5" is not a finite number'),
}


@pytest.mark.parametrize("case", list(BAD_SCHEDULES))
def test_a_bad_schedule_fails_instantiation_naming_the_problem(fmu_dir, fmi, case):
    text, message = BAD_SCHEDULES[case]
    schedule = fmu_dir / "resources" / "schedule.csv"
    if text is None:
        schedule.unlink()
    else:
        schedule.write_bytes(text.encode("latin-1"))
    out = drive(fmu_dir, fmi, [["instantiate"]])
    assert out["results"] == [None]
    errors = [m for status, category, m in out["log"] if status == ERROR]
    assert len(errors) == 1 and message in errors[0], out["log"]
    assert "schedule.csv" in errors[0]


def test_a_start_before_the_first_row_is_refused(fmu_dir, fmi):
    (fmu_dir / "resources" / "schedule.csv").write_text(_schedule(((1.0, ROWS[0][1]),)))
    out = drive(fmu_dir, fmi, [["instantiate"], ["setup", 0.5], ["enter"]])
    assert ERROR in out["results"][1:] and out["results"][0] == OK
    assert any("startTime = 0.5 s is before the schedule's first row (t = 1 s)" in m for _, _, m in out["log"])


# ---- illegal calls: Error, a reason, nothing changed ------------------------------------------
#: (name, the calls before, the illegal call, a substring of its log message).
ILLEGAL = [
    ("get before initialization", [["instantiate"]], ["get", [0]], "not allowed in state"),
    ("step before initialization", [["instantiate"]], ["step", 0.0, H], "not allowed in state"),
    ("step in initialization mode", [["instantiate"], ["setup", 0.0], ["enter"]], ["step", 0.0, H],
     "not allowed in state"),
    ("enter twice", START[:3], ["enter"], "not allowed in state"),
    ("exit before enter", [["instantiate"]], ["exit"], "not allowed in state"),
    ("terminate in initialization mode", START[:3], ["terminate"], "not allowed in state"),
    ("set an output", START, ["set", 0, 1.0], "has no inputs or parameters"),
    ("get an unknown value reference", START, ["get", [0, 99]], "99"),
    ("step from the wrong time", START + [["step", 0.0, H]], ["step", 0.0, H], "must equal the end of the last step"),
    ("step of zero length", START, ["step", 0.0, 0.0], "communicationStepSize = 0"),
    ("step of negative length", START, ["step", 0.0, -H], "communicationStepSize = -0.005"),
    ("step of NaN length", START, ["step", 0.0, float("nan")], "communicationStepSize = nan"),
    ("step from NaN", START, ["step", float("nan"), H], "currentCommunicationPoint = nan"),
    ("get the FMU state", START, ["getFMUState"], "not provided"),
]


@pytest.mark.parametrize("name, before, illegal, message", ILLEGAL, ids=[c[0] for c in ILLEGAL])
def test_an_illegal_call_returns_error_and_changes_nothing(fmu_dir, fmi, name, before, illegal, message):
    """The illegal call returns Error with a log message; the same legal calls after it give
    the same results as without it (the instance is unchanged)."""
    t = sum(c[2] for c in before if c[0] == "step")  # where the legal steps before it ended
    after = [c for c in START if c not in before] + [["step", t, H], ["step", t + H, H], ["get", ALL],
                                                     ["terminate"], ["free"]]
    with_it = drive(fmu_dir, fmi, before + [illegal] + after)
    without = drive(fmu_dir, fmi, before + after)
    n = len(before)
    assert with_it["results"][:n] == without["results"][:n]
    assert with_it["results"][n] == ERROR, with_it
    assert with_it["results"][n + 1:] == without["results"][n:]
    assert without["results"][-3] == _expected(t + 2 * H)
    refused = [m for status, _, m in with_it["log"] if status == ERROR]
    assert len(refused) == 1 and "refused" in refused[0] and message in refused[0], with_it["log"]


def test_after_terminate_only_getters_reset_and_free(fmu_dir, fmi):
    out = drive(fmu_dir, fmi, START + [["step", 0.0, H], ["terminate"], ["step", H, H], ["set", 0, 1.0],
                                       ["get", ALL], ["reset"], ["setup", 0.0], ["enter"], ["exit"],
                                       ["step", 0.0, H], ["get", ALL], ["free"]])
    assert out["results"][6:8] == [ERROR, ERROR]
    assert out["results"][8] == _expected(H)
    assert out["results"][9:14] == [OK] * 5 and out["results"][14] == _expected(H)


def test_fmi3_refuses_what_it_does_not_provide(fmu_dir, fmi):
    if fmi == 2:
        pytest.skip("FMI 3.0 functions")
    out = drive(fmu_dir, 3, [["instantiate", {"eventModeUsed": True}]])
    assert out["results"] == [None] and "no event mode" in out["log"][0][2]
    calls = START + [["call", "fmi3EnterEventMode"], ["call", "fmi3EnterConfigurationMode"],
                     ["call", "fmi3EnterStepMode"], ["set", 6, 1.0], ["get", [6]]]
    out = drive(fmu_dir, 3, calls)
    assert out["results"][4:] == [ERROR, ERROR, ERROR, ERROR, [0.0]]
    assert len([m for s, _, m in out["log"] if s == ERROR]) == 4


def test_the_sources_of_both_versions_are_one_core(built):
    """FMI 2.0 and 3.0 ship the same cmdsrc.c/cmdsrc.h, each with its thin layer only."""
    import zipfile

    files = {}
    for v in (2, 3):
        with zipfile.ZipFile(built[v]) as z:
            files[v] = {n[len("sources/"):]: z.read(n) for n in z.namelist() if n.startswith("sources/")}
    assert files[2]["cmdsrc.c"] == files[3]["cmdsrc.c"] and files[2]["cmdsrc.h"] == files[3]["cmdsrc.h"]
    assert "cmdsrc_fmi3.c" not in files[2] and "cmdsrc_fmi2.c" not in files[3]
    assert b"fmiBuildDescription" in files[3]["buildDescription.xml"]
