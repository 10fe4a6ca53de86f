"""The named profiles as SSP 1.0 parameter sets (``dist/profiles/NAME.ssv``) applied four ways
give one run: ``python -m scenarios run --profile NAME`` (our master), the scenario exported
as an SSP run in libcosim and in Ecos (the profile in the regulator's parameter set), and
fmpy's ``simulate_fmu`` with ``start_values=read_profile("NAME.ssv")``.

The scenario: ``nominal`` (0.5 m/s, nominal Cassie) learning from the first completed step,
2 s, adaptive arm, plant as an FMU, our master in Jacobi order (the SSP masters' exchange).  Ecos gives our master's doubles; libcosim
differs by ulps (its step size is a difference of integer nanoseconds: see test_ssp.py,
JACOBI_AGREEMENT).  fmpy's ``simulate_fmu`` runs the regulator FMU alone: on the recorded
inputs its outputs are the numpy core's with the profile's parameters, bit for bit.
"""
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest

from fmu_src.core.avr_core import Regulator
from fmu_src.core.avr_errors import ParameterError
from fmu_src.core.avr_params import RegulatorInputs, params_from_overrides
from fmu_src.core.avr_profiles import PROFILES, profile_overrides
from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_NAMES, PARAM_BY_NAME
from scenarios.cosim import master
from scenarios.cosim.plant_fmu import plant_factory
from scenarios.errors import ScenarioError
from scenarios.lang import spec
from scenarios.ssp import system, system_run
from scenarios.ssp.profiles import profile_ssv, read_profile, write_profiles
from support.plant_fmu_support import built_plant_fmu, built_system
from support.xml_schemas import problems as schema_problems

#: A few walking steps: long enough for the networks to learn, so that every profile's run
#: differs from the others'.
DURATION_S = 2.0
#: libcosim against our master in Jacobi order (test_ssp.py: 3e-13 measured over 30 s).
JACOBI_AGREEMENT = 1e-9
#: A scenario file's head (the tests add its regulator tables).
HEAD = ('name = "s"\ndescription = "x"\nduration_s = 1.0\nseed = 1\ncompare = ["adaptive", "pd_only", "b"]\n'
        '[[command]]\nt_s = 0.0\nvx_des = 0.5\n[[arm]]\nname = "b"\n')


@pytest.fixture(scope="module")
def profiles_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("dist")
    write_profiles(out)
    return out / "profiles"


@pytest.fixture(scope="module")
def plant_fmu(tmp_path_factory, build_module):
    return built_plant_fmu(tmp_path_factory, build_module)


@pytest.fixture(scope="module")
def system_dir(tmp_path_factory, build_module, built_fmu):
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.ERROR)
    return built_system(tmp_path_factory, build_module, built_fmu)


def test_every_profile_ships_as_a_valid_ssv_of_its_differences(profiles_dir):
    assert sorted(p.name for p in profiles_dir.iterdir()) == sorted(f"{name}.ssv" for name in PROFILES)
    for name in PROFILES:
        data = (profiles_dir / f"{name}.ssv").read_bytes()
        assert data == profile_ssv(name)
        assert schema_problems("ssv", data) == []
        assert ET.fromstring(data).get("name") == name
        values = read_profile(profiles_dir / f"{name}.ssv")
        assert values == profile_overrides(name)
        assert [type(v) for v in values.values()] == [type(v) for v in profile_overrides(name).values()]


def test_read_profile_refuses_what_the_regulator_cannot_take_naming_every_problem(tmp_path):
    rows = [("weight_norm_max", "Real", "1e-05"), ("learn_settled_steps", "Real", "3.0"),
            ("learn_ramp_max_mps2", "Real", "0.25")]
    path = tmp_path / "bad.ssv"
    path.write_bytes(system.parameter_set("bad", rows))
    with pytest.raises(ParameterError) as exc:
        read_profile(path)
    assert [p.split(": ", 1)[1] for p in exc.value.problems] == [
        "weight_norm_max: not a regulator parameter", "learn_settled_steps is an Integer, the file gives an Real"]
    path.write_bytes(system.parameter_set("bad", rows[2:]))
    with pytest.raises(ParameterError, match=r"learn_ramp_max_mps2 = 0.25 requires learn_settled_steps > 0"):
        read_profile(path)


def test_an_unknown_profile_lists_the_allowed_ones(tmp_path):
    with pytest.raises(ScenarioError, match=r"--profile: profile = 'fast': unknown \(allowed: paper, default, robust\)"):
        spec.override(spec.resolve_targets(["nominal"])[0], profile="fast")
    path = tmp_path / "s.toml"
    path.write_text(HEAD + 'regulator = { profile = "robust", learn_settled_steps = 0 }\n[regulator]\nprofile = "fast"\n')
    with pytest.raises(ScenarioError) as exc:
        spec.load_scenario(path, check_plant=False)
    text = str(exc.value)
    assert "regulator.profile: profile = 'fast': unknown (allowed: paper, default, robust)" in text
    assert "learn_ramp_max_mps2 = 0.25 requires learn_settled_steps > 0 (it is 0)" in text


def test_a_profile_in_a_scenario_file_is_the_command_line_profile(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(HEAD + 'regulator = { profile = "paper" }\n[regulator]\nprofile = "robust"\nKp_x = 0.09\n')
    scenario = spec.load_scenario(path, check_plant=False)
    robust = {**profile_overrides("robust"), "Kp_x": 0.09, "seed": 1}
    assert scenario.arm("adaptive").overrides_dict() == robust
    assert scenario.arm("pd_only").overrides_dict() == {**robust, "adaptation_enabled": False}
    assert scenario.arm("b").overrides_dict() == {**robust, "leakage_per_s": 0.0}  # on top of [regulator]
    cli = spec.override(spec.resolve_targets(["nominal"])[0], profile="robust")
    assert cli.arm("adaptive").overrides_dict() == {**profile_overrides("robust"), "seed": 1}


def test_a_campaigns_base_and_arms_take_a_profile():
    """Campaign files: ``[base.regulator] profile = ...`` and an arm's ``regulator = { profile = ... }``
    are the scenario files' keys (the campaign's base is a scenario)."""
    import tomllib

    from scenarios.campaign import spec as campaign_spec
    from support.paths import REPO_ROOT

    base = tomllib.loads((REPO_ROOT / "scenarios" / "suite" / "nominal.toml").read_text())
    base["compare"] = ["adaptive", "b"]
    base["regulator"] = {"profile": "robust"}
    base["arm"] = [{"name": "b", "regulator": {"profile": "paper", "learning_rate": 3e-6}}]
    doc = {"name": "c", "samples": 2, "seed": 1, "base": base,
           "factors": {"torso_mass_kg": {"dist": "uniform", "low": 12.0, "high": 14.0}}}
    c = campaign_spec.parse_campaign(doc, source="c.toml", base_dir=REPO_ROOT)
    scenario = spec.parse_scenario(dict(c.base_doc), source="c", base_dir=c.base_dir, check_plant=False)
    robust = {**profile_overrides("robust"), "seed": 1}
    assert scenario.arm("adaptive").overrides_dict() == robust
    assert scenario.arm("b").overrides_dict() == {**robust, "leakage_per_s": 0.0, "learning_rate": 3e-6}
    base["regulator"] = {"profile": "fastest"}
    with pytest.raises(ScenarioError, match=r"profile = 'fastest': unknown \(allowed: paper, default, robust\)"):
        campaign_spec.parse_campaign(doc, source="c.toml", base_dir=REPO_ROOT)


@pytest.fixture(scope="module")
def runs(system_dir, built_fmu, plant_fmu, tmp_path_factory, profiles_dir):
    """Per profile: the scenario exported and run in libcosim and Ecos, and our master's run."""
    from scenarios.ssp.export_ssp import export_ssp

    from support.paths import REPO_ROOT

    # nominal, learning from the first completed step (its default, 12, comes after the 4 s)
    scenario_file = tmp_path_factory.mktemp("scenario") / "nominal_learning.toml"
    scenario_file.write_text((REPO_ROOT / "scenarios" / "suite" / "nominal.toml").read_text()
                    + "\n[regulator]\nlearn_from_step = 1\n")
    out = {}
    for name in PROFILES:
        scenario = spec.override(spec.load_scenario(scenario_file), duration_s=DURATION_S, profile=name)
        folder = tmp_path_factory.mktemp(f"profile_{name}")
        path = export_ssp(scenario, "adaptive", folder / f"nominal_{name}.ssp", plant_fmu=plant_fmu,
                          regulator_fmu=built_fmu, command_fmu=system_dir / "CommandSource_fmi2.fmu")
        (ours,) = master.run_scenario(scenario, "fmu", fmu_path=built_fmu, arms=("adaptive",),
                                      plant=plant_factory(plant_fmu), exchange="jacobi")
        out[name] = {"ssp": path, "ours": ours, "libcosim": system_run.run_libcosim(path, DURATION_S),
                     "ecos": system_run.run_ecos(path, DURATION_S)}
    return out


def _gap(ours, ssp_rows) -> float:
    """Largest difference of our master's rows (t_0, t_1, ...) from an SSP master's (t_1, ...)."""
    table, _, _ = system_run.master_rows(ssp_rows, stop_at_fall=False)
    n = min(len(ours) - 1, len(table))
    assert n == int(round(DURATION_S / system.STEP_S)) - 1  # ours: t_0 .. t_(N-1); theirs: t_1 .. t_N
    return max(float(np.max(np.abs(ours[c][1:n + 1].astype(float) - table[c][:n].astype(float))))
               for c in table.dtype.names)


def test_the_exported_ssp_binds_the_profiles_values(runs, profiles_dir):
    for name, run in runs.items():
        with zipfile.ZipFile(run["ssp"]) as archive:
            ssv = ET.fromstring(archive.read(f"resources/{system.REGULATOR}_{system.PARAMETER_SET}.ssv"))
        bound = {p.get("name"): p[0].get("value") for p in ssv.iter(f"{{{system.NS['ssv']}}}Parameter")}
        for key, value in read_profile(profiles_dir / f"{name}.ssv").items():
            assert bound[key] == system.value_text(PARAM_BY_NAME[key].type, value)


def test_each_profile_gives_one_run_in_our_master_libcosim_and_ecos(runs):
    for name, run in runs.items():
        assert not run["ours"].fell, name
        assert _gap(run["ours"].rows, run["ecos"]) == 0.0, name  # Ecos: our master's doubles
        assert _gap(run["ours"].rows, run["libcosim"]) <= JACOBI_AGREEMENT, name
    # and the profiles make a difference: each run is its own (paper and default differ by the
    # leak alone, 8e-7 rad in psi_x after the 2 s)
    psi = {name: run["ours"].rows["out_psi_x"] for name, run in runs.items()}
    for a, b in (("paper", "default"), ("default", "robust"), ("paper", "robust")):
        assert not np.array_equal(psi[a], psi[b]), (a, b)


def test_fmpy_simulate_fmu_with_the_ssv_as_start_values_is_the_core_with_the_profile(built_fmu, profiles_dir,
                                                                                      tmp_path):
    """The regulator FMU alone in fmpy's simulate_fmu (4 s of walking-like inputs: the build's
    reference experiment, learning from its step 12): with ``start_values=read_profile(...)``
    every output is the numpy core's with the profile's parameters, every bit."""
    from fmpy import read_csv, simulate_fmu

    from fmu_src.packing import crosscheck

    experiment = crosscheck.EXPERIMENTS["AdaptiveVelocityRegulator"]
    inputs = tmp_path / "in.csv"
    inputs.write_bytes(crosscheck.input_csv(experiment))
    names = [s.name for s in INPUT_SPECS]
    by_profile = {}
    for name in PROFILES:
        result = simulate_fmu(str(built_fmu), start_time=0.0, stop_time=experiment.stop_time,
                              output_interval=experiment.step_size, input=read_csv(str(inputs)),
                              output=[*names, *OUTPUT_NAMES], start_values=read_profile(profiles_dir / f"{name}.ssv"),
                              fmi_type="CoSimulation")
        core = Regulator(params_from_overrides(profile_overrides(name)))
        # row k+1: the inputs of step k (fmpy records them after the step) and its outputs;
        # step k runs from k h to (k + 1) h, its size computed as fmpy does
        for k in range(experiment.steps):
            u = RegulatorInputs(**{n: (int if n == "step_index" else float)(result[n][k + 1]) for n in names})
            h = (k + 1) * experiment.step_size - k * experiment.step_size
            out = core.step(u, h)
            got = {n: float(result[n][k + 1]) for n in OUTPUT_NAMES}
            assert got == out, (name, k)
        by_profile[name] = result["psi_x"]
    assert not np.array_equal(by_profile["paper"], by_profile["default"])
    assert not np.array_equal(by_profile["robust"], by_profile["default"])


def test_export_ssp_with_a_profile_binds_its_values(system_dir, built_fmu, plant_fmu, profiles_dir, tmp_path):
    """``python -m scenarios export-ssp SCENARIO --profile NAME``: the SSP's regulator parameter set
    holds the profile's values (what libcosim and Ecos apply, test above); an unknown one: exit 2."""
    import subprocess
    import sys

    from support.paths import REPO_ROOT

    def export(profile, out):
        return subprocess.run([sys.executable, "-m", "scenarios", "export-ssp", "nominal", "--profile", profile,
                               "--out", str(out), "--fmu", str(built_fmu), "--plant-fmu", str(plant_fmu),
                               "--command-fmu", str(system_dir / "CommandSource_fmi2.fmu")],
                              cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)

    proc = export("robust", tmp_path / "robust.ssp")
    assert proc.returncode == 0, proc.stderr
    with zipfile.ZipFile(tmp_path / "robust.ssp") as archive:
        ssv = ET.fromstring(archive.read(f"resources/{system.REGULATOR}_{system.PARAMETER_SET}.ssv"))
    bound = {p.get("name"): p[0].get("value") for p in ssv.iter(f"{{{system.NS['ssv']}}}Parameter")}
    for key, value in read_profile(profiles_dir / "robust.ssv").items():
        assert bound[key] == system.value_text(PARAM_BY_NAME[key].type, value)
    proc = export("fast", tmp_path / "fast.ssp")
    assert proc.returncode == 2 and "profile = 'fast': unknown (allowed: paper, default, robust)" in proc.stderr
    assert not (tmp_path / "fast.ssp").exists()


def test_a_profile_file_is_the_same_bytes_in_a_fresh_process(profiles_dir):
    """What build.py writes does not depend on what the process serialized before (the ssv: prefix)."""
    import subprocess
    import sys

    from support.paths import REPO_ROOT

    code = "import sys; from scenarios.ssp.profiles import profile_ssv; sys.stdout.buffer.write(profile_ssv('robust'))"
    fresh = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, timeout=120).stdout
    assert fresh == (profiles_dir / "robust.ssv").read_bytes() and b"<ssv:ParameterSet" in fresh
