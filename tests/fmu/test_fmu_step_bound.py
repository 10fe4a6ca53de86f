"""Communication steps an FMU cannot finish in bounded time are refused.

The plant FMU runs 0.5 ms MuJoCo steps in a Python loop, 0.13 s of wall time per simulated
second on this project's machine; a doStep of 1e9 s would run for years and FMI 2.0 gives no
way to interrupt it (calls on one instance are never concurrent, ``canRunAsynchronuously``
is false).  So the plant has a documented maximum communication step
(``fmu_src.plant_fmu.fmu_core.MAX_STEP_S``): a longer one is fmi2Error naming it, refused by the guard
before it reaches Python, and the instance stays where it was.  The regulator FMUs make one
call per doStep whatever its length (no maximum); the native ones refuse a step whose end
time overflows (as the pythonfmu FMU's guard does).
"""
import pytest
from fmpy.fmi1 import FMICallException

from support.native_support import logged_slave
from fmu_src.plant_fmu.fmu_core import MAX_STEP_S
from support.plant_fmu_support import built_plant_fmu

OK, ERROR = 0, 3
#: A refused step must come back at once; 5 s of wall time is far above the refusal (microseconds)
#: and far below the old unbounded loop (1e9 s simulated: about four years).
REFUSAL_WALL_S = 5.0


@pytest.fixture(scope="module")
def plant_fmu_dir(tmp_path_factory, build_module, unzip):
    return unzip(built_plant_fmu(tmp_path_factory, build_module), tmp_path_factory.mktemp("plant_unzipped"))


def test_plant_refuses_a_step_beyond_its_maximum_at_once(plant_fmu_dir, raw_host):
    # the host process gets 300 s: the refusals, one 10 s step (about 1.3 s here) and the set-up
    r = raw_host(plant_fmu_dir, "step_bound", {"max_step": MAX_STEP_S}, timeout=300)
    for label in ("1e9 s", "1e300 s", "just over the maximum"):
        assert r[label]["status"] == ERROR, (label, r[label])
        assert r[label]["wall_s"] < REFUSAL_WALL_S, (label, r[label])
        assert any(f"exceeds the maximum communication step {MAX_STEP_S:g} s" in m for m in r[label]["log"]), r[label]
    assert r["then a 5 ms step"] == OK and r["then the maximum"] == OK, r
    print(f"\nplant: a {MAX_STEP_S:g} s step took {r['maximum_wall_s']:.2f} s of wall time")


def test_plant_slave_names_the_maximum_too():
    """Without the guard (the slave's own check) the same rule and message."""
    from fmu_src.plant_fmu import fmu_core

    assert fmu_core.plant_steps(MAX_STEP_S) == round(MAX_STEP_S / fmu_core.PLANT_STEP_S)
    assert fmu_core.plant_steps(MAX_STEP_S + fmu_core.PLANT_STEP_S) is None
    for h in (1e9, 1e300, MAX_STEP_S + fmu_core.PLANT_STEP_S):
        assert f"exceeds the maximum communication step {MAX_STEP_S:g} s" in fmu_core.step_problem(h)
    assert fmu_core.step_problem(MAX_STEP_S) is None


@pytest.mark.parametrize("fmi", [2, 3])
def test_native_refuses_a_step_whose_end_time_overflows(native_fmus, fmi):
    messages = []
    s = logged_slave(native_fmus[fmi], messages)
    start = 1.5e308
    if s.fmi3:
        s.fmu.enterInitializationMode(startTime=start)
    else:
        s.fmu.setupExperiment(startTime=start)
        s.fmu.enterInitializationMode()
    s.fmu.exitInitializationMode()
    with pytest.raises(FMICallException) as info:
        s.fmu.doStep(start, 1e308)
    assert info.value.status == ERROR
    assert any("currentCommunicationPoint + communicationStepSize overflows" in m for m in messages), messages
    s.fmu.doStep(start, 1.0)  # the instance is where it was
    s.close()
