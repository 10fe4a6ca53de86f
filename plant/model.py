"""Loading the MuJoCo Cassie model and applying plant perturbations.

Two descriptions of the same robot are supported (see ``/work/shared/cassie/README.md``):

* ``"menagerie"``: MuJoCo Menagerie's ``agility_cassie`` *scene* (``scene.xml``, robot
  plus floor and light), found by the ``mujoco-menagerie`` package. Offline, set
  ``MENAGERIE_ROOT`` to the folder that holds ``agility_cassie/``.
* ``"osu"``: Oregon State University's ``cassie.xml`` at :func:`osu_model_path`
  (env ``CASSIE_OSU_XML`` or ``<repo>/../shared/cassie/osu/cassie.xml``).
* anything else: the path of an MJCF file describing the same robot (same names).

Every model returned by :func:`load_model` has a ``home`` keyframe (the OSU file has
none; :func:`load_model` adds Menagerie's standing pose under that name, looked up by
joint name) and the Cassie joint, actuator and pelvis-body names checked.

Perturbations (:class:`Perturbation`) are applied in two places:

* terrain, through :class:`mujoco.MjSpec` before compiling: every world-body plane
  geom (the flat floor) is deleted and replaced by an hfield asset
  :data:`TERRAIN_HFIELD` and geom :data:`TERRAIN_GEOM` that inherit the floor's
  contact parameters. The OSU file's own ``cassie_hfield.xml``/``hf1`` is *not* used:
  building the field here works identically for both models.
* pelvis mass, pelvis COM and joint damping, on the compiled ``MjModel``
  (``body_mass``, ``body_inertia``, ``body_ipos``, ``dof_damping``), followed by
  :func:`mujoco.mj_setConst` so derived constants (subtree masses, inverse weights
  used by constraint softening) stay consistent.

A new pelvis mass scales the pelvis' principal inertia by the same ratio
(``I' = I * m'/m``): the mass distribution keeps its shape (same radii of gyration),
which is what adding or removing mass uniformly over the body would do.

Terrain layout: the hfield is a square centred on the world origin, from
``-size_m`` to ``+size_m`` in x and y (so walking in +x stays on terrain for
``size_m`` metres), sampled every ``resolution_m`` (rows along y, columns along x),
with a flat patch of height 0 within ``flat_radius_m`` of the origin where the robot
stands at ``home``. Outside the square there is no ground. (The OSU file's stair
boxes at y = 19..21 m, x = 0.1..10.1 m are kept; they stay off the +x walking line.)
"""

from __future__ import annotations

import logging
import math
import numbers
import os
import pathlib
import xml.parsers.expat
from dataclasses import dataclass

import mujoco
import numpy as np

from plant.errors import ModelError, PerturbationError

log = logging.getLogger(__name__)

PELVIS_BODY = "cassie-pelvis"
"""Name of the pelvis (torso) body in both models."""

NOMINAL_PELVIS_MASS_KG = 10.33
NOMINAL_TOTAL_MASS_KG = 33.312

_SIDES = ("left", "right")
ACTUATOR_NAMES: tuple[str, ...] = tuple(
    f"{s}-{j}" for s in _SIDES for j in ("hip-roll", "hip-yaw", "hip-pitch", "knee", "foot")
)
"""Motor names (also the names of the joints they drive), left leg first."""

JOINT_NAMES: tuple[str, ...] = tuple(
    f"{s}-{j}"
    for s in _SIDES
    for j in (
        "hip-roll", "hip-yaw", "hip-pitch", "achilles-rod", "knee", "shin",
        "tarsus", "heel-spring", "foot-crank", "plantar-rod", "foot",
    )
)
"""Every named joint of the robot (the floating base joint(s) are unnamed)."""

HOME_KEY = "home"
TERRAIN_HFIELD = "terrain"
TERRAIN_GEOM = "terrain"

MENAGERIE_ROBOT = "agility_cassie"
MENAGERIE_ENTRY = "scene"  # scene.xml: the robot plus the floor

# Standing pose of Menagerie's ``home`` keyframe (agility_cassie/cassie.xml, MIT),
# per joint name; radians, or a unit quaternion (w, x, y, z) for the ball joints.
# Used to give models without a ``home`` keyframe (the OSU file) the same one.
_HOME_PELVIS_POS_M = (0.0, 0.0, 1.0059301)
_HOME_PELVIS_QUAT = (1.0, 0.0, 0.0, 0.0)
_HOME_JOINT_QPOS: dict[str, tuple[float, ...]] = {
    "left-hip-roll": (0.00449956,),
    "left-hip-yaw": (0.0,),
    "left-hip-pitch": (0.497301,),
    "left-achilles-rod": (0.9786097486736136, -0.016410395785484994,
                          0.017776595434617837, -0.20429794753223648),
    "left-knee": (-1.1997,),
    "left-shin": (0.0,),
    "left-tarsus": (1.42671,),
    "left-heel-spring": (-2.25907e-06,),
    "left-foot-crank": (-1.52439,),
    "left-plantar-rod": (1.50645,),
    "left-foot": (-1.59681,),
    "right-hip-roll": (-0.00449956,),
    "right-hip-yaw": (0.0,),
    "right-hip-pitch": (0.497301,),
    "right-achilles-rod": (0.9787396935407306, 0.0038686987886476744,
                           -0.015157195254036375, -0.20450893596493583),
    "right-knee": (-1.1997,),
    "right-shin": (0.0,),
    "right-tarsus": (1.42671,),
    "right-heel-spring": (0.0,),
    "right-foot-crank": (-1.52439,),
    "right-plantar-rod": (1.50645,),
    "right-foot": (-1.59681,),
}

# Terrain generator constants (see generate_terrain).
_MAX_TERRAIN_SAMPLES = 2001       # samples per side; 2001**2 doubles = 32 MB per array
_FEATURE_MIN_M = 0.3              # smallest correlation length of the bumps, m
_TRANSITION_MIN_M = 1.0           # smallest width of the flat-patch blend ring, m
_HFIELD_BASE_M = 0.2              # thickness of the hfield's box below height 0, m
_SLOPE_HEADROOM = 1e-6            # relative margin kept under tan(max_slope)


# --------------------------------------------------------------------------- specs


def _is_real(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _check_range(problems: list[str], name: str, value, lo: float, hi: float,
                 unit: str, lo_open: bool) -> None:
    """Append a problem naming ``name`` and its allowed range unless lo <(=) value <= hi."""
    rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]{(' ' + unit) if unit else ''}"
    if not _is_real(value):
        problems.append(f"{name}={value!r} must be a real number in {rng}")
        return
    ok = (lo < value if lo_open else lo <= value) and value <= hi  # NaN fails both
    if not ok:
        problems.append(f"{name}={value!r} is out of range {rng}")


@dataclass(frozen=True)
class TerrainSpec:
    """A seeded, smooth random height field replacing the flat floor.

    Attributes:
        max_height_m: upper bound of the heights, m, in (0, 1]; heights lie in
            [0, max_height_m] (the peak can be lower when the slope bound needs it).
        max_slope_deg: steepest allowed slope of the surface, degrees, in (0, 45];
            bounds the gradient of every triangle/bilinear patch between neighbouring
            samples (see :func:`terrain_max_slope_deg`).
        seed: seed of the random field (int >= 0); the same spec gives identical bytes.
        size_m: half-length of the square field centred on the origin, m, in [2, 100].
        flat_radius_m: radius of the flat start patch at height 0 around the origin,
            m, in [0, size_m / 2].
        resolution_m: sample spacing, m, in [0.01, 1]; the spacing actually used is
            ``2 * size_m / (n - 1)`` with ``n = round(2 * size_m / resolution_m) + 1``
            samples per side (at most 2001).
    """

    max_height_m: float
    max_slope_deg: float
    seed: int
    size_m: float = 20.0
    flat_radius_m: float = 1.0
    resolution_m: float = 0.05

    def problems(self, prefix: str = "") -> list[str]:
        """Every problem of this spec, one string each naming the field and range."""
        p: list[str] = []
        _check_range(p, prefix + "max_height_m", self.max_height_m, 0.0, 1.0, "m", True)
        _check_range(p, prefix + "max_slope_deg", self.max_slope_deg, 0.0, 45.0, "deg", True)
        if not isinstance(self.seed, numbers.Integral) or isinstance(self.seed, bool) \
                or self.seed < 0:
            p.append(f"{prefix}seed={self.seed!r} must be an integer >= 0")
        _check_range(p, prefix + "size_m", self.size_m, 2.0, 100.0, "m", False)
        _check_range(p, prefix + "resolution_m", self.resolution_m, 0.01, 1.0, "m", False)
        size_ok = _is_real(self.size_m) and 2.0 <= self.size_m <= 100.0
        if size_ok:
            _check_range(p, prefix + "flat_radius_m", self.flat_radius_m, 0.0,
                         self.size_m / 2, "m (half of size_m)", False)
        else:
            _check_range(p, prefix + "flat_radius_m", self.flat_radius_m, 0.0, 50.0, "m", False)
        if size_ok and _is_real(self.resolution_m) and 0.01 <= self.resolution_m <= 1.0:
            n = self.samples_per_side
            if n > _MAX_TERRAIN_SAMPLES:
                p.append(
                    f"{prefix}size_m/resolution_m: 2*{self.size_m:g}/{self.resolution_m:g}+1"
                    f" = {n} samples per side, allowed [3, {_MAX_TERRAIN_SAMPLES}];"
                    " use a coarser resolution_m or a smaller size_m")
        return p

    def validate(self) -> None:
        """Raise :class:`PerturbationError` listing every problem, if any."""
        p = self.problems()
        if p:
            raise _perturbation_error(p)

    @property
    def samples_per_side(self) -> int:
        """Number of height samples along x (and y)."""
        return max(3, int(round(2.0 * self.size_m / self.resolution_m)) + 1)

    @property
    def spacing_m(self) -> float:
        """Sample spacing actually used, m."""
        return 2.0 * self.size_m / (self.samples_per_side - 1)


@dataclass(frozen=True)
class Perturbation:
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
            _check_range(p, "torso_mass_kg", self.torso_mass_kg, 0.0, 100.0, "kg (or None)", True)
        off = self.torso_com_offset_m
        try:
            comps = list(off)
        except TypeError:
            comps = None
        if comps is None or len(comps) != 3:
            p.append(f"torso_com_offset_m={off!r} must be 3 numbers, each in [-0.5, 0.5] m")
        else:
            for axis, c in zip("xyz", comps):
                _check_range(p, f"torso_com_offset_m[{axis}]", c, -0.5, 0.5, "m", False)
        _check_range(p, "joint_damping_scale", self.joint_damping_scale, 0.0, 10.0, "", False)
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

    def validate(self) -> None:
        """Raise :class:`PerturbationError` listing every problem (``.problems``), if any."""
        p = self.problems()
        if p:
            raise _perturbation_error(p)

    @property
    def is_nominal(self) -> bool:
        """True when applying this perturbation changes nothing."""
        return (self.torso_mass_kg is None and self.joint_damping_scale == 1.0
                and self.terrain is None
                and all(c == 0 for c in self.torso_com_offset_m))


def _perturbation_error(problems: list[str]) -> PerturbationError:
    err = PerturbationError(
        f"invalid perturbation, {len(problems)} problem(s): " + "; ".join(problems))
    err.problems = list(problems)
    return err


# --------------------------------------------------------------------------- terrain


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _max_slope_tan(h: np.ndarray, spacing: float) -> float:
    """Steepest gradient (rise over run) of the surface through the samples ``h``.

    For each cell, the gradient of either triangulation and of bilinear
    interpolation is a combination of one x-edge slope (bottom or top) and one
    y-edge slope (left or right), so the maximum of ``hypot(sx, sy)`` over the four
    pairs bounds all of them.
    """
    sx = np.abs(np.diff(h, axis=1)) / spacing  # (n, n-1): along x, per row
    sy = np.abs(np.diff(h, axis=0)) / spacing  # (n-1, n): along y, per column
    sx_cell = np.maximum(sx[:-1, :], sx[1:, :])  # (n-1, n-1) steeper of bottom/top
    sy_cell = np.maximum(sy[:, :-1], sy[:, 1:])  # steeper of left/right
    return float(np.max(np.hypot(sx_cell, sy_cell))) if h.size else 0.0


def generate_terrain(spec: TerrainSpec) -> np.ndarray:
    """Heights of the terrain described by ``spec``, m, shape (n, n).

    Row ``i`` is at ``y = -size_m + i * spacing``, column ``j`` at
    ``x = -size_m + j * spacing`` (``spacing = spec.spacing_m``).

    Method: white Gaussian noise from ``numpy.random.default_rng(seed)`` is
    low-pass filtered with a Gaussian kernel (FFT) whose length scale grows with
    ``max_height_m / tan(max_slope_deg)`` (at least 0.3 m), so bumps of the full
    height are possible without exceeding the slope; the field is rescaled to
    [0, max_height_m]; it is blended to 0 towards the flat patch with a smoothstep
    ring (width >= 1 m, also growing with height/slope) so the patch is exactly 0;
    finally, if the steepest slope (:func:`_max_slope_tan`) still exceeds
    ``tan(max_slope_deg)``, the whole field is scaled down to meet it. The slope
    bound therefore has priority over reaching ``max_height_m``.
    """
    spec.validate()
    n = spec.samples_per_side
    spacing = spec.spacing_m
    tan_max = math.tan(math.radians(spec.max_slope_deg))
    ratio = spec.max_height_m / tan_max  # run needed to climb max_height_m, m

    feature = min(max(_FEATURE_MIN_M, 0.5 * ratio), spec.size_m / 3.0)
    rng = np.random.default_rng(spec.seed)
    noise = rng.standard_normal((n, n))
    k = np.fft.fftfreq(n, d=spacing)  # cycles per metre
    kr = np.fft.rfftfreq(n, d=spacing)
    gain = np.exp(-2.0 * (math.pi * feature) ** 2 * (k[:, None] ** 2 + kr[None, :] ** 2))
    field = np.fft.irfft2(np.fft.rfft2(noise) * gain, s=(n, n))
    lo, hi = float(field.min()), float(field.max())
    h = (field - lo) / (hi - lo) * spec.max_height_m if hi > lo else np.zeros((n, n))

    coords = -spec.size_m + spacing * np.arange(n)
    r = np.hypot(coords[None, :], coords[:, None])
    width = min(max(_TRANSITION_MIN_M, 1.5 * ratio), spec.size_m / 2.0)
    h *= _smoothstep((r - spec.flat_radius_m) / width)

    slope = _max_slope_tan(h, spacing)
    target = tan_max * (1.0 - _SLOPE_HEADROOM)
    if slope > target:
        h *= target / slope
    log.debug("terrain seed=%d: n=%d spacing=%.4f m feature=%.2f m ring=%.2f m "
              "peak=%.4f m max slope=%.3f deg", spec.seed, n, spacing, feature, width,
              h.max(), math.degrees(math.atan(_max_slope_tan(h, spacing))))
    return h


def _add_terrain(spec: mujoco.MjSpec, terrain: TerrainSpec) -> None:
    """Replace the world's plane geoms by the hfield of ``terrain`` (in place)."""
    heights = generate_terrain(terrain)
    planes = [g for g in spec.worldbody.geoms if g.type == mujoco.mjtGeom.mjGEOM_PLANE]
    if not planes:
        log.warning("model has no floor plane in the world body; adding terrain anyway")
    n = heights.shape[0]
    peak = float(heights.max())
    # MuJoCo normalises hfield data to [0, 1] and multiplies by size[2]; passing the
    # peak as size[2] keeps the compiled heights equal to `heights`.
    hf = spec.add_hfield(name=TERRAIN_HFIELD, nrow=n, ncol=n,
                         size=[terrain.size_m, terrain.size_m, max(peak, 1e-6), _HFIELD_BASE_M])
    hf.userdata = (heights / peak).ravel().tolist() if peak > 0 else [0.0] * (n * n)
    geom = spec.worldbody.add_geom(name=TERRAIN_GEOM, type=mujoco.mjtGeom.mjGEOM_HFIELD,
                                   hfieldname=TERRAIN_HFIELD, pos=[0.0, 0.0, 0.0])
    if planes:  # same contact behaviour as the floor it replaces
        src = planes[0]
        for attr in ("contype", "conaffinity", "condim", "friction", "solref", "solimp",
                     "solmix", "priority", "margin", "gap", "group"):
            setattr(geom, attr, getattr(src, attr))
        geom.pos = [0.0, 0.0, float(src.pos[2])]  # centred on the origin, at floor level
    else:
        geom.contype, geom.conaffinity, geom.condim = 1, 15, 3
    geom.rgba = [0.45, 0.5, 0.4, 1.0]
    for g in planes:
        log.info("terrain: removing floor plane %r", g.name)
        spec.delete(g)


def _terrain_geom_id(model: mujoco.MjModel) -> int:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, TERRAIN_GEOM)


def terrain_height_at(model: mujoco.MjModel, x: float, y: float) -> float:
    """Ground height (world z, m) under the world point (x, y), m.

    On a model with terrain: bilinear interpolation of the hfield samples (MuJoCo
    collides with two triangles per cell; the two differ by at most a quarter of the
    cell's twist ``|h00 - h10 - h01 + h11|``, a few mm for the generated fields).
    Points beyond the field's edge are clamped to the edge (there is no ground
    there). Without terrain: the height of the floor plane (0 for both models).
    Costs a few microseconds (name lookup plus 4 samples); fine at 2 kHz.

    Raises:
        ValueError: x or y is not finite.
    """
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"terrain_height_at: x={x!r} m and y={y!r} m must be finite")
    gid = _terrain_geom_id(model)
    if gid < 0:
        planes = np.flatnonzero((model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)
                                & (model.geom_bodyid == 0))
        return float(model.geom_pos[planes[0], 2]) if planes.size else 0.0
    hid = int(model.geom_dataid[gid])
    nrow, ncol = int(model.hfield_nrow[hid]), int(model.hfield_ncol[hid])
    sx, sy, sz, _ = model.hfield_size[hid]
    gx, gy, _ = model.geom_pos[gid]  # world-body geom, axis-aligned as load_model builds it
    u = (min(max(x - gx, -sx), sx) + sx) / (2 * sx) * (ncol - 1)  # column coordinate
    v = (min(max(y - gy, -sy), sy) + sy) / (2 * sy) * (nrow - 1)  # row coordinate
    j0, i0 = min(int(u), ncol - 2), min(int(v), nrow - 2)
    fu, fv = u - j0, v - i0
    adr = int(model.hfield_adr[hid])
    data = model.hfield_data[adr:adr + nrow * ncol].reshape(nrow, ncol)
    h = ((1 - fv) * ((1 - fu) * data[i0, j0] + fu * data[i0, j0 + 1])
         + fv * ((1 - fu) * data[i0 + 1, j0] + fu * data[i0 + 1, j0 + 1]))
    return float(model.geom_pos[gid, 2] + sz * h)


def terrain_max_slope_deg(model: mujoco.MjModel) -> float:
    """Steepest slope of the compiled terrain, degrees (0 without terrain)."""
    gid = _terrain_geom_id(model)
    if gid < 0:
        return 0.0
    hid = int(model.geom_dataid[gid])
    nrow, ncol = int(model.hfield_nrow[hid]), int(model.hfield_ncol[hid])
    adr = int(model.hfield_adr[hid])
    h = model.hfield_data[adr:adr + nrow * ncol].reshape(nrow, ncol).astype(float)
    h *= model.hfield_size[hid, 2]
    spacing = 2.0 * model.hfield_size[hid, 0] / (ncol - 1)
    return math.degrees(math.atan(_max_slope_tan(h, spacing)))


# --------------------------------------------------------------------------- loading


def osu_model_path() -> pathlib.Path:
    """Path of OSU's ``cassie.xml``: env ``CASSIE_OSU_XML`` if set, else the shared copy
    at ``<repo>/../shared/cassie/osu/cassie.xml``."""
    env = os.environ.get("CASSIE_OSU_XML")
    if env:
        return pathlib.Path(env).expanduser()
    repo = pathlib.Path(__file__).resolve().parents[1]
    return repo.parent / "shared" / "cassie" / "osu" / "cassie.xml"


def _menagerie_spec() -> mujoco.MjSpec:
    try:
        import mujoco_menagerie
    except ImportError as e:
        raise ModelError("the 'menagerie' model needs the mujoco-menagerie package "
                         "(pip install mujoco-menagerie)") from e
    try:
        robot = mujoco_menagerie.get(MENAGERIE_ROBOT)
        path = robot.xml(MENAGERIE_ENTRY)
    except mujoco_menagerie.MenagerieError as e:
        root = os.environ.get("MENAGERIE_ROOT")
        where = (f"MENAGERIE_ROOT={root}" if root
                 else "the mujoco-menagerie download cache (MENAGERIE_ROOT is unset)")
        raise ModelError(
            f"cannot get Menagerie's {MENAGERIE_ROBOT!r} from {where}: {e}. Fix: set "
            f"MENAGERIE_ROOT to a folder holding {MENAGERIE_ROBOT}/{MENAGERIE_ENTRY}.xml "
            "(e.g. /work/shared/cassie/menagerie), or allow the one-off download") from e
    return _spec_from_file(pathlib.Path(path), "Menagerie")


class _RefusedXml(Exception):
    """Raised from expat's handlers to stop at a DTD or an entity declaration."""


def _xml_includes(path: pathlib.Path, origin: str = "") -> list[tuple[str, int]]:
    """``(file, line)`` of every ``<include>`` in ``path``; ModelError if it cannot be read,
    is not well-formed XML or declares a DTD or entities (refused before MuJoCo sees it:
    MuJoCo's parser keeps unexpanded entity text, and an entity bomb is a denial of service)."""
    parser = xml.parsers.expat.ParserCreate()
    includes: list[tuple[str, int]] = []

    def refuse(*_args):
        raise _RefusedXml(f"line {parser.CurrentLineNumber}: a DTD or entity declaration; "
                          "MJCF files may not declare any")

    def element(name, attrs):
        if name == "include":
            includes.append((attrs.get("file", ""), parser.CurrentLineNumber))

    parser.StartDoctypeDeclHandler = refuse
    parser.EntityDeclHandler = refuse
    parser.StartElementHandler = element
    try:
        with open(path, "rb") as fh:
            parser.ParseFile(fh)
    except OSError as e:
        raise ModelError(f"cannot read model file {path}{origin}: {e.strerror or e}") from None
    except _RefusedXml as e:
        raise ModelError(f"cannot parse model file {path}{origin}: {e}") from None
    except xml.parsers.expat.ExpatError as e:
        raise ModelError(f"cannot parse model file {path}{origin}: not well-formed XML: {e}") from None
    return includes


def check_mjcf_file(path: pathlib.Path) -> None:
    """Check an MJCF file and the files it includes before MuJoCo parses them.

    Each file must be readable, well-formed XML without a DTD or entity declarations;
    includes are resolved as MuJoCo 3 does (the main file's folder first, then the
    including file's) and checked the same way. Raises :class:`ModelError` naming the
    file (and the include's line).
    """
    todo, seen = [(path, "")], set()
    while todo:
        f, origin = todo.pop()
        if os.path.realpath(f) in seen:
            continue
        seen.add(os.path.realpath(f))
        for name, line in _xml_includes(f, origin):
            where = f"{f}, line {line}"
            found = [c for c in (path.parent / name, f.parent / name) if name and c.is_file()]
            if not found:
                raise ModelError(f"model file {where}: <include file={name!r}>: no such file")
            todo.append((found[0], f" (included from {where})"))


def _spec_from_file(path: pathlib.Path, what: str) -> mujoco.MjSpec:
    if not path.is_file():
        hint = (" Fix: set CASSIE_OSU_XML to OSU's cassie.xml" if what == "OSU"
                else " Fix: pass an existing MJCF file, 'menagerie' or 'osu'")
        raise ModelError(f"{what} model file not found: {path}.{hint}")
    check_mjcf_file(path)
    try:
        return mujoco.MjSpec.from_file(str(path))
    except Exception as e:  # mujoco raises ValueError with the parser's message
        raise ModelError(f"cannot parse {what} model {path}: {e}") from e


def _add_home_key(spec: mujoco.MjSpec, model: mujoco.MjModel) -> None:
    """Add the standing ``home`` keyframe, filled per joint name, to ``spec``."""
    qpos = model.qpos0.copy()
    pelvis = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PELVIS_BODY)
    for j in range(model.njnt):
        adr, typ, name = model.jnt_qposadr[j], model.jnt_type[j], model.joint(j).name
        if model.jnt_bodyid[j] == pelvis:  # floating base: free, or slides + ball (OSU)
            if typ == mujoco.mjtJoint.mjJNT_FREE:
                qpos[adr:adr + 7] = _HOME_PELVIS_POS_M + _HOME_PELVIS_QUAT
            elif typ == mujoco.mjtJoint.mjJNT_BALL:
                qpos[adr:adr + 4] = _HOME_PELVIS_QUAT
            elif typ == mujoco.mjtJoint.mjJNT_SLIDE:
                qpos[adr] = float(np.dot(model.jnt_axis[j], _HOME_PELVIS_POS_M))
        elif name in _HOME_JOINT_QPOS:
            vals = _HOME_JOINT_QPOS[name]
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


def _apply_compiled(model: mujoco.MjModel, p: Perturbation) -> None:
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


def load_model(source: str | os.PathLike = "menagerie",
               perturbation: Perturbation | None = None) -> mujoco.MjModel:
    """Compile the Cassie model with an optional perturbation.

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
    if perturbation is not None:
        if not isinstance(perturbation, Perturbation):
            raise PerturbationError(
                f"perturbation={perturbation!r} must be a Perturbation or None")
        perturbation.validate()
    src = os.fspath(source)
    if src == "menagerie":
        spec = _menagerie_spec()
    elif src == "osu":
        spec = _spec_from_file(osu_model_path(), "OSU")
    else:
        spec = _spec_from_file(pathlib.Path(src).expanduser(), "MJCF")
    try:
        model = spec.compile()
    except Exception as e:
        raise ModelError(f"cannot compile model {src!r}: {e}") from e
    _check_names(model, repr(src))

    edit_spec = False
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, HOME_KEY) < 0:
        _add_home_key(spec, model)
        edit_spec = True
    if perturbation is not None and perturbation.terrain is not None:
        _add_terrain(spec, perturbation.terrain)
        edit_spec = True
    if edit_spec:
        try:
            model = spec.compile()
        except Exception as e:
            raise ModelError(f"cannot compile model {src!r} after edits: {e}") from e
        key = model.key(HOME_KEY)
        if key.qpos.shape != (model.nq,):
            raise ModelError(f"{HOME_KEY!r} keyframe has {key.qpos.size} qpos, model nq={model.nq}")

    if perturbation is not None:
        _apply_compiled(model, perturbation)
    if log.isEnabledFor(logging.INFO):
        log.info("loaded Cassie model %r: %s", src, model_summary(model))
    return model


def model_summary(model: mujoco.MjModel) -> dict:
    """Plain-Python facts about ``model`` for reports (units in the key names)."""
    pelvis = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PELVIS_BODY)
    gid = _terrain_geom_id(model)
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
        "has_terrain": gid >= 0,
    }
    if gid >= 0:
        hid = int(model.geom_dataid[gid])
        n = int(model.hfield_ncol[hid])
        out["terrain"] = {
            "half_size_m": float(model.hfield_size[hid, 0]),
            "samples_per_side": n,
            "spacing_m": float(2 * model.hfield_size[hid, 0] / (n - 1)),
            "max_height_m": float(model.hfield_size[hid, 2]
                                  * model.hfield_data[model.hfield_adr[hid]:
                                                      model.hfield_adr[hid] + n * n].max()),
            "max_slope_deg": terrain_max_slope_deg(model),
        }
    return out
