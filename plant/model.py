"""Loading the MuJoCo Cassie model, with an optional :class:`~plant.perturbation.Perturbation`.

Two descriptions of the same robot are supported (see ``/work/shared/cassie/README.md``):

* ``"menagerie"``: MuJoCo Menagerie's ``agility_cassie`` *scene* (``scene.xml``, robot
  plus floor and light), found by the ``mujoco-menagerie`` package in the folder
  :func:`menagerie_root` names (env ``MENAGERIE_ROOT``, else the shared offline copy
  ``<repo>/../shared/cassie/menagerie`` when it exists, else the package's download cache).
* ``"osu"``: Oregon State University's ``cassie.xml`` at :func:`osu_model_path`
  (env ``CASSIE_OSU_XML`` or ``<repo>/../shared/cassie/osu/cassie.xml``).
* anything else: the path of an MJCF file describing the same robot (same names).

Every model returned by :func:`load_model` has a ``home`` keyframe (the OSU file has
none; :func:`load_model` adds Menagerie's standing pose, :data:`plant.constants.HOME_JOINT_QPOS`,
under that name, looked up by joint name) and the Cassie joint, actuator and pelvis-body
names checked. Files are checked before MuJoCo parses them (:mod:`plant.mjcf`); terrain is
built into the model (:mod:`plant.terrain`), the other perturbations are set on the compiled
model (:mod:`plant.perturbation`).

The names other packages import from here (the constants, :class:`Perturbation`,
:class:`TerrainSpec`, the terrain functions, :func:`check_mjcf_file`) are re-exported from
their own modules.
"""

from __future__ import annotations

import copy
import logging
import os
import pathlib

import mujoco

from plant.constants import (
    ACTUATOR_NAMES, HOME_JOINT_QPOS, HOME_KEY, HOME_PELVIS_POS_M, HOME_PELVIS_QUAT, JOINT_NAMES,
    PELVIS_BODY,
)
from plant.errors import ModelError, PerturbationError
from plant.mjcf import spec_from_file
from plant.perturbation import Applied, Perturbation, apply_environment, apply_to_compiled
from plant.terrain import (
    add_terrain, terrain_summary,
)

log = logging.getLogger(__name__)

MENAGERIE_ROBOT = "agility_cassie"
MENAGERIE_ENTRY = "scene"  # scene.xml: the robot plus the floor
#: The offline copy of the models kept beside the repository (never copied into it).
_SHARED_CASSIE = pathlib.Path(__file__).resolve().parents[1].parent / "shared" / "cassie"


def menagerie_root() -> pathlib.Path | None:
    """The folder holding Menagerie's ``agility_cassie/``: env ``MENAGERIE_ROOT`` if set, else
    ``<repo>/../shared/cassie/menagerie`` if that folder exists, else None (the
    mujoco-menagerie download cache)."""
    env = os.environ.get("MENAGERIE_ROOT")
    if env:
        return pathlib.Path(env).expanduser()
    shared = _SHARED_CASSIE / "menagerie"
    return shared if shared.is_dir() else None


def osu_model_path() -> pathlib.Path:
    """Path of OSU's ``cassie.xml``: env ``CASSIE_OSU_XML`` if set, else the shared copy
    at ``<repo>/../shared/cassie/osu/cassie.xml``."""
    env = os.environ.get("CASSIE_OSU_XML")
    if env:
        return pathlib.Path(env).expanduser()
    return _SHARED_CASSIE / "osu" / "cassie.xml"


def menagerie_xml_path() -> pathlib.Path:
    """Path of Menagerie's ``agility_cassie`` scene file from :func:`menagerie_root`
    (ModelError naming where it looked and the fix)."""
    try:
        import mujoco_menagerie
    except ImportError as e:
        raise ModelError("the 'menagerie' model needs the mujoco-menagerie package "
                         "(pip install mujoco-menagerie)") from e
    root = menagerie_root()
    try:
        robot = mujoco_menagerie.get(MENAGERIE_ROBOT)
        return pathlib.Path(robot.xml(MENAGERIE_ENTRY, mujoco_menagerie.Cache(root=root)))
    except mujoco_menagerie.MenagerieError as e:
        where = (f"MENAGERIE_ROOT={root}" if root
                 else "the mujoco-menagerie download cache (MENAGERIE_ROOT is unset)")
        raise ModelError(
            f"cannot get Menagerie's {MENAGERIE_ROBOT!r} from {where}: {e}. Fix: set "
            f"MENAGERIE_ROOT to a folder holding {MENAGERIE_ROBOT}/{MENAGERIE_ENTRY}.xml "
            "(e.g. /work/shared/cassie/menagerie), or allow the one-off download") from e


def _add_home_key(spec: mujoco.MjSpec, model: mujoco.MjModel) -> None:
    """Add the standing ``home`` keyframe, filled per joint name, to ``spec``."""
    qpos = model.qpos0.copy()
    pelvis = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PELVIS_BODY)
    for j in range(model.njnt):
        adr, typ, name = model.jnt_qposadr[j], model.jnt_type[j], model.joint(j).name
        if model.jnt_bodyid[j] == pelvis:  # floating base: free, or slides + ball (OSU)
            if typ == mujoco.mjtJoint.mjJNT_FREE:
                qpos[adr:adr + 7] = HOME_PELVIS_POS_M + HOME_PELVIS_QUAT
            elif typ == mujoco.mjtJoint.mjJNT_BALL:
                qpos[adr:adr + 4] = HOME_PELVIS_QUAT
            elif typ == mujoco.mjtJoint.mjJNT_SLIDE:
                ax, ay, az = model.jnt_axis[j].tolist()  # fixed-order sum, no BLAS
                qpos[adr] = ax * HOME_PELVIS_POS_M[0] + ay * HOME_PELVIS_POS_M[1] + az * HOME_PELVIS_POS_M[2]
        elif name in HOME_JOINT_QPOS:
            vals = HOME_JOINT_QPOS[name]
            qpos[adr:adr + len(vals)] = vals
    spec.add_key(name=HOME_KEY, qpos=qpos.tolist())
    log.info("added %r keyframe (Menagerie's standing pose) to the model", HOME_KEY)


def _check_names(model: mujoco.MjModel, source: str) -> None:
    missing = []
    for kind, obj, names in (("joint", mujoco.mjtObj.mjOBJ_JOINT, JOINT_NAMES),
                             ("actuator", mujoco.mjtObj.mjOBJ_ACTUATOR, ACTUATOR_NAMES),
                             ("body", mujoco.mjtObj.mjOBJ_BODY, (PELVIS_BODY,))):
        missing += [f"{kind} {n!r}" for n in names if mujoco.mj_name2id(model, obj, n) < 0]
    if missing:
        raise ModelError(f"model {source} is not the Cassie model this project expects; "
                         f"missing {', '.join(missing)}")


def _source_spec(src: str) -> mujoco.MjSpec:
    """The checked, parsed MJCF of ``src``: ``menagerie``, ``osu`` or a file path."""
    if src == "menagerie":
        return spec_from_file(menagerie_xml_path(), "Menagerie")
    if src == "osu":
        return spec_from_file(osu_model_path(), "OSU")
    return spec_from_file(pathlib.Path(src).expanduser(), "MJCF")


def _compile(spec: mujoco.MjSpec, src: str, when: str = "") -> mujoco.MjModel:
    try:
        return spec.compile()
    except Exception as e:  # mujoco raises ValueError with the compiler's message
        raise ModelError(f"cannot compile model {src!r}{when}: {e}") from e


def load_model(source: str | os.PathLike = "menagerie",
               perturbation: Perturbation | None = None) -> mujoco.MjModel:
    """Compile the Cassie model with an optional perturbation (:func:`load_perturbed`,
    without its report)."""
    return load_perturbed(source, perturbation)[0]


def load_perturbed(source: str | os.PathLike = "menagerie",
                   perturbation: Perturbation | None = None) -> tuple[mujoco.MjModel, Applied | None]:
    """Compile the Cassie model with an optional perturbation; also what the perturbation
    applied (:class:`plant.perturbation.Applied`, None without one).

    Args:
        source: ``"menagerie"`` (Menagerie's ``agility_cassie`` scene with floor),
            ``"osu"`` (the file at :func:`osu_model_path`) or the path of an MJCF file.
        perturbation: validated first (:class:`PerturbationError` lists every problem);
            None or the default changes nothing.

    Returns:
        The compiled model; it has a ``home`` keyframe (added to models lacking one).

    Raises:
        ModelError: file missing or unparsable, Menagerie unavailable, or a Cassie
            joint, actuator or the pelvis body missing.
        PerturbationError: ``perturbation`` is invalid.
    """
    _validated(perturbation)
    src = os.fspath(source)
    spec = _source_spec(src)
    model = _compile(spec, src)
    _check_names(model, repr(src))
    edited = _edited(spec, model, perturbation, src)
    return _perturbed(model if edited is None else edited, perturbation, src)


def _edited(spec: mujoco.MjSpec, model: mujoco.MjModel, perturbation: Perturbation | None,
            src: str) -> mujoco.MjModel | None:
    """``spec`` (the source as parsed) compiled with what :func:`load_perturbed` adds to it: the
    ``home`` keyframe when the source has none (filled from ``model``, the source compiled) and
    the perturbation's terrain; None when there is nothing to add."""
    edits = False
    if not any(key.name == HOME_KEY for key in spec.keys):
        _add_home_key(spec, model)  # the keyframe depends on qpos0 and the joints only
        edits = True
    if perturbation is not None and perturbation.terrain is not None:
        add_terrain(spec, perturbation.terrain)
        edits = True
    if not edits:
        return None
    edited = _compile(spec, src, " after edits")
    key = edited.key(HOME_KEY)
    if key.qpos.shape != (edited.nq,):
        raise ModelError(f"{HOME_KEY!r} keyframe has {key.qpos.size} qpos, model nq={edited.nq}")
    return edited


def perturbed_with_terrain(model: mujoco.MjModel, perturbation: Perturbation,
                           source: str | os.PathLike = "menagerie") -> tuple[mujoco.MjModel, Applied | None]:
    """``load_perturbed(source, perturbation)`` for a perturbation with terrain, given ``model``,
    what ``load_perturbed(source)`` compiled (its names and keyframe checked): ``source`` parsed
    again and compiled once, with the terrain (``load_perturbed`` compiles it a first time to
    check it), the same bytes. ValueError for a perturbation without terrain (call
    :func:`perturbed_copy`)."""
    _validated(perturbation)
    if perturbation is None or perturbation.terrain is None:
        raise ValueError("a perturbation without terrain needs no compile: use perturbed_copy")
    src = os.fspath(source)
    return _perturbed(_edited(_source_spec(src), model, perturbation, src), perturbation, src)


def perturbed_copy(model: mujoco.MjModel, perturbation: Perturbation | None,
                   source: str | os.PathLike = "") -> tuple[mujoco.MjModel, Applied | None]:
    """``load_perturbed(source, perturbation)`` from ``model``, what ``load_perturbed(source)``
    compiled, without compiling again: a copy of ``model`` with the perturbation applied, the same
    bytes. ``model`` itself is left as it is. A perturbation with terrain edits the model before it
    is compiled: ValueError (call :func:`load_perturbed`)."""
    _validated(perturbation)
    if perturbation is not None and perturbation.terrain is not None:
        raise ValueError("a perturbation with terrain is compiled into the model: use load_perturbed")
    return _perturbed(copy.copy(model), perturbation, os.fspath(source))  # MjModel's copy is a deep copy


def _validated(perturbation: Perturbation | None) -> None:
    if perturbation is not None:
        if not isinstance(perturbation, Perturbation):
            raise PerturbationError(
                f"perturbation={perturbation!r} must be a Perturbation or None")
        perturbation.validate()


def _perturbed(model: mujoco.MjModel, perturbation: Perturbation | None,
               src: str) -> tuple[mujoco.MjModel, Applied | None]:
    applied = None if perturbation is None else apply_to_compiled(model, perturbation)
    if perturbation is not None:
        apply_environment(model, perturbation)
    if log.isEnabledFor(logging.INFO):
        log.info("loaded Cassie model %r: %s (%s)", src, model_summary(model), applied)
    return model, applied


def model_summary(model: mujoco.MjModel) -> dict:
    """Plain-Python facts about ``model`` for reports (units in the key names)."""
    pelvis = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PELVIS_BODY)
    terrain = terrain_summary(model)
    out = {
        "model_name": bytes(model.names).split(b"\0", 1)[0].decode(),
        "pelvis_mass_kg": float(model.body_mass[pelvis]) if pelvis >= 0 else None,
        "pelvis_com_m": [float(c) for c in model.body_ipos[pelvis]] if pelvis >= 0 else None,
        "total_mass_kg": float(model.body_mass.sum()),
        "timestep_s": float(model.opt.timestep),
        "solver": mujoco.mjtSolver(model.opt.solver).name,
        "iterations": int(model.opt.iterations),
        "nq": int(model.nq), "nv": int(model.nv), "nu": int(model.nu),
        "nkey": int(model.nkey),
        "has_home_key": mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, HOME_KEY) >= 0,
        "dof_damping_sum": float(model.dof_damping.sum()),
        "has_terrain": terrain is not None,
    }
    if terrain is not None:
        out["terrain"] = terrain
    return out
