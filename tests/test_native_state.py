"""Native FMUs: FMU state round trips, corrupted blobs, instances, reset, and random
call sequences (legal and illegal) against an independent model of the FMI state machine
(the pythonfmu FMU's model in tests/test_fmu_call_sequences.py, and its FMI 3.0 variant).
"""
import math
import struct
import subprocess
import sys
import zlib

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fmu_src.avr_core import OUTPUT_SPECS
from native_support import AnySlave, input_sequence, native_fmus, unzipped  # noqa: F401 (fixture)
from test_fmu_call_sequences import FmiModel, _coerce, _send, calls
from test_native_fmu import DRIVERS

FMI = pytest.mark.parametrize("fmi", [2, 3])
PSI_X = [s.name for s in OUTPUT_SPECS].index("psi_x")


@FMI
def test_state_round_trips_are_bit_exact(native_fmus, fmi):
    s = AnySlave(native_fmus[fmi]).init(learning_rate=1e-4)
    seq = input_sequence(120, seed=2)
    for k, u in enumerate(seq[:60]):
        s.step(k, u)
    state = s.get_state()
    blob = s.serialize(state)
    straight = np.array([s.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    s.set_state(state)  # restore in memory, then continue
    again = np.array([s.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    other = AnySlave(native_fmus[fmi], name="other").init()  # same fixed parameters (other ones are refused)
    other.set_state(other.deserialize(blob))
    restored = np.array([other.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    assert np.array_equal(straight, again) and np.array_equal(straight, restored)
    assert np.any(straight[:, PSI_X] != 0.0)  # the state carries learned weights
    assert s.serialize(other.get_state()) == s.serialize(s.get_state())  # same history, same bytes
    for slave in (s, other):
        slave.close()


def _corruptions(blob: bytes, other_blob: bytes):
    """(name, bytes) of blobs that must be refused."""
    n_vars = struct.unpack_from("<I", blob, 64)[0]

    def with_crc(body: bytearray) -> bytes:  # a well-formed checksum over bad contents
        return bytes(body[:-4]) + struct.pack("<I", zlib.crc32(bytes(body[:-4])))

    def patched(offset, fmt, value):
        body = bytearray(blob)
        struct.pack_into(fmt, body, offset, value)
        return with_crc(body)

    values = 208  # header (format version 2: with the stride accumulators at 144..207)
    weights = values + 8 * n_vars
    yield "truncated", blob[:-1]
    yield "extended", blob + b"\0"
    yield "empty", b""
    for offset in (0, 9, 20, 70, 100, 150, 170, values, weights + 3, len(blob) - 2):
        yield f"bit flip at {offset}", blob[:offset] + bytes([blob[offset] ^ 0x10]) + blob[offset + 1:]
    yield "other FMU's state (GUID)", other_blob
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


@FMI
def test_twenty_instances_in_one_process_are_independent(native_fmus, fmi):
    unzip = unzipped(native_fmus[fmi])
    slaves = [AnySlave(native_fmus[fmi], name=f"i{i}", unzip=unzip).init(n_neurons=200, seed=i % 2,
                                                                          learning_rate=1e-4) for i in range(20)]
    seqs = [input_sequence(30, seed=100 + i) for i in range(20)]
    interleaved = [[None] * 30 for _ in range(20)]
    for k in range(30):
        for i, s in enumerate(slaves):
            interleaved[i][k] = s.step(k, seqs[i][k])
    for i in (0, 7, 19):  # each equals a run of its own in a fresh instance
        alone = AnySlave(native_fmus[fmi], name=f"alone{i}", unzip=unzip).init(n_neurons=200, seed=i % 2,
                                                                               learning_rate=1e-4)
        assert np.array_equal(np.array(interleaved[i]), np.array([alone.step(k, u) for k, u in enumerate(seqs[i])]))
        alone.close()
    for s in slaves:
        s.close()


@FMI
def test_reset_returns_the_start_state(native_fmus, fmi):
    s = AnySlave(native_fmus[fmi]).init(n_neurons=300, learning_rate=1e-4, learn_from_step=0)
    seq = input_sequence(50, seed=1)
    first = [s.step(k, u) for k, u in enumerate(seq)]
    s.fmu.terminate()
    s.fmu.reset()
    s.init(n_neurons=300, learning_rate=1e-4, learn_from_step=0)
    second = [s.step(k, u) for k, u in enumerate(seq)]
    assert np.array_equal(np.array(first), np.array(second)) and np.any(np.array(first)[:, PSI_X] != 0.0)
    s.close()


# ---- random call sequences ------------------------------------------------------------------------
class Fmi3Model(FmiModel):
    """FMI 3.0 co-simulation without event mode: no SetupExperiment (the start time goes with
    EnterInitializationMode); otherwise the same phases and rules."""

    def legal(self, op, *args):
        if op == "setup":
            return None  # not an FMI 3.0 call: not sent
        return super().legal(op, *args)


@pytest.fixture(scope="module", params=[2, 3])
def driver(request, native_fmus):
    fmi = request.param
    proc = subprocess.Popen([sys.executable, str(DRIVERS[fmi]), unzipped(native_fmus[fmi])], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
    yield fmi, proc
    proc.stdin.close()
    assert proc.wait(timeout=60) == 0, proc.stderr.read()[-2000:]


@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(sequence=st.lists(calls, min_size=1, max_size=25))
def test_random_call_sequences_never_crash_and_illegal_calls_are_refused(driver, sequence):
    fmi, proc = driver
    model = FmiModel() if fmi == 2 else Fmi3Model()
    for call in [("instantiate",)] + [_coerce(c) for c in sequence] + [("free",)]:
        legal = model.legal(*call)
        if legal is None:
            continue
        answer = _send(proc, call)
        if legal:
            assert answer["status"] == 0, f"FMI {fmi}: legal call {call} answered {answer} in phase {model.phase}"
            model.apply(*call)
        else:
            assert answer["status"] != 0, f"FMI {fmi}: illegal call {call} answered OK in phase {model.phase}"
    assert proc.poll() is None


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
def test_a_state_with_other_fixed_parameters_is_refused_until_they_match(native_fmus, fmi):
    """As the pythonfmu FMU: a state restores only into an instance with the state's n_neurons
    and seed (it used to bring its own along, silently changing the instance's networks)."""
    seq = input_sequence(20, seed=4)
    a = AnySlave(native_fmus[fmi], name="a").init(n_neurons=20, seed=0, learning_rate=1e-3)
    for k, u in enumerate(seq[:10]):
        a.step(k, u)
    blob = a.serialize(a.get_state())
    expected = np.array([a.step(k, u) for k, u in enumerate(seq[10:], start=10)])
    a.close()

    b = AnySlave(native_fmus[fmi], name="b").init(n_neurons=10, seed=5)
    with pytest.raises(FMICallException):
        b.set_state(b.deserialize(blob))
    b.step(0, seq[0])  # refused, nothing changed: b still steps from its own start
    b.close()

    c = AnySlave(native_fmus[fmi], name="c").init(n_neurons=20, seed=0)
    c.set_state(c.deserialize(blob))
    np.testing.assert_array_equal([c.step(k, u) for k, u in enumerate(seq[10:], start=10)], expected)
    c.close()
