"""The CassiePlant FMU's floor and link parameters (floor_friction, floor_slope_deg,
floor_cross_slope_deg, link_mass_scale_<link>): refused out of range naming the field and
its range, all at once, and carried into the model when accepted."""
import json

import pytest

from plant.perturbation import Perturbation
from support import warm
from support.paths import SUPPORT_DIR
from support.plant_fmu_support import built_plant_fmu

DRIVER = SUPPORT_DIR / "fmi" / "driver.py"
OK, ERROR = 0, 3
H = 0.005


@pytest.fixture(scope="module")
def plant_dir(tmp_path_factory, build_module, unzip):
    return unzip(built_plant_fmu(tmp_path_factory, build_module), tmp_path_factory.mktemp("plant_unzipped"))


def run_calls(fmu_dir, calls):
    proc = warm.run(DRIVER, [fmu_dir, json.dumps(calls)], timeout=300)
    assert proc.returncode == 0, f"driver died (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    lines = proc.stdout.strip().splitlines()
    return [r["status"] for r in json.loads(lines[-1])], "\n".join(lines[:-1]) + proc.stderr


def test_floor_and_link_parameters_refused_out_of_range_then_accepted(plant_dir):
    bad = {"floor_friction": 3.0, "floor_slope_deg": 20.0, "link_mass_scale_left_shin": 9.0}
    good = {"floor_friction": 0.6, "floor_slope_deg": 4.0, "floor_cross_slope_deg": -2.0,
            "link_mass_scale_left_shin": 1.3}
    calls = [["instantiate"], *[["set", k, v] for k, v in bad.items()], *[["set", k, v] for k, v in good.items()],
             ["setup", 0.0], ["enter"], ["exit"], ["step", 0.0, H], ["get", "fell"], ["get", "floor_slope_deg"]]
    statuses, log = run_calls(plant_dir, calls)
    assert statuses == [OK] + [ERROR] * len(bad) + [OK] * (len(good) + 6), log
    # each refusal names the parameter and its declared range (the plant's own ranges)
    for line in ("floor_friction = 3: out of range [0, 2]", "floor_slope_deg = 20: out of range [-15, 15]",
                 "link_mass_scale_left_shin = 9: out of range [0, 5]"):
        assert line in log, (line, log)


def test_a_zero_floor_friction_is_refused_by_the_plant_naming_its_range(plant_dir):
    """0 is inside the declared [0, 2] but the friction range is open at 0: the plant's own
    check refuses it when initialization ends, with the plant's message."""
    calls = [["instantiate"], ["set", "floor_friction", 0.0], ["setup", 0.0], ["enter"], ["exit"]]
    statuses, log = run_calls(plant_dir, calls)
    assert statuses == [OK] * 4 + [ERROR], log
    problem = Perturbation(floor_friction=0.0).problems()[0]
    assert f"fmi2ExitInitializationMode refused: {problem}" in log, log
