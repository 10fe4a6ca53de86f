"""The native CassiePlant FMU (C, no Python): what it links, the same outputs as the Python
plant bit for bit, the closed loop in a plain C host with an empty environment, its refusals.

The reference is the pythonfmu plant FMU's own core (``fmu_src/plant_fmu/fmu_core.py``: the
walker with the Python controller) driven in-process with the same inputs; the native FMU
runs the C controller (plant/native/) on the same MuJoCo library, so every output must carry
the same bits (compared through their IEEE bytes, tolerance zero).
"""
from __future__ import annotations

import ctypes
import itertools
import shutil
import struct
import subprocess
import zipfile
import zlib
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave
from fmpy.fmi2 import (FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE,
                        fmi2LastSuccessfulTime, fmi2Terminated)
from fmpy.logging import addLoggerProxy

from fmu_src.plant_fmu import fmu_core
from plant.constants import OFFSET_NAMES
from plant.terrain import GroundHeight
from support.native_support import CC, FMI2_INCLUDE, MINGW_CC, NATIVE_DIR, WINE, compile_c, require, wine_env

#: Communication step of the loops (s): the suite's regulator period.
H = 0.01
#: The regulator's inputs the plant provides (the Integer step_index last).
LOOP_SIGNALS = ("vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate")


@pytest.fixture(scope="module")
def plant_fmus(native_plant_fmus):
    """{2: path, 3: path}: both native plant FMUs as build.py builds them (conftest.py)."""
    return native_plant_fmus


@pytest.fixture(scope="module")
def plant_fmu(plant_fmus):
    return plant_fmus[2]


@pytest.fixture(scope="module")
def plant_dir(plant_fmu, tmp_path_factory):
    return Path(extract(str(plant_fmu), unzipdir=str(tmp_path_factory.mktemp("native_plant_unzipped"))))


def _bits(x) -> bytes:
    return struct.pack("<d", float(x))


_NAMES = itertools.count()
#: Each instance's log messages by instance name: fmpy's logger proxy (which formats the "%s"
#: varargs in C) keeps one Python logger for the process, so one logger routes by name.
_MESSAGES: dict[str, list] = {}


def _route(_env, name, status, _category, message):
    _MESSAGES.setdefault(name.decode(), []).append((status, message.decode()))


_LOGGER = fmi2CallbackLoggerTYPE(_route)


class _Plant:
    """The native plant through fmpy, with the refusals it logs."""

    def __init__(self, fmu: Path, unzipped: Path, params: dict | None = None):
        self.md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.messages = []
        name = f"plant-{next(_NAMES)}"
        _MESSAGES[name] = self.messages

        self.callbacks = fmi2CallbackFunctions()  # kept: the FMU holds its pointers
        self.callbacks.logger = _LOGGER
        self.callbacks.allocateMemory = defaultCallbacks.allocateMemory
        self.callbacks.freeMemory = defaultCallbacks.freeMemory
        addLoggerProxy(ctypes.byref(self.callbacks))  # formats the "%s" varargs in C
        self.s = FMU2Slave(guid=self.md.guid, unzipDirectory=str(unzipped), modelIdentifier="CassiePlantNative",
                           instanceName=name)
        self.s.instantiate(loggingOn=False, callbacks=self.callbacks)
        self.s.setupExperiment(startTime=0.0)
        self.s.enterInitializationMode()
        for name, value in (params or {}).items():
            if self.types[name] == "String":
                self.s.setString([self.vr[name]], [value])
            elif self.types[name] == "Integer":
                self.s.setInteger([self.vr[name]], [value])
            else:
                self.s.setReal([self.vr[name]], [value])

    def outputs(self) -> dict:
        out = {}
        for spec in fmu_core.OUTPUT_SPECS:
            vr = [self.vr[spec.name]]
            out[spec.name] = {"Real": lambda: self.s.getReal(vr)[0], "Integer": lambda: self.s.getInteger(vr)[0],
                              "Boolean": lambda: bool(self.s.getBoolean(vr)[0])}[spec.type]()
        return out

    def step(self, t: float, inputs: dict) -> dict:
        names = list(inputs)
        self.s.setReal([self.vr[n] for n in names], [inputs[n] for n in names])
        self.s.doStep(t, H)
        return self.outputs()

    def serialize(self) -> bytes:
        state = self.s.getFMUstate()
        blob = self.s.serializeFMUstate(state)
        self.s.freeFMUstate(state)
        return blob

    def deserialize_and_set(self, blob: bytes) -> None:
        state = self.s.deSerializeFMUstate(blob)
        self.s.setFMUstate(state)
        self.s.freeFMUstate(state)


class _Plant3(_Plant):
    """The FMI 3.0 native plant through fmpy (the same calls as _Plant, FMI 3.0's names)."""

    def __init__(self, fmu: Path, unzipped: Path, params: dict | None = None):
        self.md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.messages = []
        self.s = FMU3Slave(guid=self.md.guid, unzipDirectory=str(unzipped), modelIdentifier="CassiePlantNative",
                           instanceName=f"plant-{next(_NAMES)}")
        self.s.instantiate()
        self.s.enterInitializationMode(startTime=0.0)
        setters = {"String": self.s.setString, "Int32": self.s.setInt32, "Float64": self.s.setFloat64}
        for name, value in (params or {}).items():
            setters[self.types[name]]([self.vr[name]], [value])

    def outputs(self) -> dict:
        getters = {"Float64": lambda vr: self.s.getFloat64(vr)[0], "Int32": lambda vr: self.s.getInt32(vr)[0],
                   "Boolean": lambda vr: bool(self.s.getBoolean(vr)[0])}
        return {spec.name: getters[self.types[spec.name]]([self.vr[spec.name]]) for spec in fmu_core.OUTPUT_SPECS}

    def step(self, t: float, inputs: dict) -> dict:
        names = list(inputs)
        self.s.setFloat64([self.vr[n] for n in names], [inputs[n] for n in names])
        self.s.doStep(t, H)
        return self.outputs()

    def serialize(self) -> bytes:
        state = self.s.getFMUState()
        blob = self.s.serializeFMUState(state)
        self.s.freeFMUState(state)
        return blob

    def deserialize_and_set(self, blob: bytes) -> None:
        state = self.s.deserializeFMUState(blob)
        self.s.setFMUState(state)
        self.s.freeFMUState(state)


def _compare(got: dict, want: dict, t: float) -> None:
    bad = [n for n in want if _bits(got[n]) != _bits(want[n])]
    assert not bad, f"t = {t:.3f} s: " + ", ".join(f"{n}: native {got[n]!r} python {want[n]!r}" for n in bad)


#: Parameter sets: nominal, every perturbation the native plant takes, the OSU model.
PARAMS = {
    "nominal": {},
    "perturbed": {"torso_mass_kg": 16.0, "torso_com_offset_x_m": 0.02, "torso_com_offset_z_m": 0.03,
                  "joint_damping_scale": 1.5},
    "osu": {"cassie_model": "osu"},
}


@pytest.mark.parametrize("name", PARAMS)
def test_same_outputs_as_the_python_plant_bit_for_bit(plant_fmu, plant_dir, name):
    """3 s with a command change and a push: every output equals the Python plant's, every step."""
    params = PARAMS[name]
    plant = _Plant(plant_fmu, plant_dir, params)
    plant.s.exitInitializationMode()
    walker = fmu_core.start(dict(fmu_core.PARAM_DEFAULTS, **params))
    _compare(plant.outputs(), fmu_core.outputs(walker), 0.0)
    inputs = {n: 0.0 for n in fmu_core.INPUT_NAMES}
    t = 0.0
    for k in range(300):
        inputs["vx_des"] = 0.5 if k < 150 else 0.8
        inputs["yaw_rate_des"] = 0.0 if k < 200 else 0.2
        inputs["push_fy"] = 40.0 if 220 <= k < 240 else 0.0
        for i, n in enumerate(OFFSET_NAMES):  # small offsets, as a regulator sends
            inputs[n] = 0.01 * ((k + i) % 5 - 2) if k > 100 else 0.0
        got = plant.step(t, inputs)
        want = fmu_core.advance(walker, inputs, 20)
        t += H
        _compare(got, want, t)
    assert want["step_index"] >= 5 and not want["fell"]
    plant.s.terminate()
    plant.s.freeInstance()


def test_links_no_python_and_carries_mujoco(plant_dir):
    """The binary needs libmujoco (beside it, found through $ORIGIN), libm and libc only."""
    lib = plant_dir / "binaries" / "linux64" / "CassiePlantNative.so"
    dump = subprocess.run(["objdump", "-p", str(lib)], capture_output=True, text=True, check=True).stdout
    needed = sorted(line.split()[1] for line in dump.splitlines() if line.strip().startswith("NEEDED"))
    assert needed == ["libc.so.6", "libm.so.6", "libmujoco.so.4.0.0"] or all(
        n.startswith(("libc.", "libm.", "libmujoco.")) for n in needed), needed
    assert "RUNPATH              $ORIGIN" in dump or "RPATH                $ORIGIN" in dump
    ldd = subprocess.run(["ldd", str(lib)], capture_output=True, text=True, env={}).stdout
    assert "python" not in ldd and "numpy" not in ldd and "not found" not in ldd, ldd
    assert f"{plant_dir / 'binaries' / 'linux64' / 'libmujoco.so.4.0.0'}" in ldd
    assert (plant_dir / "binaries" / "linux64" / "MUJOCO_LICENSE").is_file()
    for model in ("menagerie", "osu"):
        assert (plant_dir / "resources" / "models" / model / "LICENSE").is_file()


#: Per FMI version: the C loop host, its FMI headers, the binary folders (Linux, Windows).
LOOP_HOSTS = {2: ("fmi2_loop_host.c", FMI2_INCLUDE, ("linux64", "win64")),
              3: ("fmi3_loop_host.c", FMI2_INCLUDE.parent / "fmi3", ("x86_64-linux", "x86_64-windows"))}


def _loop_host(compiler, fmi: int, out: Path) -> Path:
    source, include, _ = LOOP_HOSTS[fmi]
    flags = ("-static",) if compiler == MINGW_CC else ("-ldl",)
    return compile_c(compiler, [NATIVE_DIR / source], out, "-std=c99", "-O1", f"-I{include}", *flags)


def _loop_script(plant_fmu, plant_dir, reg_fmu, reg_dir, steps: int, vx_des: float,
                 windows: bool = False, fmi: int = 2, plant_params: dict | None = None) -> tuple[str, list[str]]:
    """The fmi<fmi>_loop_host script: the regulator (FMU 0) and the plant (FMU 1, with
    ``plant_params``) in a loop; with ``windows`` the Windows libraries, their paths as Wine sees
    them (drive Z: is /)."""
    pmd, rmd = read_model_description(str(plant_fmu)), read_model_description(str(reg_fmu))
    pv = {v.name: v for v in pmd.modelVariables}
    rv = {v.name: v for v in rmd.modelVariables}
    folder = LOOP_HOSTS[fmi][2][windows]
    suffix, drive = (".dll", "Z:") if windows else (".so", "")
    reg_lib = reg_dir / "binaries" / folder / (rmd.coSimulation.modelIdentifier + suffix)
    plant_lib = plant_dir / "binaries" / folder / ("CassiePlantNative" + suffix)
    resources = (plant_dir / "resources").as_posix()
    if fmi == 2:  # a file URI
        plant_res, reg_res = f"file://{'/' + drive if drive else ''}{resources}", "file:///"
    else:  # a path ending in a separator
        plant_res, reg_res = f"{drive}{resources}/", "-"
    lines = [f"F {drive}{reg_lib} {rmd.guid} {reg_res}", f"F {drive}{plant_lib} {pmd.guid} {plant_res}",
             f"P 0 R {rv['vx_des'].valueReference} {vx_des!r}", f"P 1 R {pv['vx_des'].valueReference} {vx_des!r}"]
    letter = {"Real": "R", "Float64": "R", "Integer": "I", "Int32": "I", "String": "S"}
    lines += [f"P 1 {letter[pv[n].type]} {pv[n].valueReference} {value}" for n, value in (plant_params or {}).items()]
    lines += [f"L 1 R {pv[n].valueReference} 0 {rv[n].valueReference}" for n in LOOP_SIGNALS]
    lines.append(f"L 1 I {pv['step_index'].valueReference} 0 {rv['step_index'].valueReference}")
    lines += [f"L 0 R {rv[n].valueReference} 1 {pv[n].valueReference}" for n in OFFSET_NAMES]
    printed = [s.name for s in fmu_core.OUTPUT_SPECS]
    type_letter = {"Real": "R", "Float64": "R", "Integer": "I", "Int32": "I", "Boolean": "B"}
    lines += [f"O 1 {type_letter[pv[n].type]} {pv[n].valueReference}" for n in printed]
    lines.append(f"T {H!r} {steps}")
    return "\n".join(lines) + "\n", printed


def _run_loop(host: Path, script: str, folder: Path, env_prefix=("env", "-i"), env=None) -> list[list[float]]:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "loop.txt").write_text(script)
    proc = subprocess.run([*env_prefix, str(host), str(folder / "loop.txt")], capture_output=True, text=True,
                          timeout=900, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return [[float(x) for x in line.split()] for line in proc.stdout.splitlines()]


@pytest.fixture(scope="module")
def regulator_fmus(native_fmus):
    """{2: path, 3: path}: both native regulator FMUs as build.py builds them (conftest.py)."""
    return native_fmus


def test_loop_walks_in_a_c_host_with_an_empty_environment(plant_fmus, plant_dir, regulator_fmus, tmp_path):
    """10 s at 0.5 m/s, native regulator and native plant in a plain C host under ``env -i``, FMI 2.0
    and FMI 3.0; on linux64 every plant output of every step equals the Python plant's in the same
    loop, in both versions."""
    steps, vx_des = 1000, 0.5
    loops = {}
    for fmi in (2, 3):
        host = _loop_host(CC, fmi, tmp_path / f"fmi{fmi}_loop_host")
        reg_dir = Path(extract(str(regulator_fmus[fmi]), unzipdir=str(tmp_path / f"regulator{fmi}")))
        unzipped = plant_dir if fmi == 2 else Path(extract(str(plant_fmus[3]), unzipdir=str(tmp_path / "plant3")))
        script, printed = _loop_script(plant_fmus[fmi], unzipped, regulator_fmus[fmi], reg_dir, steps, vx_des, fmi=fmi)
        loops[fmi] = _run_loop(host, script, tmp_path / f"run{fmi}")
    rows = loops[2]
    assert len(rows) == steps
    last = dict(zip(printed, rows[-1]))
    assert last["fell"] == 0.0 and last["step_index"] >= 25 and last["pelvis_x"] > 3.5, last
    assert loops[3] == rows  # %.17g round-trips: the same doubles
    regulator_fmu = regulator_fmus[2]
    reg_dir = tmp_path / "regulator2"

    # The same loop with the Python plant (fmu_core, in-process) and the same regulator FMU.
    rmd = read_model_description(str(regulator_fmu))
    rv = {v.name: v.valueReference for v in rmd.modelVariables}
    reg = FMU2Slave(guid=rmd.guid, unzipDirectory=str(reg_dir), modelIdentifier=rmd.coSimulation.modelIdentifier,
                    instanceName="regulator")
    reg.instantiate()
    reg.setupExperiment(startTime=0.0)
    reg.enterInitializationMode()
    reg.setReal([rv["vx_des"]], [vx_des])
    reg.exitInitializationMode()
    walker = fmu_core.start(dict(fmu_core.PARAM_DEFAULTS))
    out = fmu_core.outputs(walker)
    inputs = dict({n: 0.0 for n in fmu_core.INPUT_NAMES}, vx_des=vx_des)
    for k in range(steps):
        reg.setReal([rv[n] for n in LOOP_SIGNALS], [out[n] for n in LOOP_SIGNALS])
        reg.setInteger([rv["step_index"]], [out["step_index"]])
        reg.doStep(k * H, H)
        inputs.update(zip(OFFSET_NAMES, reg.getReal([rv[n] for n in OFFSET_NAMES])))
        out = fmu_core.advance(walker, inputs, 20)
        got = dict(zip(printed, rows[k]))
        bad = [n for n in printed if _bits(got[n]) != _bits(out[n])]
        assert not bad, f"step {k}: " + ", ".join(f"{n}: C host {got[n]!r} python {out[n]!r}" for n in bad)
    reg.terminate()
    reg.freeInstance()


@pytest.mark.wine
def test_win64_loop_walks_under_wine(plant_fmus, regulator_fmus, tmp_path, tmp_path_factory):
    """The Windows pair (native regulator, native plant with its mujoco.dll), FMI 2.0 and 3.0, in the
    C host built with MinGW-w64, under Wine with nothing in the environment but Wine's own: 5 s at
    0.5 m/s.  (Not the Linux bits: Windows' libm and the MSVC-built mujoco.dll round differently
    in the last place.)"""
    env = wine_env(tmp_path_factory)
    for fmi in (2, 3):
        host = _loop_host(require(MINGW_CC), fmi, tmp_path / f"fmi{fmi}_loop_host.exe")
        reg_dir = Path(extract(str(regulator_fmus[fmi]), unzipdir=str(tmp_path / f"regulator{fmi}")))
        plant_dir = Path(extract(str(plant_fmus[fmi]), unzipdir=str(tmp_path / f"plant{fmi}")))
        script, printed = _loop_script(plant_fmus[fmi], plant_dir, regulator_fmus[fmi], reg_dir, 500, 0.5,
                                       windows=True, fmi=fmi)
        rows = _run_loop(host, script, tmp_path / f"run{fmi}", env_prefix=(str(require(WINE)),), env=env)
        assert len(rows) == 500
        last = dict(zip(printed, rows[-1]))
        # measured under Wine: step 15, pelvis 1.89 m at 5 s (33 steps, 4.33 m at 10 s)
        assert last["fell"] == 0.0 and last["step_index"] >= 12 and last["pelvis_x"] > 1.5, (fmi, last)
        assert abs(last["plant_time"] - 5.0) < 1e-9


@pytest.mark.wine
def test_win64_plant_walks_on_the_handed_over_terrain_under_wine(plant_fmus, regulator_fmus, terrain_field, tmp_path,
                                                                 tmp_path_factory):
    """The Windows plant reads the height field too (its MuJoCo model editing goes through the
    mujoco.dll it loads): 3 s of the terrain_mass_com ground in the FMI 2.0 loop under Wine walk
    as the Linux loop does, to 1e-6 m (Windows rounds differently in the last place; on the flat
    floor, not reading the field, the pelvis would be centimetres off)."""
    env = wine_env(tmp_path_factory)
    reg_dir = Path(extract(str(regulator_fmus[2]), unzipdir=str(tmp_path / "regulator")))
    plant_dir = Path(extract(str(plant_fmus[2]), unzipdir=str(tmp_path / "plant")))
    rows = {}
    for windows in (False, True):
        params = dict(TERRAIN_PARAMS, terrain_field_file=("Z:" if windows else "") + terrain_field.as_posix())
        script, printed = _loop_script(plant_fmus[2], plant_dir, regulator_fmus[2], reg_dir, 300, 0.5,
                                       windows=windows, plant_params=params)
        if windows:
            host = _loop_host(require(MINGW_CC), 2, tmp_path / "fmi2_loop_host.exe")
            rows[windows] = _run_loop(host, script, tmp_path / "win", env_prefix=(str(require(WINE)),), env=env)
        else:
            rows[windows] = _run_loop(_loop_host(CC, 2, tmp_path / "fmi2_loop_host"), script, tmp_path / "linux")
    linux, win = (dict(zip(printed, rows[w][-1])) for w in (False, True))
    assert linux["fell"] == 0.0 and win["fell"] == 0.0 and win["step_index"] == linux["step_index"] >= 4, (linux, win)
    assert abs(win["pelvis_x"] - linux["pelvis_x"]) < 1e-6 and abs(win["pelvis_z"] - linux["pelvis_z"]) < 1e-6


def test_fmi3_same_outputs_and_state(plant_fmus, tmp_path):
    """The FMI 3.0 FMU (the same C source): the Python plant's outputs bit for bit for 2 s of
    walking on the OSU model, and a state that restores the exact continuation."""
    fmu = plant_fmus[3]
    md = read_model_description(str(fmu), validate=True)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    assert [v.name for v in md.modelVariables] == [s.name for s in fmu_core.SPECS] + ["terrain_field_file", "time"]
    s = FMU3Slave(guid=md.guid, unzipDirectory=str(extract(str(fmu), unzipdir=str(tmp_path / "fmu"))),
                  modelIdentifier="CassiePlantNative", instanceName="plant3")
    s.instantiate()
    s.enterInitializationMode(startTime=0.0)
    s.setString([vr["cassie_model"]], ["osu"])
    s.exitInitializationMode()
    walker = fmu_core.start(dict(fmu_core.PARAM_DEFAULTS, cassie_model="osu"))
    inputs = dict({n: 0.0 for n in fmu_core.INPUT_NAMES}, vx_des=0.5)
    real = [o.name for o in fmu_core.OUTPUT_SPECS if o.type == "Real"]
    t, state, saved = 0.0, None, []
    for k in range(200):
        names = list(inputs)
        s.setFloat64([vr[n] for n in names], [inputs[n] for n in names])
        s.doStep(t, H)
        t += H
        want = fmu_core.advance(walker, inputs, 20)
        got = dict(zip(real, s.getFloat64([vr[n] for n in real])))
        got["step_index"] = s.getInt32([vr["step_index"]])[0]
        got["fell"] = bool(s.getBoolean([vr["fell"]])[0])
        _compare(got, {n: want[n] for n in got}, t)
        if k == 150:
            state, t_saved = s.getFMUState(), t
        elif k > 150:
            saved.append(got)
    assert s.getFloat64([vr["time"]])[0] == t  # the independent variable time
    s.setFMUState(state)
    t = t_saved
    for k, want in enumerate(saved):
        s.doStep(t, H)
        t += H
        got = dict(zip(real, s.getFloat64([vr[n] for n in real])))
        assert all(_bits(got[n]) == _bits(want[n]) for n in real), k
    s.terminate()
    s.freeInstance()


def _refused(plant, call, *args) -> str:
    plant.messages.clear()
    with pytest.raises(Exception, match=r"status 3 \(error\)"):
        call(*args)
    assert plant.messages, "a refusal must log why"
    return plant.messages[-1][1]


def test_refusals_name_the_field_and_change_nothing(plant_fmu, plant_dir):
    plant = _Plant(plant_fmu, plant_dir)
    vr = plant.vr
    assert "cassie_model = 'atlas'" in _refused(plant, plant.s.setString, [vr["cassie_model"]], ["atlas"])
    assert "vx_des = 3.5" in _refused(plant, plant.s.setReal, [vr["vx_des"]], [3.5])
    assert "torso_mass_kg = nan" in _refused(plant, plant.s.setReal, [vr["torso_mass_kg"]], [float("nan")])
    assert "is an output" in _refused(plant, plant.s.setReal, [vr["pitch"]], [0.1])
    plant.s.setReal([vr["terrain_max_height_m"]], [0.05])
    assert "needs the height field: set terrain_field_file" in _refused(plant, plant.s.exitInitializationMode)
    plant.s.setReal([vr["terrain_max_height_m"]], [0.0])
    plant.s.exitInitializationMode()  # still in initialization mode after the refusal: now it starts
    assert "fixed parameter" in _refused(plant, plant.s.setReal, [vr["torso_mass_kg"]], [12.0])
    assert "whole multiple of the plant step" in _refused(plant, plant.s.doStep, 0.0, 0.0007)
    assert "exceeds the maximum communication step" in _refused(plant, plant.s.doStep, 0.0, 10.5)
    assert "must equal the end of the last step" in _refused(plant, plant.s.doStep, 1.0, 0.01)
    assert "not provided" in _refused(plant, plant.s.getDirectionalDerivative, [vr["vx"]], [vr["vx_des"]], [1.0])
    assert plant.s.getReal([vr["plant_time"]])[0] == 0.0  # nothing stepped
    plant.s.doStep(0.0, 0.01)
    assert plant.s.getReal([vr["plant_time"]])[0] == pytest.approx(0.01, abs=1e-12)  # sum of 20 x 0.5 ms
    # the status functions of every native FMU (fmi2_common.c): the end of the last step, never terminated
    assert plant.s.getRealStatus(fmi2LastSuccessfulTime) == 0.01 and plant.s.getBooleanStatus(fmi2Terminated) == 0
    assert "only fmi2LastSuccessfulTime" in _refused(plant, plant.s.getRealStatus, fmi2Terminated)
    plant.s.terminate()
    plant.s.freeInstance()


def _walk(plant, t: float, steps: int) -> tuple[float, list[dict]]:
    inputs = dict({n: 0.0 for n in fmu_core.INPUT_NAMES}, vx_des=0.5)
    rows = []
    for k in range(steps):
        inputs["delta_swing_hip_pitch"] = 0.02 * ((k % 7) - 3) / 3
        rows.append(plant.step(t, inputs))
        t += H
    return t, rows


#: The blob layout (cp_instance.c): header, phase, has-walker flag, time, the values, then the walker.
HEADER = 4 + 4 + 4 + 40
VALUES_AT = HEADER + 4 + 4 + 8
WALKER_AT = VALUES_AT + 8 * (len(fmu_core.SPECS) + 1)  # the pythonfmu plant's variables, then terrain_field_file
#: Within the walker: substep, fell, fall reason, three commands, then the controller memory.
MEMORY_AT = WALKER_AT + 4 + 4 + 160 + 3 * 8
#: tau: after the six offsets, six speeds/rates, mode, stance, step_index, t_step_start.
TAU_AT = MEMORY_AT + 12 * 8 + 4 + 4 + 8 + 8
#: The MuJoCo state: its length, then time, then qpos (the pelvis quaternion at qpos[3:7]).
MJSTATE_AT = TAU_AT + 8 * 10
QUAT_AT = MJSTATE_AT + 4 + 8 + 3 * 8


def _forge(blob: bytes, at: int, fmt: str, value) -> bytes:
    """``blob`` with one field replaced and its CRC-32 made valid again."""
    body = bytearray(blob[:-4])
    struct.pack_into(fmt, body, at, value)
    return bytes(body) + struct.pack("<I", zlib.crc32(bytes(body)))


def test_fmu_state_restores_the_run_exactly(plant_fmu, plant_dir):
    """A state taken while walking restores (in the same instance, and serialized into a fresh
    one) the exact continuation: every output of the next 100 steps carries the same bits."""
    plant = _Plant(plant_fmu, plant_dir, PARAMS["perturbed"])
    plant.s.exitInitializationMode()
    t, _ = _walk(plant, 0.0, 150)
    state = plant.s.getFMUState()
    blob = plant.s.serializeFMUState(state)
    _, first = _walk(plant, t, 100)
    plant.s.setFMUState(state)
    _, again = _walk(plant, t, 100)
    assert [{n: _bits(v) for n, v in r.items()} for r in again] == [{n: _bits(v) for n, v in r.items()} for r in first]
    other = _Plant(plant_fmu, plant_dir, PARAMS["perturbed"])  # never initialized: the state builds its walker
    restored = other.s.deserializeFMUState(blob)
    other.s.setFMUState(restored)
    _, fresh = _walk(other, t, 100)
    assert [{n: _bits(v) for n, v in r.items()} for r in fresh] == [{n: _bits(v) for n, v in r.items()} for r in first]
    assert first[-1]["step_index"] > 5

    # Corrupt or unreachable states are refused; the instance keeps walking as before.
    nominal = _Plant(plant_fmu, plant_dir)
    forged = {
        "checksum mismatch": blob[:100] + bytes([blob[100] ^ 1]) + blob[101:],
        "fixed parameter torso_mass_kg": _forge(blob, VALUES_AT + 8 * plant.vr["torso_mass_kg"], "<d", 17.0),
        "vx_des = 7": _forge(blob, VALUES_AT + 8 * plant.vr["vx_des"], "<d", 7.0),
        "tau": _forge(blob, TAU_AT, "<d", 5.0),
        "norm": _forge(blob, QUAT_AT, "<d", 2.0),
        "substep": _forge(blob, WALKER_AT, "<I", 4),
        "saved by another FMU": blob[:12] + b"{x" + blob[14:-4] + struct.pack("<I", zlib.crc32(blob[:12] + b"{x" + blob[14:-4])),
    }
    for why, bad in forged.items():
        plant.messages.clear()
        try:
            bad_state = plant.s.deserializeFMUState(bad)
        except Exception:  # noqa: BLE001 - refused already at deserialization
            assert why in plant.messages[-1][1], (why, plant.messages)
            continue
        message = _refused(plant, plant.s.setFMUState, bad_state)
        assert why in message, (why, message)
    assert "differs from this instance" in _refused(nominal, nominal.s.setFMUState, nominal.s.deserializeFMUState(blob))
    plant.s.setFMUState(state)
    _, after = _walk(plant, t, 100)
    assert [{n: _bits(v) for n, v in r.items()} for r in after] == [{n: _bits(v) for n, v in r.items()} for r in first]
    for p in (plant, other, nominal):
        p.s.freeInstance()


def test_model_description_matches_the_pythonfmu_plant(plant_fmu):
    """Same variables, value references, types, causalities, variabilities, starts and ranges as
    fmu_core.SPECS (the pythonfmu plant's table), then terrain_field_file."""
    md = read_model_description(str(plant_fmu), validate=True)
    # then the one the native plant has more: the terrain's height field, handed over as a file
    assert [v.name for v in md.modelVariables] == [s.name for s in fmu_core.SPECS] + ["terrain_field_file"]
    for v, s in zip(md.modelVariables, fmu_core.SPECS):
        assert (v.type, v.causality, v.variability) == (s.type, s.causality, s.variability), s.name
        if s.type in ("Real", "Integer") and s.min is not None:
            assert float(v.min) == s.min and float(v.max) == s.max, s.name
    with zipfile.ZipFile(plant_fmu) as z:
        names = z.namelist()
    assert "binaries/linux64/CassiePlantNative.so" in names and "sources/cassie_ctrl.c" in names


# ---- uneven terrain: the height field handed over as a file (plant.terrain.write_field) ----------
#: The terrain_mass_com scenario's ground and model change (scenarios/suite/terrain_mass_com.toml).
TERRAIN_PARAMS = {"terrain_max_height_m": 0.4, "terrain_max_slope_deg": 20.0, "terrain_seed": 7,
                  "terrain_size_m": 45.0, "torso_mass_kg": 10.33 + 5.0, "torso_com_offset_x_m": 0.1}


@pytest.fixture(scope="module")
def terrain_field(tmp_path_factory) -> Path:
    """The height-field file of TERRAIN_PARAMS, as a host writes it for the native plant."""
    from plant.terrain import TerrainSpec, write_field

    spec = TerrainSpec(max_height_m=TERRAIN_PARAMS["terrain_max_height_m"],
                       max_slope_deg=TERRAIN_PARAMS["terrain_max_slope_deg"], seed=TERRAIN_PARAMS["terrain_seed"],
                       size_m=TERRAIN_PARAMS["terrain_size_m"])
    return Path(write_field(spec, tmp_path_factory.mktemp("terrain") / "terrain_mass_com.cptf"))


@pytest.mark.parametrize("fmi", [2, 3])
def test_terrain_walk_same_bits_as_the_python_plant(plant_fmus, terrain_field, fmi, tmp_path):
    """3 s of the terrain_mass_com scenario's ground and model change, walking at 0.5 m/s then
    0.8 m/s with a regulator's small offsets: every output of the native plant (the field read
    from the file) carries the Python plant's bits (the field generated by numpy), every step;
    a state taken at 1.5 s and set into a fresh instance (which builds its walker on the same
    file) continues with the same bits."""
    params = dict(TERRAIN_PARAMS, terrain_field_file=str(terrain_field))
    unzipped = Path(extract(str(plant_fmus[fmi]), unzipdir=str(tmp_path / "fmu")))
    plant = _Plant3(plant_fmus[fmi], unzipped, params) if fmi == 3 else _Plant(plant_fmus[fmi], unzipped, params)
    plant.s.exitInitializationMode()
    walker = fmu_core.start(dict(fmu_core.PARAM_DEFAULTS, **TERRAIN_PARAMS))
    assert walker.physics.model.hfield_nrow[0] == 1801  # the Python plant walks on the generated field
    _compare(plant.outputs(), fmu_core.outputs(walker), 0.0)
    inputs = {n: 0.0 for n in fmu_core.INPUT_NAMES}
    t, state = 0.0, None
    rows = []
    for k in range(300):
        inputs["vx_des"] = 0.5 if k < 150 else 0.8
        for i, n in enumerate(OFFSET_NAMES):
            inputs[n] = 0.01 * ((k + i) % 5 - 2) if k > 100 else 0.0
        if k == 150:
            state = plant.serialize()
        got = plant.step(t, inputs)
        want = fmu_core.advance(walker, inputs, 20)
        t += H
        _compare(got, want, t)
        rows.append(want)
    assert want["step_index"] >= 4 and not want["fell"]
    # on the bumps: the ground under the pelvis has risen 8.9 cm by the end (5 cm: a margin, not a bound)
    assert GroundHeight(walker.physics.model)(want["pelvis_x"], want["pelvis_y"]) > 0.05
    other = _Plant3(plant_fmus[fmi], unzipped, params) if fmi == 3 else _Plant(plant_fmus[fmi], unzipped, params)
    other.deserialize_and_set(state)
    t = 150 * H
    for k in range(150, 300):
        inputs["vx_des"] = 0.5 if k < 150 else 0.8
        for i, n in enumerate(OFFSET_NAMES):
            inputs[n] = 0.01 * ((k + i) % 5 - 2)
        got = other.step(t, inputs)
        t += H
        _compare(got, rows[k], t)
    for p in (plant, other):
        p.s.terminate()
        p.s.freeInstance()


#: Floor friction and the six link mass factors, each off its default (fmu_core.LINK_MASS_BODIES).
ENVIRONMENT_PARAMS = {"floor_friction": 0.3, "link_mass_scale_left_hip_pitch": 1.5, "link_mass_scale_left_shin": 0.7,
                      "link_mass_scale_left_tarsus": 1.3, "link_mass_scale_right_hip_pitch": 1.2,
                      "link_mass_scale_right_shin": 1.4, "link_mass_scale_right_tarsus": 0.8}


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("which", ["floor_friction", "link_mass_scale", "both_osu"])
def test_floor_friction_and_link_masses_same_bits_as_the_python_plant(plant_fmus, fmi, which, tmp_path):
    """2 s walking at 0.6 m/s with a slippery floor (friction 0.3), with every link mass factor
    off 1, and with both on the OSU model: the native plant's outputs carry the Python plant's
    bits every step, and differ from the nominal walk's (the parameters act, none is ignored)."""
    if which == "floor_friction":
        params = {"floor_friction": 0.3}
    elif which == "link_mass_scale":
        params = {k: v for k, v in ENVIRONMENT_PARAMS.items() if k != "floor_friction"}
    else:
        params = dict(ENVIRONMENT_PARAMS, cassie_model="osu")
    baseline = {"cassie_model": params["cassie_model"]} if "cassie_model" in params else {}
    _walk_with_python_bits(plant_fmus[fmi], fmi, params, baseline, tmp_path)


def _walk_with_python_bits(fmu: Path, fmi: int, params: dict, baseline: dict, tmp_path: Path) -> None:
    """2 s walking at 0.6 m/s of the native plant FMU ``fmu`` with ``params``: its outputs carry
    the Python plant's bits at every step, and its pelvis ends elsewhere than the Python plant's
    with only ``baseline`` set (the parameters act, none is ignored)."""
    unzipped = Path(extract(str(fmu), unzipdir=str(tmp_path / "fmu")))
    plant = _Plant3(fmu, unzipped, params) if fmi == 3 else _Plant(fmu, unzipped, params)
    plant.s.exitInitializationMode()
    walker = fmu_core.start(dict(fmu_core.PARAM_DEFAULTS, **params))
    reference = fmu_core.start(dict(fmu_core.PARAM_DEFAULTS, **baseline))
    _compare(plant.outputs(), fmu_core.outputs(walker), 0.0)
    inputs = dict.fromkeys(fmu_core.INPUT_NAMES, 0.0)
    inputs["vx_des"] = 0.6
    t = 0.0
    for _ in range(200):
        got = plant.step(t, inputs)
        want = fmu_core.advance(walker, inputs, 20)
        base = fmu_core.advance(reference, inputs, 20)
        t += H
        _compare(got, want, t)
    assert want["step_index"] >= 2
    assert _bits(want["pelvis_x"]) != _bits(base["pelvis_x"]) and _bits(got["pelvis_x"]) != _bits(base["pelvis_x"])
    plant.s.terminate()
    plant.s.freeInstance()


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("params", [{"floor_slope_deg": 5.0}, {"floor_cross_slope_deg": -4.0},
                                    {"floor_slope_deg": -3.0, "floor_cross_slope_deg": 2.5, "floor_friction": 0.6}],
                         ids=["slope", "cross_slope", "both_friction"])
def test_floor_slopes_same_bits_as_the_python_plant(plant_fmus, fmi, params, tmp_path):
    """2 s walking at 0.6 m/s uphill (5 deg), on a cross slope (-4 deg), and on both with the floor
    friction changed: the native plant's outputs carry the Python plant's bits every step, and
    differ from the flat floor's walk (the slope acts, it is not ignored)."""
    _walk_with_python_bits(plant_fmus[fmi], fmi, params, {}, tmp_path)


@pytest.mark.parametrize("params, name, why", [
    ({"floor_friction": 0.0}, "floor_friction", "floor_friction = 0: must be in (0, 2]"),
    ({"link_mass_scale_right_shin": 0.0}, "link_mass_scale_right_shin",
     "link_mass_scale_right_shin = 0: must be in (0, 5]"),
    ({"floor_cross_slope_deg": -1.5, "terrain_max_height_m": 0.1}, "terrain_max_height_m",
     "floor_slope_deg = 0 deg, floor_cross_slope_deg = -1.5 deg with terrain_max_height_m = 0.10000000000000001 m: "
     "the slopes tilt the flat floor; give a slope or a terrain, not both"),
], ids=["zero_friction", "zero_link_mass", "slope_with_terrain"])
def test_zero_factors_and_a_slope_on_terrain_are_refused_at_initialization(plant_fmu, plant_dir, params, name, why):
    """A zero friction or link factor (the Python plant's ranges are open at 0) and a floor slope
    given with an uneven terrain (the Python plant's "a slope or a terrain, not both") are refused
    at ExitInitializationMode naming the parameters, their values and what is allowed; the
    instance stays in initialization mode and starts once ``name`` is back at its default."""
    plant = _Plant(plant_fmu, plant_dir, params)
    assert why in _refused(plant, plant.s.exitInitializationMode)
    plant.s.setReal([plant.vr[name]], [fmu_core.PARAM_DEFAULTS[name]])
    plant.s.exitInitializationMode()
    plant.s.doStep(0.0, H)
    plant.s.terminate()
    plant.s.freeInstance()


def _field_with(data: bytes, at: int, fmt: str, value) -> bytes:
    """The height-field file ``data`` with one field replaced and its CRC-32 made valid again."""
    body = bytearray(data[:-4])
    struct.pack_into(fmt, body, at, value)
    return bytes(body) + struct.pack("<I", zlib.crc32(bytes(body)))


def test_bad_height_fields_are_refused_naming_the_parameter(plant_fmu, plant_dir, terrain_field, tmp_path):
    """Each bad file is refused at ExitInitializationMode with a message naming terrain_field_file
    (or the terrain parameter it contradicts) and what is allowed; the instance stays in
    initialization mode and starts once given the right file."""
    data = terrain_field.read_bytes()
    n = struct.unpack_from("<I", data, 56)[0]
    bad = {
        "cannot be opened": None,
        "is not a height-field file": b"not a field at all, but long enough to have a header of 68 bytes......",
        "checksum mismatch": data[:1000] + bytes([data[1000] ^ 4]) + data[1001:],
        "its header says": data[:-4096],
        "terrain_seed = 8": _field_with(data, 52, "<I", 8),
        "terrain_max_slope_deg = 25": _field_with(data, 20, "<d", 25.0),
        "resolution_m": _field_with(data, 44, "<d", 0.1),
        "peak height": _field_with(data, 60, "<d", 0.5),
        "sample 5 = nan": _field_with(data, 68 + 4 * 5, "<f", float("nan")),
        "sample 7 = 1.5": _field_with(data, 68 + 4 * 7, "<f", 1.5),
        "format version 2": _field_with(data, 4, "<I", 2),
    }
    assert n == 1801
    plant = _Plant(plant_fmu, plant_dir, TERRAIN_PARAMS)
    vr = plant.vr["terrain_field_file"]
    for i, (why, content) in enumerate(bad.items()):
        path = tmp_path / f"bad{i}.cptf"
        if content is not None:
            path.write_bytes(content)
        plant.s.setString([vr], [str(path)])
        message = _refused(plant, plant.s.exitInitializationMode)
        assert why in message and "terrain_field_file" in message, (why, message)
    assert "at most 4095 bytes" in _refused(plant, plant.s.setString, [vr], ["x" * 5000])
    plant.s.setString([vr], [str(terrain_field)])
    assert plant.s.getString([vr]) == [str(terrain_field).encode()]
    plant.s.exitInitializationMode()  # still in initialization mode after the refusals: now it starts
    assert "fixed parameter" in _refused(plant, plant.s.setString, [vr], [str(terrain_field)])
    plant.s.doStep(0.0, H)
    plant.s.terminate()
    plant.s.freeInstance()


#: AddressSanitizer + UBSan, as the regulator's sanitized build (tests/native/test_native_hosts.py).
SANITIZE = ("-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g", "-Wno-error")
LINUX = {2: "linux64", 3: "x86_64-linux"}


@pytest.mark.sanitize
@pytest.mark.parametrize("fmi", [2, 3])
def test_sanitized_plant_runs_every_call_in_every_state_and_walks_with_zero_findings(plant_fmus, terrain_field, fmi,
                                                                                   tmp_path):
    """The native plant's Linux library rebuilt from its own sources/ with ASan + UBSan: every FMI
    function in every state (tests/support/fmi/phase_matrix.py, NULL and zero arguments), then
    walking instances with state round trips and corrupted states, a terrain walk and a walk on a
    floor sloped both ways (each with the floor friction and link mass factors off their defaults),
    a slope on the terrain refused, and bad height fields
    (sanitize_run.py --plant): zero sanitizer findings, and the phase matrix follows the table."""
    import json
    import os
    import sys

    from fmu_src.fmi import phase_rules
    from fmu_src.plant_fmu.native import build_native_plant
    from plant.native import native_ctrl
    from support.paths import SUPPORT_DIR

    unzipped = Path(extract(str(plant_fmus[fmi]), unzipdir=str(tmp_path / "fmu")))
    lib = build_native_plant.compile_library(unzipped / "sources", fmi, "linux", native_ctrl.mujoco_library(),
                                             tmp_path / "CassiePlantNative.so", extra_flags=SANITIZE)
    assert b"__asan_report" in lib.read_bytes() and b"__ubsan_handle" in lib.read_bytes()  # instrumented
    shutil.copyfile(lib, unzipped / "binaries" / LINUX[fmi] / "CassiePlantNative.so")
    libasan = subprocess.run([str(require(CC)), "-print-file-name=libasan.so"], capture_output=True,
                             text=True).stdout.strip()
    # Python itself is not instrumented and keeps memory until exit: leak checking would report it, not us.
    env = {**os.environ, "LD_PRELOAD": libasan, "ASAN_OPTIONS": "detect_leaks=0:halt_on_error=1",
           "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1"}
    matrix = subprocess.run([sys.executable, str(SUPPORT_DIR / "fmi" / "phase_matrix.py"), str(unzipped), str(fmi)],
                            env=env, capture_output=True, text=True, timeout=900)
    findings = matrix.stderr.count("ERROR: AddressSanitizer") + matrix.stderr.count("runtime error:")
    assert matrix.returncode == 0 and findings == 0, matrix.stderr[-4000:]
    table = phase_rules.FMI2_ALLOWED if fmi == 2 else phase_rules.FMI3_ALLOWED
    answers = json.loads(matrix.stdout.strip().splitlines()[-1])
    assert all(a["status"] != 0 for name, by_state in answers.items() for state, a in by_state.items()
               if name in table and state not in table[name]), "a call outside its states answered OK"
    run = subprocess.run([sys.executable, str(SUPPORT_DIR / "native" / "sanitize_run.py"), "--plant", str(unzipped),
                          str(fmi), str(terrain_field), json.dumps(dict(TERRAIN_PARAMS, **ENVIRONMENT_PARAMS))],
                         env=env, capture_output=True,
                         text=True, timeout=900)
    findings = run.stderr.count("ERROR: AddressSanitizer") + run.stderr.count("runtime error:")
    assert run.returncode == 0 and findings == 0, run.stderr[-4000:]
    print(f"\n{run.stdout.splitlines()[-1]}; every function in every state; 0 sanitizer findings")
