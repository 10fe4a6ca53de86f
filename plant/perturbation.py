"""Changes to the nominal plant (:class:`Perturbation`): the one place their ranges are checked.

Terrain is built into the model before compiling (:func:`plant.terrain.add_terrain`); torso
(pelvis body) mass, its COM and joint damping are set on the compiled ``MjModel`` by
:func:`apply_to_compiled` (``body_mass``, ``body_inertia``, ``body_ipos``, ``dof_damping``),
followed by :func:`mujoco.mj_setConst` so derived constants (subtree masses, inverse
weights used by constraint softening) stay consistent.

A new torso mass scales the pelvis body's principal inertia by the same ratio
(``I' = I * m'/m``): the mass distribution keeps its shape (same radii of gyration),
which is what adding or removing mass uniformly over the body would do.

The plant resolves a mass given relative to the model's own (``torso_added_mass_kg``) on
the model it compiles, and :func:`apply_to_compiled` reports the torso mass before and after
(:class:`Applied`): nobody above the plant needs to compile a model to learn its mass.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from plant.checks import Checked, check_range, is_real
from plant.constants import PELVIS_BODY
from plant.errors import PerturbationError
from plant.terrain import TerrainSpec

#: Largest torso mass a perturbation may set, kg (about three times the robot's 33 kg).
MAX_TORSO_MASS_KG = 100.0
#: Largest pelvis COM shift per axis, m (half the pelvis' size and more).
MAX_COM_OFFSET_M = 0.5
#: Largest joint damping factor.
MAX_DAMPING_SCALE = 10.0
#: Floor friction (MuJoCo's sliding coefficient) range: (0, 2]. Both models' floor has 1;
#: 0.5-1.0 is the rubber-on-floor range robustness studies draw from, 2 leaves headroom.
MAX_FLOOR_FRICTION = 2.0
#: Steepest constant floor slope, deg, either way along x or y: the walker starts in its
#: flat standing pose at the origin, where a 15 deg plane is 1.3 cm off under the feet.
MAX_FLOOR_SLOPE_DEG = 15.0
#: Largest link mass factor (0, 5] and link mass (0, 50] kg (the heaviest link, a hip
#: pitch body, is 5.5 kg).
MAX_LINK_MASS_SCALE = 5.0
MAX_LINK_MASS_KG = 50.0


@dataclass(frozen=True)
class Perturbation(Checked):
    """Changes to the nominal plant. The defaults change nothing.

    Attributes:
        torso_mass_kg: new torso (pelvis body) mass, kg, in (0, 100] (nominal 10.33 kg);
            None keeps it. The pelvis inertia is scaled by the same ratio.
        torso_added_mass_kg: mass added to the model's own torso mass, kg (instead of
            ``torso_mass_kg``: not both); the sum must be in (0, 100]. None adds nothing.
        torso_com_offset_m: added to the pelvis centre of mass, m, in the pelvis
            body frame (x forward, y left, z up); each component in [-0.5, 0.5].
        joint_damping_scale: multiplies every ``dof_damping`` (N*m*s/rad or N*s/m),
            in [0, 10].
        terrain: replaces the flat floor by a random height field; None keeps it.
        floor_friction: sliding friction of every world-body geom (the floor or the
            terrain), in (0, 2]; None keeps the model's (1 for both models). The floor
            gets a contact priority above the robot's geoms, so its friction is the
            contact's (MuJoCo otherwise takes the larger of the two).
        slope_deg: tilts the flat floor plane about the world y axis so the ground rises
            by ``tan(slope_deg)`` per metre along +x (uphill walking forward), deg, in
            [-15, 15]; only without terrain.
        cross_slope_deg: the same along +y (the ground rises to the robot's left).
        link_mass_scale: ``(body, factor)`` pairs: the body's mass and inertia times the
            factor, in (0, 5]; any body of the model but the world and the pelvis
            (``torso_mass_kg``); checked against the model when it is loaded.
        link_mass_kg: ``(body, kg)`` pairs: the body's new mass, in (0, 50] kg, its
            inertia scaled by the same ratio; a body is named at most once in both lists.
    """

    torso_mass_kg: float | None = None
    torso_added_mass_kg: float | None = None
    torso_com_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joint_damping_scale: float = 1.0
    terrain: TerrainSpec | None = None
    floor_friction: float | None = None
    slope_deg: float = 0.0
    cross_slope_deg: float = 0.0
    link_mass_scale: tuple[tuple[str, float], ...] = ()
    link_mass_kg: tuple[tuple[str, float], ...] = ()

    def problems(self, base_torso_mass_kg: float | None = None) -> list[str]:
        """Every problem of this perturbation, one string each naming field and range, on a
        model whose own torso mass is ``base_torso_mass_kg`` (the sum with ``torso_added_mass_kg``
        is checked only when it is given: :func:`apply_to_compiled` checks it on the model)."""
        p: list[str] = []
        if self.torso_mass_kg is not None:
            check_range(p, "torso_mass_kg", self.torso_mass_kg, 0.0, MAX_TORSO_MASS_KG,
                        "kg (or None)", True)
        if self.torso_added_mass_kg is not None:
            if self.torso_mass_kg is not None:
                p.append("torso_mass_kg and torso_added_mass_kg: give one of them, not both")
            added = self.torso_added_mass_kg
            if not is_real(added):
                p.append(f"torso_added_mass_kg={added!r} must be a real number (kg)")
            elif base_torso_mass_kg is not None:  # the sum is checked as it will be set (base + added), to the last bit
                mass = base_torso_mass_kg + added
                if not 0.0 < mass <= MAX_TORSO_MASS_KG:
                    p.append(f"torso_added_mass_kg={added!r} makes the torso mass {base_torso_mass_kg:g} + {added:g} = "
                             f"{mass:g} kg: it must be in (0, {MAX_TORSO_MASS_KG:g}] kg")
        off = self.torso_com_offset_m
        try:
            comps = list(off)
        except TypeError:
            comps = None
        if comps is None or len(comps) != 3:
            p.append(f"torso_com_offset_m={off!r} must be 3 numbers, each in "
                     f"[{-MAX_COM_OFFSET_M:g}, {MAX_COM_OFFSET_M:g}] m")
        else:
            for axis, c in zip("xyz", comps):
                check_range(p, f"torso_com_offset_m[{axis}]", c, -MAX_COM_OFFSET_M,
                            MAX_COM_OFFSET_M, "m", False)
        check_range(p, "joint_damping_scale", self.joint_damping_scale, 0.0, MAX_DAMPING_SCALE,
                    "", False)
        if self.terrain is not None:
            if isinstance(self.terrain, TerrainSpec):
                p.extend(self.terrain.problems(prefix="terrain."))
            else:
                p.append(f"terrain={self.terrain!r} must be a TerrainSpec or None")
        p.extend(self.environment_problems())
        return p

    def environment_problems(self) -> list[str]:
        """The problems of the floor (friction, slope) and link mass fields."""
        p: list[str] = []
        if self.floor_friction is not None:
            check_range(p, "floor_friction", self.floor_friction, 0.0, MAX_FLOOR_FRICTION, "(or None)", True)
        for name in ("slope_deg", "cross_slope_deg"):
            check_range(p, name, getattr(self, name), -MAX_FLOOR_SLOPE_DEG, MAX_FLOOR_SLOPE_DEG, "deg", False)
        if self.terrain is not None and (self.slope_deg != 0 or self.cross_slope_deg != 0):
            p.append("slope_deg/cross_slope_deg tilt the flat floor: give a slope or a terrain, not both")
        seen: set[str] = set()
        for field, pairs, hi, unit in (("link_mass_scale", self.link_mass_scale, MAX_LINK_MASS_SCALE, ""),
                                       ("link_mass_kg", self.link_mass_kg, MAX_LINK_MASS_KG, "kg")):
            try:
                items = [tuple(pair) for pair in pairs]
            except TypeError:
                p.append(f"{field}={pairs!r} must be (body name, number) pairs")
                continue
            for item in items:
                if len(item) != 2 or not isinstance(item[0], str):
                    p.append(f"{field} entry {item!r} must be a (body name, number) pair")
                    continue
                body, value = item
                check_range(p, f"{field}[{body!r}]", value, 0.0, hi, unit, True)
                if body == PELVIS_BODY:
                    p.append(f"{field}[{body!r}]: the pelvis is set by torso_mass_kg")
                elif body in seen:
                    p.append(f"{field}[{body!r}]: body named twice (each body once in link_mass_scale and "
                             "link_mass_kg)")
                seen.add(body)
        return p

    @property
    def environment_is_nominal(self) -> bool:
        """True when the floor and link mass fields change nothing."""
        return (self.floor_friction is None and self.slope_deg == 0 and self.cross_slope_deg == 0
                and not self.link_mass_scale and not self.link_mass_kg)

    def __post_init__(self):
        # Accept any length-3 sequence (list, numpy array) for the offset; store a
        # tuple so the frozen instance stays hashable. Bad values are left for validate().
        off = self.torso_com_offset_m
        if not isinstance(off, tuple) and not isinstance(off, (str, bytes)):
            try:
                object.__setattr__(self, "torso_com_offset_m", tuple(off))
            except TypeError:
                pass
        for name in ("link_mass_scale", "link_mass_kg"):  # hashable pairs, in a stable order
            pairs = getattr(self, name)
            try:
                object.__setattr__(self, name, tuple(sorted(tuple(pair) for pair in pairs)))
            except TypeError:
                pass

    @property
    def is_nominal(self) -> bool:
        """True when applying this perturbation changes nothing."""
        return (self.torso_mass_kg is None and self.torso_added_mass_kg is None and self.joint_damping_scale == 1.0
                and self.terrain is None
                and all(c == 0 for c in self.torso_com_offset_m)
                and self.environment_is_nominal)


def torso_mass_on(p: Perturbation, base_torso_mass_kg: float) -> float | None:
    """The torso mass ``p`` sets on a model whose own is ``base_torso_mass_kg``, kg (None: kept)."""
    if p.torso_added_mass_kg is not None:
        return base_torso_mass_kg + p.torso_added_mass_kg
    return p.torso_mass_kg


def resolved(p: Perturbation, base_torso_mass_kg: float) -> Perturbation:
    """``p`` with a ``torso_added_mass_kg`` turned into the absolute ``torso_mass_kg`` it sets on
    a model whose own torso mass is ``base_torso_mass_kg`` (for a consumer that takes absolute
    masses only: the plant FMU's parameter)."""
    if p.torso_added_mass_kg is None:
        return p
    return dataclasses.replace(p, torso_mass_kg=torso_mass_on(p, base_torso_mass_kg), torso_added_mass_kg=None)


@dataclass(frozen=True)
class Applied:
    """What :func:`apply_to_compiled` did to a model: its torso mass before and after, kg."""

    torso_mass_before_kg: float
    torso_mass_after_kg: float


def torso_mass_kg(model: mujoco.MjModel) -> float:
    """The torso (pelvis body) mass of a compiled model, kg."""
    return float(model.body_mass[model.body(PELVIS_BODY).id])


def apply_to_compiled(model: mujoco.MjModel, p: Perturbation) -> Applied:
    """Torso mass/COM and damping on the compiled model, then mj_setConst; what was applied.

    Raises PerturbationError when ``p`` does not fit this model (a ``torso_added_mass_kg``
    taking its torso mass out of range); the model is then unchanged.
    """
    pelvis = model.body(PELVIS_BODY).id
    m0 = float(model.body_mass[pelvis])
    problems = p.problems(m0)
    if problems:
        raise PerturbationError(f"invalid perturbation on this model, {len(problems)} problem(s): "
                                + "; ".join(problems))
    mass = torso_mass_on(p, m0)
    changed = False
    if mass is not None:
        model.body_mass[pelvis] = mass
        model.body_inertia[pelvis] *= mass / m0
        changed = True
    if any(c != 0 for c in p.torso_com_offset_m):
        model.body_ipos[pelvis] += np.asarray(p.torso_com_offset_m, dtype=float)
        changed = True
    if p.joint_damping_scale != 1.0:
        model.dof_damping[:] *= p.joint_damping_scale
        changed = True
    if changed:
        mujoco.mj_setConst(model, mujoco.MjData(model))
    return Applied(torso_mass_before_kg=m0, torso_mass_after_kg=float(model.body_mass[pelvis]))


# --------------------------------------------------------------------------- floor and links
def world_geoms(model: mujoco.MjModel) -> np.ndarray:
    """Ids of the world-body geoms: the floor (plane or terrain) and fixed obstacles."""
    return np.flatnonzero(model.geom_bodyid == 0)


def model_problems(model: mujoco.MjModel, p: Perturbation) -> list[str]:
    """What of ``p`` does not fit this compiled model: link bodies it does not have."""
    out = []
    for field, pairs in (("link_mass_scale", p.link_mass_scale), ("link_mass_kg", p.link_mass_kg)):
        for body, _ in pairs:
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
            if bid <= 0:
                names = [model.body(i).name for i in range(1, model.nbody) if model.body(i).name != PELVIS_BODY]
                out.append(f"{field}[{body!r}]: the model has no such body; its bodies: {', '.join(names)}")
    return out


def slope_quat(slope_deg: float, cross_slope_deg: float) -> np.ndarray:
    """Orientation (w, x, y, z) of the plane rising ``tan(slope_deg)`` per metre along +x and
    ``tan(cross_slope_deg)`` along +y: the rotation of +z onto the plane's unit normal, about
    their cross product.  Scalar ``math`` (the C library's ``tan``/``acos``, as the native
    plant's C), never numpy's vector loops or BLAS, whose last bits depend on the CPU."""
    tx, ty = -math.tan(math.radians(slope_deg)), -math.tan(math.radians(cross_slope_deg))
    norm = math.sqrt((tx * tx + ty * ty) + 1.0)
    n0, n1, n2 = tx / norm, ty / norm, 1.0 / norm
    a0, a1 = -n1, n0  # +z x n
    a_len = math.sqrt(a0 * a0 + a1 * a1)
    quat = np.zeros(4)
    mujoco.mju_axisAngle2Quat(quat, np.array([a0 / a_len, a1 / a_len, 0.0]), math.acos(min(1.0, max(-1.0, n2))))
    return quat


def _set_link_mass(model: mujoco.MjModel, bid: int, mass: float) -> None:
    model.body_inertia[bid] *= mass / float(model.body_mass[bid])
    model.body_mass[bid] = mass


def apply_environment(model: mujoco.MjModel, p: Perturbation) -> None:
    """Floor friction, floor slope and link masses of ``p`` on the compiled model (after
    :func:`apply_to_compiled`); PerturbationError when a named body is missing."""
    if p.environment_is_nominal:
        return
    found = model_problems(model, p)
    if found:
        from plant.errors import PerturbationError

        err = PerturbationError(f"invalid perturbation for this model, {len(found)} problem(s): " + "; ".join(found))
        err.problems = found
        raise err
    if p.floor_friction is not None:
        set_floor_friction(model, p.floor_friction)
    if p.slope_deg != 0 or p.cross_slope_deg != 0:
        planes = world_geoms(model)
        planes = planes[model.geom_type[planes] == mujoco.mjtGeom.mjGEOM_PLANE]
        quat = slope_quat(p.slope_deg, p.cross_slope_deg)
        for g in planes:  # tilted about the point under the origin: the robot starts there
            model.geom_quat[g] = quat
    for body, scale in p.link_mass_scale:
        bid = model.body(body).id
        _set_link_mass(model, bid, float(model.body_mass[bid]) * scale)
    for body, kg in p.link_mass_kg:
        _set_link_mass(model, model.body(body).id, kg)
    mujoco.mj_setConst(model, mujoco.MjData(model))


def set_floor_friction(model: mujoco.MjModel, friction: float) -> None:
    """Sliding friction of every world-body geom, with a contact priority above every
    other geom's so the floor's friction is the contact's."""
    geoms = world_geoms(model)
    model.geom_friction[geoms, 0] = friction
    model.geom_priority[geoms] = int(model.geom_priority.max()) + 1


def change_plant(model: mujoco.MjModel, *, torso_mass_kg: float | None = None,
                 torso_com_shift_m=None, damping_factor: float | None = None,
                 floor_friction: float | None = None) -> None:
    """Change the running plant (an event during a walk): the pelvis mass (inertia scaled
    with it), a shift of the pelvis COM (pelvis frame, m), a factor on every joint
    damping, the floor friction. MuJoCo reads these from the model at every step; the
    derived constants are recomputed (:func:`mujoco.mj_setConst` on a scratch MjData,
    the running one is not touched)."""
    pelvis = model.body(PELVIS_BODY).id
    if torso_mass_kg is not None:
        _set_link_mass(model, pelvis, float(torso_mass_kg))
    if torso_com_shift_m is not None:
        model.body_ipos[pelvis] += np.asarray(torso_com_shift_m, dtype=float)
    if damping_factor is not None:
        model.dof_damping[:] *= float(damping_factor)
    if floor_friction is not None:
        set_floor_friction(model, float(floor_friction))
    mujoco.mj_setConst(model, mujoco.MjData(model))
