"""Run a CassieAVR system (``dist/CassieAVR.ssp``, or a scenario's SSP from
``python -m scenarios export-ssp``) in libcosim, fmpy and Ecos, each with its own plain call.

The command and the pushes come from the system's ``command`` component (the
CommandSource FMU, its ``resources/schedule.csv``) through connections, so no master
needs anything but the SSP file; the parameter sets bind only parameters.

* libcosim: ``CosimExecution.from_ssp_file(ssp)`` applies every component's first
  parameter binding;
* Ecos: ``EcosSimulation(ssp_path=ssp, step_size=...).init(parameter_set="nominal")``
  applies every component's set of that name (hence one name for all,
  :data:`scenarios.ssp.system.PARAMETER_SET`); :func:`run_ecos` hands it the SSP unpacked
  (Ecos leaves its own unpacked copy of a ``.ssp`` behind);
* fmpy 0.3: ``simulate_ssp(ssp, ..., parameter_set=...)`` reads no parameter binding
  itself, so :func:`ssp_parameter_set` hands it the SSP's own bindings under their
  hierarchical names (``plant.torso_mass_kg``), String values left out (fmpy cannot
  set them).

Exchange: all three step every FMU with the inputs of the previous communication point
(Jacobi) and read the outputs after the step.  Our own master does the same with
``exchange="jacobi"`` (:func:`scenarios.cosim.master.run_arm`), which gives the SSP masters'
trajectory; its default (Gauss-Seidel) hands the regulator's offsets to the plant in the
step they are computed, 5 ms earlier.  :func:`master_rows` turns a run's rows into our
master's columns, so the suite's metrics and claim checks (:func:`claim_verdict`) apply
to it.

fmu-manipulation-toolbox's ``fmucontainer`` packs the SSP's three FMUs into one FMU
(:func:`build_container`, from a JSON description: :func:`container_description`) that
any FMI 2.0 importer runs (:func:`run_container`: fmpy's ``simulate_fmu``).  Its default
(parallel) mode is the Jacobi exchange; ``sequential=True`` orders regulator, plant,
command source, which is our master's default Gauss-Seidel order.
"""
from __future__ import annotations

import io
import logging
import zipfile
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from scenarios.ssp import system

log = logging.getLogger(__name__)

#: What the runners record per communication point: (instance, variable).
RECORDED = (("command", "vx_des"), ("command", "vy_des"), ("command", "yaw_rate_des"), ("command", "push_fx"),
            ("command", "push_fy"), ("command", "push_fz"),
            ("plant", "vx"), ("plant", "vy"), ("plant", "pitch"), ("plant", "roll"), ("plant", "pitch_rate"),
            ("plant", "roll_rate"), ("plant", "step_index"), ("plant", "pelvis_x"), ("plant", "pelvis_y"),
            ("plant", "pelvis_vx"), ("plant", "pelvis_vy"), ("plant", "yaw"), ("plant", "yaw_rate"),
            ("plant", "fell"),
            ("avr", "delta_swing_hip_pitch"), ("avr", "delta_swing_knee"), ("avr", "delta_swing_hip_roll"),
            ("avr", "delta_stance_hip_roll"), ("avr", "delta_stance_hip_pitch"), ("avr", "delta_stance_knee"),
            ("avr", "psi_x"), ("avr", "psi_y"), ("avr", "psi_pitch"), ("avr", "psi_roll"))
#: Our master's columns from the recorded ones (scenarios.cosim.master's row layout; telemetry as
#: scenarios.cosim.plant_fmu.FmuPlant names the plant FMU's outputs).
MASTER_COLUMNS = {
    "cmd_vx_des": "command_vx_des", "cmd_vy_des": "command_vy_des", "cmd_yaw_rate_des": "command_yaw_rate_des",
    "push_fx": "command_push_fx", "push_fy": "command_push_fy", "push_fz": "command_push_fz",
    **{f"in_{n}": f"plant_{n}" for n in ("vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate", "step_index")},
    **{f"out_{n}": f"avr_{n}" for i, n in RECORDED if i == "avr"},
    "tel_pelvis_x": "plant_pelvis_x", "tel_pelvis_y": "plant_pelvis_y", "tel_vx": "plant_pelvis_vx",
    "tel_vy": "plant_pelvis_vy", "tel_vx_step_avg": "plant_vx", "tel_vy_signal": "plant_vy",
    "tel_yaw": "plant_yaw", "tel_yaw_rate": "plant_yaw_rate",
}


# ------------------------------------------------------------------------------ masters
def run_libcosim(ssp: str | Path, duration_s: float, start_values: Mapping[str, Mapping[str, Any]] | None = None
                 ) -> np.ndarray:
    """Run the SSP in libcosim for ``duration_s``; rows of :data:`RECORDED` after every step.

    ``start_values``: {instance: {variable: value}} on top of the SSP's parameter sets.
    """
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    execution = CosimExecution.from_ssp_file(str(ssp))
    index, refs = _libcosim_variables(execution)
    for inst, values in (start_values or {}).items():
        for name, value in values.items():
            _libcosim_initial(execution, index[inst], refs[inst][name], value)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    n = int(round(duration_s / system.STEP_S))
    rows = np.zeros(n, dtype=_dtype())
    reads = _libcosim_reads(observer, index, refs)
    for k in range(n):
        if not execution.step():
            raise RuntimeError(f"libcosim step {k} failed")
        rows["t"][k] = (k + 1) * system.STEP_S
        for getter, slave, vrs, columns in reads:
            for column, value in zip(columns, getter(slave, vrs)):
                rows[column][k] = value
    return rows


def _libcosim_reads(observer, index, refs):
    """(getter, slave, value references, columns) per slave and type of :data:`RECORDED`."""
    getters = {0: observer.last_real_values, 1: observer.last_integer_values, 3: observer.last_boolean_values}
    groups: dict[tuple[str, int], tuple[list, list]] = {}
    for inst, var in RECORDED:
        ref = refs[inst][var]
        vrs, columns = groups.setdefault((inst, ref.type), ([], []))
        vrs.append(ref.reference)
        columns.append(f"{inst}_{var}")
    return [(getters[kind], index[inst], vrs, columns) for (inst, kind), (vrs, columns) in groups.items()]


def _libcosim_variables(execution):
    index = {i.name.decode(): i.index for i in execution.slave_infos()}
    refs = {inst: {v.name.decode(): v for v in execution.slave_variables(idx)} for inst, idx in index.items()}
    return index, refs


def _libcosim_initial(execution, slave: int, var, value) -> None:
    kind = var.type
    setter = {0: execution.real_initial_value, 1: execution.integer_initial_value,
              2: execution.string_initial_value, 3: execution.boolean_initial_value}[kind]
    if not setter(slave, var.reference, value):
        raise RuntimeError(f"libcosim refused the start value {var.name.decode()} = {value!r}")


def _libcosim_value(observer, slave: int, var):
    getter = {0: observer.last_real_values, 1: observer.last_integer_values, 3: observer.last_boolean_values}
    return getter[var.type](slave, [var.reference])[0]


def run_fmpy(ssp: str | Path, duration_s: float, start_values: Mapping[str, Mapping[str, Any]] | None = None
             ) -> np.ndarray:
    """Run the SSP with fmpy's ``simulate_ssp``; rows of :data:`RECORDED` after every step.

    The SSP's parameter bindings are passed as ``parameter_set`` (fmpy 0.3's simulate_ssp
    reads none itself; it applies this set to each FMU before its initialization mode)
    with ``start_values`` on top; fmpy 0.3 cannot set String variables, so String
    parameters must stay at their defaults.
    """
    from fmpy.ssp.simulation import simulate_ssp

    result = simulate_ssp(str(ssp), start_time=0.0, stop_time=duration_s - 0.5 * system.STEP_S,
                          step_size=system.STEP_S, parameter_set=ssp_parameter_set(ssp, start_values))
    rows = np.zeros(len(result), dtype=_dtype())
    rows["t"] = result["time"] + system.STEP_S  # fmpy labels a row with the step's start
    for inst, var in RECORDED:
        rows[f"{inst}_{var}"] = result[f"{inst}.{var}"]
    return rows


def run_ecos(ssp: str | Path, duration_s: float, parameter_set: str = system.PARAMETER_SET) -> np.ndarray:
    """Run the SSP in Ecos (``ecospy``) for ``duration_s``; rows of :data:`RECORDED` after every step.

    ``EcosSimulation(ssp_path=..., step_size=0.005).init(parameter_set=...)``: Ecos applies
    each component's binding named ``parameter_set`` in initialization mode.  Ecos takes
    the SSP file or its unpacked folder; it is given the folder, unpacked here into a
    temporary folder that is removed afterwards, because Ecos 0.7.2 leaves its own
    unpacked copy of a ``.ssp`` (``ecos_ssp_<uuid>``, 2 MB) in the system temp folder.
    Ecos has no start values on top of a parameter set (values set before ``init`` are
    not applied; a fixed parameter cannot change after it): other values need their
    own parameter set.
    """
    import tempfile

    ecos_simulation, ecos_lib = _ecospy()
    n = int(round(duration_s / system.STEP_S))
    rows = np.zeros(n, dtype=_dtype())
    kinds = _dtype()
    with tempfile.TemporaryDirectory(prefix="cassie_avr_ecos_") as unpacked:
        with zipfile.ZipFile(ssp) as archive:
            archive.extractall(unpacked)
        with ecos_simulation(ssp_path=unpacked, step_size=system.STEP_S) as sim:
            if not sim.init(parameter_set=parameter_set):
                raise RuntimeError(f"Ecos could not initialise {ssp} with parameter set {parameter_set!r}: "
                                   f"{ecos_lib.get_last_error()}")
            getters = [({"i": sim.get_integer, "b": sim.get_bool}.get(kinds[f"{i}_{v}"].kind, sim.get_real),
                        f"{i}::{v}") for i, v in RECORDED]
            for k in range(n):
                sim.step()
                t = sim.get_time()
                if abs(t - (k + 1) * system.STEP_S) > 0.5 * system.STEP_S:
                    raise RuntimeError(f"Ecos step {k} reached t = {t!r} s: {ecos_lib.get_last_error()}")
                rows[k] = ((k + 1) * system.STEP_S, *(get(name) for get, name in getters))
            sim.terminate()
    return rows


def _ecospy():
    """ecospy's EcosSimulation and EcosLib; its library needs TBB (Debian: libtbb12)."""
    import os

    path = os.environ.get("PATH")
    try:
        from ecospy import EcosLib, EcosSimulation
    except OSError as exc:
        raise RuntimeError(f"ecospy's library did not load ({exc}); on Debian it needs the package libtbb12") from exc
    finally:  # importing ecospy puts its binaries/ first on PATH (for its proxyfmu, unused here)
        if path is None:
            os.environ.pop("PATH", None)
        else:
            os.environ["PATH"] = path
    return EcosSimulation, EcosLib


def ssp_parameter_set(ssp: str | Path, start_values=None):
    """The SSP's parameter bindings (and ``start_values``) as one fmpy ParameterSet, each
    name prefixed with its instance (SSP's hierarchical names, what fmpy matches),
    String parameters at their FMU default left out."""
    from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd

    values: dict[str, tuple[str, str]] = {}
    for comp in read_ssd(str(ssp)).system.elements:
        for binding in comp.parameterBindings:
            for pset in binding.parameterValues:
                for p in pset.parameters:
                    values[f"{comp.name}.{p.name}"] = (p.type, p.value)
    for inst, extra in (start_values or {}).items():
        for name, value in extra.items():
            kind = "Boolean" if isinstance(value, bool) else "Integer" if isinstance(value, int) else "Real"
            values[f"{inst}.{name}"] = (kind, repr(value))
    out = ParameterSet(name="parameters")
    for name, (kind, value) in values.items():
        if kind == "String":
            continue
        out.parameters.append(Parameter(name=name, type=kind, value=_fmpy_value(kind, value)))
    return out


def _fmpy_value(kind: str, text: str):
    if kind == "Boolean":
        return text.lower() in ("true", "1")
    return int(text) if kind == "Integer" else float(text)


def _dtype() -> np.dtype:
    kinds = {"step_index": "i8", "fell": "?"}
    return np.dtype([("t", "f8")] + [(f"{i}_{v}", kinds.get(v, "f8")) for i, v in RECORDED])


def step_averaged_speed_error(rows: np.ndarray, vx_des: float, window_s: float = 5.0) -> float:
    """Mean |step-averaged forward speed - vx_des| over the last ``window_s`` (the suite's metric)."""
    from scenarios.results.metrics import steady_state_error

    table = np.zeros(len(rows), dtype=[("t", "f8"), ("cmd_vx_des", "f8"), ("cmd_vy_des", "f8"),
                                       ("tel_vx_step_avg", "f8"), ("in_vy", "f8"), ("in_step_index", "i8")])
    table["t"], table["cmd_vx_des"] = rows["t"], vx_des
    table["tel_vx_step_avg"], table["in_vy"], table["in_step_index"] = rows["plant_vx"], rows["plant_vy"], \
        rows["plant_step_index"]
    return steady_state_error(table, "vx", window_s=window_s)


def master_rows(rows: np.ndarray, *, stop_at_fall: bool = True) -> tuple[np.ndarray, bool, float | None]:
    """``rows`` of a runner in our master's columns (:data:`MASTER_COLUMNS`) for the suite's
    metrics, and (fell, t_fall_s) as our master reports them: the rows end with the first
    communication point at which the plant's ``fell`` is set (our master stops there)."""
    fell_at = np.flatnonzero(rows["plant_fell"])
    fell = bool(len(fell_at))
    t_fall = float(rows["t"][fell_at[0]]) if fell else None
    if fell and stop_at_fall:
        rows = rows[:fell_at[0] + 1]
    kinds = {"in_step_index": "i8"}
    out = np.zeros(len(rows), dtype=[("t", "f8")] + [(c, kinds.get(c, "f8")) for c in MASTER_COLUMNS])
    out["t"] = rows["t"]
    for column, recorded in MASTER_COLUMNS.items():
        out[column] = rows[recorded]
    return out, fell, t_fall


def arm_metrics(rows: np.ndarray, scenario) -> dict:
    """The per-arm metrics of ``summary.json`` for a runner's ``rows`` of ``scenario``'s arm."""
    from scenarios.results.metrics import summarize_arm

    table, fell, t_fall = master_rows(rows)
    return summarize_arm(table, fell=fell, t_fall_s=t_fall, perturbation_t_s=scenario.perturbation_t_s)


def claim_verdict(scenario, arm_rows: Mapping[str, np.ndarray]) -> dict:
    """The scenario's claim verdict (``scenarios.results.output.verdict``) from each arm's runner rows."""
    from scenarios.results.output import evaluate_claim, scenario_header

    arms = {arm: arm_metrics(rows, scenario) for arm, rows in arm_rows.items()}
    return evaluate_claim(scenario_header(scenario, "ssp").get("claim"), arms)


# ------------------------------------------------------------------ the FMU container
#: The container's embedded FMUs in sequential mode: the regulator steps on the plant's outputs
#: at t_k, the plant on the regulator's new offsets (our master's Gauss-Seidel order), the
#: command source last (its outputs after the step are the command of t_(k+1)).
SEQUENTIAL_ORDER = (system.REGULATOR, system.PLANT, system.COMMAND)


def container_description(ssp: str | Path, *, sequential: bool = False, name: str = "CassieAVR_container.fmu"
                          ) -> tuple[dict, dict[str, bytes]]:
    """fmucontainer's JSON description of the SSP's system, and the FMU files it names.

    From the SSP itself: one embedded FMU per component (named by its file name), the
    SSP's connections as links, every :data:`RECORDED` variable as a container output
    named ``instance.variable``, every other output dropped, the parameter sets' values
    as start values (fmucontainer reads an SSP's routing only, not its parameter sets,
    hence a JSON description).  Nothing is exposed automatically; the container steps
    every 5 ms, in parallel (Jacobi) or, ``sequential``, in :data:`SEQUENTIAL_ORDER`.
    """
    from fmpy import read_model_description
    from fmpy.ssp.ssd import read_ssd

    ssd = read_ssd(str(ssp))
    files: dict[str, str] = {}
    blobs: dict[str, bytes] = {}
    start: list[list[str]] = []
    outputs: dict[str, list[str]] = {}
    with zipfile.ZipFile(ssp) as archive:
        for comp in ssd.system.elements:
            fmu = Path(comp.source).name
            if fmu in blobs:
                raise ValueError(f"{ssp}: two components use {fmu}; fmucontainer names an FMU by its file name")
            files[comp.name], blobs[fmu] = fmu, archive.read(comp.source)
            md = read_model_description(io.BytesIO(blobs[fmu]))
            outputs[comp.name] = [v.name for v in md.modelVariables if v.causality == "output"]
            start += [[fmu, p.name, p.value] for b in comp.parameterBindings for pset in b.parameterValues
                      for p in pset.parameters]
    links = [[files[c.startElement], c.startConnector, files[c.endElement], c.endConnector]
             for c in ssd.system.connections]
    used = {(c.startElement, c.startConnector) for c in ssd.system.connections} | set(RECORDED)
    order = SEQUENTIAL_ORDER if sequential else tuple(files)
    description = {
        "name": name, "step_size": system.STEP_S, "sequential": sequential, "mt": False,
        "auto_link": False, "auto_input": False, "auto_output": False, "auto_parameter": False, "auto_local": False,
        "fmu": [files[inst] for inst in order],
        "link": links,
        "output": [[files[inst], var, f"{inst}.{var}"] for inst, var in RECORDED],
        "drop": [[files[inst], var] for inst, names in outputs.items() for var in names if (inst, var) not in used],
        "start": start,
    }
    return description, blobs


def fmucontainer_command() -> Path:
    """fmu-manipulation-toolbox's ``fmucontainer`` beside the running interpreter."""
    import sys

    exe = Path(sys.executable).parent / ("fmucontainer.exe" if sys.platform == "win32" else "fmucontainer")
    if not exe.is_file():
        raise RuntimeError(f"{exe}: no fmucontainer beside the interpreter (pip install 'fmu-manipulation-toolbox>=2.0')")
    return exe


def build_container(ssp: str | Path, out: str | Path, *, sequential: bool = False) -> Path:
    """Pack the SSP's FMUs into the container FMU ``out`` with ``fmucontainer -container
    <description>.json -fmu-directory <folder>`` (the tool's documented command), built in a
    temporary folder beside ``out`` that is removed afterwards."""
    import json
    import shutil
    import subprocess
    import tempfile

    out = Path(out).resolve()  # fmucontainer runs in the temporary folder: every path it gets is absolute
    description, blobs = container_description(ssp, sequential=sequential, name=out.name)
    with tempfile.TemporaryDirectory(prefix="container_", dir=out.parent) as tmp:
        folder = Path(tmp)
        for name, data in blobs.items():
            (folder / name).write_bytes(data)
        (folder / "container.json").write_text(json.dumps(description, indent=1))
        proc = subprocess.run([str(fmucontainer_command()), "-container", "container.json", "-fmu-directory",
                               str(folder)], cwd=folder, capture_output=True, text=True, timeout=600)
        built = folder / out.name
        if proc.returncode != 0 or not built.is_file():
            raise RuntimeError(f"fmucontainer failed (exit {proc.returncode}):\n{proc.stdout[-3000:]}{proc.stderr[-3000:]}")
        log.debug("fmucontainer: %s", proc.stdout)
        shutil.move(str(built), out)
    return out


def run_container(fmu: str | Path, duration_s: float) -> np.ndarray:
    """Run a container FMU (:func:`build_container`) with fmpy's ``simulate_fmu`` for
    ``duration_s``, a communication point every 5 ms; rows of :data:`RECORDED` after every
    step (the row fmpy records at t = 0, after initialization, left out)."""
    from fmpy import simulate_fmu

    n = int(round(duration_s / system.STEP_S))
    result = simulate_fmu(str(fmu), start_time=0.0, stop_time=n * system.STEP_S, step_size=system.STEP_S,
                          output_interval=system.STEP_S, output=[f"{i}.{v}" for i, v in RECORDED])
    if len(result) != n + 1:
        raise RuntimeError(f"{fmu}: fmpy recorded {len(result)} rows, not {n + 1}")
    rows = np.zeros(n, dtype=_dtype())
    rows["t"] = (np.arange(n) + 1) * system.STEP_S
    for inst, var in RECORDED:
        rows[f"{inst}_{var}"] = result[f"{inst}.{var}"][1:]
    return rows
