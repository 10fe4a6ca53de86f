"""The regulator state as bytes: :func:`state_to_bytes` and its checked inverse.

Deterministic (identical states give identical bytes), no pickle, format version 5.
Layout (little-endian): header ``_HEADER`` (magic ``b"AVRSTATE"``, format version
uint16, number of weight rows (4) uint16, n_neurons uint32, then the network key:
seed uint32 and the three input scales float64 (NaN = unknown), then
last_step_index int64, n_calls int64, vx_at_step, vy_at_step, pd_x, pd_y, time_s
float64, stride_boundaries int64, stride_calls int64, stride_sum_vy,
stride_sum_roll, vy_mean_prev, vy_mean_last, roll_mean_prev, roll_mean_last,
ref_vx, ref_vy, ref_sum_vx, ref_vx_step float64, settled_steps int64), the weights as 4*n float64 in C
order, then a CRC-32 (uint32) of everything before it.
"""
from __future__ import annotations

import math
import struct
import zlib

import numpy as np

from fmu_src.core.avr_errors import StateError
from fmu_src.core.avr_params import network_key
from fmu_src.core.avr_regulator import MAX_CALLS, N_WEIGHT_ROWS, STRIDE_READY, RegulatorState
from fmu_src.core.avr_specs import INPUT_SPECS, SETTLED_STEPS_MAX

__all__ = ["state_to_bytes", "state_from_bytes"]

_MAGIC = b"AVRSTATE"
_VERSION = 5  # 2: the stride accumulators (version 1 had none); 3: the command reference;
# 4: settled_steps; 5: the same layout for the regulator without error_deadzone_mps,
# weight_norm_max and overspeed_unlearn (a version 4 state may have learned with them)
# magic, version, n_rows, n_neurons, seed, velocity/angle/rate scales,
# last_step_index, n_calls, vx_at_step, vy_at_step, pd_x, pd_y, time_s,
# stride_boundaries, stride_calls, stride_sum_vy, stride_sum_roll,
# vy_mean_prev, vy_mean_last, roll_mean_prev, roll_mean_last, ref_vx, ref_vy, ref_sum_vx,
# ref_vx_step, settled_steps
_HEADER = struct.Struct("<8sHHII3dqq5dqq10dq")
#: The magic and the version: what can be read before the size is known; then the counts.
_PREFIX = struct.Struct("<8sH")
_COUNTS = struct.Struct("<8sHHI")  # magic, version, n_rows, n_neurons
#: The float64 fields after stride_calls: the stride sums and means, then the command reference.
_TAIL_FLOATS = ("stride_sum_vy", "stride_sum_roll", "vy_mean_prev", "vy_mean_last",
                "roll_mean_prev", "roll_mean_last", "ref_vx", "ref_vy", "ref_sum_vx", "ref_vx_step")
_CRC = struct.Struct("<I")
_FLOAT64_BYTES = 8
_UNKNOWN_SCALES = (math.nan,) * 3


def state_to_bytes(state: RegulatorState) -> bytes:
    """Serialise ``state`` (layout: the module docstring)."""
    if state.network_key is not None:
        seed, *scales = state.network_key
    else:
        seed, scales = 0, _UNKNOWN_SCALES
    head = _HEADER.pack(_MAGIC, _VERSION, N_WEIGHT_ROWS, state.n_neurons, seed, *scales,
                        state.last_step_index, state.n_calls, state.vx_at_step,
                        state.vy_at_step, state.pd_x, state.pd_y, state.time_s,
                        state.stride_boundaries, state.stride_calls,
                        *(getattr(state, name) for name in _TAIL_FLOATS), state.settled_steps)
    body = head + state.weights.astype("<f8", copy=False).tobytes(order="C")
    return body + _CRC.pack(zlib.crc32(body))


def state_from_bytes(blob: bytes, params) -> RegulatorState:
    """Inverse of :func:`state_to_bytes` for a regulator with ``params``.

    Raises :class:`StateError` on a non-bytes blob, bad magic, unknown version, wrong
    size or checksum, an n_neurons (or, when recorded, seed or input scale) different
    from ``params``, or invalid contents (non-finite values, step index < -1).
    """
    blob = _checked_frame(blob)
    (_, _, _, n_neurons, seed, velocity_scale, angle_scale, rate_scale, last, n_calls, vx_at,
     vy_at, pd_x, pd_y, time_s, boundaries, stride_calls, *tail, settled) = _HEADER.unpack_from(blob, 0)
    key = _checked_key(n_neurons, seed, (velocity_scale, angle_scale, rate_scale), params)
    weights = np.frombuffer(blob, dtype="<f8", count=N_WEIGHT_ROWS * n_neurons,
                            offset=_HEADER.size)
    weights = weights.astype(np.float64).reshape(N_WEIGHT_ROWS, n_neurons)  # owned, native-endian
    scalars = (vx_at, vy_at, pd_x, pd_y, time_s, *tail)
    if not (np.all(np.isfinite(weights)) and all(math.isfinite(value) for value in scalars)):
        raise StateError("state contains non-finite values")
    problems = counter_problems(last, n_calls, time_s, boundaries, stride_calls, settled)
    if problems:
        raise StateError("state has invalid counters: " + "; ".join(problems))
    weights.flags.writeable = False
    return RegulatorState(weights, last, vx_at, vy_at, pd_x, pd_y, n_calls, time_s, key,
                          boundaries, stride_calls, *tail, settled)


#: The largest step_index (the input's declared maximum): the largest last_step_index.
_MAX_STEP_INDEX = next(spec.max for spec in INPUT_SPECS if spec.name == "step_index")


def counter_problems(last_step_index: int, n_calls: int, time_s: float, stride_boundaries: int,
                     stride_calls: int, settled_steps: int = 0) -> list[str]:
    """Why these counters are not ones a run can reach (each problem names the field and its
    range), or [].  A run starts with last_step_index = -1, n_calls = 0, time_s = 0 and no stride;
    each call sets last_step_index to its step_index (in [0, max]), adds one to n_calls (up to
    MAX_CALLS) and its dt > 0 to time_s; stride_calls counts calls of the current step, so at most
    n_calls; settled_steps counts step_index changes, at most one per call, up to SETTLED_STEPS_MAX.
    The native FMU checks the same (avr_state.c)."""
    problems = []
    if not 0 <= n_calls <= MAX_CALLS:
        problems.append(f"n_calls = {n_calls}: must be in [0, {MAX_CALLS}]")
    if not -1 <= last_step_index <= _MAX_STEP_INDEX:
        problems.append(f"last_step_index = {last_step_index}: must be in [-1, {_MAX_STEP_INDEX}]")
    elif (last_step_index == -1) != (n_calls == 0):
        problems.append(f"last_step_index = {last_step_index} with n_calls = {n_calls}: -1 exactly before the first call")
    if not (time_s >= 0.0 and (n_calls > 0 or time_s == 0.0)):
        problems.append(f"time_s = {time_s!r} with n_calls = {n_calls}: a sum of steps > 0 (0 before the first call)")
    if not 0 <= stride_boundaries <= STRIDE_READY:
        problems.append(f"stride_boundaries = {stride_boundaries}: must be in [0, {STRIDE_READY}]")
    if not 0 <= stride_calls <= n_calls or (stride_boundaries == 0) != (stride_calls == 0):
        problems.append(f"stride_calls = {stride_calls}: must be in [0, n_calls = {n_calls}], 0 exactly when "
                        f"stride_boundaries is (here {stride_boundaries})")
    if not 0 <= settled_steps <= min(n_calls, SETTLED_STEPS_MAX):
        problems.append(f"settled_steps = {settled_steps}: must be in [0, min(n_calls = {n_calls}, "
                        f"{SETTLED_STEPS_MAX})]")
    return problems


def _checked_frame(blob) -> bytes:
    """``blob`` as bytes once its type, magic, version, row count, size and CRC are right."""
    if not isinstance(blob, (bytes, bytearray, memoryview)):
        raise StateError(f"state blob must be bytes, got {type(blob).__name__}")
    blob = bytes(blob)
    if len(blob) < _PREFIX.size + _CRC.size:
        raise StateError(f"state blob too short ({len(blob)} bytes)")
    magic, version = _PREFIX.unpack_from(blob, 0)
    if magic != _MAGIC:
        raise StateError(f"not a regulator state (magic {magic!r}, expected {_MAGIC!r})")
    if version != _VERSION:
        raise StateError(f"unsupported state format version {version} (this build reads "
                         f"{_VERSION}; older states predate the stride-averaged lateral/roll "
                         f"learning (version 1), the command reference (version 2), the "
                         f"settled-step count (version 3) or the retirement of error_deadzone_mps, "
                         f"weight_norm_max and overspeed_unlearn (version 4) and cannot be continued)")
    if len(blob) < _HEADER.size + _CRC.size:
        raise StateError(f"state blob too short ({len(blob)} bytes)")
    _, _, n_rows, n_neurons = _COUNTS.unpack_from(blob, 0)
    if n_rows != N_WEIGHT_ROWS:
        raise StateError(f"state has {n_rows} weight rows, expected {N_WEIGHT_ROWS}")
    expected = _HEADER.size + _FLOAT64_BYTES * N_WEIGHT_ROWS * n_neurons + _CRC.size
    if len(blob) != expected:
        raise StateError(f"state blob has {len(blob)} bytes, expected {expected} "
                         f"for n_neurons = {n_neurons}")
    (crc,) = _CRC.unpack_from(blob, len(blob) - _CRC.size)
    if zlib.crc32(blob[:-_CRC.size]) != crc:
        raise StateError("state blob checksum mismatch (corrupted)")
    return blob


def _checked_key(n_neurons: int, seed: int, scales: tuple, params):
    """The state's network key (None if unrecorded), refused if it is not ``params``'."""
    if n_neurons != params.n_neurons:
        raise StateError(f"state has n_neurons = {n_neurons}, regulator has {params.n_neurons}")
    if all(math.isnan(scale) for scale in scales):
        return None
    if seed != params.seed:
        raise StateError(f"state was saved with seed = {seed}, regulator has {params.seed}")
    here = network_key(params)[1:]
    if scales != here:
        raise StateError(f"state was saved with input scales {scales}, regulator has {here}")
    return (seed, *scales)
