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
    """

    torso_mass_kg: float | None = None
    torso_added_mass_kg: float | None = None
    torso_com_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joint_damping_scale: float = 1.0
    terrain: TerrainSpec | None = None

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
        return p

    def __post_init__(self):
        # Accept any length-3 sequence (list, numpy array) for the offset; store a
        # tuple so the frozen instance stays hashable. Bad values are left for validate().
        off = self.torso_com_offset_m
        if not isinstance(off, tuple) and not isinstance(off, (str, bytes)):
            try:
                object.__setattr__(self, "torso_com_offset_m", tuple(off))
            except TypeError:
                pass

    @property
    def is_nominal(self) -> bool:
        """True when applying this perturbation changes nothing."""
        return (self.torso_mass_kg is None and self.torso_added_mass_kg is None and self.joint_damping_scale == 1.0
                and self.terrain is None
                and all(c == 0 for c in self.torso_com_offset_m))


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
