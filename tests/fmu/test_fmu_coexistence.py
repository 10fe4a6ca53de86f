"""Any number of builds and instances of the two pythonfmu FMUs in one host process, called as users
call them: ``fmpy.simulate_fmu("X.fmu")``, which extracts the FMU into a new temporary folder and
deletes it afterwards.

pythonfmu imports an FMU's slave module by name and keeps it in ``sys.modules``; each build
imports its code under names private to it (``fmu_src/packing/pack.py``).  Each host runs
in a process of its own (a crash fails the test instead of ending pytest) with an empty TMPDIR
that must stay empty.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

from support.paths import REPO_ROOT
from support.plant_fmu_support import built_plant_fmu
from support.pythonfmu_support import build_edited, run_host

#: The regulator's default Kp_x in the repository and in the second build.
KP_X, KP_X_B = 0.1, 0.5
#: The plant's default joint_damping_scale in the repository and in the second build.
DAMPING, DAMPING_B = 1.0, 2.0
VX = 0.7  # m/s, with vx_des = 0: the P term is Kp_x * VX
REGULATOR_OUT = ["Kp_x", "delta_swing_hip_pitch", "delta_swing_knee", "psi_x"]
PLANT_OUT = ["joint_damping_scale", "pelvis_x", "pelvis_z", "pelvis_vx", "fell"]
PLANT_STOP_S = 0.05  # 100 plant steps: enough to load the models and the gaits and to move

HOST = """
import json, logging, sys, tempfile
import fmpy
logging.basicConfig(level=logging.WARNING)
results = []
for call in json.load(sys.stdin):
    r = fmpy.simulate_fmu(call["fmu"], stop_time=call["stop_time"], start_values=call["start_values"],
                          output=call["output"])
    results.append({name: r[name].tolist() for name in r.dtype.names})
extracted = [p for p in sys.path if p.startswith(tempfile.gettempdir())]  # fmpy's (deleted) folders
public = sorted(n for n in sys.modules if n.split(".")[0] in ("plant", "fmu_src") or n.startswith(("avr", "cassie")))
print(json.dumps({"results": results, "extracted_on_sys_path": extracted, "public_modules": public}))
"""


@pytest.fixture(scope="module")
def builds(tmp_path_factory, build_module, built_fmu):
    """{"regulator": .fmu, "regulator_b": the same with Kp_x's default 0.5, "plant": .fmu,
    "plant_b": the same with joint_damping_scale's default 2.0}, each built by build.py."""
    regulator_b = build_edited(tmp_path_factory.mktemp("regulator_b"), "build_fmu", {
        "fmu_src/core/avr_specs.py": (f'_param("Kp_x", METHOD, {KP_X},', f'_param("Kp_x", METHOD, {KP_X_B},')})
    plant_b = build_edited(tmp_path_factory.mktemp("plant_b"), "build_plant_fmu", {
        "fmu_src/plant_fmu/fmu_core.py": (f'_p("joint_damping_scale", {DAMPING},', f'_p("joint_damping_scale", {DAMPING_B},')})
    return {"regulator": built_fmu, "regulator_b": regulator_b,
            "plant": built_plant_fmu(tmp_path_factory, build_module), "plant_b": plant_b}


def _call(fmu, **start_values) -> dict:
    regulator = "Regulator" in fmu.name
    if regulator:
        start_values = {"vx": VX, **start_values}
    return {"fmu": str(fmu), "start_values": start_values, "output": REGULATOR_OUT if regulator else PLANT_OUT,
            "stop_time": 0.05 if regulator else PLANT_STOP_S}


def test_simulate_fmu_five_times_alternating_plant_and_regulator(builds, tmp_path):
    """Issue 26.1: the second simulate_fmu of the plant crashed the host (its slave module, kept in
    sys.modules, pointed into the deleted folder).  The plant twice before anything else, then
    alternating with the regulator and a second plant build, each five times: every call returns
    what the first one returned, and nothing is left in TMPDIR or on sys.path."""
    order = ["plant", "plant", "plant_b"] + ["regulator", "plant", "plant_b"] * 3 + ["regulator", "plant_b"] + \
        ["regulator"]
    assert {name: order.count(name) for name in order} == {"plant": 5, "plant_b": 5, "regulator": 5}
    host, stderr = run_host(HOST, [_call(builds[name]) for name in order], tmp_path)
    results = host["results"]
    first = {}
    for name, result in zip(order, results):
        first.setdefault(name, result)
        assert result == first[name], name  # the same code and models (the gaits too) at every call
    assert first["plant"]["joint_damping_scale"][-1] == DAMPING
    assert first["plant_b"]["joint_damping_scale"][-1] == DAMPING_B
    assert first["plant"]["pelvis_x"] != first["plant_b"]["pelvis_x"]  # each build walks with its own default
    assert first["regulator"]["Kp_x"][-1] == KP_X
    assert "gait library" not in stderr, stderr  # the plant never lost its data folder
    assert host["extracted_on_sys_path"] == []
    # under public names only the entry modules, one per build: the code is under private names
    assert len(host["public_modules"]) == 3, host["public_modules"]
    assert all(re.fullmatch(r"(avr_slave|cassie_plant_slave)_[0-9a-f]{16}", n) for n in host["public_modules"])


@pytest.mark.parametrize("order", [("regulator", "regulator_b"), ("regulator_b", "regulator")])
def test_builds_differing_in_a_default_each_compute_with_their_own(builds, tmp_path, order):
    """Issue 21.1: a build differing only in Kp_x's default, loaded after the original in one process,
    reported and used the original's Kp_x (its modules came from sys.modules).  Both orders, with
    the plant between, and the original with Kp_x set to the second build's default as reference."""
    a, b = order
    calls = [_call(builds[a]), _call(builds[b]), _call(builds["plant"]), _call(builds[a]), _call(builds[b]),
             _call(builds["regulator"], Kp_x=KP_X_B)]
    results = run_host(HOST, calls, tmp_path)[0]["results"]
    by_build = {a: [results[0], results[3]], b: [results[1], results[4]]}
    expected_kp = {"regulator": KP_X, "regulator_b": KP_X_B}
    for name, runs in by_build.items():
        for r in runs:
            assert r["Kp_x"][-1] == expected_kp[name], (name, r["Kp_x"])
        assert runs[0] == runs[1], name
    # the second build computes exactly what the original computes with Kp_x = 0.5
    assert by_build["regulator_b"][0] == results[5]
    # at the first steps the output is the P term alone (psi = 0): one product, a few ulp at most
    np.testing.assert_allclose(by_build["regulator"][0]["delta_swing_hip_pitch"][-1], KP_X * VX, rtol=1e-12)
    np.testing.assert_allclose(by_build["regulator_b"][0]["delta_swing_hip_pitch"][-1], KP_X_B * VX, rtol=1e-12)
    assert results[2]["joint_damping_scale"][-1] == DAMPING


BUILD_AFTER_LOAD = """
import json, sys
from pathlib import Path
import fmpy
args = json.load(sys.stdin)
fmpy.simulate_fmu(fmpy.extract(args["fmu"], unzipdir=args["unzipped"]), stop_time=0.01)
sys.path.insert(0, args["repo"])
import build
try:
    build.build_fmu(Path(args["out"]))
except RuntimeError as exc:
    print(json.dumps({"error": str(exc)}))
else:
    print(json.dumps({"error": None}))
"""


def test_a_build_after_loading_a_pythonfmu_fmu_in_process_says_to_build_in_a_fresh_process(built_fmu, tmp_path):
    """An FMU loaded in process imports its own copy of pythonfmu, which has no binaries: a build in
    that process must say so (it once failed with a bare KeyError for the library's name)."""
    (tmp_path / "out").mkdir()
    args = {"fmu": str(built_fmu), "unzipped": str(tmp_path / "unzipped"), "repo": str(REPO_ROOT),
            "out": str(tmp_path / "out")}
    result, _ = run_host(BUILD_AFTER_LOAD, args, tmp_path)
    assert "which has no binaries" in (result["error"] or "") and "build in a fresh process" in result["error"]
    assert not list((tmp_path / "out").iterdir())
