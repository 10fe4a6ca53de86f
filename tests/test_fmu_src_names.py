"""No module or package in fmu_src/ shadows an installed one.

pythonfmu's builder puts the slave's folder, ``fmu_src/``, first on ``sys.path`` of the
process that builds the FMU (build.py, the CLI, the tests): a ``fmu_src/packaging/`` there
once hid PyPA's ``packaging`` from matplotlib in the same process.
"""
import importlib.machinery
import sys
from pathlib import Path

FMU_SRC = Path(__file__).resolve().parents[1] / "fmu_src"


def test_no_fmu_src_name_shadows_an_installed_module():
    names = {p.stem for p in FMU_SRC.glob("*.py")} | {p.name for p in FMU_SRC.iterdir() if (p / "__init__.py").is_file()}
    elsewhere = [p for p in sys.path if Path(p or ".").resolve() not in (FMU_SRC, FMU_SRC.parent)]
    specs = {n: importlib.machinery.PathFinder.find_spec(n, elsewhere) for n in names - {"__init__"}}
    # a spec without origin is a namespace package (a bare folder such as tests/native/): not installed code
    shadowed = sorted(n for n, spec in specs.items() if spec is not None and spec.origin is not None)
    assert shadowed == [], f"fmu_src/ names that hide installed modules once fmu_src/ is on sys.path: {shadowed}"
