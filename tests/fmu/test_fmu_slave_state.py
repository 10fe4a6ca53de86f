"""The slave's FMU-state blob, in process (no FMU library): the slave's own line of defence.

pythonfmu turns any exception from ``_fmu_state_from_bytes`` into fmi2Fatal, so the slave
must never raise there: a blob it refuses comes back as ``REFUSED_STATE`` + the reason
(the guard reads that and answers fmi2Error).  Restoring a refused or mismatched blob
raises StateError without changing the instance.
"""
import json
import math
import struct
import zlib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fmu_src.fmi import avr_fmustate as fmustate
from fmu_src.core.avr_errors import StateError
from fmu_src.regulator_fmu.avr_slave import _ALL_SPECS, REFUSED_STATE, AdaptiveVelocityRegulator

H = 0.005


def _slave(instance_name="unit", **params):
    """The regulator slave, its parameters set, initialized."""
    s = AdaptiveVelocityRegulator(instance_name=instance_name)
    for name, value in params.items():
        s._set(name, value)
    s.setup_experiment(0.0)
    s.enter_initialization_mode()
    s.exit_initialization_mode()
    return s


@pytest.fixture(scope="module")
def learned():
    s = _slave(n_neurons=12, learn_from_step=0)
    for k in range(40):
        s._set("vx", 0.9)
        assert s.do_step(k * H, H)
    return s._get_fmu_state()


def test_blob_round_trips_and_carries_a_crc(learned):
    parts = fmustate.decode(learned, _ALL_SPECS)
    assert parts.phase == "stepComplete" and parts.time_s == pytest.approx(40 * H, rel=1e-12)  # 40 sums of h
    assert fmustate.encode(parts.values, parts.phase, parts.time_s, parts.core) == learned
    body, (crc,) = learned[:-4], struct.unpack("<I", learned[-4:])
    assert zlib.crc32(body) == crc
    assert AdaptiveVelocityRegulator._fmu_state_from_bytes(learned) == learned


@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_corrupted_blob_is_refused_as_data_never_by_raising(learned, data):
    """Random damage (bit flips, truncation, insertion): refused with a reason, nothing raised."""
    blob = bytearray(learned)
    kind = data.draw(st.sampled_from(["flip", "truncate", "insert"]))
    if kind == "flip":
        for bit in data.draw(st.lists(st.integers(0, 8 * len(blob) - 1), min_size=1, max_size=4, unique=True)):
            blob[bit // 8] ^= 1 << (bit % 8)
    elif kind == "truncate":
        blob = blob[:data.draw(st.integers(0, len(blob) - 1))]
    else:
        at = data.draw(st.integers(0, len(blob)))
        blob[at:at] = data.draw(st.binary(min_size=1, max_size=8))
    verdict = AdaptiveVelocityRegulator._fmu_state_from_bytes(bytes(blob))
    assert verdict.startswith(REFUSED_STATE) and len(verdict) > len(REFUSED_STATE)


@pytest.mark.parametrize("bad", [None, 3, "text", b"", REFUSED_STATE + b"why"])
def test_non_blobs_are_refused_as_data(bad):
    assert AdaptiveVelocityRegulator._fmu_state_from_bytes(bad).startswith(REFUSED_STATE)


def test_restoring_a_state_with_other_fixed_parameters_raises_and_changes_nothing(learned):
    other = _slave(n_neurons=10, seed=5)
    before = other._get_fmu_state()
    with pytest.raises(StateError, match=r"n_neurons = 12 \(this instance: 10\), seed = 0 \(this instance: 5\)"):
        other._set_fmu_state(learned)
    assert other._get_fmu_state() == before
    with pytest.raises(StateError, match="checksum mismatch"):
        other._set_fmu_state(before[:-1] + bytes([before[-1] ^ 1]))
    assert other._get_fmu_state() == before


def test_decode_names_every_problem_of_a_well_formed_but_invalid_table(learned):
    """A forged table (right layout and CRC, wrong values): every problem is named at once."""
    parts = fmustate.decode(learned, _ALL_SPECS)
    values = dict(parts.values, Kp_x=99.0, vx=math.inf, n_neurons=True)
    del values["seed"]
    text = json.dumps({"phase": "stepComplete", "time_s": 0.2, "values": values}).encode()
    body = fmustate.HEADER.pack(fmustate.MAGIC, fmustate.VERSION, len(text), len(parts.core)) + text + parts.core
    with pytest.raises(StateError) as exc:
        fmustate.decode(body + fmustate.CRC.pack(zlib.crc32(body)), _ALL_SPECS)
    message = str(exc.value)
    for expected in ("lacks seed", "Kp_x = 99.0: out of range [-5.0, 5.0]", "vx = inf: must be a finite number",
                     "n_neurons = True: must be an Integer"):
        assert expected in message, message


def test_a_format_2_blob_is_refused_naming_its_version(learned):
    """Format 2 blobs hold the retired error_deadzone_mps, weight_norm_max and overspeed_unlearn."""
    old = bytearray(learned)
    struct.pack_into("<I", old, 4, 2)
    old[-4:] = struct.pack("<I", zlib.crc32(bytes(old[:-4])))
    refused = AdaptiveVelocityRegulator._fmu_state_from_bytes(bytes(old))
    assert refused.startswith(REFUSED_STATE)
    assert b"state of format version 2: this FMU reads version 3" in refused


def test_a_ramp_limit_without_settled_steps_is_refused_at_initialization_and_while_stepping():
    """learn_ramp_max_mps2 > 0 requires learn_settled_steps > 0: the end of initialization is
    refused (logged as an error, the guard's fmi2Error; the slave stays in initialization mode),
    and while stepping the set that breaks it is refused."""
    s = AdaptiveVelocityRegulator(instance_name="rule")
    logged = []
    s.log = lambda message, status=None, *args, **kwargs: logged.append(message)
    s._set("learn_ramp_max_mps2", 0.25)
    s.setup_experiment(0.0)
    s.enter_initialization_mode()
    s.exit_initialization_mode()
    assert s._phase == "initializationMode" and s._params is None
    assert logged == ["fmi2ExitInitializationMode refused: learn_ramp_max_mps2 = 0.25 requires "
                      "learn_settled_steps > 0 (it is 0)"]
    s._set("learn_settled_steps", 3)
    s.exit_initialization_mode()
    assert s._phase == "stepComplete"
    logged.clear()
    s._set("learn_settled_steps", 0)  # logged, not raised (the guard answers fmi2Error); nothing changes
    assert logged == ["learn_ramp_max_mps2 = 0.25 requires learn_settled_steps > 0 (it is 0)"]
    assert s._values["learn_settled_steps"] == 3 and s._params.learn_settled_steps == 3
    s._set("learn_ramp_max_mps2", 0.0)  # in the other order both are legal
    s._set("learn_settled_steps", 0)
    assert s._params.learn_settled_steps == 0
