"""The uneven terrain: its spec, its generation, its hfield in the model, and the ground height.

Terrain layout: the hfield is a square centred on the world origin, from ``-size_m`` to
``+size_m`` in x and y (so walking in +x stays on terrain for ``size_m`` metres), sampled
every ``resolution_m`` (rows along y, columns along x), with a flat patch of height 0
within ``flat_radius_m`` of the origin where the robot stands at ``home``. Outside the
square there is no ground. :func:`add_terrain` builds it through :class:`mujoco.MjSpec`
before compiling: every world-body plane geom (the flat floor) is deleted and replaced by
an hfield asset :data:`TERRAIN_HFIELD` and geom :data:`TERRAIN_GEOM` that inherit the
floor's contact parameters. (The OSU file's own ``cassie_hfield.xml``/``hf1`` is not used:
building the field here works identically for both models; its stair boxes at
y = 19..21 m, x = 0.1..10.1 m are kept, off the +x walking line.)

:class:`GroundHeight` is the one ground-height lookup (the plant's fall check and swing
foot, the reports' :func:`terrain_height_at`).
"""
from __future__ import annotations

import logging
import math
import numbers
import os
import struct
import zlib
from dataclasses import dataclass

import mujoco
import numpy as np

from plant.checks import Checked, check_range, is_real

log = logging.getLogger(__name__)

TERRAIN_HFIELD = "terrain"
TERRAIN_GEOM = "terrain"

#: Allowed ranges of :class:`TerrainSpec` (the FMU's parameter table declares the same).
MAX_HEIGHT_M = 1.0                # heights in (0, MAX_HEIGHT_M], m
MAX_SLOPE_DEG = 45.0              # slopes in (0, MAX_SLOPE_DEG], deg
SIZE_RANGE_M = (2.0, 100.0)       # half-length of the field, m
RESOLUTION_RANGE_M = (0.01, 1.0)  # sample spacing, m

# Terrain generator constants (see generate_terrain).
_MAX_TERRAIN_SAMPLES = 2001       # samples per side; 2001**2 doubles = 32 MB per array
_FEATURE_MIN_M = 0.3              # smallest correlation length of the bumps, m
_TRANSITION_MIN_M = 1.0           # smallest width of the flat-patch blend ring, m
_HFIELD_BASE_M = 0.2              # thickness of the hfield's box below height 0, m
_SLOPE_HEADROOM = 1e-6            # relative margin kept under tan(max_slope)


@dataclass(frozen=True)
class TerrainSpec(Checked):
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
        check_range(p, prefix + "max_height_m", self.max_height_m, 0.0, MAX_HEIGHT_M, "m", True)
        check_range(p, prefix + "max_slope_deg", self.max_slope_deg, 0.0, MAX_SLOPE_DEG, "deg", True)
        if not isinstance(self.seed, numbers.Integral) or isinstance(self.seed, bool) \
                or self.seed < 0:
            p.append(f"{prefix}seed={self.seed!r} must be an integer >= 0")
        check_range(p, prefix + "size_m", self.size_m, *SIZE_RANGE_M, "m", False)
        check_range(p, prefix + "resolution_m", self.resolution_m, *RESOLUTION_RANGE_M, "m", False)
        size_ok = is_real(self.size_m) and SIZE_RANGE_M[0] <= self.size_m <= SIZE_RANGE_M[1]
        if size_ok:
            check_range(p, prefix + "flat_radius_m", self.flat_radius_m, 0.0,
                        self.size_m / 2, "m (half of size_m)", False)
        else:
            check_range(p, prefix + "flat_radius_m", self.flat_radius_m, 0.0,
                        SIZE_RANGE_M[1] / 2, "m", False)
        lo, hi = RESOLUTION_RANGE_M
        if size_ok and is_real(self.resolution_m) and lo <= self.resolution_m <= hi:
            n = self.samples_per_side
            if n > _MAX_TERRAIN_SAMPLES:
                p.append(
                    f"{prefix}size_m/resolution_m: 2*{self.size_m:g}/{self.resolution_m:g}+1"
                    f" = {n} samples per side, allowed [3, {_MAX_TERRAIN_SAMPLES}];"
                    " use a coarser resolution_m or a smaller size_m")
        return p

    @property
    def samples_per_side(self) -> int:
        """Number of height samples along x (and y)."""
        return max(3, int(round(2.0 * self.size_m / self.resolution_m)) + 1)

    @property
    def spacing_m(self) -> float:
        """Sample spacing actually used, m."""
        return 2.0 * self.size_m / (self.samples_per_side - 1)


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
    # The Gaussian's transfer function is separable, exp(c k^2) exp(c kr^2): one scalar
    # math.exp per frequency instead of numpy's float64 exp, whose AVX-512 and AVX2 loops give
    # other last bits than its baseline loop (the terrain would depend on the CPU).
    w = math.pi * feature
    c = -2.0 * (w * w)
    gain = np.multiply.outer(np.array([math.exp(c * (f * f)) for f in k.tolist()]),
                             np.array([math.exp(c * (f * f)) for f in kr.tolist()]))
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


def add_terrain(spec: mujoco.MjSpec, terrain: TerrainSpec) -> None:
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


#: The height-field file (:func:`field_bytes`): what a host hands a plant that cannot generate the
#: terrain itself (the native CassiePlant FMU's ``terrain_field_file``).  Little endian:
#:   "CPTF" u32 version u32 total bytes                                    header (12 bytes)
#:   f64 max_height_m f64 max_slope_deg f64 size_m f64 flat_radius_m       the spec it was made from
#:   f64 resolution_m u32 seed u32 n                                       (n samples per side)
#:   f64 peak                                                              heights.max(), m
#:   f32 samples[n * n]   heights / peak (0 where peak is 0), row i at y = -size_m + i * spacing
#:   u32 CRC-32 (zlib's) of every byte before it
#: The samples are exactly the hfield data :func:`add_terrain` gives MuJoCo, so a model built
#: from the file compiles to the same bits.
FIELD_MAGIC = b"CPTF"
#: What a reader of the file needs to build :func:`add_terrain`'s hfield: the box below height 0,
#: m, and the most samples per side a field has.
FIELD_HFIELD_BASE_M = _HFIELD_BASE_M
FIELD_MAX_SAMPLES = _MAX_TERRAIN_SAMPLES
FIELD_VERSION = 1
FIELD_HEADER = struct.Struct("<4sII5dIId")


def field_bytes(terrain: TerrainSpec) -> bytes:
    """The height-field file of ``terrain`` (layout: :data:`FIELD_MAGIC`)."""
    heights = generate_terrain(terrain)
    n = heights.shape[0]
    peak = float(heights.max())
    samples = (heights / peak if peak > 0 else np.zeros((n, n))).astype("<f4").tobytes()
    size = FIELD_HEADER.size + len(samples) + 4
    head = FIELD_HEADER.pack(FIELD_MAGIC, FIELD_VERSION, size, float(terrain.max_height_m),
                             float(terrain.max_slope_deg), float(terrain.size_m), float(terrain.flat_radius_m),
                             float(terrain.resolution_m), int(terrain.seed), n, peak)
    body = head + samples
    return body + struct.pack("<I", zlib.crc32(body))


def write_field(terrain: TerrainSpec, path: str | os.PathLike) -> str:
    """Write :func:`field_bytes` of ``terrain`` to ``path``; returns the path as a string."""
    data = field_bytes(terrain)
    with open(path, "wb") as f:
        f.write(data)
    log.info("terrain seed=%d: wrote the %d-byte height field %s", terrain.seed, len(data), os.fspath(path))
    return os.fspath(path)


def _terrain_ids(model: mujoco.MjModel) -> tuple[int, int] | None:
    """(geom id, hfield id) of the terrain :func:`add_terrain` built, None without terrain."""
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, TERRAIN_GEOM)
    return None if gid < 0 else (gid, int(model.geom_dataid[gid]))


def _terrain_heights(model: mujoco.MjModel, hid: int) -> np.ndarray:
    """The normalised samples of hfield ``hid`` as (nrow, ncol) float32 (a view)."""
    nrow, ncol = int(model.hfield_nrow[hid]), int(model.hfield_ncol[hid])
    adr = int(model.hfield_adr[hid])
    return model.hfield_data[adr:adr + nrow * ncol].reshape(nrow, ncol)


class GroundHeight:
    """Ground height (world z, m) under a world point of ``model``; set up once per model.

    On a model with terrain: bilinear interpolation of the hfield samples (MuJoCo
    collides with two triangles per cell; the two differ by at most a quarter of the
    cell's twist ``|h00 - h10 - h01 + h11|``, a few mm for the generated fields).
    Points beyond the field's edge are clamped to the edge (there is no ground
    there). Without terrain: the height of the first world-body floor plane (0 for
    both models; on a tilted plane, its height under the point), or 0 without one. Non-finite x or y give NaN.
    """

    def __init__(self, model: mujoco.MjModel):
        ids = _terrain_ids(model)
        self.has_terrain = ids is not None
        if not self.has_terrain:
            planes = np.flatnonzero((model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)
                                    & (model.geom_bodyid == 0))
            self.flat_m = float(model.geom_pos[planes[0], 2]) if planes.size else 0.0
            self._plane = None  # a tilted floor (plant.perturbation's slope): (x0, y0, -nx/nz, -ny/nz)
            if planes.size:
                mat = np.zeros(9)
                mujoco.mju_quat2Mat(mat, model.geom_quat[planes[0]])
                nx, ny, nz = mat[2], mat[5], mat[8]  # the plane's z axis in the world
                if nx != 0.0 or ny != 0.0:
                    gx, gy = model.geom_pos[planes[0], :2]
                    self._plane = (float(gx), float(gy), float(-nx / nz), float(-ny / nz))
            return
        gid, hid = ids
        self._heights = _terrain_heights(model, hid)
        self._nrow, self._ncol = self._heights.shape
        # numpy float64 scalars, as in the compiled model (the arithmetic below relies on it)
        self._sx, self._sy, self._sz, _ = model.hfield_size[hid]
        self._gx, self._gy, self._gz = model.geom_pos[gid]  # world-body geom, axis-aligned

    def __call__(self, x: float, y: float) -> float:
        if not self.has_terrain:
            if self._plane is None:
                return self.flat_m
            x0, y0, sx, sy = self._plane
            return self.flat_m + sx * (x - x0) + sy * (y - y0)
        if not (math.isfinite(x) and math.isfinite(y)):
            return math.nan
        sx, sy, nrow, ncol = self._sx, self._sy, self._nrow, self._ncol
        u = (min(max(x - self._gx, -sx), sx) + sx) / (2 * sx) * (ncol - 1)  # column coordinate
        v = (min(max(y - self._gy, -sy), sy) + sy) / (2 * sy) * (nrow - 1)  # row coordinate
        j0, i0 = min(int(u), ncol - 2), min(int(v), nrow - 2)
        fu, fv = u - j0, v - i0
        data = self._heights
        h = ((1 - fv) * ((1 - fu) * data[i0, j0] + fu * data[i0, j0 + 1])
             + fv * ((1 - fu) * data[i0 + 1, j0] + fu * data[i0 + 1, j0 + 1]))
        return float(self._gz + self._sz * h)


def terrain_height_at(model: mujoco.MjModel, x: float, y: float) -> float:
    """Ground height (world z, m) under the world point (x, y), m (see :class:`GroundHeight`).

    Costs a few microseconds (name lookup plus 4 samples); a caller asking often keeps
    a :class:`GroundHeight`.

    Raises:
        ValueError: x or y is not finite.
    """
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"terrain_height_at: x={x!r} m and y={y!r} m must be finite")
    return GroundHeight(model)(x, y)


def terrain_max_slope_deg(model: mujoco.MjModel) -> float:
    """Steepest slope of the compiled terrain, degrees (0 without terrain)."""
    ids = _terrain_ids(model)
    if ids is None:
        return 0.0
    hid = ids[1]
    h = _terrain_heights(model, hid).astype(float)
    h *= model.hfield_size[hid, 2]
    spacing = 2.0 * model.hfield_size[hid, 0] / (h.shape[1] - 1)
    return math.degrees(math.atan(_max_slope_tan(h, spacing)))


def terrain_summary(model: mujoco.MjModel) -> dict | None:
    """Plain-Python facts about the compiled terrain for reports, None without terrain."""
    ids = _terrain_ids(model)
    if ids is None:
        return None
    hid = ids[1]
    heights = _terrain_heights(model, hid)
    n = heights.shape[1]
    return {
        "half_size_m": float(model.hfield_size[hid, 0]),
        "samples_per_side": n,
        "spacing_m": float(2 * model.hfield_size[hid, 0] / (n - 1)),
        "max_height_m": float(model.hfield_size[hid, 2] * heights.max()),
        "max_slope_deg": terrain_max_slope_deg(model),
    }
