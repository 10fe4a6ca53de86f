"""Metrics of one closed-loop run: pure functions over the master's structured array.

The array has one row per communication step ``k`` (state at ``t = k*h`` and the
regulator action applied over ``[t, t+h)``); the columns the metrics use are

- ``t``: the communication point (s),
- ``cmd_vx_des``, ``cmd_vy_des``: the command in force (m/s); ``cmd_yaw_rate_des``
  its turning rate (rad/s),
- ``tel_vx_step_avg`` (and ``tel_vy_step_avg`` if the plant reports it): the forward
  (lateral) velocity averaged over the last completed step (m/s),
- ``in_vx``, ``in_vy``, ``in_step_index``: the regulator's inputs (used to rebuild a
  step average the plant does not report),
- ``in_pitch``, ``in_roll``: torso angles (rad),
- ``tel_yaw``: the pelvis heading (rad, wrapped to [-pi, pi]).

Velocity error = step-averaged velocity - command (the quantity the paper regulates).
Laterally the step average alternates with the left/right sway (the pelvis moves
towards the stance foot every step), so the lateral metrics also come stride-averaged:
the mean of the last two step averages (one left and one right step), the quantity the
regulator's lateral networks learn from.

Turning is judged on the heading itself: the mean yaw rate over a window is the
least-squares slope of the unwrapped heading over it (the instantaneous yaw rate and the
heading sway with every step; see :func:`steady_state_error_yaw_rate`).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from scenarios.lang.formatting import show

#: Convergence band on the step-averaged velocity error (m/s).
CONVERGENCE_TOL_MPS = 0.05
#: The steady-state window at the end of a run (s).
STEADY_WINDOW_S = 5.0
#: Window at the end of each command level for ``level_errors_vx`` (s).
LEVEL_WINDOW_S = 4.0
#: Start-up excluded from the whole-run error (s): from rest to the first steady steps.
STARTUP_S = 5.0
#: Time a command must have been constant before ``settled_error_vx`` counts a row (s): the
#: gait ramps to a new command at 0.5 m/s^2, so a step across the campaigns' 0..1 m/s range
#: takes it up to 2 s, and the step-averaged velocity lags by one walking step (~0.3 s).
SETTLE_S = 2.5
#: A convergence must hold at least this long before the end of the run to count (s).
MIN_HOLD_S = 1.0


def comm_step(rows: np.ndarray) -> float:
    """The communication step of the run (difference of the first two time stamps)."""
    if len(rows) < 2:
        return 0.0
    return float(rows["t"][1] - rows["t"][0])


def end_time(rows: np.ndarray) -> float:
    """The time at the end of the last recorded communication step."""
    if len(rows) == 0:
        return 0.0
    return float(rows["t"][-1]) + comm_step(rows)


def step_average(values: np.ndarray, step_index: np.ndarray) -> np.ndarray:
    """For each row, the mean of ``values`` over the last *completed* step.

    A step is a run of equal ``step_index``; rows in the first step (no completed step
    yet) get the running mean of the values so far.
    """
    values = np.asarray(values, dtype=float)
    step_index = np.asarray(step_index)
    out = np.empty_like(values)
    if len(values) == 0:
        return out
    start = 0
    last_avg = None
    running_sum = 0.0
    for i in range(len(values)):
        if i > 0 and step_index[i] != step_index[i - 1]:
            last_avg = float(np.mean(values[start:i]))
            start = i
        if last_avg is None:
            running_sum += values[i]
            out[i] = running_sum / (i + 1)
        else:
            out[i] = last_avg
    return out


def _stepavg_column(rows: np.ndarray, axis: str) -> np.ndarray:
    name = f"tel_{axis}_step_avg"
    if name in rows.dtype.names:
        return np.asarray(rows[name], dtype=float)
    return step_average(rows[f"in_{axis}"], rows["in_step_index"])


def stride_average(step_avg: np.ndarray, step_index: np.ndarray) -> np.ndarray:
    """For each row, the mean of the last two step averages (a stride: one left, one
    right step).  ``step_avg`` holds, per row, the average over the last completed step
    (as :func:`step_average` gives); rows before the second completed step keep it."""
    out = np.array(step_avg, dtype=float)
    changes = np.nonzero(np.diff(np.asarray(step_index)))[0] + 1
    bounds = list(changes) + [len(out)]
    for j in range(1, len(changes)):
        a, b = bounds[j], bounds[j + 1]
        out[a:b] = 0.5 * (float(step_avg[changes[j - 1]]) + float(step_avg[a]))
    return out


def velocity_errors(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ex, ey): step-averaged velocity minus command, per row (m/s)."""
    ex = _stepavg_column(rows, "vx") - np.asarray(rows["cmd_vx_des"], dtype=float)
    ey = _stepavg_column(rows, "vy") - np.asarray(rows["cmd_vy_des"], dtype=float)
    return ex, ey


def lateral_stride_error(rows: np.ndarray) -> np.ndarray:
    """Stride-averaged lateral velocity minus command, per row (m/s)."""
    vy = stride_average(_stepavg_column(rows, "vy"), rows["in_step_index"])
    return vy - np.asarray(rows["cmd_vy_des"], dtype=float)


def _last_window(rows: np.ndarray, window_s: float) -> np.ndarray:
    t_end = end_time(rows)
    return np.asarray(rows["t"], dtype=float) >= t_end - window_s - 1e-9


def steady_state_error(rows: np.ndarray, axis: str = "vx", *, window_s: float = STEADY_WINDOW_S,
                       fell: bool = False) -> float | None:
    """Mean |step-averaged velocity error| over the last ``window_s`` of the run;
    ``axis`` ``"vx"``, ``"vy"`` or ``"vy_stride"`` (the stride-averaged lateral error).

    ``None`` when the robot fell (a steady state was never reached) or there is no data.
    """
    if fell or len(rows) == 0:
        return None
    ex, ey = velocity_errors(rows)
    e = {"vx": ex, "vy": ey}[axis] if axis != "vy_stride" else lateral_stride_error(rows)
    sel = _last_window(rows, window_s)
    return float(np.mean(np.abs(e[sel])))


def settled_error_vx(rows: np.ndarray, *, settle_s: float = SETTLE_S, startup_s: float = STARTUP_S,
                     fell: bool = False) -> float | None:
    """Mean |step-averaged forward velocity error| over the rows where the command
    (``cmd_vx_des`` and ``cmd_vy_des``) has been constant for at least ``settle_s`` and the
    run is past ``startup_s``: the error the regulator leaves once the gait has reached the
    command, over every command level of the run (each hold of a stepped profile after its
    first ``settle_s``, the holds after the ramps of a ramped one). A run with changing
    commands is judged where a steady state exists; :func:`steady_state_error` over the
    last seconds would judge the last command step's transient instead.

    ``None`` when the robot fell or no row qualifies.
    """
    if fell or len(rows) == 0:
        return None
    t = np.asarray(rows["t"], dtype=float)
    cmd_x = np.asarray(rows["cmd_vx_des"], dtype=float)
    cmd_y = np.asarray(rows["cmd_vy_des"], dtype=float)
    changed = np.concatenate(([True], (np.diff(cmd_x) != 0.0) | (np.diff(cmd_y) != 0.0)))
    since = t - np.maximum.accumulate(np.where(changed, t, -np.inf))
    sel = (since >= settle_s - 1e-9) & (t >= startup_s - 1e-9)
    if not sel.any():
        return None
    ex, _ = velocity_errors(rows)
    return float(np.mean(np.abs(ex[sel])))


def steady_state_error_yaw_rate(rows: np.ndarray, *, window_s: float = STEADY_WINDOW_S,
                                fell: bool = False) -> float | None:
    """|mean yaw rate - mean commanded yaw rate| over the last ``window_s`` of the run
    (rad/s), the window as in :func:`steady_state_error`.  The mean yaw rate is the
    least-squares slope of the unwrapped ``tel_yaw`` over the window: the pelvis yaws
    back and forth by ~0.1-0.25 rad every step, which a slope from the window's two ends
    alone would read as up to ~0.03 rad/s of turning; the command is averaged over the
    same rows.

    ``None`` when the robot fell, the window holds fewer than two rows, or the rows lack
    ``tel_yaw`` or ``cmd_yaw_rate_des``.
    """
    names = rows.dtype.names or ()
    if fell or "tel_yaw" not in names or "cmd_yaw_rate_des" not in names:
        return None
    sel = np.nonzero(_last_window(rows, window_s))[0]
    if len(sel) < 2:
        return None
    t = np.asarray(rows["t"][sel], dtype=float)
    yaw = np.unwrap(np.asarray(rows["tel_yaw"][sel], dtype=float))
    tc = t - t.mean()
    # Elementwise products and numpy's pairwise sum (a fixed order on every CPU); np.dot
    # would go through the BLAS kernel OpenBLAS picks for the CPU.
    slope = float(np.sum(tc * (yaw - yaw.mean())) / np.sum(tc * tc))
    commanded = float(np.mean(np.asarray(rows["cmd_yaw_rate_des"][sel], dtype=float)))
    return abs(slope - commanded)


def run_error_vx(rows: np.ndarray, *, startup_s: float = STARTUP_S, fell: bool = False) -> float | None:
    """Mean |step-averaged forward velocity error| over the whole run after ``startup_s``
    (the terrain judgement: over uneven ground the last seconds alone compare two arms on
    different ground); ``None`` if the robot fell or the run is no longer than start-up."""
    if fell or len(rows) == 0:
        return None
    sel = np.asarray(rows["t"], dtype=float) >= startup_s - 1e-9
    if not sel.any():
        return None
    ex, _ = velocity_errors(rows)
    return float(np.mean(np.abs(ex[sel])))


def convergence_time(rows: np.ndarray, *, t_from: float = 0.0, tol: float = CONVERGENCE_TOL_MPS,
                     min_hold_s: float = MIN_HOLD_S, fell: bool = False) -> float | None:
    """Time from ``t_from`` after which |ex| (step-averaged) and |ey| (stride-averaged:
    the step average's left/right sway is no error) stay <= ``tol`` to the end of the run.

    Returns ``t_c - t_from`` where ``t_c`` is the first row time >= ``t_from`` from which
    every later row is inside the band (0 if it never leaves the band after ``t_from``);
    ``None`` if the run fell, never settles, or settles less than ``min_hold_s`` before
    the end.
    """
    if fell or len(rows) == 0:
        return None
    t = np.asarray(rows["t"], dtype=float)
    ex, _ = velocity_errors(rows)
    ey = lateral_stride_error(rows)
    inside = (np.abs(ex) <= tol) & (np.abs(ey) <= tol)
    after = t >= t_from - 1e-9
    if not after.any():
        return None
    bad = np.nonzero(after & ~inside)[0]
    if len(bad) == 0:
        t_c = float(t[after][0])
    else:
        last_bad = int(bad[-1])
        if last_bad + 1 >= len(t):
            return None
        t_c = float(t[last_bad + 1])
    if end_time(rows) - t_c < min_hold_s - 1e-9:
        return None
    return max(0.0, t_c - t_from)


def step_alternation(rows: np.ndarray, column: str, t0: float, t1: float) -> float | None:
    """Step-to-step alternation amplitude of ``column`` in ``[t0, t1)``: half the mean
    |difference| between its values at consecutive changes of ``in_step_index`` (a
    signal that flips between +a and -a with the stance side gives a).  ``None`` with
    fewer than three step changes in the window."""
    if len(rows) == 0 or column not in rows.dtype.names:
        return None
    si = np.asarray(rows["in_step_index"])
    changes = np.nonzero(np.diff(si))[0] + 1
    t = np.asarray(rows["t"], dtype=float)[changes]
    values = np.asarray(rows[column], dtype=float)[changes][(t >= t0 - 1e-9) & (t < t1 - 1e-9)]
    if len(values) < 3:
        return None
    return float(np.mean(np.abs(np.diff(values))) / 2.0)


def level_errors_vx(rows: np.ndarray, *, window_s: float = LEVEL_WINDOW_S,
                    fell: bool = False) -> list[dict[str, Any]]:
    """Per command level (a run of rows with one ``cmd_vx_des``): its start ``t_s``,
    ``vx_des`` and ``error_vx``, the mean |step-averaged forward error| over the level's
    last ``window_s`` (m/s); ``None`` for a level shorter than the window and, when the
    run ``fell``, for the level it fell in."""
    if len(rows) == 0:
        return []
    t = np.asarray(rows["t"], dtype=float)
    cmd = np.asarray(rows["cmd_vx_des"], dtype=float)
    ex, _ = velocity_errors(rows)
    starts = np.concatenate(([0], np.nonzero(np.diff(cmd))[0] + 1))
    ends = np.concatenate((starts[1:], [len(t)]))
    out = []
    for a, b in zip(starts, ends):
        t_end = t[b] if b < len(t) else end_time(rows)
        window = (t[a:b] >= t_end - window_s - 1e-9)
        ok = t_end - t[a] >= window_s - 1e-9 and window.any() and not (fell and b == len(t))
        out.append({"t_s": float(t[a]), "vx_des": float(cmd[a]),
                    "error_vx": float(np.mean(np.abs(ex[a:b][window]))) if ok else None})
    return out


def mean_last(rows: np.ndarray, column: str, *, window_s: float = STEADY_WINDOW_S) -> float | None:
    if len(rows) == 0 or column not in rows.dtype.names:
        return None
    return float(np.mean(rows[column][_last_window(rows, window_s)]))


def max_abs(rows: np.ndarray, column: str) -> float | None:
    if len(rows) == 0 or column not in rows.dtype.names:
        return None
    return float(np.max(np.abs(rows[column])))


def summarize_arm(rows: np.ndarray, *, fell: bool, t_fall_s: float | None, perturbation_t_s: float = 0.0,
                  wall_s: float | None = None) -> dict[str, Any]:
    """The per-arm metrics of ``summary.json`` (JSON-ready: floats, bools, None)."""
    sim_s = end_time(rows)
    out: dict[str, Any] = {
        "fell": bool(fell),
        "t_fall_s": None if t_fall_s is None else float(t_fall_s),
        "steady_state_error_vx": steady_state_error(rows, "vx", fell=fell),
        "steady_state_error_vy": steady_state_error(rows, "vy", fell=fell),
        "steady_state_error_vy_stride": steady_state_error(rows, "vy_stride", fell=fell),
        "steady_state_error_yaw_rate": steady_state_error_yaw_rate(rows, fell=fell),
        "run_error_vx": run_error_vx(rows, fell=fell),
        "settled_error_vx": settled_error_vx(rows, fell=fell),
        "level_errors_vx": level_errors_vx(rows, fell=fell),
        "convergence_time_s": convergence_time(rows, t_from=perturbation_t_s, fell=fell),
        "mean_vx_last_s": mean_last(rows, "tel_vx" if "tel_vx" in rows.dtype.names else "in_vx"),
        "mean_vy_last_s": mean_last(rows, "tel_vy" if "tel_vy" in rows.dtype.names else "in_vy"),
        "max_abs_pitch_rad": max_abs(rows, "in_pitch"),
        "max_abs_roll_rad": max_abs(rows, "in_roll"),
        "sim_s": sim_s,
        "n_comm_steps": int(len(rows)),
        "wall_s": None if wall_s is None else float(wall_s),
        "realtime_factor": (sim_s / wall_s) if wall_s and wall_s > 0 else None,
    }
    # the longitudinal offsets at the end: which joint carries the correction (redundancy)
    for joint in ("swing_hip_pitch", "swing_knee"):
        out[f"mean_delta_{joint}_last_s"] = mean_last(rows, f"out_delta_{joint}")
    psi = {}
    for name in ("psi_x", "psi_y", "psi_pitch", "psi_roll"):
        col = f"out_{name}"
        if len(rows) and col in rows.dtype.names:
            psi[name] = float(rows[col][-1])
    out["final_psi"] = psi
    return _json_clean(out)


def _json_clean(d: dict[str, Any]) -> dict[str, Any]:
    """NaN/inf become None so summary.json stays strict JSON."""
    clean: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, float) and not math.isfinite(v):
            clean[k] = None
        elif isinstance(v, dict):
            clean[k] = _json_clean(v)
        else:
            clean[k] = v
    return clean


# --------------------------------------------------------------------------- claim checks
_OPS = {
    "<": lambda a, b: a < b,
    "<=": lambda a, b: a <= b,
    ">": lambda a, b: a > b,
    ">=": lambda a, b: a >= b,
    "==": lambda a, b: a == b,
    "!=": lambda a, b: a != b,
}


def evaluate_check(check: dict[str, Any], arms: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Evaluate one claim check against the per-arm metrics.

    ``check`` has ``arm``, ``metric``, ``op`` and ``value`` or ``other_arm``. Returns
    ``{"verdict": "pass"|"miss"|"n/a", "lhs": ..., "rhs": ..., "text": ...}``; ``n/a``
    when an arm is missing or a metric is null (e.g. the error of a run that fell).
    """
    arm, metric, op = check["arm"], check["metric"], check["op"]
    other = check.get("other_arm")
    rhs_label = f"{other}.{metric}" if other else show(check.get("value"), quote=False)
    text = f"{arm}.{metric} {op} {rhs_label}"
    lhs = arms.get(arm, {}).get(metric) if arm in arms else None
    if other:
        rhs = arms.get(other, {}).get(metric) if other in arms else None
    else:
        rhs = check.get("value")
    if arm not in arms or (other and other not in arms):
        return {"verdict": "n/a", "lhs": lhs, "rhs": rhs, "text": text, "why": "arm not run"}
    if lhs is None or rhs is None:
        return {"verdict": "n/a", "lhs": lhs, "rhs": rhs, "text": text, "why": "metric is null"}
    ok = bool(_OPS[op](lhs, rhs))
    return {"verdict": "pass" if ok else "miss", "lhs": lhs, "rhs": rhs, "text": text}

