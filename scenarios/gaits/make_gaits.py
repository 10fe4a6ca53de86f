"""Calibrate the gait library on the nominal model: ``python -m scenarios.gaits.make_gaits``.

For every grid point (vx_des, vy_des) the landing offsets of the gait
(``leg_angle_offset_rad``, ``lateral_offset_rad``) are adjusted so that the
closed loop of nominal controller + the regulator core ``fmu_src.core.avr_core`` with
adaptation off (the paper's PD, default gains) settles at the commanded speed:
each iteration walks ``--duration`` s from rest (the library with the candidate
gait at this point, so the start-up ramp passes through the neighbours' gaits)
and measures the steady errors over the second half; the first update adds the
mean ``delta_swing_hip_pitch`` / ``delta_swing_hip_roll`` to the offsets (a
fixed point: zero mean regulator output is zero error), later ones take the
secant.  A point is done when |vx error| < ``VX_TOL_MPS`` and |vy error| <
``VY_TOL_MPS``.  Deterministic (no randomness), so no seed.

The grid is ``VX_GRID`` x ``VY_GRID`` (forward -0.5 to 1.5 m/s, lateral +-0.3 m/s).
``--update`` keeps every point of the existing library that still verifies (its
steady errors within ``KEEP_TOL_MPS``) and calibrates only the others, from rest
outward, each starting from its calibrated neighbour; without it every point
is calibrated afresh.  Every point's final errors are stored in the library's
``meta["verification"]`` (``python -m scenarios.gaits.make_gaits --verify-only`` re-measures
them without changing the library).

Writes ``plant/data/gait_library.json`` (or ``--out``).  Options: ``--source``
(menagerie|osu|path), ``--iterations``, ``--duration``, ``--update``,
``--verify-only``.  About 1 s per walk on one core.
"""
from __future__ import annotations

import argparse

from scenarios.lang.cmdline import Parser
import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from fmu_src.core.avr_core import Regulator
from fmu_src.core.avr_params import RegulatorParams
from plant.gaits import DEFAULT_LIBRARY_PATH, GaitLibrary, GaitParams
from plant.model import load_model
from plant.sim import CassieWalker
from scenarios.cosim.inprocess import apply_regulator

log = logging.getLogger(__name__)

VX_GRID = (-0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
VY_GRID = (-0.3, -0.2, 0.0, 0.2, 0.3)
#: A grid point is calibrated when its steady errors are below these (m/s).
VX_TOL_MPS = 0.01
VY_TOL_MPS = 0.02
#: The library's promise at every grid point (m/s, both axes): ``--update`` keeps an
#: existing point whose errors are within it.
KEEP_TOL_MPS = 0.02
COMM_STEPS = 20  # regulator called every 10 ms (20 plant steps), like the co-simulation
#: The regulator of the calibration and the walking tests: the core's paper-form PD
#: with its default gains (Kp_x = Kp_y = 0.1 rad/(m/s), all other gains 0).
PD_ONLY_PARAMS = RegulatorParams(adaptation_enabled=False)


@dataclass
class WalkResult:
    fell: bool
    fall_reason: str | None
    t_end_s: float
    #: (t, vx_step_avg, step_index, pelvis_x, pelvis_y, delta_swing_hip_pitch, delta_swing_hip_roll)
    log: list
    #: Largest |heading change| from the start over the run (rad).
    max_abs_yaw_rad: float = 0.0

    def window(self, t_from: float):
        return [r for r in self.log if r[0] >= t_from]

    def steady_vx(self, t_from: float) -> float:
        """Mean step-averaged forward speed of the steps completed after t_from (m/s)."""
        seen, vals = set(), []
        for r in self.window(t_from):
            if r[2] not in seen:
                seen.add(r[2])
                vals.append(r[1])
        return float(np.mean(vals)) if vals else float("nan")

    def mean_velocity_xy(self, t_from: float) -> tuple[float, float]:
        """Mean pelvis (x, y) world velocity over [t_from, end] by displacement (m/s)."""
        w = self.window(t_from)
        if len(w) < 2:
            return float("nan"), float("nan")
        dt = w[-1][0] - w[0][0]
        return (w[-1][3] - w[0][3]) / dt, (w[-1][4] - w[0][4]) / dt

    def mean_deltas(self, t_from: float) -> tuple[float, float]:
        w = self.window(t_from)
        return float(np.mean([r[5] for r in w])), float(np.mean([r[6] for r in w]))


def simulate_walk(model, vx: float, vy: float, duration_s: float, gaits=None, params=None,
                  reg_params: RegulatorParams | None = None, push=None, regulator=None) -> WalkResult:
    """Walk from rest at the command (vx, vy) (m/s) for ``duration_s`` (s) with the
    regulator called every 10 ms (``COMM_STEPS`` plant steps); stop early on a fall.

    The regulator is ``fmu_src.core.avr_core.Regulator(reg_params)``, by default
    ``PD_ONLY_PARAMS`` (adaptation off), unless ``regulator`` is given: any object
    with the core's ``step(RegulatorInputs, dt_s) -> dict`` (see
    :func:`plant.sim.apply_regulator`).  ``push`` = (t_start_s, duration_s,
    force_xyz_n) applies a pelvis force (N).
    """
    w = CassieWalker(model, params=params, gaits=gaits)
    w.set_command(vx, vy)
    reg = regulator or Regulator(reg_params or PD_ONLY_PARAMS)
    dt_s = COMM_STEPS * w.SIM_DT_S
    rows = []
    zero = (0.0, 0.0, 0.0)
    yaw0, max_yaw = w.physics.heading_yaw(), 0.0
    while w.time_s < duration_s - 1e-9 and not w.fell():
        if push is not None:
            t0, dur, f = push
            w.set_pelvis_force(f if t0 <= w.time_s < t0 + dur else zero)
        off = apply_regulator(w, reg, dt_s)
        w.advance(COMM_STEPS)
        c = w.controller
        p = w.physics.data.qpos
        fq = w.physics.free_qadr
        rows.append((w.time_s, c.vx_step_avg, c.step_index, float(p[fq]), float(p[fq + 1]),
                     off["delta_swing_hip_pitch"], off["delta_swing_hip_roll"]))
        max_yaw = max(max_yaw, abs(math.remainder(w.physics.heading_yaw() - yaw0, math.tau)))
    return WalkResult(w.fell(), w.fall_reason, w.time_s, rows, max_yaw)


def _secant(hist, key_o, key_e, first_step, max_step=0.05):
    """Next offset from (offset, error) history: fixed-point step first, then secant."""
    o1, e1 = hist[-1][key_o], hist[-1][key_e]
    if len(hist) < 2 or abs(hist[-1][key_o] - hist[-2][key_o]) < 1e-6 or hist[-1][key_e] == hist[-2][key_e]:
        step = first_step
    else:
        o0, e0 = hist[-2][key_o], hist[-2][key_e]
        step = -e1 * (o1 - o0) / (e1 - e0)
    return o1 + max(-max_step, min(max_step, step))


def measure_point(model_fn, vx, vy, gaits: GaitLibrary, duration_s: float) -> dict:
    """Walk ``duration_s`` from rest at (vx, vy) with ``gaits``; the second half's steady
    errors (m/s) and mean regulator outputs (rad), or ``fell`` with its time."""
    r = simulate_walk(model_fn(), vx, vy, duration_s, gaits=gaits)
    if r.fell:
        return {"fell": True, "t_fall_s": round(r.t_end_s, 3), "reason": r.fall_reason}
    t_from = duration_s / 2
    dx, dy = r.mean_deltas(t_from)
    _, vy_mean = r.mean_velocity_xy(t_from)
    return {"fell": False, "err_vx": r.steady_vx(t_from) - vx, "err_vy": vy_mean - vy, "dx": dx, "dy": dy,
            "max_abs_yaw_rad": r.max_abs_yaw_rad}


def _within(m: dict, vx_tol: float = VX_TOL_MPS, vy_tol: float = VY_TOL_MPS) -> bool:
    return not m["fell"] and abs(m["err_vx"]) < vx_tol and abs(m["err_vy"]) < vy_tol


def calibrate_point(model_fn, vx, vy, start: GaitParams, iterations: int, duration_s: float, place):
    """Find the landing offsets that make the steady speed equal (vx, vy) (m/s).

    ``place(gait)`` makes the library walked with a candidate gait (:func:`calibrate_grid`
    puts it into the library at this grid point).  Each iteration
    measures the second half's errors (:func:`measure_point`); the first update adds
    the mean regulator outputs to the offsets (fixed point), later ones use the secant
    through the last two (offset, error) pairs, per axis, step <= 0.05 rad.  A fall
    halves the way back to the last good offsets.  Returns the best gait and the history.
    """
    g = start
    hist, good = [], []
    for it in range(iterations):
        m = measure_point(model_fn, vx, vy, place(g), duration_s)
        h = {"it": it, "offset_x": g.leg_angle_offset_rad, "offset_y": g.lateral_offset_rad, **m}
        hist.append(h)
        if m["fell"]:
            log.warning("vx=%.2f vy=%.2f it=%d fell at %.2f s (%s)", vx, vy, it, m["t_fall_s"], m["reason"])
            ref = good[-1] if good else {"offset_x": start.leg_angle_offset_rad,
                                          "offset_y": start.lateral_offset_rad}
            g = replace(g, leg_angle_offset_rad=0.5 * (g.leg_angle_offset_rad + ref["offset_x"]),
                        lateral_offset_rad=0.5 * (g.lateral_offset_rad + ref["offset_y"]))
            continue
        good.append(h)
        log.info("vx=%.2f vy=%.2f it=%d err_vx=%+.3f err_vy=%+.3f off=(%.4f, %.4f)",
                 vx, vy, it, m["err_vx"], m["err_vy"], g.leg_angle_offset_rad, g.lateral_offset_rad)
        if _within(m):
            break
        ox = _secant(good, "offset_x", "err_vx", m["dx"]) if abs(m["err_vx"]) >= VX_TOL_MPS else g.leg_angle_offset_rad
        oy = _secant(good, "offset_y", "err_vy", m["dy"]) if abs(m["err_vy"]) >= VY_TOL_MPS else g.lateral_offset_rad
        g = replace(g, leg_angle_offset_rad=ox, lateral_offset_rad=oy)
    if good:
        best = min(good, key=lambda h: abs(h["err_vx"]) + abs(h["err_vy"]))
        g = replace(g, leg_angle_offset_rad=best["offset_x"], lateral_offset_rad=best["offset_y"])
    return g, hist


def _order(vxg, vyg):
    """Grid points from rest outward: the rows by |vy|, each from vx = 0 outward, so that
    the points a walk from rest passes through (the rectangle between (0, 0) and its
    target) are all done before it."""
    order_x = sorted(range(len(vxg)), key=lambda i: (abs(vxg[i]), vxg[i]))
    order_y = sorted(range(len(vyg)), key=lambda j: (abs(vyg[j]), vyg[j]))
    return [(i, j) for j in order_y for i in order_x]


def _start_gait(pts, i, j, j0, base):
    """A calibrated neighbour (toward rest): the gait a new point starts from."""
    for k in ((i - 1, j), (i + 1, j), (i, j0), (i, j - 1), (i, j + 1)):
        if k in pts:
            return pts[k]
    return base


def calibrate_grid(model_fn, vxg, vyg, old: GaitLibrary | None, iterations: int, duration_s: float):
    """Every grid point: kept from ``old`` if it still verifies, else calibrated inside
    the library of the points done so far (missing ones filled from ``old`` or base)."""
    base = old.base if old is not None else GaitParams()
    pts, notes = {}, []
    j0 = vyg.index(0.0)

    def library_with(i, j, g):
        full = {(a, b): pts.get((a, b)) or _old_point(old, vxg[a], vyg[b]) or g
                for a in range(len(vxg)) for b in range(len(vyg))}
        full[(i, j)] = g
        return GaitLibrary(tuple(vxg), tuple(vyg), full, base)

    for i, j in _order(vxg, vyg):
        vx, vy = vxg[i], vyg[j]
        kept = _old_point(old, vx, vy)
        if kept is not None:
            m = measure_point(model_fn, vx, vy, library_with(i, j, kept), duration_s)
            if _within(m, KEEP_TOL_MPS, KEEP_TOL_MPS):
                pts[(i, j)] = kept
                notes.append({"vx": vx, "vy": vy, "kept": True, "history": [m]})
                log.info("vx=%.2f vy=%.2f kept (err_vx=%+.4f err_vy=%+.4f)", vx, vy, m["err_vx"], m["err_vy"])
                continue
        start = kept or _start_gait(pts, i, j, j0, base)
        g, hist = calibrate_point(model_fn, vx, vy, start, iterations, duration_s,
                                  place=lambda g, i=i, j=j: library_with(i, j, g))
        pts[(i, j)] = g
        notes.append({"vx": vx, "vy": vy, "kept": False, "history": hist})
    return GaitLibrary(tuple(vxg), tuple(vyg), pts, base), notes


def _old_point(old: GaitLibrary | None, vx: float, vy: float) -> GaitParams | None:
    if old is None or vx not in old.vx_grid or vy not in old.vy_grid:
        return None
    return old.points[(old.vx_grid.index(vx), old.vy_grid.index(vy))]


def verify(model_fn, lib: GaitLibrary, duration_s: float) -> list[dict]:
    """Every grid point's steady errors with the library as it is (m/s)."""
    out = []
    for vx in lib.vx_grid:
        for vy in lib.vy_grid:
            m = measure_point(model_fn, vx, vy, lib, duration_s)
            out.append({"vx": vx, "vy": vy, **{k: (round(v, 5) if isinstance(v, float) else v)
                                               for k, v in m.items()}})
            log.info("verify vx=%+.2f vy=%+.2f %s", vx, vy, out[-1])
    return out


def main(argv=None):
    ap = Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--source", default="menagerie")
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--duration", type=float, default=16.0)
    ap.add_argument("--out", default=str(DEFAULT_LIBRARY_PATH))
    ap.add_argument("--update", action="store_true", help="keep the existing points that still verify")
    ap.add_argument("--verify-only", action="store_true", help="re-measure the library's errors only")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")

    def model_fn():
        return load_model(a.source)

    t0 = time.time()
    old = GaitLibrary.load(DEFAULT_LIBRARY_PATH) if (a.update or a.verify_only) and DEFAULT_LIBRARY_PATH.exists() else None
    if a.verify_only:
        if old is None:
            ap.error(f"--verify-only: no library at {DEFAULT_LIBRARY_PATH}")
        lib, meta = old, dict(old.meta or {})
    else:
        lib, notes = calibrate_grid(model_fn, VX_GRID, VY_GRID, old, a.iterations, a.duration)
        meta = {"generated_by": "python -m scenarios.gaits.make_gaits" + (" --update" if a.update else ""),
                "source": a.source, "regulator": "fmu_src.core.avr_core.Regulator " + repr(PD_ONLY_PARAMS),
                "duration_s": a.duration,
                "tolerance_mps": {"vx": VX_TOL_MPS, "vy": VY_TOL_MPS, "keep": KEEP_TOL_MPS},
                "calibration": notes}
    meta["verification"] = verify(model_fn, lib, a.duration)
    meta["wall_s"] = round(time.time() - t0, 1)
    lib = replace(lib, meta=meta)
    lib.save(a.out)
    log.info("wrote %s in %.0f s", a.out, time.time() - t0)


if __name__ == "__main__":
    main()
