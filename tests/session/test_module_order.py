"""The order in which the test session hands its modules to the workers (``support.builds``)."""
import json
from types import SimpleNamespace

from support import builds


def _item(nodeid, reads=False):
    return SimpleNamespace(nodeid=nodeid, fixturenames=(builds.BUILD_FIXTURE,) if reads else ("tmp_path",))


def test_modules_without_a_build_first_then_the_longest_first(tmp_path, monkeypatch):
    monkeypatch.setattr(builds, "MODULE_SECONDS", tmp_path / "module_seconds.json")
    builds.MODULE_SECONDS.write_text(json.dumps({"tests/a.py": 1.0, "tests/b.py": 30.0, "tests/c.py": 5.0,
                                                 "tests/d.py": 2.0, "tests/e.py": 9.0}))
    items = [_item("tests/a.py::one", True), _item("tests/a.py::two", True), _item("tests/b.py::one", True),
             _item("tests/c.py::one"), _item("tests/d.py::one"), _item("tests/e.py::one", True),
             _item("tests/new.py::one", True), _item("tests/c.py::two")]
    order = [i.nodeid for i in builds.builds_last(items)]
    # c and d read no build: first, the longer first; then the unlisted module (as the longest), b, e, a
    assert order == ["tests/c.py::one", "tests/c.py::two", "tests/d.py::one", "tests/new.py::one",
                     "tests/b.py::one", "tests/e.py::one", "tests/a.py::one", "tests/a.py::two"]


def test_without_the_file_the_modules_with_more_tests_first(tmp_path, monkeypatch):
    monkeypatch.setattr(builds, "MODULE_SECONDS", tmp_path / "missing.json")
    items = [_item("tests/a.py::one", True), _item("tests/b.py::one", True), _item("tests/b.py::two", True),
             _item("tests/c.py::one")]
    assert [i.nodeid for i in builds.builds_last(items)] == ["tests/c.py::one", "tests/b.py::one", "tests/b.py::two",
                                                             "tests/a.py::one"]


def test_the_reports_times_are_summed_per_module_and_written(tmp_path, monkeypatch):
    monkeypatch.setattr(builds, "MODULE_SECONDS", tmp_path / "module_seconds.json")
    monkeypatch.setattr(builds, "_TIMES", {})
    for nodeid, seconds in (("tests/b.py::one", 0.3), ("tests/b.py::one", 2.0), ("tests/a.py::x[1]", 1.04)):
        builds.add_report(nodeid, seconds)
    builds.write_module_seconds()
    assert json.loads(builds.MODULE_SECONDS.read_text()) == {"tests/a.py": 1.0, "tests/b.py": 2.3}
