"""The default run's module order under ``pytest -n 2`` (``support.schedule``)."""
from types import SimpleNamespace

from support import schedule
from support.builds import BUILD_FIXTURE
from support.paths import REPO_ROOT


def _item(nodeid, reads_build=False):
    return SimpleNamespace(nodeid=nodeid, fixturenames=[BUILD_FIXTURE] if reads_build else [])


def test_modules_without_a_build_first_then_the_longest_first_each_module_together():
    items = ([_item("tests/a/test_short.py::t1"), _item("tests/ssp/test_ssp_repeat.py::t1", True)]
             + [_item(f"tests/a/test_many.py::t{k}") for k in range(30)]
             + [_item("tests/ssp/test_ssp.py::t1", True), _item("tests/a/test_short.py::t2"),
                _item("tests/plant/test_blas_independence.py::t1")])
    got = [i.nodeid for i in schedule.order(items)]
    assert got == (["tests/plant/test_blas_independence.py::t1"]  # listed in MODULE_SECONDS
                   + [f"tests/a/test_many.py::t{k}" for k in range(30)]  # unlisted: 30 x 0.1 s
                   + ["tests/a/test_short.py::t1", "tests/a/test_short.py::t2",  # 2 x 0.1 s
                      "tests/ssp/test_ssp.py::t1", "tests/ssp/test_ssp_repeat.py::t1"])  # reads the build: last


def test_every_listed_module_exists():
    """A renamed or deleted module must leave the table (its number would order nothing)."""
    missing = [m for m in schedule.MODULE_SECONDS if not (REPO_ROOT / "tests" / m).is_file()]
    assert not missing, missing
