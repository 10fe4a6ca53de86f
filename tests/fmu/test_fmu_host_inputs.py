"""What a host passes in that the FMU must survive: resource URIs, names, GUIDs, log
categories and strings, including NULL and non-UTF-8 bytes.

Every call goes through ctypes to the real built guard library in a process of its own
(tests/support/fmi/raw_host.py), so a crash is a failed test.  The legal URI forms of FMI 2.0
(file:///p, file:/p, file://localhost/p, percent-escapes) must instantiate a working
FMU; everything else must give NULL with a logged reason.
"""
import math
import urllib.parse
from pathlib import Path

import pytest

OK, ERROR = 0, 3


def _hex(text):
    return (text.encode("utf-8") if isinstance(text, str) else text).hex()


def _slave_module(fmu_dir) -> str:
    """The entry module pythonfmu imports (its name is private to the build)."""
    return (Path(fmu_dir) / "resources" / "slavemodule.txt").read_text().strip()


@pytest.fixture(scope="module")
def folders(tmp_path_factory, built_fmu, unzip):
    """Copies of the FMU at awkward paths, and folders that are not this FMU's resources."""
    base = tmp_path_factory.mktemp("uri")
    spaced = Path(unzip(built_fmu, base / "dir with space ü #1"))
    pct20 = Path(unzip(built_fmu, base / "x%20y"))
    other = base / "other_fmu_resources"
    other.mkdir()
    (other / "slavemodule.txt").write_text("other_slave\n")
    (other / "other_slave.py").write_text("")
    no_module = base / "no_module"
    no_module.mkdir()
    (no_module / "slavemodule.txt").write_text(_slave_module(spaced) + "\n")
    broken = Path(unzip(built_fmu, base / "broken"))  # this FMU, but its slave fails to import
    (broken / "resources" / f"{_slave_module(broken)}.py").write_text("raise RuntimeError('broken on purpose')\n")
    return {"spaced": spaced / "resources", "pct20": pct20 / "resources", "other": other, "no_module": no_module,
            "broken": broken / "resources"}


def _attempts(fmu_dir, folders):
    res = Path(fmu_dir) / "resources"
    escaped = "file://" + urllib.parse.quote(str(res)).replace("resources", "%72esources")
    legal = {
        "file:///abs": "default",
        "file:/abs": _hex(f"file:{res}"),
        "file://localhost/abs": _hex(f"file://localhost{res}"),
        "FILE:// upper-case scheme, trailing slash": _hex(f"FILE://{res}/"),
        "percent-escaped letters": _hex(escaped),
        "space, non-ASCII and # in the path (as fmpy encodes it)": _hex(folders["spaced"].as_uri()),
    }
    refused = {  # label -> (uri, a phrase the logged reason must contain)
        "empty": (_hex(""), "only file: URIs"),
        "garbage": (_hex(b"\x01garbage"), "only file: URIs"),
        "nonexistent path": (_hex("file:///nonexistent/avr/resources"), "not an existing folder"),
        "file:///etc": (_hex("file:///etc"), "not this FMU's resources folder"),
        "http URI": (_hex("http://example.com/avr/resources"), "only file: URIs"),
        "100 kB long": (_hex("file:///" + "a" * 100_000), "too long"),
        "relative path": (_hex("file:resources"), "must be absolute"),
        "remote host": (_hex(f"file://example.com{res}"), "remote host"),
        "query": (_hex(f"file://{res}?x=1"), "query or fragment"),
        "bad percent-escape": (_hex(f"file://{res}%zz"), "invalid percent-escape"),
        "escaped NUL": (_hex(f"file://{res}%00"), "escaped NUL (%00)"),
        "non-UTF-8 bytes": (_hex(b"file:///tmp/\xff\xfe"), "not valid UTF-8"),
        "escaped non-UTF-8": (_hex("file:///tmp/%FF"), "not valid UTF-8"),
        "NULL": (None, "is NULL"),
        "the FMU's root, not resources/": (_hex(Path(fmu_dir).as_uri()), "not this FMU's resources folder"),
        "another FMU's resources": (_hex(folders["other"].as_uri()), "another FMU's resources"),
        "resources without the slave module": (_hex(folders["no_module"].as_uri()), "lacks avr_slave_"),
        "a path pythonfmu would garble (%20 in a folder name)": (_hex(folders["pct20"].as_uri()), "%20"),
        "a slave that fails to import": (_hex(folders["broken"].as_uri()), "could not create the Python slave"),
    }
    names = {  # label -> (name, guid, reason)
        "instanceName NULL": (None, "default", "instanceName is NULL"),
        "instanceName empty": (_hex(""), "default", "instanceName is empty"),
        "instanceName non-UTF-8": (_hex(b"\xff\xfe"), "default", "instanceName is not valid UTF-8"),
        "instanceName overlong encoding": (_hex(b"a\xc0\xaf"), "default", "instanceName is not valid UTF-8"),
        "instanceName UTF-16 surrogate": (_hex(b"\xed\xa0\x80"), "default", "instanceName is not valid UTF-8"),
        "instanceName 1 MB": (_hex("n" * 1_000_000), "default", "instanceName is too long"),
        "GUID NULL": ("default", None, "fmuGUID is NULL"),
        "GUID non-UTF-8": ("default", _hex(b"{\xff}"), "fmuGUID is not valid UTF-8"),
        "GUID of another FMU": ("default", _hex("{00000000-0000-0000-0000-000000000000}"), "does not match"),
    }
    attempts = [[label, "default", "default", uri] for label, uri in legal.items()]
    attempts += [[label, "default", "default", uri] for label, (uri, _) in refused.items()]
    attempts += [[label, name, guid, "default"] for label, (name, guid, _) in names.items()]
    reasons = {label: reason for label, (_, reason) in refused.items()}
    reasons.update({label: reason for label, (_, _, reason) in names.items()})
    return legal, reasons, attempts


def test_instantiate_accepts_every_legal_uri_and_refuses_the_rest_with_a_reason(fmu_dir, folders, raw_host):
    legal, reasons, attempts = _attempts(fmu_dir, folders)
    results = raw_host(fmu_dir, "instantiate", attempts)
    outputs = []
    for label in legal:
        r = results[label]
        assert not r["null"], (label, r["log"])
        assert r["terminate"] == OK and all(math.isfinite(v) for v in r["outputs"]), label
        outputs.append(r["outputs"])
    assert all(o == outputs[0] for o in outputs)  # the same FMU, whichever way it was located
    for label, reason in reasons.items():
        r = results[label]
        assert r["null"], f"{label}: instantiated"
        assert any("fmi2Instantiate failed" in m and reason in m for m in r["log"]), (label, r["log"])
    assert results["null callbacks"]["null"]


def test_set_debug_logging_refuses_null_non_utf8_and_unknown_categories(fmu_dir, raw_host):
    r = raw_host(fmu_dir, "debug_logging")
    expected = {"[NULL]": (ERROR, "categories[0] is NULL"), "[logAll, NULL]": (ERROR, "categories[1] is NULL"),
                "non-UTF-8": (ERROR, "categories[0] is not valid UTF-8"),
                "unknown category": (ERROR, "not a log category of this FMU (known: logStatusWarning"),
                "categories NULL": (ERROR, "categories is NULL"), "declared categories": (OK, None),
                "none": (OK, None)}
    for label, (status, reason) in expected.items():
        assert r[label]["status"] == status, (label, r[label])
        assert reason is None or any(reason in m for m in r[label]["log"]), (label, r[label]["log"])
    assert all(math.isfinite(v) for v in r["still usable"])


def test_null_and_non_utf8_strings_and_null_arrays_are_refused(fmu_dir, raw_host):
    r = raw_host(fmu_dir, "strings")
    for label in ("NULL", "non-UTF-8", "text"):  # this FMU has no String variable at all
        assert r[label]["status"] == ERROR and any("is not of this type" in m for m in r[label]["log"]), r[label]
    assert r["NULL vr"] == ERROR and r["NULL values"] == ERROR
    assert all(math.isfinite(v) for v in r["still usable"])
