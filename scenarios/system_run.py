"""Run the CassieAVR system (``dist/CassieAVR.ssp``) in libcosim, fmpy and Ecos, and script it.

Both FMUs take the command's speeds (``vx_des``, ``vy_des``); the plant alone takes its
yaw rate (``yaw_rate_des``: the regulator has no such input) and the push
(``push_fx/fy/fz``); nothing in the system drives them (:data:`SCRIPTED`).  The SSP's
parameter sets give the nominal start values (0.5 m/s, no turn, no push).  Over time:

* **libcosim**: an OSP scenario file (JSON: override events per variable and time),
  :func:`osp_scenario` writes one from a scenario TOML; ``execution.load_scenario``.
* **fmpy**: ``fmpy.ssp.simulation.simulate_ssp`` feeds ``input`` functions to the
  *system's* input connectors only, and libcosim's SSP reader refuses connections from
  system connectors, so the SSP file has none; :func:`with_system_inputs` writes a copy
  of it whose system has the :data:`SCRIPTED` inputs fanned out to both FMUs, and
  :func:`read_input_csv` turns an input CSV (``time`` + those columns; zero-order hold)
  into the ``input`` functions.  fmpy applies system inputs one step late (it copies
  connections after each step).

Each master with its own documented call on the same file (:func:`run_libcosim`,
:func:`run_fmpy`, :func:`run_ecos`):

* libcosim: ``CosimExecution.from_ssp_file(ssp)`` applies every component's first
  parameter binding;
* Ecos: ``EcosSimulation(ssp_path=ssp, step_size=...).init(parameter_set="nominal")``
  applies every component's set of that name (hence one name for both,
  :data:`scenarios.system.PARAMETER_SET`); :func:`run_ecos` hands it the SSP unpacked
  (Ecos leaves its own unpacked copy of a ``.ssp`` behind);
* fmpy 0.3: ``simulate_ssp(ssp, ..., parameter_set=...)`` reads no parameter binding
  itself, so :func:`ssp_parameter_set` hands it the SSP's own bindings under their
  hierarchical names (``plant.torso_mass_kg``), String values left out (fmpy cannot
  set them).

Exchange: all three step the two FMUs with the inputs of the previous communication
point (Jacobi) and read the outputs after the step, so they give the same trajectory;
our own master (``python -m scenarios run NAME --plant fmu``) senses the plant, steps
the regulator and hands its outputs to the plant in the same step (Gauss-Seidel), so
the regulator's offsets reach the plant 5 ms earlier there.
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from scenarios import system

SCRIPTED = ("vx_des", "vy_des", "yaw_rate_des", "push_fx", "push_fy", "push_fz")
#: The scripted inputs of both FMUs (the others are the plant's only).
COMMAND = ("vx_des", "vy_des")
#: What the runners record per communication point: (instance, variable).
RECORDED = (("plant", "vx"), ("plant", "vy"), ("plant", "step_index"), ("plant", "pelvis_x"),
            ("plant", "pelvis_y"), ("plant", "pitch"), ("plant", "fell"), ("avr", "delta_swing_hip_pitch"),
            ("avr", "psi_x"))


# ------------------------------------------------------------------------------ scripts
def schedule(scenario) -> list[tuple[float, dict[str, float]]]:
    """(time, values of :data:`SCRIPTED`) at t = 0 and wherever the scenario's command or push changes."""
    out, last = [], None
    for k in range(scenario.n_comm_steps):
        now = dict(zip(SCRIPTED, (*scenario.command_at_step(k), *scenario.push_force_at_step(k))))
        if now != last:
            out.append((k * scenario.comm_step_s, now))
            last = now
    return out


def osp_scenario(scenario) -> dict:
    """libcosim's scenario (override events) for the scenario's commands and pushes."""
    events, last = [], {}
    for t, values in schedule(scenario):
        for name, value in values.items():
            if last.get(name) != value:
                for model in ("plant", "avr") if name in COMMAND else ("plant",):
                    events.append({"time": t, "model": model, "variable": name, "action": "override",
                                   "value": value})
        last = values
    return {"description": f"{scenario.name}: commands and pushes", "events": events, "end": scenario.duration_s}


def input_csv(scenario) -> str:
    """fmpy's input CSV for the scenario's commands and pushes (zero-order hold between rows)."""
    rows = ["time," + ",".join(SCRIPTED)]
    rows += [f"{t!r}," + ",".join(repr(float(v[n])) for n in SCRIPTED) for t, v in schedule(scenario)]
    return "\n".join(rows) + "\n"


def read_input_csv(path: str | Path) -> dict[str, Callable[[float], float]]:
    """``simulate_ssp``'s ``input``: per column, the value of the last row at or before t."""
    from fmpy.util import read_csv

    signals = read_csv(str(path))
    times = np.asarray(signals["time"], dtype=float)

    def hold(values):
        return lambda t: float(values[max(int(np.searchsorted(times, t + 1e-12, side="right")) - 1, 0)])
    return {n: hold(np.asarray(signals[n], dtype=float)) for n in signals.dtype.names if n != "time"}


def with_system_inputs(ssp: str | Path, out: str | Path, names=SCRIPTED) -> Path:
    """A copy of the SSP whose system has input connectors ``names`` wired to every FMU input
    of that name (for fmpy's ``simulate_ssp(..., input=...)``; libcosim cannot read it)."""
    import xml.etree.ElementTree as ET

    q = system._q
    with zipfile.ZipFile(ssp) as archive:
        entries = {n: archive.read(n) for n in archive.namelist()}
    for prefix, uri in system.NS.items():
        ET.register_namespace(prefix, uri)
    root = ET.fromstring(entries["SystemStructure.ssd"])
    sysel = root.find(q("ssd:System"))
    connectors = ET.Element(q("ssd:Connectors"))
    sysel.insert(0, connectors)
    conns = sysel.find(q("ssd:Connections"))
    comps = [(c, _inputs_of(entries[c.get("source")])) for c in sysel.find(q("ssd:Elements"))]
    for name in names:
        ET.SubElement(ET.SubElement(connectors, q("ssd:Connector"), name=name, kind="input"), q("ssc:Real"))
        for comp, inputs in comps:
            if name in inputs:
                connector = ET.SubElement(comp.find(q("ssd:Connectors")), q("ssd:Connector"), name=name, kind="input")
                ET.SubElement(connector, q("ssc:Real"))
                ET.SubElement(conns, q("ssd:Connection"), startConnector=name, endElement=comp.get("name"),
                              endConnector=name)
    ET.indent(root)
    entries["SystemStructure.ssd"] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(entries):
            archive.writestr(name, entries[name])
    return Path(out)


def _inputs_of(fmu_bytes: bytes) -> set[str]:
    import io

    from fmpy import read_model_description

    md = read_model_description(io.BytesIO(fmu_bytes))
    return {v.name for v in md.modelVariables if v.causality == "input"}


# ------------------------------------------------------------------------------ masters
def run_libcosim(ssp: str | Path, duration_s: float, start_values: Mapping[str, Mapping[str, Any]] | None = None,
                 scenario_file: str | Path | None = None) -> np.ndarray:
    """Run the SSP in libcosim for ``duration_s``; rows of :data:`RECORDED` after every step.

    ``start_values``: {instance: {variable: value}} on top of the SSP's parameter sets.
    """
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver

    execution = CosimExecution.from_ssp_file(str(ssp))
    index, refs = _libcosim_variables(execution)
    for inst, values in (start_values or {}).items():
        for name, value in values.items():
            _libcosim_initial(execution, index[inst], refs[inst][name], value)
    if scenario_file is not None:
        manager = CosimManipulator.create_scenario_manager()
        execution.add_manipulator(manager)
        execution.load_scenario(manager, str(scenario_file))
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    n = int(round(duration_s / system.STEP_S))
    rows = np.zeros(n, dtype=_dtype())
    for k in range(n):
        if not execution.step():
            raise RuntimeError(f"libcosim step {k} failed")
        rows[k] = ((k + 1) * system.STEP_S, *(_libcosim_value(observer, index[i], refs[i][v]) for i, v in RECORDED))
    return rows


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


def run_fmpy(ssp: str | Path, duration_s: float, start_values: Mapping[str, Mapping[str, Any]] | None = None,
             inputs: Mapping[str, Callable[[float], float]] | None = None) -> np.ndarray:
    """Run the SSP with fmpy's ``simulate_ssp``; rows of :data:`RECORDED` after every step.

    The SSP's parameter bindings are passed as ``parameter_set`` (fmpy 0.3's simulate_ssp
    reads none itself; it applies this set to each FMU before its initialization mode)
    with ``start_values`` on top; fmpy 0.3 cannot set String variables, so String
    parameters must stay at their defaults.
    """
    from fmpy.ssp.simulation import simulate_ssp

    result = simulate_ssp(str(ssp), start_time=0.0, stop_time=duration_s - 0.5 * system.STEP_S,
                          step_size=system.STEP_S, parameter_set=ssp_parameter_set(ssp, start_values),
                          input=dict(inputs or {}))
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
    from scenarios.metrics import steady_state_error

    table = np.zeros(len(rows), dtype=[("t", "f8"), ("cmd_vx_des", "f8"), ("cmd_vy_des", "f8"),
                                       ("tel_vx_step_avg", "f8"), ("in_vy", "f8"), ("in_step_index", "i8")])
    table["t"], table["cmd_vx_des"] = rows["t"], vx_des
    table["tel_vx_step_avg"], table["in_vy"], table["in_step_index"] = rows["plant_vx"], rows["plant_vy"], \
        rows["plant_step_index"]
    return steady_state_error(table, "vx", window_s=window_s)


def write_osp_scenario(scenario, path: str | Path) -> Path:
    Path(path).write_text(json.dumps(osp_scenario(scenario), indent=1) + "\n")
    return Path(path)
