"""Changes to the nominal plant (:class:`Perturbation`): the one place their ranges are checked.

Terrain is built into the model before compiling (:func:`plant.terrain.add_terrain`); pelvis
mass, pelvis COM and joint damping are set on the compiled ``MjModel`` by
:func:`apply_to_compiled` (``body_mass``, ``body_inertia``, ``body_ipos``, ``dof_damping``),
followed by :func:`mujoco.mj_setConst` so derived constants (subtree masses, inverse
weights used by constraint softening) stay consistent.

A new pelvis mass scales the pelvis' principal inertia by the same ratio
(``I' = I * m'/m``): the mass distribution keeps its shape (same radii of gyration),
which is what adding or removing mass uniformly over the body would do.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from plant.checks import Checked, check_range
from plant.constants import PELVIS_BODY
from plant.terrain import TerrainSpec

#: Largest pelvis mass a perturbation may set, kg (about three times the robot's 33 kg).
MAX_TORSO_MASS_KG = 100.0
#: Largest pelvis COM shift per axis, m (half the pelvis' size and more).
MAX_COM_OFFSET_M = 0.5
#: Largest joint damping factor.
MAX_DAMPING_SCALE = 10.0


@dataclass(frozen=True)
class Perturbation(Checked):
    """Changes to the nominal plant. The defaults change nothing.

    Attributes:
        torso_mass_kg: new pelvis body mass, kg, in (0, 100] (nominal 10.33 kg);
            None keeps it. The pelvis inertia is scaled by the same ratio.
        torso_com_offset_m: added to the pelvis centre of mass, m, in the pelvis
            body frame (x forward, y left, z up); each component in [-0.5, 0.5].
        joint_damping_scale: multiplies every ``dof_damping`` (N*m*s/rad or N*s/m),
            in [0, 10].
        terrain: replaces the flat floor by a random height field; None keeps it.
    """

    torso_mass_kg: float | None = None
    torso_com_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joint_damping_scale: float = 1.0
    terrain: TerrainSpec | None = None

    def problems(self) -> list[str]:
        """Every problem of this perturbation, one string each naming field and range."""
        p: list[str] = []
        if self.torso_mass_kg is not None:
            check_range(p, "torso_mass_kg", self.torso_mass_kg, 0.0, MAX_TORSO_MASS_KG,
                        "kg (or None)", True)
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
        return (self.torso_mass_kg is None and self.joint_damping_scale == 1.0
                and self.terrain is None
                and all(c == 0 for c in self.torso_com_offset_m))


def apply_to_compiled(model: mujoco.MjModel, p: Perturbation) -> None:
    """Pelvis mass/COM and damping on the compiled model, then mj_setConst."""
    pelvis = model.body(PELVIS_BODY).id
    changed = False
    if p.torso_mass_kg is not None:
        m0 = float(model.body_mass[pelvis])
        model.body_mass[pelvis] = p.torso_mass_kg
        model.body_inertia[pelvis] *= p.torso_mass_kg / m0
        changed = True
    if any(c != 0 for c in p.torso_com_offset_m):
        model.body_ipos[pelvis] += np.asarray(p.torso_com_offset_m, dtype=float)
        changed = True
    if p.joint_damping_scale != 1.0:
        model.dof_damping[:] *= p.joint_damping_scale
        changed = True
    if changed:
        mujoco.mj_setConst(model, mujoco.MjData(model))
