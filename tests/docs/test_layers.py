"""The layers of docs/architecture.md, held against the code: every project import (Python
``import``/``from``, C ``#include``) goes to the same layer or one below, and no module reaches
itself again through its imports."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from support.paths import REPO_ROOT

#: docs/architecture.md's rows, top first: each import must go to its own row or one below.
LAYERS = (
    ("entry points", ("build.py", "benchmarks", "scenarios/cli.py", "scenarios/report.py", "scenarios/docs.py", "scenarios/__main__.py")),
    ("experiments", ("scenarios/run", "scenarios/campaign", "scenarios/ssp", "scenarios/gaits", "scenarios/rl_hzd")),
    ("results", ("scenarios/results",)),
    ("co-simulation", ("scenarios/cosim", "scenarios/rl_hzd/policy.py")),
    ("scenario files", ("scenarios/lang", "scenarios/errors.py", "scenarios/__init__.py")),
    ("FMUs", ("fmu_src/regulator_fmu", "fmu_src/plant_fmu", "fmu_src/command_source", "fmu_src/packing")),
    ("FMI layer", ("fmu_src/fmi",)),
    ("models", ("plant", "fmu_src/core", "fmu_src/__init__.py")),
)
#: A native model's hooks: the shared FMI layer's C includes "fmi_model.h", which each native
#: FMU's build takes from that FMU's own folder (as the Reference-FMUs' config.h): the model
#: fills in the layer, the layer names no model.
MODEL_HOOK = "fmi_model.h"
#: Folders of one row that must not import each other.
APART = (("plant", "fmu_src/core"),)
PACKAGES = ("fmu_src", "plant", "scenarios")


def layer_of(rel: str) -> int | None:
    best = None
    for i, (_, places) in enumerate(LAYERS):
        for place in places:
            if rel == place or rel.startswith(place + "/"):
                if best is None or len(place) > best[1]:
                    best = (i, len(place))
    return None if best is None else best[0]


def python_files():
    for top in (*PACKAGES, "benchmarks"):
        yield from (p for p in (REPO_ROOT / top).rglob("*.py") if "__pycache__" not in p.parts)
    yield REPO_ROOT / "build.py"


def module_file(module: str) -> Path | None:
    path = REPO_ROOT.joinpath(*module.split("."))
    for candidate in (path.with_suffix(".py"), path / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def python_imports(path: Path) -> set[Path]:
    """The project files ``path`` imports (a package's ``__init__`` for ``from pkg import``
    names that are not modules)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
        for name in names:
            if name.split(".")[0] in PACKAGES and (target := module_file(name)) is not None:
                if target.name != "__init__.py" or name == getattr(node, "module", None):
                    found.add(target)
    return {f for f in found if f != path}


def c_imports(path: Path) -> set[Path]:
    found = set()
    for name in re.findall(r'^\s*#\s*include\s+"([^"]+)"', path.read_text(encoding="utf-8", errors="replace"), re.M):
        matches = [p for p in (REPO_ROOT / "fmu_src").rglob(name) if "third_party" not in p.parts]
        local = path.parent / name
        if name == MODEL_HOOK and not local.is_file():
            continue
        found.update([local] if local.is_file() else matches)
    return {f for f in found if f != path}


def graph() -> dict[Path, set[Path]]:
    edges = {p: python_imports(p) for p in python_files()}
    for p in (REPO_ROOT / "fmu_src").rglob("*.[ch]"):
        if "third_party" not in p.parts:
            edges[p] = c_imports(p)
    return edges


def rel(p: Path) -> str:
    return p.relative_to(REPO_ROOT).as_posix()


def test_every_file_has_a_layer():
    assert [rel(p) for p in graph() if layer_of(rel(p)) is None] == []


def test_imports_go_down_or_stay_in_their_row():
    upward = [f"{rel(a)} ({LAYERS[layer_of(rel(a))][0]}) imports {rel(b)} ({LAYERS[layer_of(rel(b))][0]})"
              for a, targets in graph().items() for b in targets
              if layer_of(rel(b)) is not None and layer_of(rel(b)) < layer_of(rel(a))]
    assert upward == []


@pytest.mark.parametrize("first, second", APART)
def test_folders_kept_apart_do_not_import_each_other(first, second):
    crossing = [f"{rel(a)} imports {rel(b)}" for a, targets in graph().items() for b in targets
                for x, y in ((first, second), (second, first))
                if rel(a).startswith(x + "/") and rel(b).startswith(y + "/")]
    assert crossing == []


def test_no_import_circle():
    edges = graph()
    state, stack, circles = {}, [], []

    def visit(node):  # depth-first search; a grey node met again closes a circle
        state[node] = "grey"
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == "grey":
                circles.append(" -> ".join(rel(p) for p in stack[stack.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = "black"

    for node in sorted(edges):
        if node not in state:
            visit(node)
    assert circles == []
