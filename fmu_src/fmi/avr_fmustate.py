"""The slave's FMU-state blob: encoding and complete validation (numpy-free, pure).

Layout (little endian)::

    "AVRS"  u32 version (3)  u32 json bytes  u32 core bytes    header, 16 bytes
    JSON    {"phase": ..., "time_s": ..., "values": {name: value, ...}}
    core    avr_core.state_to_bytes(...) (empty before initialization)
    u32     CRC-32 (zlib) of every byte before it

``MAGIC``, ``VERSION``, ``HEADER``, ``CRC``, ``PHASES`` and ``REFUSED_STATE`` (what the
regulator slave's deserialization yields for a blob it refuses) are also the C guard's.

On linux64 the FMU's C guard wraps this blob in its own serialized form (GUID, fixed
parameters, CRC-64) and checks all of that before Python sees a byte; this module is
the second line of defence (and the only one where pythonfmu's library runs without the
guard).  :func:`decode` accepts only a blob :func:`encode` could have written for this
FMU: every variable present, of its type, finite and in its range, a known phase and a
finite time; anything else raises :class:`StateError` naming the problem.
"""
from __future__ import annotations

import json
import math
import struct
import zlib
from dataclasses import dataclass

from fmu_src.core.avr_errors import StateError

MAGIC = b"AVRS"
VERSION = 3  # 3: the regulator without error_deadzone_mps, weight_norm_max, overspeed_unlearn
HEADER = struct.Struct("<4sIII")
CRC = struct.Struct("<I")
#: FMI phases the slave tracks (FMI 2.0 section 4.2.4)
PHASES = ("instantiated", "initializationMode", "stepComplete", "terminated")
#: What the regulator slave's deserialization yields for a refused blob (then the reason,
#: UTF-8); the guard reads it back and answers fmi2Error with the reason.
REFUSED_STATE = b"\0AVR-REFUSED\0"
#: How the JSON of every blob :func:`encode` writes begins (``json.dumps`` with sorted keys):
#: ``JSON_PREFIX`` phase ``JSON_TIME`` time ``JSON_VALUES`` {values}``}``.  The guard reads the
#: phase and the time there and refuses a blob whose header says otherwise.
JSON_PREFIX = '{"phase": "'
JSON_TIME = '", "time_s": '
JSON_VALUES = ', "values": '


@dataclass(frozen=True)
class FmuStateParts:
    """A decoded blob: every variable's value, the FMI phase, the time (s) and the core's bytes."""

    values: dict
    phase: str
    time_s: float
    core: bytes


def _json_text(values: dict, phase: str, time_s, allow_nan: bool = False) -> str:
    return json.dumps({"values": values, "phase": phase, "time_s": time_s}, sort_keys=True, allow_nan=allow_nan)


def encode(values: dict, phase: str, time_s: float, core: bytes) -> bytes:
    """The blob for these parts (deterministic: identical parts give identical bytes)."""
    text = _json_text(values, phase, time_s).encode("utf-8")
    body = HEADER.pack(MAGIC, VERSION, len(text), len(core)) + text + core
    return body + CRC.pack(zlib.crc32(body))


def value_problem(spec, value) -> str | None:
    """Why ``value`` is not a legal value of the variable ``spec`` (type, finite, range), or None."""
    if spec.type == "Boolean":
        return None if type(value) is bool else f"{spec.name} = {value!r}: must be a Boolean"
    if spec.type == "Integer" and (type(value) is not int):
        return f"{spec.name} = {value!r}: must be an Integer"
    if spec.type == "Real" and (type(value) not in (int, float) or not math.isfinite(value)):
        return f"{spec.name} = {value!r}: must be a finite number in {range_text(spec)}"
    if (spec.min is not None and value < spec.min) or (spec.max is not None and value > spec.max):
        return f"{spec.name} = {value!r}: out of range {range_text(spec)}"
    return None


def range_text(spec) -> str:
    """``[min, max]`` of a variable (``-inf``/``inf`` where it has none)."""
    low = "-inf" if spec.min is None else repr(spec.min)
    high = "inf" if spec.max is None else repr(spec.max)
    return f"[{low}, {high}]"


def decode(blob, specs) -> FmuStateParts:
    """Parse and check ``blob`` against the variable declarations ``specs`` (VarSpec)."""
    if not isinstance(blob, (bytes, bytearray, memoryview)):
        raise StateError(f"FMU state must be bytes, got {type(blob).__name__}")
    blob = bytes(blob)
    if len(blob) < HEADER.size + CRC.size:
        raise StateError(f"FMU state of {len(blob)} bytes is shorter than its header and checksum")
    magic, version, n_text, n_core = HEADER.unpack_from(blob)
    if magic != MAGIC:
        raise StateError(f"not an AdaptiveVelocityRegulator state (magic {magic!r}, expected {MAGIC!r})")
    if version != VERSION:
        raise StateError(f"AdaptiveVelocityRegulator state of format version {version}: this FMU reads "
                         f"version {VERSION} (older states hold parameters this FMU no longer has and "
                         f"cannot be continued)")
    if len(blob) != HEADER.size + n_text + n_core + CRC.size:
        raise StateError(f"FMU state has {len(blob)} bytes, its header says {HEADER.size + n_text + n_core + CRC.size}")
    if zlib.crc32(blob[:-CRC.size]) != CRC.unpack_from(blob, len(blob) - CRC.size)[0]:
        raise StateError("FMU state checksum mismatch: the state is corrupted")
    try:
        text = blob[HEADER.size:HEADER.size + n_text].decode("utf-8")
        scalars = json.loads(text)
    except (UnicodeDecodeError, ValueError) as exc:
        raise StateError(f"FMU state's variable table is not valid JSON ({exc})") from None
    if not (isinstance(scalars, dict) and set(scalars) == {"values", "phase", "time_s"}
            and isinstance(scalars["values"], dict)):
        raise StateError("FMU state's variable table does not have this FMU's layout")
    values, phase, time_s = scalars["values"], scalars["phase"], scalars["time_s"]
    by_name = {spec.name: spec for spec in specs}
    problems = [f"unknown variable {name!r}" for name in sorted(set(values) - set(by_name))]
    problems += [f"lacks {name}" for name in by_name if name not in values]
    problems += [problem for name, spec in by_name.items() if name in values
                 for problem in [value_problem(spec, values[name])] if problem]
    if phase not in PHASES:
        problems.append(f"unknown FMI phase {phase!r}")
    elif (phase in ("stepComplete", "terminated")) != (n_core > 0):  # the core exists from initialization on
        problems.append(f"phase {phase} with{'out' if n_core == 0 else ''} the regulator's state")
    if type(time_s) not in (int, float) or not math.isfinite(time_s):
        problems.append(f"time_s = {time_s!r}: must be a finite number")
    if not problems and _json_text(values, phase, time_s, allow_nan=True) != text:
        # duplicate keys, other spacing or order: json.loads would take the last duplicate, which
        # the guard (reading the first phase and time) would not see
        problems.append("the variable table is not in the form this FMU writes (sorted keys, each once, "
                        "json.dumps spacing)")
    if problems:
        raise StateError("invalid FMU state: " + "; ".join(problems))
    return FmuStateParts(values, phase, float(time_s), blob[HEADER.size + n_text:-CRC.size])
