"""Curves and leg geometry the nominal controller uses: Bezier virtual constraints and the
rigid-spring sagittal leg kinematics fitted on the model itself."""
from __future__ import annotations

import math

import mujoco
import numpy as np

from plant.cassie import CassiePhysics

#: Knee angles (rad) the leg geometry is sampled on: from fully folded to nearly straight,
#: beyond the range walking uses (about -1.9 to -1.0 rad).
KNEE_GRID_RAD = (-2.6, -0.7)
#: Number of knee samples on :data:`KNEE_GRID_RAD`.
KNEE_GRID_POINTS = 40
#: Degree of the polynomials fitted to the samples (fit error below 2 mm on Cassie).
FIT_DEGREE = 5
#: Joints held at zero while sampling (the leg in the sagittal plane, springs at rest).
_ZEROED_JOINTS = ("hip-roll", "hip-yaw", "hip-pitch", "shin", "heel-spring")


def bezier(coeffs, s: float) -> float:
    """Bezier polynomial ``sum_i a_i C(n,i) s^i (1-s)^(n-i)`` at ``s`` clipped to [0, 1]."""
    s = 0.0 if s < 0.0 else (1.0 if s > 1.0 else s)
    n = len(coeffs) - 1
    t = 1.0 - s
    # de Casteljau: stable and short.
    b = list(coeffs)
    for r in range(1, n + 1):
        for i in range(n - r + 1):
            b[i] = t * b[i] + s * b[i + 1]
    return float(b[0])


def _horner(coeffs, x: float) -> float:
    """Polynomial with ``coeffs`` (highest power first) at ``x``."""
    r = 0.0
    for c in coeffs:
        r = r * x + c
    return r


def _fit(x, y) -> tuple[float, ...]:
    """Coefficients (highest power first, Python floats) of the :data:`FIT_DEGREE` least-squares
    polynomial through the points (x, y).

    Householder QR of the Vandermonde matrix, its columns scaled to unit norm (as
    ``numpy.polyfit`` does), in scalar Python arithmetic in a fixed order.  ``numpy.polyfit``
    solves the same problem through LAPACK, whose last bits depend on the BLAS kernel OpenBLAS
    picks for the CPU: the fitted leg geometry, and with it every trajectory, would differ
    from one machine to the next.
    """
    xs = [float(v) for v in x]
    ys = [float(v) for v in y]
    m, n = len(xs), FIT_DEGREE + 1
    if m < n:
        raise ValueError(f"_fit: {m} points cannot determine a degree-{FIT_DEGREE} polynomial")
    # Column k holds x^(FIT_DEGREE - k) (highest power first), scaled to unit norm; the
    # powers by repeated multiplication (libm's pow has CPU-specific variants).
    powers = [[1.0] * m]
    for _ in range(FIT_DEGREE):
        powers.append([p * xi for p, xi in zip(powers[-1], xs)])
    cols = powers[::-1]
    scale = [math.sqrt(_dot(c, c)) for c in cols]
    cols = [[v / sc for v in c] for c, sc in zip(cols, scale)]
    rhs = list(ys)
    for k in range(n):  # Householder reflection zeroing column k below the diagonal
        ck = cols[k]
        alpha = math.sqrt(_dot(ck[k:], ck[k:]))
        if ck[k] > 0.0:
            alpha = -alpha
        v = [0.0] * k + [ck[k] - alpha] + ck[k + 1:]
        vv = _dot(v[k:], v[k:])
        if vv == 0.0:
            raise ValueError("_fit: the sample points are not distinct enough for the fit")
        for c in cols[k:] + [rhs]:
            f = 2.0 * _dot(v[k:], c[k:]) / vv
            for i in range(k, m):
                c[i] -= f * v[i]
    coeffs = [0.0] * n
    for k in reversed(range(n)):  # back substitution with the upper triangle R
        acc = rhs[k]
        for j in range(k + 1, n):
            acc -= cols[j][k] * coeffs[j]
        coeffs[k] = acc / cols[k][k]
    return tuple(c / sc for c, sc in zip(coeffs, scale))


def _dot(a, b) -> float:
    """Sum of ``a[i] * b[i]`` accumulated left to right (a fixed order on every CPU)."""
    acc = 0.0
    for ai, bi in zip(a, b):
        acc += ai * bi
    return acc


class LegKinematics:
    """Rigid-spring sagittal leg kinematics fitted on the model itself.

    With the shin and heel springs at rest the tarsus follows the knee
    (``tarsus = tarsus_offset - knee``, 0.2269 rad for Cassie); the hip-pitch
    pivot to ankle distance ``L(knee)`` and the angle ``g(knee)`` of that line
    from the thigh's zero are sampled on a grid and fitted by polynomials.
    Absolute leg angle (forward positive) = ``hip_pitch + g(knee) - pelvis_pitch``.
    """

    def __init__(self, phys: CassiePhysics, side: str = "left", tarsus_offset: float | None = None):
        model = phys.model
        data = mujoco.MjData(model)
        data.qpos[:] = phys.data.qpos
        leg = phys.legs[side]
        qadr = leg.qadr
        if tarsus_offset is None:
            tarsus_offset = float(data.qpos[qadr["tarsus"]] + data.qpos[qadr["knee"]])
        self.tarsus_offset = tarsus_offset
        data.qpos[phys.free_qadr + 3:phys.free_qadr + 7] = [1, 0, 0, 0]
        for joint in _ZEROED_JOINTS:
            data.qpos[qadr[joint]] = 0.0
        knees = np.linspace(*KNEE_GRID_RAD, KNEE_GRID_POINTS)
        lengths, angles = [], []
        for knee in knees:
            data.qpos[qadr["knee"]] = knee
            data.qpos[qadr["tarsus"]] = tarsus_offset - knee
            mujoco.mj_kinematics(model, data)
            v = data.xanchor[leg.foot_jid] - data.xanchor[leg.hip_pitch_jid]
            lengths.append(math.hypot(v[0], v[2]))
            angles.append(math.atan2(v[0], -v[2]))
        self._length_poly = _fit(knees, lengths)
        self._angle_poly = _fit(knees, angles)
        self._knee_poly = _fit(lengths, knees)
        #: Leg lengths (m) the fit covers: (shortest, longest).
        self.length_range_m = (min(lengths), max(lengths))

    def length(self, knee: float) -> float:
        """Hip-pitch pivot to ankle distance (m) for a knee angle (rad)."""
        return _horner(self._length_poly, knee)

    def angle_offset(self, knee: float) -> float:
        """g(knee) (rad): leg line angle at zero hip pitch and level pelvis."""
        return _horner(self._angle_poly, knee)

    def knee_for_length(self, length_m: float) -> float:
        """Knee angle (rad) giving leg length ``length_m`` (clipped to the fitted range)."""
        lo, hi = self.length_range_m
        return _horner(self._knee_poly, min(max(length_m, lo), hi))
