"""Shared pytest set-up: the FMU under test and the tools beside the interpreter (the
offline Menagerie model beside the repository is the model loader's own default).

Tests never use the system temp folder directly: FMUs are built and extracted under
pytest's ``tmp_path``/``tmp_path_factory``, and tools are found beside the running
interpreter (``venv_tool``), never through ``PATH``. The FMUs build.py builds are built once
per test session, whatever the number of pytest-xdist workers (``support.builds``): from one
whole build when the session reads it anyway, else each alone; they are only read, and each
worker extracts its own copy.

``AVR_TEST_FMU=/path/to/AdaptiveVelocityRegulator.fmu`` makes the FMU tests use that FMU
instead of building one (the sanitizer run, tests/fmu/test_fmu_sanitize.py, points it at a
guard built with AddressSanitizer); the tests parametrized over every regulator FMU
(``regulator_fmu``) then run on that one only.
"""
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

# Test modules of one layer reuse another layer's tables (e.g. the native hosts run the FMU
# compliance calls), whatever subset pytest collects.
sys.path[:0] = [str(p) for p in sorted(Path(__file__).parent.iterdir())
                if p.is_dir() and p.name not in ("support", "third_party", "__pycache__")]

from support.native_support import REGULATOR_FMUS  # noqa: E402
from support.paths import SUPPORT_DIR  # noqa: E402
from support import builds, native_support, schedule, warm  # noqa: E402


@pytest.hookimpl(trylast=True)  # after -m has deselected
def pytest_collection_modifyitems(session, config, items):
    """The test modules that read no build first, the longest first (``support.schedule``)."""
    items[:] = schedule.order(items)


def pytest_sessionstart(session):
    native_support.UNZIP_ROOT["folder"] = session.config._tmp_path_factory.mktemp("unzipped")


def pytest_collection_finish(session):
    """One whole build for the session's FMUs when its tests read the whole build anyway,
    started now, while the first tests run (``support.builds``)."""
    if builds.use_whole_build(session.items) and not session.config.option.collectonly:
        builds.start_whole_build(session.config._tmp_path_factory)


def pytest_sessionfinish(session):
    builds.stop_whole_build()


@pytest.fixture(scope="session")
def build_module():
    """build.py as a module (the CLI's loader: `import build` would clash with PyPA's build)."""
    from scenarios.cosim.fmus import load_build_module

    return load_build_module()


@pytest.fixture(scope="session")
def built_fmu(tmp_path_factory, build_module):
    """The FMU exactly as build.py builds it, into a fresh temporary folder (once per session)."""
    given = os.environ.get("AVR_TEST_FMU")
    if given:
        return Path(given)
    return builds.regulator_fmu(tmp_path_factory, build_module)


def _unzip(fmu, dest) -> str:
    from fmpy import extract

    return str(extract(str(fmu), unzipdir=str(dest)))


@pytest.fixture(scope="session")
def unzip():
    """``unzip(fmu, dest)``: extract an FMU into ``dest`` (a folder under tmp_path; never fmpy's
    default, a fresh folder in the system temp folder that nobody removes)."""
    return _unzip


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory, built_fmu):
    """The built FMU, extracted once per session (a folder holding modelDescription.xml, binaries/, ...)."""
    return _unzip(built_fmu, tmp_path_factory.mktemp("fmu_unzipped"))


@dataclass(frozen=True)
class BuiltAll:
    """One full ``build.py`` run (``build_all``) into a fresh folder: ``dist`` and the paths it returned."""

    dist: Path
    built: tuple[Path, ...]


@pytest.fixture(scope="session")
def built_all(tmp_path_factory, build_module) -> BuiltAll:
    """``build_all`` once per session, shared by the tests that read a whole build (its XML
    documents, fmus.json, the cross-check tree); they only read it."""
    out, built = builds.whole_build(tmp_path_factory)
    return BuiltAll(out, tuple(built))


@pytest.fixture(scope="session")
def native_fmus(tmp_path_factory, build_module):
    """{2: path, 3: path}: both native FMUs exactly as build.py builds them."""
    return builds.by_version(tmp_path_factory, build_module, "native_fmus", build_module.build_native.fmu_name,
                             build_module.build_native_fmu)


@pytest.fixture(scope="session")
def native_plant_fmus(tmp_path_factory, build_module):
    """{2: path, 3: path}: both native CassiePlant FMUs exactly as build.py builds them."""
    from fmu_src.plant_fmu.native import build_native_plant

    return builds.by_version(tmp_path_factory, build_module, "native_plant_fmus", build_native_plant.fmu_name,
                             build_module.build_native_plant_fmu)


@pytest.fixture(scope="session")
def command_sources(tmp_path_factory, build_module):
    """{2: path, 3: path}: both CommandSource FMUs exactly as build.py builds them."""
    return builds.by_version(tmp_path_factory, build_module, "command_sources", build_module.command_source.fmu_name,
                             build_module.build_command_source)


@dataclass(frozen=True)
class RegulatorFmu:
    """One of the regulator FMUs build.py builds: ``implementation`` "python" (pythonfmu) or
    "native" (C), its FMI version, the .fmu and the folder it is extracted to."""

    implementation: str
    fmi: int
    path: Path
    dir: str

    def rebuild(self, build_module, out_dir) -> Path:
        """The same FMU built again into ``out_dir``."""
        if self.implementation == "python":
            return build_module.build_fmu(out_dir)
        return build_module.build_native_fmu(self.fmi, out_dir)


@pytest.fixture(scope="session", params=REGULATOR_FMUS)
def regulator_fmu(request, tmp_path_factory, build_module) -> RegulatorFmu:
    """Each regulator FMU in turn: the pythonfmu FMU (FMI 2.0) and the native FMI 2.0 and 3.0 FMUs.
    (``build_module``: the collection sees that it reads a build, whose fixtures it asks for by name.)"""
    implementation, version = request.param.split("-fmi")
    if implementation == "python":
        return RegulatorFmu("python", 2, request.getfixturevalue("built_fmu"), request.getfixturevalue("fmu_dir"))
    if os.environ.get("AVR_TEST_FMU"):
        pytest.skip("AVR_TEST_FMU names the one FMU this run tests")
    path = request.getfixturevalue("native_fmus")[int(version)]
    return RegulatorFmu("native", int(version), path, _unzip(path, tmp_path_factory.mktemp(request.param)))


@pytest.fixture(scope="session")
def venv_tool():
    """``venv_tool("fmutool")``: the path of a console script installed with the running interpreter."""
    def find(name: str) -> str:
        path = Path(sys.executable).parent / name
        assert path.is_file(), f"{name} is not installed beside {sys.executable}: pip install -e '.[test]'"
        return str(path)
    return find


RAW_HOST = SUPPORT_DIR / "fmi" / "raw_host.py"


@pytest.fixture(scope="session")
def raw_host():
    """``raw_host(fmu_dir, case, args)``: run a case of tests/support/fmi/raw_host.py (direct ctypes calls
    with hostile arguments) in a process of its own; the process must not die."""
    def run(fmu_dir, case, args=None, timeout=600):
        proc = warm.run(RAW_HOST, [fmu_dir, case], input=json.dumps(args), timeout=timeout)
        assert proc.returncode == 0, f"the host process died (exit {proc.returncode}) in {case}:\n{proc.stderr[-3000:]}"
        return json.loads(proc.stdout.strip().splitlines()[-1])
    return run
