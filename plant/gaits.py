"""Gait library: calibrated gait parameters per commanded (forward, lateral) speed.

Each grid point of ``plant/data/gait_library.json`` holds the numeric fields of
:class:`GaitParams` (step time, landing leg-angle offset,
lateral offset, step width, torso pitch) found by ``python -m scenarios.gaits.make_gaits``
on the nominal Menagerie model; the Bezier shapes are shared by all points.
:meth:`GaitLibrary.lookup` interpolates bilinearly in (vx, vy) and clamps to the
grid's range (commands outside it get the edge gait).

The committed library is read once, when this module is imported (:meth:`GaitLibrary.default`
hands out that copy): nothing reads the file at run time, because inside the pythonfmu
CassiePlant FMU this module's folder is a host's extraction folder, which the host may delete
while later instances still run (libcosim does when an execution ends).  A missing or
unreadable library is an error naming the file (:class:`plant.errors.GaitLibraryError`), never
a fallback to another gait.
"""
from __future__ import annotations

import bisect
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from plant.errors import GaitLibraryError

#: The committed library's file (read once, with the module: :data:`_DEFAULT`).
DEFAULT_LIBRARY_PATH = Path(__file__).resolve().parent / "data" / "gait_library.json"
#: GaitParams fields interpolated over the grid (the rest are shared shapes).
NUMERIC_FIELDS = ("step_time_s", "leg_angle_offset_rad", "lateral_offset_rad",
                  "step_width_rad", "torso_pitch_des_rad")


@dataclass(frozen=True)
class GaitParams:
    """Gait parameters for one commanded speed (one row of the gait library).

    Angles in rad, lengths in m, times in s.  Forward leg angle is the angle of
    the hip-to-ankle line from vertical in the heading frame, positive forward;
    lateral leg angle likewise, positive toward +y.
    """

    step_time_s: float = 0.4
    #: Landing leg angle = asin(vx_ref*T/(2L)) + leg_angle_offset_rad (+ regulator offset).
    leg_angle_offset_rad: float = 0.0
    #: Landing lateral angle = asin(vy_ref*T/(2L)) + lateral_offset_rad + side*step_width_rad.
    lateral_offset_rad: float = 0.0
    step_width_rad: float = 0.0
    torso_pitch_des_rad: float = 0.0
    #: Bezier shape (0 -> 1) of the swing angles vs tau/swing_end_tau.
    swing_shape: tuple = (0.0, 0.0, 1.0, 1.0, 1.0)
    swing_end_tau: float = 0.8
    #: Bezier of the swing ankle height above its standing height (m) vs tau/height_end_tau;
    #: ends negative so the foot keeps pressing down until contact (no late touchdown).
    swing_height: tuple = (0.0, 0.2, 0.2, -0.03, -0.03, -0.03)
    height_end_tau: float = 0.85


def _bracket(grid, x):
    """Indices (i, j) and weight w so that x ~ (1-w) grid[i] + w grid[j] (clamped)."""
    if x <= grid[0]:
        return 0, 0, 0.0
    if x >= grid[-1]:
        n = len(grid) - 1
        return n, n, 0.0
    j = bisect.bisect_right(grid, x)
    i = j - 1
    return i, j, (x - grid[i]) / (grid[j] - grid[i])


@dataclass(frozen=True)
class GaitLibrary:
    """Gaits on a (vx, vy) grid; ``points[(i, j)]`` is the gait at (vx_grid[i], vy_grid[j])."""

    vx_grid: tuple
    vy_grid: tuple
    points: dict
    base: GaitParams = GaitParams()
    meta: dict | None = None

    @classmethod
    def default(cls) -> "GaitLibrary":
        """The committed library as read when this module was imported; GaitLibraryError
        naming the file if it could not be read then."""
        if isinstance(_DEFAULT, GaitLibraryError):
            raise GaitLibraryError(str(_DEFAULT))
        return _DEFAULT

    @classmethod
    def uniform(cls, gait: GaitParams) -> "GaitLibrary":
        return cls((0.0,), (0.0,), {(0, 0): gait}, gait)

    @classmethod
    def load(cls, path) -> "GaitLibrary":
        """The library in the JSON file ``path``; GaitLibraryError naming the file if it is
        missing, unreadable or malformed."""
        try:
            return cls._parse(json.loads(Path(path).read_text(encoding="utf-8")), path)
        except GaitLibraryError:
            raise
        except OSError as exc:
            raise GaitLibraryError(f"gait library {path}: cannot be read: {exc.strerror or exc}") from exc
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise GaitLibraryError(f"gait library {path}: not a gait library ({type(exc).__name__}: {exc})") from exc

    @classmethod
    def _parse(cls, raw: dict, path) -> "GaitLibrary":
        base = GaitParams(**{k: tuple(v) if isinstance(v, list) else v for k, v in raw["base"].items()})
        vx, vy = tuple(raw["vx_grid"]), tuple(raw["vy_grid"])
        pts = {}
        for p in raw["points"]:
            i, j = vx.index(p["vx"]), vy.index(p["vy"])
            pts[(i, j)] = replace(base, **{k: float(p[k]) for k in NUMERIC_FIELDS if k in p})
        missing = [(a, b) for a in range(len(vx)) for b in range(len(vy)) if (a, b) not in pts]
        if missing:
            raise GaitLibraryError(f"gait library {path}: misses grid points {missing}")
        return cls(vx, vy, pts, base, raw.get("meta"))

    def save(self, path) -> None:
        pts = []
        for (i, j), g in sorted(self.points.items()):
            d = {"vx": self.vx_grid[i], "vy": self.vy_grid[j]}
            d.update({k: getattr(g, k) for k in NUMERIC_FIELDS})
            pts.append(d)
        raw = {"meta": self.meta or {}, "vx_grid": list(self.vx_grid), "vy_grid": list(self.vy_grid),
               "base": {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self.base).items()},
               "points": pts}
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(raw, indent=1) + "\n")

    def lookup(self, vx: float, vy: float) -> GaitParams:
        """Bilinearly interpolated gait for commanded (vx, vy) (m/s), clamped to the grid."""
        i0, i1, wx = _bracket(self.vx_grid, vx)
        j0, j1, wy = _bracket(self.vy_grid, vy)
        vals = {}
        for k in NUMERIC_FIELDS:
            f = lambda i, j: getattr(self.points[(i, j)], k)  # noqa: E731
            vals[k] = ((1 - wx) * ((1 - wy) * f(i0, j0) + wy * f(i0, j1))
                       + wx * ((1 - wy) * f(i1, j0) + wy * f(i1, j1)))
        return replace(self.points[(i0, j0)], **vals)


def _read_default() -> GaitLibrary | GaitLibraryError:
    try:
        return GaitLibrary.load(DEFAULT_LIBRARY_PATH)
    except GaitLibraryError as exc:
        return exc


#: The committed library, read with the module (or why it could not be: raised by :meth:`GaitLibrary.default`).
_DEFAULT = _read_default()
