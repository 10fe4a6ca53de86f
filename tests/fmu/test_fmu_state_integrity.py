"""FMU states the FMU must never take, and what happens after a fatal error.

Everything runs through ctypes against the real built guard library, in a process of its
own per case (tests/support/fmi/raw_host.py), so a crash is a failed test.  A refused state must
answer fmi2Error naming why (never fmi2OK, never fmi2Fatal) and leave the instance
unchanged and usable.
"""
import sys
from pathlib import Path

import pytest

from support.paths import SUPPORT_DIR

sys.path.insert(0, str(SUPPORT_DIR / "fmi"))
from raw_host import crc64  # noqa: E402 - the tests' own CRC-64, checked below

OK, ERROR, FATAL = 0, 3, 4


def test_the_tests_crc64_is_crc64_xz():
    assert crc64(b"123456789") == 0x995DC9BBDF1939FA  # the published check value of CRC-64/XZ


def _assert_all_refused(result):
    assert result["statuses"] == {str(ERROR): result["flips"]}, result  # never OK, never Fatal
    assert result["unchanged"] and result["same_future"], result
    assert result["restore_original"] == [OK, OK], result


def test_every_single_bit_flip_of_a_serialized_state_is_refused(fmu_dir, raw_host):
    """All 8 x ~2,000 one-bit corruptions of a real blob (10 neurons): the CRC-64 catches every one."""
    result = raw_host(fmu_dir, "bitflip", {"n_neurons": 10})
    assert result["flips"] == 8 * result["blob_bytes"] > 10_000
    _assert_all_refused(result)


def test_random_bit_flips_of_a_full_size_state_are_refused(fmu_dir, raw_host):
    """10,000 seeded random flips of a 1000-neuron state (~34 kB)."""
    result = raw_host(fmu_dir, "bitflip", {"n_neurons": 1000, "count": 10_000, "seed": 20240607})
    assert result["flips"] == 10_000 and result["blob_bytes"] > 30_000
    _assert_all_refused(result)


REASONS = {  # case -> what the fmi2Error message must say
    "Kp_x 0.1 -> 0.3 in the JSON": "checksum mismatch",
    "Kp_x 0.1 -> 0.3, checksum resealed": "FMU state checksum mismatch",  # the slave's own CRC-32
    "time NaN": "time is nan: must be finite",
    "time +inf": "time is inf: must be finite",
    "time -inf": "time is -inf: must be finite",
    "another FMU's GUID": "saved by another FMU or another build of this one",
    "format version 1": "format version 1; this FMU reads version 2",
    "truncated by one byte": "truncated or padded",
    "truncated to the header": "truncated: 64 bytes",
    "empty": "truncated: 0 bytes",
    "one byte appended": "truncated or padded",
    "zeros": "bad magic",
    "forged: Kp_x = 99": "Kp_x = 99.0: out of range [-5.0, 5.0]",
    "forged: Kp_x = NaN": "Kp_x = nan: must be a finite number",
    "forged: vx is text": "vx = 'fast': must be a finite number",
    "forged: no vx": "lacks vx",
    "forged: unknown phase": "header says phase stepComplete, its slave part does not",  # the guard sees it first
    "forged: JSON time inf": "its slave part inf s (header and contents must agree)",  # the guard sees it first
    "forged: JSON n_neurons 10, core 20": "state has n_neurons = 20, regulator has 10",
    "forged: core truncated": "state blob has",
    "forged: JSON a list": "header says phase stepComplete, its slave part does not",  # the guard sees it first
}


def test_corrupt_foreign_truncated_and_non_finite_states_are_refused_naming_why(fmu_dir, raw_host):
    r = raw_host(fmu_dir, "crafted_states")
    for case, reason in REASONS.items():
        assert r[case]["status"] == ERROR, (case, r[case])
        assert any(reason in m for m in r[case]["log"]), (case, r[case]["log"])
    assert r["unchanged"] and r["steps after"] == [OK] * 3


def test_a_state_with_other_fixed_parameters_is_refused_until_they_match(fmu_dir, raw_host):
    r = raw_host(fmu_dir, "foreign_state")
    for case in ("into instantiated n_neurons=10 seed=5", "into initialized n_neurons=10 seed=5",
                 "in-memory state into b"):
        status = r[case]["status"]
        assert status in (ERROR, [ERROR]), (case, r[case])
        message = " ".join(r[case]["log"])
        assert "n_neurons = 20 (this instance: 10)" in message and "seed = 0 (this instance: 5)" in message, message
        assert "Set them to the state's values before restoring it" in message, message
    assert r["b still steps"] == OK
    assert r["into matching instance"] == [OK, OK] and r["continues like the original"]


def inject_fault(fmu_dir) -> str:
    """Make the extracted FMU's slave raise in exit_initialization_mode: pythonfmu answers fmi2Fatal."""
    slave = Path(fmu_dir) / "resources" / "avr_regulator_lib" / "fmu_src" / "regulator_fmu" / "avr_slave.py"
    slave.write_text(slave.read_text() + "\n\ndef _injected_fault(self):\n"
                     "    raise RuntimeError('fault injected by the test')\n\n\n"
                     "AdaptiveVelocityRegulator.exit_initialization_mode = _injected_fault\n")
    return str(fmu_dir)


@pytest.fixture(scope="module")
def faulty_fmu_dir(tmp_path_factory, built_fmu, unzip):
    return inject_fault(unzip(built_fmu, tmp_path_factory.mktemp("faulty")))


def test_after_a_fatal_error_nothing_reaches_pythonfmu_and_free_is_safe(faulty_fmu_dir, raw_host):
    """pythonfmu frees the slave when Python raises and again in fmi2FreeInstance; the guard must
    not forward anything after a Fatal (five cycles, then the garbage collector runs)."""
    r = raw_host(faulty_fmu_dir, "fatal_cycles", {"cycles": 5})
    for cycle in r["cycles"]:
        assert cycle == {"exit": [OK, OK, FATAL], "doStep": FATAL, "set": FATAL, "reset": FATAL,
                         "free state": OK}, r
    assert any("the Python slave failed" in m for m in r["log"]), r["log"]
    assert any("only fmi2FreeInstance is allowed" in m for m in r["log"]), r["log"]
