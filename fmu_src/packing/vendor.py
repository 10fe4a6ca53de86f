"""A pythonfmu FMU's Python code as one package: the project modules a slave needs, vendored
with their project imports made package-relative (:func:`vendor_modules`; :mod:`.pack` loads
the package under a private name), and the CassiePlant FMU's data and robot models with their
licenses."""
from __future__ import annotations

import ast
import logging
import shutil
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
#: The plant FMU's data files (repository paths); its package carries them.
PLANT_DATA = (Path("plant") / "data" / "gait_library.json",)
#: Packages whose absolute imports are rewritten to package-relative ones.
PROJECT_PACKAGES = ("plant", "fmu_src")
MODEL_LICENSES = REPO_ROOT / "plant" / "model_licenses"  # menagerie.txt, osu.txt (texts, not models)

log = logging.getLogger("avr_build")


def _project_import(node, depth: int) -> str | None:
    """The package-relative module an absolute ``from plant|fmu_src... import`` names, seen from
    a module ``depth`` packages below the FMU's package, else None."""
    if not isinstance(node, ast.ImportFrom) or node.level or not node.module:
        return None
    if node.module.partition(".")[0] not in PROJECT_PACKAGES:
        return None
    return "." * (depth + 1) + node.module


def _vendored_source(path: Path) -> tuple[str, list[Path]]:
    """The module's text with its project imports made package-relative, and the files it imports."""
    rel = path.relative_to(REPO_ROOT)
    lines = path.read_text().splitlines(keepends=True)
    needed = []
    for node in ast.walk(ast.parse("".join(lines))):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] in PROJECT_PACKAGES for a in node.names):
            raise RuntimeError(f"{rel}:{node.lineno}: use 'from  import' for project modules (vendoring)")
        target = _project_import(node, len(rel.parts) - 1)
        if target is None:
            continue
        line = lines[node.lineno - 1]
        if f"from {node.module} import" not in line:
            raise RuntimeError(f"{rel}:{node.lineno}: cannot rewrite the import of {node.module}")
        lines[node.lineno - 1] = line.replace(f"from {node.module} import", f"from {target} import", 1)
        module = REPO_ROOT.joinpath(*node.module.split("."))
        if module.with_suffix(".py").is_file():
            needed.append(module.with_suffix(".py"))
        else:  # a package: the modules imported from it by name
            needed += [module / f"{a.name}.py" for a in node.names if (module / f"{a.name}.py").is_file()]
    return "".join(lines), needed


def vendor_modules(lib: Path, roots) -> None:
    """Copy the modules ``roots`` (repository paths) and every project module they import with
    ``from plant|fmu_src... import`` to ``lib``, those imports made package-relative, and an
    ``__init__.py`` for ``lib`` and each project package in it."""
    todo, done = list(roots), set()
    while todo:
        path = todo.pop()
        if path in done:
            continue
        done.add(path)
        text, needed = _vendored_source(path)
        (lib / path.relative_to(REPO_ROOT)).parent.mkdir(parents=True, exist_ok=True)
        (lib / path.relative_to(REPO_ROOT)).write_text(text)
        todo.extend(needed)
    for package in sorted({p.parent for p in lib.rglob("*.py")} - {lib}):
        name = package.relative_to(lib).as_posix().replace("/", ".")
        (package / "__init__.py").write_text(f'"""The {name} modules this FMU needs."""\n')
    (lib / "__init__.py").write_text('"""This FMU\'s Python code, loaded under a private name by its entry module."""\n')


def copy_plant_data(lib: Path) -> None:
    """The plant's data files (``PLANT_DATA``) into the package folder ``lib``."""
    for data in PLANT_DATA:
        (lib / data).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(REPO_ROOT / data, lib / data)


def copy_models(models: Path) -> None:
    """Menagerie's agility_cassie (mujoco-menagerie / MENAGERIE_ROOT) and OSU's model, with licenses."""
    from plant import model

    menagerie = model.menagerie_xml_path().parent  # the loader's MENAGERIE_ROOT default
    shutil.copytree(menagerie, models / "menagerie" / menagerie.name)
    shutil.copyfile(MODEL_LICENSES / "menagerie.txt", models / "menagerie" / "LICENSE")
    osu = model.osu_model_path()
    if not osu.is_file():
        log.warning("OSU model not found at %s (set CASSIE_OSU_XML): the FMU's cassie_model='osu' will be refused", osu)
        return
    (models / "osu").mkdir(parents=True)
    shutil.copyfile(osu, models / "osu" / "cassie.xml")
    shutil.copytree(osu.parent / "cassie-stl-meshes", models / "osu" / "cassie-stl-meshes")
    shutil.copyfile(MODEL_LICENSES / "osu.txt", models / "osu" / "LICENSE")
