"""Forged FMU states: every checksum right, the contents no run of the FMU can reach.

A restored state is checked for meaning, not only for integrity, on all four FMUs:

* the pythonfmu FMUs (regulator and plant): the guard's header and the slave's blob must
  agree on the FMI phase and the time, and the slave's JSON must be in the one form it
  writes (a repeated key is refused: ``json.loads`` keeps the last one, the guard reads the
  first);
* the plant: the walker's physics (finite, within MuJoCo's bound, unit quaternions), the
  controller's memory (finite numbers, a known mode and stance, ordered step times) and
  the command and offsets within the FMU's input ranges;
* the regulator's counters (n_calls, stride_calls, last_step_index, time_s) within what a
  run can reach, in the numpy core's blob and in the native blob (there a counter at
  INT64_MAX made the next doStep a signed overflow; the sanitizer run replays these with
  UBSan: tests/support/native/sanitize_run.py takes tests/support/native/test_native_state.py's corruptions).

Each answers fmi2Error naming the field (never OK then Fatal); the instance is unchanged
and goes on.
"""
import struct
import zlib

import pytest
from fmpy.fmi1 import FMICallException

from fmu_src.fmi import avr_fmustate as fmustate
from fmu_src.core.avr_regulator import MAX_CALLS
from fmu_src.regulator_fmu.avr_slave import _ALL_SPECS, REFUSED_STATE, AdaptiveVelocityRegulator
from test_fmu_slave_state import _slave as initialized_slave
from support.native_support import input_sequence, logged_slave
from support.plant_fmu_support import built_plant_fmu

OK, ERROR = 0, 3
INT64_MAX = 2**63 - 1


@pytest.fixture(scope="module")
def plant_fmu_dir(tmp_path_factory, build_module, unzip):
    return unzip(built_plant_fmu(tmp_path_factory, build_module), tmp_path_factory.mktemp("plant_unzipped"))


AGREEMENT_REASONS = {
    "header initializationMode, slave instantiated": "header says phase initializationMode, its slave part does not",
    "header stepComplete, slave instantiated": "header says phase stepComplete, its slave part does not",
    "header instantiated, slave stepComplete": "header says phase instantiated, its slave part does not",
    "header time 5 s, slave 0.005 s": "header says time 5 s, its slave part 0.005 s",
    "header time 0.005 s, slave 7 s": "header says time 0.005 s, its slave part 7 s",
    "slave JSON repeats time_s": "not in the form this FMU writes",
}


@pytest.mark.parametrize("which", ["regulator", "plant"])
def test_header_and_slave_blob_must_agree(which, fmu_dir, plant_fmu_dir, raw_host):
    r = raw_host(fmu_dir if which == "regulator" else plant_fmu_dir, "forged_agreement")
    for case, reason in AGREEMENT_REASONS.items():
        assert r[case]["status"] == ERROR, (case, r[case])
        assert any(reason in m for m in r[case]["log"]), (case, r[case]["log"])
    assert r["unchanged"] and r["own states restore"] == [[OK, OK], [OK, OK]] and r["steps after"] == [OK, OK], r


WALKER_REASONS = {
    "walker vx_des = NaN": "walker vx_des = nan: must be a finite number",
    "controller mode = 'garbage'": "controller mode = 'garbage': must be one of 'stand', 'shift', 'walk'",
    "controller stance = 'up'": "controller stance = 'up': must be one of 'left', 'right'",
    "controller offsets NaN": "controller offsets['delta_swing_knee'] = nan: must be a finite number",
    "pelvis quaternion zero": "has norm 0.0: must be 1",
    "pelvis z = 1e300": "physics qpos[2] = 1e+300: must be finite, in [-1e+10, 1e+10]",
    "commanded vx 5 m/s (input range [-3, 3])": "controller vx_des = 5.0: out of range [-3, 3]",
    "controller step times after the physics time": "must satisfy 0 <= t_step_start <= _last_t <= the simulated time",
}


def test_plant_refuses_walker_memory_no_run_reaches(plant_fmu_dir, raw_host):
    r = raw_host(plant_fmu_dir, "forged_walker")
    for case, reason in WALKER_REASONS.items():
        status = r[case]["status"]
        # the plant's slave checks a walker state when it is set (it needs the model): deserialization
        # may pass, fmi2SetFMUstate must then answer Error
        assert status in (ERROR, [OK, ERROR]), (case, r[case])
        assert any(reason in m for m in r[case]["log"]), (case, r[case]["log"])
    assert r["unchanged"] and r["steps after"] == [OK, OK], r


# ---- the regulator's counters -----------------------------------------------------------------
#: The core blob's header (fmu_src/core/avr_statebytes.py): the byte offsets of the counters.
_CORE_HEADER = struct.Struct("<8sHHII3dqq5dqq6d")
_LAST, _N_CALLS, _TIME_S, _BOUNDARIES, _STRIDE_CALLS = 44, 52, 92, 100, 108


def _slave(**params):
    return initialized_slave("forged", **params)


def _with_core_field(blob: bytes, offset: int, fmt: str, value) -> bytes:
    """The slave blob with one field of its core changed, both CRC-32s right again."""
    parts = fmustate.decode(blob, _ALL_SPECS)
    core = bytearray(parts.core[:-4])
    struct.pack_into(fmt, core, offset, value)
    core = bytes(core) + struct.pack("<I", zlib.crc32(bytes(core)))
    return fmustate.encode(parts.values, parts.phase, parts.time_s, core)


def test_core_blob_offsets_are_a_real_states():
    s = _slave(n_neurons=12)
    for k in range(7):
        s._set("step_index", k // 3)
        assert s.do_step(k * 0.005, 0.005)
    core, state = fmustate.decode(s._get_fmu_state(), _ALL_SPECS).core, s._state
    assert _CORE_HEADER.unpack_from(core)[8:11] == (state.last_step_index, state.n_calls, state.vx_at_step)
    for offset, fmt, value in ((_LAST, "<q", 2), (_N_CALLS, "<q", 7), (_TIME_S, "<d", state.time_s),
                               (_BOUNDARIES, "<q", 3), (_STRIDE_CALLS, "<q", 1)):
        assert struct.unpack_from(fmt, core, offset)[0] == value


CORE_FORGERIES = {
    "n_calls = INT64_MAX": (_N_CALLS, "<q", INT64_MAX, f"n_calls = {INT64_MAX}: must be in [0, {MAX_CALLS}]"),
    "n_calls = MAX_CALLS + 1": (_N_CALLS, "<q", MAX_CALLS + 1, "n_calls = 9007199254740993: must be in"),
    "stride_calls = INT64_MAX": (_STRIDE_CALLS, "<q", INT64_MAX, "stride_calls = 9223372036854775807: must be in [0, n_calls = 40]"),
    "last_step_index beyond step_index's range": (_LAST, "<q", 2**31, "last_step_index = 2147483648: must be in [-1, 2147483647]"),
    "last_step_index -1 after calls": (_LAST, "<q", -1, "last_step_index = -1 with n_calls = 40"),
    "time_s negative": (_TIME_S, "<d", -1.0, "time_s = -1.0 with n_calls = 40"),
}


@pytest.mark.parametrize("case", CORE_FORGERIES)
def test_pythonfmu_regulator_refuses_counters_no_run_reaches(case):
    s = _slave(n_neurons=12, learn_from_step=0)
    for k in range(40):
        s._set("vx", 0.9)
        s._set("step_index", 1 + k // 30)
        assert s.do_step(k * 0.005, 0.005)
    blob = s._get_fmu_state()
    offset, fmt, value, reason = CORE_FORGERIES[case]
    verdict = AdaptiveVelocityRegulator._fmu_state_from_bytes(_with_core_field(blob, offset, fmt, value))
    assert verdict.startswith(REFUSED_STATE) and reason in verdict.decode(), verdict


def test_counters_stop_at_max_calls_instead_of_overflowing():
    """A state at the bound (reachable in principle) steps on: the counters stay at MAX_CALLS and the
    next state is accepted (the int64 fields never overflow)."""
    s = _slave(n_neurons=12)
    s.do_step(0.0, 0.005)
    blob = _with_core_field(_with_core_field(s._get_fmu_state(), _N_CALLS, "<q", MAX_CALLS), _STRIDE_CALLS, "<q",
                            MAX_CALLS)
    s._set_fmu_state(blob)
    assert s.do_step(0.005, 0.005)
    assert (s._state.n_calls, s._state.stride_calls) == (MAX_CALLS, MAX_CALLS)
    assert AdaptiveVelocityRegulator._fmu_state_from_bytes(s._get_fmu_state()) == s._get_fmu_state()


NATIVE_COUNTERS = {  # offset in the native blob (fmu_src/regulator_fmu/native/avr_state.c), value, reason
    "n_calls = INT64_MAX": (96, INT64_MAX, f"n_calls = {INT64_MAX}: must be in [0, {MAX_CALLS}]"),
    "stride_calls = INT64_MAX": (152, INT64_MAX, "stride_calls = 9223372036854775807"),
    "last_step_index -1 after calls": (88, -1, "last_step_index = -1 with n_calls = 10"),
}


@pytest.mark.parametrize("fmi", [2, 3])
def test_native_regulator_refuses_counters_no_run_reaches(native_fmus, fmi):
    messages = []
    s = logged_slave(native_fmus[fmi], messages).init(n_neurons=30)
    for k, u in enumerate(input_sequence(10, seed=3)):
        s.step(k, u)
    blob = s.serialize(s.get_state())
    for case, (offset, value, reason) in NATIVE_COUNTERS.items():
        body = bytearray(blob)
        struct.pack_into("<q", body, offset, value)
        forged = bytes(body[:-4]) + struct.pack("<I", zlib.crc32(bytes(body[:-4])))
        del messages[:]
        with pytest.raises(FMICallException) as info:
            s.deserialize(forged)
        assert info.value.status == ERROR, case
        assert any(reason in m for m in messages), (case, messages)
    assert s.serialize(s.get_state()) == blob
    s.close()
