"""Native FMUs: their serialized FMU state refuses every corruption of its own format, and
FMI 3.0's independent variable.  (Round trips, instances, reset, fixed parameters and the
random call sequences run on every regulator FMU: tests/fmu/test_fmu_compliance.py and
tests/fmu/test_fmu_call_sequences.py; the pythonfmu FMU's blob format: tests/fmu/test_fmu_state_integrity.py.)
"""
import math
import struct
import zlib

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from support.native_support import AnySlave, input_sequence

FMI = pytest.mark.parametrize("fmi", [2, 3])


def _corruptions(blob: bytes, other_blob: bytes):
    """(name, bytes) of blobs that must be refused."""
    n_vars = struct.unpack_from("<I", blob, 64)[0]

    def with_crc(body: bytearray) -> bytes:  # a well-formed checksum over bad contents
        return bytes(body[:-4]) + struct.pack("<I", zlib.crc32(bytes(body[:-4])))

    def patched(offset, fmt, value):
        body = bytearray(blob)
        struct.pack_into(fmt, body, offset, value)
        return with_crc(body)

    values = 248  # header (format version 5: stride accumulators and reference at 144..239, settled_steps at 240)
    weights = values + 8 * n_vars
    yield "truncated", blob[:-1]
    yield "extended", blob + b"\0"
    yield "empty", b""
    for offset in (0, 9, 20, 70, 100, 150, 170, values, weights + 3, len(blob) - 2):
        yield f"bit flip at {offset}", blob[:offset] + bytes([blob[offset] ^ 0x10]) + blob[offset + 1:]
    yield "other FMU's state (GUID)", other_blob
    # the GUID field is the GUID NUL-padded (fmi_blob.c, as the guard's): nothing may follow the GUID
    yield "a byte after the GUID in its field, valid checksum", patched(16 + 47, "<B", ord("x"))
    yield "NaN weight, valid checksum", patched(weights + 8, "<d", math.nan)
    yield "NaN time, valid checksum", patched(72, "<d", math.nan)
    yield "psi_limit out of range, valid checksum", patched(values + 8 * 11, "<d", 7.0)
    yield "n_neurons not the weights', valid checksum", patched(80, "<I", 7)
    yield "unknown phase, valid checksum", patched(68, "<I", 64)
    yield "step index below -1, valid checksum", patched(88, "<q", -5)
    yield "format version 1 (before the stride accumulators), valid checksum", patched(8, "<I", 1)
    yield "stride boundaries beyond 4, valid checksum", patched(144, "<q", 5)
    yield "negative stride calls, valid checksum", patched(152, "<q", -1)
    yield "NaN stride mean, valid checksum", patched(184, "<d", math.nan)
    # counters no run reaches: the next doStep would overflow them (UBSan: tests/support/native/sanitize_run.py)
    yield "n_calls = INT64_MAX, valid checksum", patched(96, "<q", 2**63 - 1)
    yield "stride_calls = INT64_MAX, valid checksum", patched(152, "<q", 2**63 - 1)
    yield "settled_steps beyond n_calls, valid checksum", patched(240, "<q", 2**40)
    yield "negative settled_steps, valid checksum", patched(240, "<q", -1)


@FMI
def test_corrupted_or_foreign_blobs_are_refused_and_change_nothing(native_fmus, fmi):
    s = AnySlave(native_fmus[fmi]).init(n_neurons=30, learning_rate=1e-4)
    other = AnySlave(native_fmus[5 - fmi], name="other").init(n_neurons=30)
    seq = input_sequence(20, seed=3)
    for k, u in enumerate(seq[:10]):
        s.step(k, u)
    blob, other_blob = s.serialize(s.get_state()), other.serialize(other.get_state())
    before = s.serialize(s.get_state())
    refused = []
    for name, bad in _corruptions(blob, other_blob):
        with pytest.raises(FMICallException) as info:
            s.deserialize(bad)
        assert info.value.status == 3, name
        refused.append(name)
    assert len(refused) >= 21 and s.serialize(s.get_state()) == before  # nothing changed
    s.set_state(s.deserialize(blob))  # and the instance still works
    assert np.all(np.isfinite([s.step(k, u) for k, u in enumerate(seq[10:], start=10)]))
    for slave in (s, other):
        slave.close()


def test_fmi3_time_is_the_independent_variable(native_fmus):
    s = AnySlave(native_fmus[3]).init()
    time_vr = s.vars["time"].valueReference
    for k in range(3):
        s.step(k, {"vx": 0.1})
    assert s.fmu.getFloat64([time_vr]) == [3 * 0.005]
    with pytest.raises(FMICallException):
        s.fmu.setFloat64([time_vr], [1.0])
    assert s.fmu.getFloat64([time_vr]) == [3 * 0.005]
    s.close()


@FMI
def test_a_version_4_state_is_refused_naming_the_version(native_fmus, fmi):
    """Version 4 states hold error_deadzone_mps, weight_norm_max and overspeed_unlearn (retired):
    refused with a message naming the version, even with a valid checksum."""
    messages = []
    s = AnySlave(native_fmus[fmi], messages=messages).init(n_neurons=30)
    blob = bytearray(s.serialize(s.get_state()))
    assert struct.unpack_from("<I", blob, 8) == (5,)
    struct.pack_into("<I", blob, 8, 4)
    blob[-4:] = struct.pack("<I", zlib.crc32(bytes(blob[:-4])))
    with pytest.raises(FMICallException):
        s.deserialize(bytes(blob))
    assert any("version 4" in m and "error_deadzone_mps, weight_norm_max and overspeed_unlearn" in m
               for m in messages), messages
    s.close()


@pytest.mark.parametrize("fmi", [2, 3, "python"])
def test_a_ramp_limit_without_settled_steps_is_refused_naming_both(native_fmus, built_fmu, fmi):
    """learn_ramp_max_mps2 > 0 requires learn_settled_steps > 0 (avr_specs.PARAM_REQUIRES): refused
    with Error when initialization ends (the instance stays in it and takes the missing value),
    and while stepping on the set that would break it; a forged native state that breaks it is
    refused.  The same in the pythonfmu FMU (its guard answers Error for the slave's logged refusal)."""
    messages = []
    s = AnySlave(built_fmu if fmi == "python" else native_fmus[fmi], messages=messages)
    s.set("learn_ramp_max_mps2", 0.25)
    if s.fmi3:
        s.fmu.enterInitializationMode(startTime=0.0)
    else:
        s.fmu.setupExperiment(startTime=0.0)
        s.fmu.enterInitializationMode()
    with pytest.raises(FMICallException):
        s.fmu.exitInitializationMode()
    assert any("learn_ramp_max_mps2 = 0.25 requires learn_settled_steps > 0 (it is 0)" in m for m in messages)
    s.set("learn_settled_steps", 2)
    s.fmu.exitInitializationMode()  # now legal
    s.step(0, {"vx": 0.1})
    messages.clear()
    with pytest.raises(FMICallException):
        s.set("learn_settled_steps", 0)
    assert any("learn_ramp_max_mps2 = 0.25 requires learn_settled_steps > 0 (it is 0)" in m for m in messages)
    assert np.all(np.isfinite(s.step(1, {"vx": 0.1})))  # refused, not fatal: the instance steps on
    if fmi == "python":
        s.close()
        return
    blob = bytearray(s.serialize(s.get_state()))
    vr = s.vars["learn_settled_steps"].valueReference
    struct.pack_into("<d", blob, 248 + 8 * vr, 0.0)
    blob[-4:] = struct.pack("<I", zlib.crc32(bytes(blob[:-4])))
    with pytest.raises(FMICallException):
        s.deserialize(bytes(blob))
    assert any("state has parameters no instance can have" in m for m in messages)
    s.set("learn_ramp_max_mps2", 0.0)  # in the other order both are legal
    s.set("learn_settled_steps", 0)
    s.close()
