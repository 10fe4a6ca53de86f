"""Calibrate the gait library on the nominal model: ``python -m plant.make_gaits``.

For every grid point (vx_des, vy_des) the landing offsets of the gait
(``leg_angle_offset_rad``, ``lateral_offset_rad``) are adjusted so that the
closed loop of nominal controller + the regulator core ``fmu_src.avr_core`` with
adaptation off (the paper's PD, default gains) settles with zero mean regulator
output, i.e. with zero steady-state speed error: each iteration walks
``--duration`` s from rest and adds the mean ``delta_swing_hip_pitch`` /
``delta_swing_hip_roll`` of the second half to the offsets (a fixed-point
iteration; it converges because the regulator gain is larger than the
sensitivity of the landing angle needed for a speed, ~0.03 rad per m/s).  Deterministic (no randomness), so no seed.

Writes ``plant/data/gait_library.json`` (or ``--out``).  Options: ``--source``
(menagerie|osu|path), ``--iterations``, ``--duration``, ``--quick`` (fewer points).
Takes ~5 min on one core.
"""
from __future__ import annotations

import argparse
import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from fmu_src.avr_core import Regulator, RegulatorParams
from plant.gaits import DEFAULT_LIBRARY_PATH, GaitLibrary, GaitParams
from plant.model import load_model
from plant.sim import CassieWalker, apply_regulator

log = logging.getLogger(__name__)

VX_GRID = (0.0, 0.25, 0.5, 0.75, 1.0)
VY_GRID = (-0.2, 0.0, 0.2)
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

    The regulator is ``fmu_src.avr_core.Regulator(reg_params)``, by default
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


def calibrate_point(model_fn, vx, vy, start: GaitParams, iterations: int, duration_s: float):
    """Find the landing offsets that make the steady speed equal (vx, vy) (m/s).

    Each iteration walks ``duration_s`` from rest and measures, over the second
    half, the speed errors and the mean regulator outputs.  The first update adds
    the mean regulator outputs to the offsets (fixed point); later ones use the
    secant through the last two (offset, error) pairs, per axis, step <= 0.05 rad.
    """
    g = start
    hist, good = [], []
    for it in range(iterations):
        r = simulate_walk(model_fn(), vx, vy, duration_s, gaits=GaitLibrary.uniform(g))
        t_from = duration_s / 2
        if r.fell:
            log.warning("vx=%.2f vy=%.2f it=%d fell at %.2f s (%s)", vx, vy, it, r.t_end_s, r.fall_reason)
            hist.append({"it": it, "fell": True, "offset_x": g.leg_angle_offset_rad,
                         "offset_y": g.lateral_offset_rad})
            ref = good[-1] if good else {"offset_x": start.leg_angle_offset_rad,
                                          "offset_y": start.lateral_offset_rad}
            g = replace(g, leg_angle_offset_rad=0.5 * (g.leg_angle_offset_rad + ref["offset_x"]),
                        lateral_offset_rad=0.5 * (g.lateral_offset_rad + ref["offset_y"]))
            continue
        dx, dy = r.mean_deltas(t_from)
        ev = r.steady_vx(t_from) - vx
        _, vyy = r.mean_velocity_xy(t_from)
        h = {"it": it, "err_vx": ev, "err_vy": vyy - vy, "dx": dx, "dy": dy,
             "offset_x": g.leg_angle_offset_rad, "offset_y": g.lateral_offset_rad}
        hist.append(h)
        good.append(h)
        log.info("vx=%.2f vy=%.2f it=%d err_vx=%+.3f err_vy=%+.3f off=(%.4f, %.4f)",
                 vx, vy, it, ev, vyy - vy, g.leg_angle_offset_rad, g.lateral_offset_rad)
        if abs(ev) < 0.01 and abs(vyy - vy) < 0.02:
            break
        ox = _secant(good, "offset_x", "err_vx", dx) if abs(ev) >= 0.01 else g.leg_angle_offset_rad
        oy = _secant(good, "offset_y", "err_vy", dy) if abs(vyy - vy) >= 0.02 else g.lateral_offset_rad
        g = replace(g, leg_angle_offset_rad=ox, lateral_offset_rad=oy)
    if good:
        best = min(good, key=lambda h: abs(h["err_vx"]) + abs(h["err_vy"]))
        g = replace(g, leg_angle_offset_rad=best["offset_x"], lateral_offset_rad=best["offset_y"])
    return g, hist


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--source", default="menagerie")
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--duration", type=float, default=16.0)
    ap.add_argument("--out", default=str(DEFAULT_LIBRARY_PATH))
    ap.add_argument("--quick", action="store_true", help="only vy=0 and vx in {0, 0.5, 1}")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    def model_fn():
        return load_model(a.source)

    vxg = (0.0, 0.5, 1.0) if a.quick else VX_GRID
    vyg = (0.0,) if a.quick else VY_GRID
    t0 = time.time()
    base = GaitParams()
    pts, meta_pts = {}, []
    # vy = 0 row first, outward from 0.5 m/s, each point starting from its neighbour.
    order_x = sorted(range(len(vxg)), key=lambda i: abs(vxg[i] - 0.5))
    j0 = vyg.index(0.0)
    order = [(i, j0) for i in order_x] + [(i, j) for j in range(len(vyg)) if j != j0 for i in order_x]
    for i, j in order:
        vx, vy = vxg[i], vyg[j]
        neighbours = [pts[k] for k in ((i - 1, j), (i + 1, j), (i, j0)) if k in pts]
        start = neighbours[0] if neighbours else base
        g, hist = calibrate_point(model_fn, vx, vy, start, a.iterations, a.duration)
        pts[(i, j)] = g
        meta_pts.append({"vx": vx, "vy": vy, "history": hist})
    lib = GaitLibrary(tuple(vxg), tuple(vyg), pts, base, {
        "generated_by": "python -m plant.make_gaits", "source": a.source,
        "regulator": "fmu_src.avr_core.Regulator " + repr(PD_ONLY_PARAMS),
        "duration_s": a.duration, "calibration": meta_pts,
        "wall_s": round(time.time() - t0, 1)})
    lib.save(a.out)
    log.info("wrote %s in %.0f s", a.out, time.time() - t0)


if __name__ == "__main__":
    main()
