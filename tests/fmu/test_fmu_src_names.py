"""No module or package in fmu_src/ shadows an installed one.

pythonfmu's builder puts the slave's folder, ``fmu_src/``, first on ``sys.path`` of the
process that builds the FMU (build.py, the CLI, the tests): a ``fmu_src/packaging/`` there
once hid PyPA's ``packaging`` from matplotlib in the same process.
"""
import importlib.machinery
import sysconfig
from pathlib import Path
from support.paths import REPO_ROOT

FMU_SRC = REPO_ROOT / "fmu_src"


def test_no_fmu_src_name_shadows_an_installed_module():
    names = {p.stem for p in FMU_SRC.glob("*.py")} | {p.name for p in FMU_SRC.iterdir() if (p / "__init__.py").is_file()}
    # where installed code lives: the standard library and site-packages (not sys.path, which also holds the
    # resources/ folders of pythonfmu FMUs loaded in this process, with their copies of fmu_src modules)
    paths = sysconfig.get_paths()
    installed = sorted({paths[k] for k in ("stdlib", "platstdlib", "purelib", "platlib")} |
                       {str(Path(paths[k]) / "lib-dynload") for k in ("stdlib", "platstdlib")})
    specs = {n: importlib.machinery.PathFinder.find_spec(n, installed) for n in names - {"__init__"}}
    # a spec without origin is a namespace package (a bare folder): not installed code
    shadowed = sorted(n for n, spec in specs.items() if spec is not None and spec.origin is not None)
    assert shadowed == [], f"fmu_src/ names that hide installed modules once fmu_src/ is on sys.path: {shadowed}"
