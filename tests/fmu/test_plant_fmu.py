"""The CassiePlant FMU on its own, exactly as build.py builds it.

Calls that could crash run in a subprocess (tests/support/fmi/driver.py, the regulator's driver:
it reports each call's FMI status), so a crash fails a test instead of killing pytest.
"""
import ast
import json
import math
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from plant.perturbation import Perturbation
from plant.terrain import TerrainSpec
from support import warm
from support.paths import REPO_ROOT, SUPPORT_DIR
from support.plant_fmu_support import Plant, built_plant_fmu, status_of

DRIVER = SUPPORT_DIR / "fmi" / "driver.py"
OK, ERROR = 0, 3
H = 0.005
INIT = [["instantiate"], ["setup", 0.0], ["enter"], ["exit"]]


@pytest.fixture(scope="module")
def plant_fmu(tmp_path_factory, build_module):
    return built_plant_fmu(tmp_path_factory, build_module)


@pytest.fixture(scope="module")
def plant_dir(plant_fmu, unzip, tmp_path_factory):
    """The plant FMU extracted (once per module)."""
    return unzip(plant_fmu, tmp_path_factory.mktemp("plant_unzipped"))


def run_calls(fmu_dir, calls, env=None):
    """(statuses, the FMU's log) of `calls` in a fresh process; the process must not die."""
    proc = warm.run(DRIVER, [fmu_dir, json.dumps(calls)], timeout=300, env=env)
    assert proc.returncode == 0, f"driver died (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    lines = proc.stdout.strip().splitlines()
    return [r["status"] for r in json.loads(lines[-1])], "\n".join(lines[:-1]) + proc.stderr


# ---- the file -------------------------------------------------------------------------------
def test_fmpy_validate_and_fmutool_check_are_clean(plant_fmu):
    assert validate_fmu(str(plant_fmu)) == []
    fmutool = Path(sys.executable).parent / "fmutool"
    proc = subprocess.run([str(fmutool), "-input", str(plant_fmu), "-check"], capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "compliant with FMI-2.0" in out and "No semantic error" in out, out


def test_variables_have_units_and_the_regulators_names(plant_fmu, built_fmu):
    root = ET.fromstring(zipfile.ZipFile(plant_fmu).read("modelDescription.xml"))
    units = {u.get("name") for u in root.find("UnitDefinitions")}
    reals = [v for v in root.find("ModelVariables") if v[0].tag == "Real"]
    assert reals and all(v[0].get("unit") in units for v in reals), [v.get("name") for v in reals
                                                                      if v[0].get("unit") not in units]
    plant = {v.get("name"): (v.get("causality"), v[0].tag) for v in root.find("ModelVariables")}
    regulator = {v.get("name"): (v.get("causality"), v[0].tag)
                 for v in ET.fromstring(zipfile.ZipFile(built_fmu).read("modelDescription.xml")).find("ModelVariables")}
    for name in ("vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate", "step_index"):
        assert plant[name] == ("output", regulator[name][1]) and regulator[name][0] == "input", name
    deltas = [n for n, (c, _) in regulator.items() if n.startswith("delta_") and c == "output"]
    assert len(deltas) == 6 and all(plant[n] == ("input", "Real") for n in deltas)
    for name in ("vx_des", "vy_des", "yaw_rate_des", "push_fx", "push_fy", "push_fz"):
        assert plant[name] == ("input", "Real")
    assert "yaw_rate_des" not in regulator  # the turning rate is the plant's only: speeds are in the heading frame
    assert plant["fell"] == ("output", "Boolean")
    assert {"pelvis_x", "pelvis_y", "pelvis_z", "pelvis_vx", "pelvis_vy", "yaw", "yaw_rate", "stance",
            "left_foot_force", "right_foot_force"} <= set(plant)
    # The model choice is `cassie_model`: a bare `model` collides with masters' own vocabulary
    # (OMSimulator resolves it as its root model and fails); no generic names in either FMU.
    assert plant["cassie_model"] == ("parameter", "String")
    assert not {"model", "system", "root", "time"} & (set(plant) | set(regulator))


def test_model_files_and_licenses_travel_inside_not_in_the_repository(plant_fmu):
    names = set(zipfile.ZipFile(plant_fmu).namelist())
    lib = "resources/cassie_plant_lib/models/"
    for must in ("menagerie/agility_cassie/scene.xml", "menagerie/agility_cassie/cassie.xml", "menagerie/LICENSE",
                 "osu/cassie.xml", "osu/LICENSE"):
        assert lib + must in names, must
    tracked = subprocess.run(["git", "ls-files"], cwd=REPO_ROOT, capture_output=True, text=True)
    if tracked.returncode != 0:
        pytest.skip("not a git checkout")
    models = [f for f in tracked.stdout.split() if f.endswith((".obj", ".stl")) or f.endswith("cassie.xml")]
    assert models == []


def test_vendored_plant_imports_only_inside_its_package(plant_fmu):
    """The plant package travels under a private name: no absolute import may reach the host's."""
    with zipfile.ZipFile(plant_fmu) as z:
        sources = {n: z.read(n).decode() for n in z.namelist()
                   if n.startswith("resources/cassie_plant_lib/") and n.endswith(".py")}
        assert re.fullmatch(r"cassie_plant_slave_[0-9a-f]{16}", z.read("resources/slavemodule.txt").decode())
    assert any(n.endswith("fmu_src/plant_fmu/fmu_core.py") for n in sources)
    for name, text in sources.items():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                assert node.module.split(".")[0] not in ("plant", "fmu_src", "scenarios"), (name, node.module)


def test_two_builds_have_the_same_sha256(plant_fmu, build_module, tmp_path):
    again = build_module.build_plant_fmu(tmp_path)
    assert build_module.sha256_of(again) == build_module.sha256_of(plant_fmu)


# ---- the state machine and bad input ------------------------------------------------------------
@pytest.mark.parametrize("case, calls", [
    ("doStep before initialization", [["instantiate"], ["step", 0.0, H]]),
    ("doStep in initialization mode", [["instantiate"], ["setup", 0.0], ["enter"], ["step", 0.0, H]]),
    ("exitInitializationMode twice", INIT + [["exit"]]),
    ("setupExperiment after initialization", INIT + [["setup", 0.0]]),
    ("get before initialization", [["instantiate"], ["get", "vx"]]),
    ("set an output", INIT + [["set", "vx", 0.1]]),
    ("set a fixed parameter after initialization", INIT + [["set", "torso_mass_kg", 12.0]]),
    ("terminate twice", INIT + [["terminate"], ["terminate"]]),
    ("doStep after terminate", INIT + [["step", 0.0, H], ["terminate"], ["step", H, H]]),
    ("set after terminate", INIT + [["terminate"], ["set", "vx_des", 0.1]]),
    ("step of 0.7 ms", INIT + [["step", 0.0, 0.0007]]),
    ("step of 0.25 ms", INIT + [["step", 0.0, 0.00025]]),
    ("zero step", INIT + [["step", 0.0, 0.0]]),
    ("step not starting at the current time", INIT + [["step", 0.0, H], ["step", 3 * H, H]]),
    ("NaN input", INIT + [["set", "delta_swing_knee", math.nan]]),
    ("push beyond its range", INIT + [["set", "push_fx", 1e6]]),
    ("torso mass above 100 kg", [["instantiate"], ["set", "torso_mass_kg", 150.0]]),
    ("garbage serialized state", INIT + [["deserialize", -1]]),
])
def test_illegal_call_is_refused_with_an_error_and_the_instance_survives(plant_dir, case, calls):
    statuses, _ = run_calls(plant_dir, calls + [["free"]])
    assert statuses[:-2] == [OK] * (len(calls) - 1), case
    assert statuses[-2] == ERROR, case
    assert statuses[-1] == OK


def test_a_wrong_step_is_named_and_changes_nothing(plant_dir):
    statuses, log = run_calls(plant_dir, INIT + [["step", 0.0, 0.0012], ["get", "plant_time"], ["step", 0.0, 0.001],
                                                  ["get", "plant_time"]])
    assert statuses == [OK] * 4 + [ERROR, OK, OK, OK], log
    assert "communicationStepSize = 0.0011999999999999999 s: must be a whole multiple of the plant step 0.0005 s" in log


def test_bad_parameters_are_refused_naming_field_and_range_all_at_once(plant_dir):
    bad = {"torso_mass_kg": 0.0, "terrain_max_height_m": 0.2, "terrain_max_slope_deg": 0.0, "terrain_size_m": 80.0}
    calls = [["instantiate"], *[["set", k, v] for k, v in bad.items()], ["setup", 0.0], ["enter"], ["exit"],
             ["set", "torso_mass_kg", 20.0], ["set", "terrain_max_slope_deg", 15.0], ["set", "terrain_size_m", 10.0],
             ["exit"], ["step", 0.0, H]]
    statuses, log = run_calls(plant_dir, calls)
    assert statuses == [OK] * 7 + [ERROR] + [OK] * 5, log
    # the very messages of the plant's own validation (the scenario files run the same one)
    expected = Perturbation(torso_mass_kg=0.0, terrain=TerrainSpec(max_height_m=0.2, max_slope_deg=0.0, seed=0,
                                                                   size_m=80.0)).problems()
    assert len(expected) == 3
    for problem in expected:
        assert f"fmi2ExitInitializationMode refused: {problem}" in log, (problem, log)


def test_model_name_is_checked(plant_dir):
    p = Plant(plant_dir)
    assert status_of(p.set, "cassie_model", "cassie3") == ERROR
    p.fmu.setupExperiment(startTime=0.0)
    p.fmu.enterInitializationMode()
    assert p.get("cassie_model") == b"menagerie"  # refused: unchanged
    assert status_of(p.set, "cassie_model", "osu") == OK
    p.fmu.exitInitializationMode()
    assert p.get("cassie_model") == b"osu" and not p.step()[-1]  # the OSU model stands and steps
    p.free()


def test_guard_has_no_memory_or_undefined_behaviour_errors(build_module, unzip, tmp_path):
    """The plant's FMI guard built with AddressSanitizer + UBSan (build.py's sanitize build), driven
    through legal and illegal calls by fmpy and by libcosim's worker threads: no finding."""
    from test_fmu_sanitize import _preload

    sanitized = build_module.build_plant_fmu(tmp_path, sanitize=True)
    reports = tmp_path / "reports"
    reports.mkdir()
    env = dict(os.environ, LD_PRELOAD=_preload(),
               ASAN_OPTIONS=f"detect_leaks=0:halt_on_error=1:log_path={reports}/asan",
               UBSAN_OPTIONS=f"print_stacktrace=1:halt_on_error=1:log_path={reports}/ubsan")
    calls = [["instantiate"], ["step", 0.0, H], ["set", "torso_mass_kg", 0.0], ["setup", 0.0], ["enter"], ["exit"],
             ["set", "torso_mass_kg", 20.0], ["exit"], ["step", 0.0, 0.0007], ["step", 0.0, H], ["set", "vx", 1.0],
             ["get_state"], ["step", H, H], ["serialize", 0], ["deserialize", 0], ["set_state", 1],
             ["deserialize", -1], ["terminate"], ["step", 2 * H, H], ["reset"], ["setup", 0.0], ["enter"], ["exit"],
             ["step", 0.0, 2 * H], ["free"]]
    statuses, log = run_calls(unzip(sanitized, tmp_path / "fmu"), calls, env=env)
    assert sorted(reports.iterdir()) == [], log
    assert statuses == [OK, ERROR, OK, OK, OK, ERROR, OK, OK, ERROR, OK, ERROR] + [OK] * 5 + [ERROR, OK, ERROR] + \
        [OK] * 6, log
    # libcosim steps FMUs in worker threads Python did not create: the guard's thread-state path
    osp = tmp_path / "osp"
    osp.mkdir()
    Path(sanitized).replace(osp / "CassiePlant.fmu")
    (osp / "OspSystemStructure.xml").write_text(ONE_PLANT_OSP)
    proc = subprocess.run([sys.executable, "-c", LIBCOSIM_STEPS, str(osp)], env=env, capture_output=True, text=True,
                          timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "stepped" in out, out[-3000:]
    assert sorted(reports.iterdir()) == [], out[-3000:]


ONE_PLANT_OSP = """<?xml version="1.0" encoding="utf-8"?>
<OspSystemStructure xmlns="http://opensimulationplatform.com/MSMI/OSPSystemStructure" version="0.1">
  <StartTime>0.0</StartTime><BaseStepSize>0.005</BaseStepSize><Algorithm>fixedStep</Algorithm>
  <Simulators><Simulator name="plant" source="CassiePlant.fmu" stepSize="0.005"/></Simulators>
</OspSystemStructure>
"""
LIBCOSIM_STEPS = """
import sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
log_output_level(CosimLogLevel.ERROR)
execution = CosimExecution.from_osp_config_file(sys.argv[1])
assert execution.step(200)
del execution
print("stepped")
"""


# ---- behaviour ----------------------------------------------------------------------------------
def _inputs(k):
    """Deterministic, varied inputs (offsets like a regulator's, a push from step 150 to 170)."""
    return {"vx_des": 0.5, "delta_swing_hip_pitch": 0.02 * math.sin(0.05 * k), "delta_stance_knee": -0.01,
            "push_fx": 40.0 if 150 <= k < 170 else 0.0}


def test_state_round_trip_is_bit_exact(plant_dir):
    p = Plant(plant_dir).init(torso_mass_kg=20.0)
    for k in range(300):
        p.step(**_inputs(k))
    state = p.fmu.getFMUstate()
    blob = bytes(p.fmu.serializeFMUstate(state))
    t_saved = p.t
    straight = [p.step(**_inputs(k)) for k in range(300, 500)]
    p.fmu.setFMUstate(state)
    p.t = t_saved
    again = [p.step(**_inputs(k)) for k in range(300, 500)]
    fresh = Plant(plant_dir, name="fresh")  # not initialized; its fixed parameters must be the state's
    assert status_of(fresh.fmu.deSerializeFMUstate, blob) == ERROR  # saved with 20 kg, this one has 10.33 kg
    fresh.set("torso_mass_kg", 20.0)
    fresh.fmu.setFMUstate(fresh.fmu.deSerializeFMUstate(blob))
    fresh.t = t_saved
    restored = [fresh.step(**_inputs(k)) for k in range(300, 500)]
    assert straight == again == restored  # exact equality of every output, Real, Integer and Boolean
    assert straight[-1] != straight[0] and fresh.get("torso_mass_kg") == 20.0
    p.free()
    fresh.free()


def test_a_state_of_the_other_model_is_refused_and_changes_nothing(plant_dir):
    """The guard compares numeric fixed parameters; the String ``cassie_model`` is the slave's to check."""
    osu = Plant(plant_dir, name="osu").init(cassie_model="osu")
    osu.step(vx_des=0.5)
    blob = bytes(osu.fmu.serializeFMUstate(osu.fmu.getFMUstate()))
    menagerie = Plant(plant_dir, name="menagerie").init()
    before = menagerie.step()
    state = menagerie.fmu.deSerializeFMUstate(blob)  # the numeric fixed parameters match: accepted so far
    assert status_of(menagerie.fmu.setFMUstate, state) == ERROR
    assert menagerie.get("cassie_model") == b"menagerie" and menagerie.outputs() == before
    for p in (osu, menagerie):
        p.free()


def test_walks_10s_at_half_a_metre_per_second_through_fmpy(plant_dir):
    names = ["vx", "pelvis_x", "fell", "step_index"]
    r = simulate_fmu(str(plant_dir), stop_time=10.0, output_interval=H, start_values={"vx_des": 0.5}, output=names)
    assert not r["fell"].any()
    last = r["time"] >= 5.0
    # No regulator here: the calibrated gait alone settles about 0.015 m/s slow; 0.05 m/s is the
    # walking tests' criterion for "walks at the command".
    assert abs(np.mean(r["vx"][last]) - 0.5) < 0.05
    assert r["pelvis_x"][-1] > 3.0 and r["step_index"][-1] > 20


def test_a_fall_is_an_output_and_the_simulation_goes_on(plant_dir):
    p = Plant(plant_dir).init(vx_des=0.5)
    fell_at = None
    for k in range(600):
        out = dict(zip([v.name for v in p.md.modelVariables if v.causality == "output"],
                       p.step(push_fy=4000.0 if 300 <= k < 330 else 0.0)))
        if out["fell"] and fell_at is None:
            fell_at = k
    assert fell_at is not None and fell_at >= 300
    assert out["fell"] and all(math.isfinite(v) for v in out.values() if isinstance(v, float))
    p.free()


FMUS_AND_HOST_PLANT = """
import sys
from pathlib import Path
import numpy as np
import plant.sim                                     # the host's own plant package, imported first
from fmu_src.plant_fmu.fmu_core import INPUT_NAMES, advance, start
from fmu_src.core.avr_core import Regulator, RegulatorInputs, RegulatorParams
sys.path.insert(0, {tests!r})
from support.plant_fmu_support import Plant
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave

plant_dir, regulator_dir = sys.argv[1], sys.argv[2]
md = read_model_description(regulator_dir)
vr = {{v.name: v.valueReference for v in md.modelVariables}}
reg = FMU2Slave(guid=md.guid, unzipDirectory=regulator_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName="avr")
reg.instantiate(); reg.setupExperiment(startTime=0.0); reg.enterInitializationMode(); reg.exitInitializationMode()
fmu = Plant(plant_dir).init(vx_des=0.5, yaw_rate_des=0.3)
walker = start(dict(cassie_model="menagerie", torso_mass_kg=10.33, torso_com_offset_x_m=0.0, torso_com_offset_y_m=0.0,
                    torso_com_offset_z_m=0.0, joint_damping_scale=1.0, terrain_max_height_m=0.0,
                    terrain_max_slope_deg=10.0, terrain_seed=0, terrain_size_m=20.0))
core = Regulator(RegulatorParams())
inputs = {{n: 0.0 for n in INPUT_NAMES}}
inputs["vx_des"], inputs["yaw_rate_des"] = 0.5, 0.3
deltas = ["delta_swing_hip_pitch", "delta_swing_knee", "delta_swing_hip_roll", "delta_stance_hip_roll",
          "delta_stance_hip_pitch", "delta_stance_knee"]
for k in range(400):                                 # the FMU pair and the in-process pair side by side
    sensed = {{n: fmu.get(n) for n in ("vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate")}}
    reg.setReal([vr[n] for n in sensed] + [vr["vx_des"]], list(sensed.values()) + [0.5])
    reg.setInteger([vr["step_index"]], [fmu.get("step_index")])
    reg.doStep(k * 0.005, 0.005)
    offsets = dict(zip(deltas, reg.getReal([vr[n] for n in deltas])))
    out_fmu = fmu.step(**offsets)
    mine = walker.regulator_inputs()
    ref = core.step(RegulatorInputs(vx_des=0.5, **mine), 0.005)
    out_in = advance(walker, dict(inputs, **{{n: ref[n] for n in deltas}}), 10)
    assert offsets == {{n: ref[n] for n in deltas}}, k
    assert out_fmu == tuple(out_in[v.name] for v in fmu.md.modelVariables if v.causality == "output"), k
import plant as host_plant
assert Path(host_plant.__file__).resolve().parent == Path({repo!r}) / "plant", host_plant.__file__
private = [m for m in sys.modules if m.startswith("_cassie_plant_") and m.endswith(".plant.sim")]
assert len(private) == 1 and Path(sys.modules[private[0]].__file__).is_relative_to(fmu.fmu.unzipDirectory)
print("same", out_fmu[0], private[0])
"""


def test_plant_fmu_regulator_fmu_and_the_hosts_plant_in_one_process(plant_dir, fmu_dir):
    """Both FMUs and the repository's plant package in one process: each uses its own code and
    the FMU pair gives bit for bit what the in-process pair gives."""
    script = FMUS_AND_HOST_PLANT.format(tests=str(REPO_ROOT / "tests"), repo=str(REPO_ROOT))
    proc = subprocess.run([sys.executable, "-c", script, str(plant_dir), str(fmu_dir)], capture_output=True,
                          text=True, timeout=300, cwd=REPO_ROOT)
    assert proc.returncode == 0 and "same" in proc.stdout, proc.stdout[-2000:] + proc.stderr[-3000:]
