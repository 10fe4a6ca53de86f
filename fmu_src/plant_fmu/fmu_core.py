"""The pure core of the ``CassiePlant`` FMU: its variables and what each FMI call does.

The FMU (``fmu_src/plant_fmu/cassie_plant_slave.py``) is a thin translator over this module; this
module knows nothing of FMI.  It wraps :class:`plant.sim.CassieWalker` (MuJoCo at its
0.5 ms step with the nominal controller, starting from rest in the ``home`` pose):

* :data:`PARAM_SPECS` are fixed parameters: ``cassie_model`` (``menagerie`` or ``osu``) and the
  perturbation, mapped onto :class:`plant.perturbation.Perturbation` by
  :func:`perturbation_from_values`, whose ``problems()`` are the one validation (the
  scenario files run the same one): every message names the field and its range.
* :data:`INPUT_SPECS` carry the command (speeds and yaw rate), the regulator's six joint offsets (the names
  of the regulator FMU's outputs) and an external force on the pelvis.
* :data:`OUTPUT_SPECS` are the regulator's inputs under the regulator's names
  (``vx`` is the step-averaged forward speed, ``vy`` the filtered lateral speed; see
  ``plant/controller.py``), telemetry and ``fell`` (a fall is an output: the physics
  goes on).

:func:`start` builds a walker, :func:`advance` applies inputs and runs whole plant
steps, :func:`outputs` reads them, :func:`state_to_bytes`/:func:`state_from_bytes`
carry MuJoCo's integration state and the controller's memory bit-exactly.
"""
from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import Mapping

from fmu_src.fmi import avr_fmustate
from fmu_src.core.avr_specs import VarSpec
from fmu_src.core.avr_errors import StateError
from plant.constants import NOMINAL_TORSO_MASS_KG, OFFSET_NAMES, SIDES
from plant.errors import PerturbationError
from plant.gaits import GaitLibrary
from plant.model import load_model
from plant.perturbation import (MAX_COM_OFFSET_M, MAX_DAMPING_SCALE, MAX_FLOOR_FRICTION, MAX_FLOOR_SLOPE_DEG,
                                MAX_LINK_MASS_SCALE, MAX_TORSO_MASS_KG, Perturbation)
from plant.sim import CassieWalker
from plant.terrain import MAX_HEIGHT_M, MAX_SLOPE_DEG, SIZE_RANGE_M, TerrainSpec

MODEL_IDENTIFIER = "CassiePlant"
#: The plant step (s) of both models; communication steps must be whole multiples of it.
PLANT_STEP_S = 0.0005
#: The ``cassie_model`` parameter's values and the MJCF file of each, relative to the models folder.
MODEL_FILES = {"menagerie": "menagerie/agility_cassie/scene.xml", "osu": "osu/cassie.xml"}
#: A relative tolerance on "a whole number of plant steps" (the master's own rule is 1e-6
#: of a plant step; any float h = k * 0.5 ms computed by a master is within 1e-12 of it).
STEPS_TOL = 1e-6
#: The longest communication step (s): 20,000 plant steps, 1.3 to 2 s of wall time on this
#: project's 2-core machine (0.13 to 0.2 s per simulated second, alone or shared).  Nothing can
#: stop a doStep once it runs: fmi2CancelStep is for asynchronous steps (canRunAsynchronuously is
#: false), and neither the guard nor pythonfmu makes two threads' calls on one instance safe
#: (fmi2Terminate or fmi2FreeInstance during a doStep would race on the instance).  So a longer
#: step, which could run for hours, is refused (fmi2Error naming this maximum); a master takes
#: several steps instead.
MAX_STEP_S = 10.0


#: The links whose mass the FMU can scale (``link_mass_scale_<body with _>``): the thigh (hip
#: pitch body, 5.5 kg, the heaviest), the shin and the tarsus of each leg. Each parameter costs
#: every instance's registration (pythonfmu keeps about 0.2 kB per variable per instantiate/free
#: cycle, tests/fmu/test_fmu_memory.py bounds the total), so the lighter links and the linkage's
#: rods and springs are the scenario files' only (``[[link_mass]]``, --plant inprocess).
LINK_MASS_BODIES = tuple(f"{side}-{link}" for side in ("left", "right") for link in ("hip-pitch", "shin", "tarsus"))
#: The floor friction of both models' floor (the parameter's default leaves it).
MODEL_FLOOR_FRICTION = 1.0


def link_parameter(body: str) -> str:
    return "link_mass_scale_" + body.replace("-", "_")


def _p(name, default, lo, hi, unit, description, type="Real"):
    return VarSpec(name, type, default, lo, hi, unit, "parameter", "fixed", description)


def _i(name, lo, hi, unit, description):
    return VarSpec(name, "Real", 0.0, lo, hi, unit, "input", "continuous", description)


def _o(name, unit, description, type="Real"):
    variability = "continuous" if type == "Real" else "discrete"
    default = {"Real": 0.0, "Integer": 0, "Boolean": False}[type]
    return VarSpec(name, type, default, None, None, unit, "output", variability, description)


PARAM_SPECS: tuple[VarSpec, ...] = (
    _p("cassie_model", "menagerie", None, None, "",
       "Cassie model: 'menagerie' (MuJoCo Menagerie's agility_cassie) or 'osu' (Oregon State's "
       "cassie-mujoco-sim model); both travel in the FMU's resources", type="String"),
    _p("torso_mass_kg", NOMINAL_TORSO_MASS_KG, 0.0, MAX_TORSO_MASS_KG, "kg",
       f"Torso (pelvis) mass, kg, in (0, {MAX_TORSO_MASS_KG:g}]; the nominal {NOMINAL_TORSO_MASS_KG:g} kg "
       "leaves the model as it is; the pelvis inertia scales with it"),
    *(_p(f"torso_com_offset_{axis}_m", 0.0, -MAX_COM_OFFSET_M, MAX_COM_OFFSET_M, "m",
         f"Torso COM offset, pelvis frame {axis} ({where}), m, in [{-MAX_COM_OFFSET_M:g}, {MAX_COM_OFFSET_M:g}]")
      for axis, where in (("x", "forward"), ("y", "left"), ("z", "up"))),
    _p("joint_damping_scale", 1.0, 0.0, MAX_DAMPING_SCALE, "1",
       f"Multiplies every joint damping, in [0, {MAX_DAMPING_SCALE:g}]"),
    _p("terrain_max_height_m", 0.0, 0.0, MAX_HEIGHT_M, "m",
       f"Uneven terrain: highest bump, m, in (0, {MAX_HEIGHT_M:g}]; 0 keeps the flat floor (the other "
       "terrain_* parameters are then unused)"),
    _p("terrain_max_slope_deg", 10.0, 0.0, MAX_SLOPE_DEG, "deg",
       f"Uneven terrain: steepest slope, deg, in (0, {MAX_SLOPE_DEG:g}]"),
    _p("terrain_seed", 0, 0, 2**31 - 1, "1", "Uneven terrain: seed of the random field, >= 0", type="Integer"),
    _p("terrain_size_m", 20.0, *SIZE_RANGE_M, "m",
       f"Uneven terrain: half-length of the square field around the start, m, in [{SIZE_RANGE_M[0]:g}, "
       f"{SIZE_RANGE_M[1]:g}] (at most 2001 samples per side at 0.05 m, so at most 50 m); no ground beyond it"),
    _p("floor_friction", MODEL_FLOOR_FRICTION, 0.0, MAX_FLOOR_FRICTION, "1",
       f"Sliding friction of the floor (or terrain), in (0, {MAX_FLOOR_FRICTION:g}]; the floor's friction is the "
       f"contact's (it has the higher contact priority); {MODEL_FLOOR_FRICTION:g} is the models' own"),
    _p("floor_slope_deg", 0.0, -MAX_FLOOR_SLOPE_DEG, MAX_FLOOR_SLOPE_DEG, "deg",
       f"Constant slope of the flat floor along world x (positive: rising ahead), deg, in "
       f"[{-MAX_FLOOR_SLOPE_DEG:g}, {MAX_FLOOR_SLOPE_DEG:g}]; not with terrain"),
    _p("floor_cross_slope_deg", 0.0, -MAX_FLOOR_SLOPE_DEG, MAX_FLOOR_SLOPE_DEG, "deg",
       f"Constant slope of the flat floor along world y (positive: rising to the left), deg, in "
       f"[{-MAX_FLOOR_SLOPE_DEG:g}, {MAX_FLOOR_SLOPE_DEG:g}]; not with terrain"),
    *(_p(link_parameter(body), 1.0, 0.0, MAX_LINK_MASS_SCALE, "1",
         f"Mass (and inertia) factor of the {body} link, in (0, {MAX_LINK_MASS_SCALE:g}]; 1 leaves it")
      for body in LINK_MASS_BODIES),
)

INPUT_SPECS: tuple[VarSpec, ...] = (
    _i("vx_des", -3.0, 3.0, "m/s", "Commanded forward speed (heading frame), m/s; selects the gait"),
    _i("vy_des", -3.0, 3.0, "m/s", "Commanded lateral speed (heading frame), m/s; selects the gait"),
    _i("yaw_rate_des", -2.0, 2.0, "rad/s", "Commanded turning rate, rad/s, positive turns left (the reference "
       "heading turns at it, rate-limited; the speeds stay in the heading frame)"),
    *(_i(k, -1.5, 1.5, "rad", f"Regulator offset {k[6:]} added to the virtual constraint, rad "
         "(signs in plant/controller.py)") for k in OFFSET_NAMES),
    _i("push_fx", -5000.0, 5000.0, "N", "External force on the pelvis COM, world x, N"),
    _i("push_fy", -5000.0, 5000.0, "N", "External force on the pelvis COM, world y, N"),
    _i("push_fz", -5000.0, 5000.0, "N", "External force on the pelvis COM, world z, N"),
)

OUTPUT_SPECS: tuple[VarSpec, ...] = (
    _o("vx", "m/s", "Forward pelvis speed averaged over the last completed walking step, m/s "
       "(0 before the first step): the regulator's vx"),
    _o("vy", "m/s", "Lateral pelvis speed, heading frame, low-pass filtered (0.1 s), m/s: the regulator's vy"),
    _o("pitch", "rad", "Torso pitch, rad, positive nose down"),
    _o("roll", "rad", "Torso roll, rad, positive left side up"),
    _o("pitch_rate", "rad/s", "Torso pitch rate (heading frame), rad/s"),
    _o("roll_rate", "rad/s", "Torso roll rate (heading frame), rad/s"),
    _o("step_index", "1", "Completed walking steps (the regulator's step_index)", type="Integer"),
    *(_o(f"pelvis_{axis}", "m", f"Pelvis position, world {axis}, m") for axis in "xyz"),
    _o("pelvis_vx", "m/s", "Instantaneous forward pelvis speed (heading frame), m/s"),
    _o("pelvis_vy", "m/s", "Instantaneous lateral pelvis speed (heading frame), m/s"),
    _o("yaw", "rad", "Pelvis heading (yaw about world z), rad, wrapped to [-pi, pi]"),
    _o("yaw_rate", "rad/s", "Pelvis yaw rate about world z, rad/s"),
    _o("stance", "1", "Stance leg: 0 left, 1 right", type="Integer"),
    _o("gait_phase", "1", "Phase of the current walking step, 0 at touch-down (0 while standing)"),
    *(_o(f"{side}_foot_force", "N", f"Contact normal force on the {side} foot, N") for side in SIDES),
    _o("plant_time", "s", "MuJoCo's simulated time (the sum of its 0.5 ms steps), s"),
    _o("fell", "1", "True once the robot has fallen (pelvis below 0.55 m above the ground or tilted "
       "beyond 0.7 rad); latched; the simulation goes on", type="Boolean"),
)

SPECS: tuple[VarSpec, ...] = (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)
PARAM_DEFAULTS = {s.name: s.default for s in PARAM_SPECS}
INPUT_NAMES = tuple(s.name for s in INPUT_SPECS)


# ------------------------------------------------------------------------------ parameters
def perturbation_from_values(values: Mapping) -> Perturbation:
    """The plant Perturbation the parameter values describe (not validated here); the
    floor and link parameters may be left out (their defaults change nothing)."""
    def get(name):
        return values.get(name, PARAM_DEFAULTS[name])

    friction = get("floor_friction")
    mass = values["torso_mass_kg"]
    terrain = None
    if values["terrain_max_height_m"] != 0.0:
        terrain = TerrainSpec(max_height_m=values["terrain_max_height_m"],
                              max_slope_deg=values["terrain_max_slope_deg"],
                              seed=values["terrain_seed"], size_m=values["terrain_size_m"])
    return Perturbation(
        torso_mass_kg=None if mass == NOMINAL_TORSO_MASS_KG else mass,
        torso_com_offset_m=(values["torso_com_offset_x_m"], values["torso_com_offset_y_m"],
                            values["torso_com_offset_z_m"]),
        joint_damping_scale=values["joint_damping_scale"], terrain=terrain,
        floor_friction=None if friction == MODEL_FLOOR_FRICTION else friction,
        slope_deg=get("floor_slope_deg"), cross_slope_deg=get("floor_cross_slope_deg"),
        link_mass_scale=tuple((body, get(link_parameter(body))) for body in LINK_MASS_BODIES
                              if get(link_parameter(body)) != 1.0))


def values_from_perturbation(model: str, perturbation: Perturbation | None) -> dict:
    """The parameter values of ``model`` with ``perturbation`` (the inverse of
    :func:`perturbation_from_values`); the scenarios' --plant fmu path uses it."""
    p = perturbation or Perturbation()
    if p.torso_added_mass_kg is not None:
        raise ValueError(f"torso_added_mass_kg = {p.torso_added_mass_kg!r}: the CassiePlant FMU takes the absolute "
                         "torso_mass_kg only (plant.perturbation.resolved gives it)")
    values = dict(PARAM_DEFAULTS, cassie_model=model, joint_damping_scale=float(p.joint_damping_scale))
    if p.torso_mass_kg is not None:
        values["torso_mass_kg"] = float(p.torso_mass_kg)
    for axis, c in zip("xyz", p.torso_com_offset_m):
        values[f"torso_com_offset_{axis}_m"] = float(c)
    if p.floor_friction is not None:
        values["floor_friction"] = float(p.floor_friction)
    values.update(floor_slope_deg=float(p.slope_deg), floor_cross_slope_deg=float(p.cross_slope_deg))
    for body, scale in p.link_mass_scale:
        if link_parameter(body) in values:  # others: plantio.fmu_unsupported refuses the scenario
            values[link_parameter(body)] = float(scale)
    if p.terrain is not None:
        values.update(terrain_max_height_m=float(p.terrain.max_height_m),
                      terrain_max_slope_deg=float(p.terrain.max_slope_deg),
                      terrain_seed=int(p.terrain.seed), terrain_size_m=float(p.terrain.size_m))
    return values


def model_problem(model) -> str | None:
    if model in MODEL_FILES:
        return None
    return f"cassie_model = {model!r}: must be one of {', '.join(repr(m) for m in MODEL_FILES)}"


def problems(values: Mapping) -> list[str]:
    """Every problem of the parameter values (the model's and the Perturbation's own)."""
    found = [p for p in [model_problem(values["cassie_model"])] if p]
    return found + perturbation_from_values(values).problems()


# ------------------------------------------------------------------------------ stepping
def start(values: Mapping, models_dir: str | Path | None = None, gaits: GaitLibrary | None = None) -> CassieWalker:
    """A walker at rest in the ``home`` pose for the parameter values, walking on ``gaits``
    (None: the committed library, :meth:`plant.gaits.GaitLibrary.default`).

    ``models_dir`` holds the :data:`MODEL_FILES` (the FMU's resources); None loads the
    models by name (``plant.model.load_model``).  PerturbationError lists every problem
    (``.problems``, one string each); ModelError when a model file is missing.
    """
    found = problems(values)
    if found:
        err = PerturbationError(f"invalid CassiePlant parameters, {len(found)} problem(s): " + "; ".join(found))
        err.problems = found
        raise err
    model = values["cassie_model"]
    source = model if models_dir is None else str(Path(models_dir) / MODEL_FILES[model])
    walker = CassieWalker(load_model(source, perturbation_from_values(values)), gaits=gaits)
    if walker.SIM_DT_S != PLANT_STEP_S:
        raise PerturbationError(f"model {model!r} has a {walker.SIM_DT_S} s step, the FMU needs {PLANT_STEP_S} s")
    return walker


def plant_steps(step_size_s: float) -> int | None:
    """``step_size_s`` as a number of plant steps, or None unless it is a whole number in
    [1, MAX_STEP_S / PLANT_STEP_S]."""
    n = step_size_s / PLANT_STEP_S
    if not (math.isfinite(n) and n >= 1.0 - STEPS_TOL and abs(n - round(n)) <= STEPS_TOL
            and step_size_s <= MAX_STEP_S):
        return None
    return int(round(n))


def step_problem(step_size_s: float) -> str | None:
    if not step_size_s <= MAX_STEP_S:  # also NaN
        return (f"communicationStepSize = {step_size_s!r} s: exceeds the maximum communication step "
                f"{MAX_STEP_S:g} s of this FMU (take several steps)")
    if plant_steps(step_size_s) is None:
        return (f"communicationStepSize = {step_size_s!r} s: must be a whole multiple of the plant step "
                f"{PLANT_STEP_S} s")
    return None


def apply_inputs(walker: CassieWalker, inputs: Mapping) -> None:
    """Command (only when it changes: a new command re-selects the gait), offsets, force."""
    command = (float(inputs["vx_des"]), float(inputs["vy_des"]), float(inputs["yaw_rate_des"]))
    if command != (walker.vx_des, walker.vy_des, walker.yaw_rate_des):
        walker.set_command(*command)
    walker.set_offsets({k: inputs[k] for k in OFFSET_NAMES})
    force = [inputs["push_fx"], inputs["push_fy"], inputs["push_fz"]]
    ph = walker.physics
    if force != ph.data.xfrc_applied[ph.pelvis_body, :3].tolist():
        walker.set_pelvis_force(force)


def advance(walker: CassieWalker, inputs: Mapping, n_steps: int) -> dict:
    """Apply ``inputs`` (held over the step), run ``n_steps`` plant steps, return the outputs."""
    apply_inputs(walker, inputs)
    walker.advance(n_steps)
    return outputs(walker)


def outputs(walker: CassieWalker) -> dict:
    """Every output by name (Python float, int or bool)."""
    reg = walker.regulator_inputs()
    tel = walker.telemetry()
    out = {n: float(reg[n]) for n in ("vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate")}
    out["step_index"] = int(reg["step_index"])
    out.update({n: float(tel[n]) for n in ("pelvis_x", "pelvis_y", "pelvis_z", "left_foot_force",
                                           "right_foot_force")})
    out.update(pelvis_vx=float(tel["vx"]), pelvis_vy=float(tel["vy"]), yaw=float(tel["yaw"]),
               yaw_rate=float(tel["yaw_rate"]), stance=int(tel["stance"]),
               gait_phase=float(tel["tau"]), plant_time=float(tel["t"]), fell=walker.fell())
    return out


# ------------------------------------------------------------------------------ state
def encode_fmu_state(values: Mapping, phase: str, time_s: float, walker: CassieWalker | None) -> bytes:
    """The FMU state blob (the regulator's format, ``fmu_src/fmi/avr_fmustate.py``: every variable, the FMI
    phase, the time, then the walker's exact state, CRC-32)."""
    return avr_fmustate.encode(dict(values), phase, time_s, b"" if walker is None else state_to_bytes(walker))


def decode_fmu_state(blob) -> avr_fmustate.FmuStateParts:
    """:func:`encode_fmu_state`'s parts, every value checked against :data:`SPECS` (StateError names why)."""
    return avr_fmustate.decode(blob, SPECS)


#: Walker state blob: magic, version, JSON length.
_STATE_HEADER = struct.Struct("<4sII")
_STATE_MAGIC = b"CPWS"
_STATE_VERSION = 2


def state_to_bytes(walker: CassieWalker) -> bytes:
    """The walker's exact state (MuJoCo integration state, servo gains, memories) as bytes."""
    text = json.dumps(walker.get_state(), sort_keys=True).encode("utf-8")  # float repr round-trips exactly
    return _STATE_HEADER.pack(_STATE_MAGIC, _STATE_VERSION, len(text)) + text


def state_from_bytes(walker: CassieWalker, blob: bytes) -> None:
    """Restore :func:`state_to_bytes` into ``walker`` (built with the same parameters).

    StateError (the walker unchanged) when the blob is not such a state or does not fit.
    """
    state = checked_state(walker, blob)
    try:
        walker.set_state(state)
    except (ValueError, KeyError, TypeError) as exc:
        raise StateError(f"CassiePlant walker state does not fit this plant: {exc}") from None


def checked_state(walker: CassieWalker, blob: bytes) -> dict:
    """The walker state in ``blob`` (:func:`state_to_bytes`) once it is one ``walker`` (built with the
    same parameters) can have reached under this FMU (``CassieWalker.state_problems``, and the
    command and offsets within the inputs' ranges); StateError naming every problem otherwise.
    Nothing changes."""
    if len(blob) < _STATE_HEADER.size:
        raise StateError(f"plant state of {len(blob)} bytes is shorter than its header")
    magic, version, n = _STATE_HEADER.unpack_from(blob)
    if magic != _STATE_MAGIC or version != _STATE_VERSION or len(blob) != _STATE_HEADER.size + n:
        raise StateError(f"not a CassiePlant walker state (magic {magic!r}, version {version}, {len(blob)} bytes)")
    try:
        state = json.loads(blob[_STATE_HEADER.size:].decode("utf-8"))
    except ValueError as exc:
        raise StateError(f"CassiePlant walker state is not valid JSON ({exc})") from None
    problems = walker.state_problems(state) or _command_problems(state)
    if problems:
        raise StateError("invalid CassiePlant walker state: " + "; ".join(problems))
    return state


#: The command and offsets a walker state holds, each with the input whose range it has (the
#: controller's own copies too: its rate-limited gait speed and yaw rate, ``*_ref``, lie between 0 and the
#: command): a state outside them cannot come from this FMU.
_STATE_INPUTS = (("walker", "vx_des", "vx_des"), ("walker", "vy_des", "vy_des"),
                 ("walker", "yaw_rate_des", "yaw_rate_des"),
                 ("controller", "vx_des", "vx_des"), ("controller", "vx_ref", "vx_des"),
                 ("controller", "vy_des", "vy_des"), ("controller", "vy_ref", "vy_des"),
                 ("controller", "yaw_rate_des", "yaw_rate_des"), ("controller", "yaw_rate_ref", "yaw_rate_des"))


def _command_problems(state: Mapping) -> list[str]:
    """The walker state's command and offsets outside the ranges of this FMU's inputs (the walker
    has checked their types)."""
    specs = {spec.name: spec for spec in INPUT_SPECS}
    checks = [(f"{part} {field}", state[part][field], specs[name]) for part, field, name in _STATE_INPUTS]
    checks += [(f"controller offsets[{k!r}]", state["controller"]["offsets"][k], specs[k]) for k in OFFSET_NAMES]
    return [f"{label} = {value!r}: out of range [{spec.min:g}, {spec.max:g}] (the input {spec.name}'s)"
            for label, value, spec in checks if not spec.min <= value <= spec.max]
