"""Every code example in README.md and docs/ runs as written (Sybil parses the pages).

- ``python`` blocks run in order in one namespace per page (in this process);
- ``bash`` blocks run with ``bash -euo pipefail``, ``python`` being this interpreter;
- ``toml`` blocks are validated: a whole file (it has ``name``) as a scenario or, in
  docs/campaigns.md, as a campaign; a fragment merged into the ``nominal`` suite scenario;
- ``text`` blocks are pictures, formulas and printed output, never run; a fence without a
  language is refused, so nothing is left out by accident.

A long example runs shortened where the page marks it, right above the block, with
``<!-- docs-test: "OLD" -> "NEW" -->`` (the text OLD of the block replaced by NEW) and says so in
its own text.

Each page's examples run from a fresh working folder laid out like the clone: its code folders
link to one copy of the clone's code made for the session (the code finds ``dist/`` and
``build/`` beside itself, and a link into the clone would resolve to the clone's), ``dist/`` is
the session's own ``build.py`` run. So what they write (``runs/``, plots, exported files, an
FMU built on demand) lands under pytest's temporary folders, never in the clone. A block the tests do not
run carries ``<!-- skip: next "why" -->`` and says why in the page's own text.
"""
import os
import re
import shutil
import subprocess
import sys
import tomllib
import unittest
from pathlib import Path

import pytest
from sybil import Sybil
from sybil.parsers.markdown import CodeBlockParser, SkipParser

from support.paths import MODEL_ENV, REPO_ROOT
from support.shared import made_once

PAGES = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]
#: Fence languages that are shown, not run.
SHOWN = ("text", "xml", "csv", "c")
#: What a page's working folder takes from the clone (through the session's copy of it).
LINKED = ("build.py", "benchmarks", "fmu_src", "plant", "scenarios", "tests", "pyproject.toml")
#: What the copy leaves out of the clone (besides dot-folders and *.egg-info): what builds and
#: runs write, and caches.
NOT_COPIED = ("dist", "build", "runs", "__pycache__", "dist-asan")
#: A bash block's time limit, s: the slowest documented example (a short campaign on a local
#: Dask cluster) takes about a minute on the 2-core CI machine when nothing else runs.
BASH_TIMEOUT_S = 600


def _env() -> dict[str, str]:
    """This environment with this interpreter first on PATH and the models as absolute paths (the
    code copy is not beside the clone's ``shared/``)."""
    env = {**os.environ, **MODEL_ENV}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '/usr/bin:/bin')}"
    return env


SHORTEN = re.compile(r'<!-- docs-test: "(.+?)" -> "(.+?)" -->\n')


def source(example) -> str:
    """The block's text, with the page's ``docs-test`` replacement just above it applied."""
    text = example.document.text[:example.region.start]
    marks = list(SHORTEN.finditer(text))
    code = example.parsed
    if marks and marks[-1].end() == len(text.rstrip("\n")) + 1:
        old, new = marks[-1].groups()
        assert old in code, f"{example.path}:{example.line}: docs-test mark {old!r} not in the block"
        code = code.replace(old, new)
    return code


def run_python(example):
    exec(compile(source(example), f"{example.path}:{example.line}", "exec"), example.namespace)


def run_bash(example):
    proc = subprocess.run(["bash", "-euo", "pipefail", "-c", source(example)], cwd=os.getcwd(), env=_env(),
                          capture_output=True, text=True, timeout=BASH_TIMEOUT_S)
    if proc.returncode != 0:
        return (f"{example.path}:{example.line}: exit {proc.returncode}\n--- stdout\n{proc.stdout[-3000:]}"
                f"\n--- stderr\n{proc.stderr[-3000:]}")
    return None


def check_toml(example):
    from scenarios.campaign.spec import parse_campaign
    from scenarios.lang.spec import parse_scenario, suite_files

    doc = tomllib.loads(source(example))
    base_dir = Path(os.getcwd())
    if Path(example.path).name == "campaigns.md":
        parse_campaign(doc, f"{example.path}:{example.line}", base_dir=base_dir)
    elif "name" in doc:
        parse_scenario(doc, f"{example.path}:{example.line}", base_dir=base_dir)
    else:
        nominal = tomllib.loads(next(p for p in suite_files() if p.stem == "nominal").read_text())
        if "command_profile" in doc:  # the alternative to [[command]]
            nominal.pop("command")
        parse_scenario({**nominal, **doc}, f"{example.path}:{example.line}", base_dir=base_dir)
    return None


def untyped_fences(text: str) -> list[int]:
    """The lines of opening fences that name no language."""
    lines, inside = [], False
    for number, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            if not inside and not line.lstrip()[3:].strip():
                lines.append(number)
            inside = not inside
    return lines


SYBIL = Sybil(parsers=[
    CodeBlockParser("python", evaluator=run_python),
    CodeBlockParser("bash", evaluator=run_bash),
    CodeBlockParser("toml", evaluator=check_toml),
    *(CodeBlockParser(lang, evaluator=lambda example: None) for lang in SHOWN),
    SkipParser(),
])


def _copy_code(folder: Path, dist: Path) -> Path:
    """The clone's code in ``folder`` (copies: the code finds its ``dist/`` and ``build/`` beside
    its resolved path), ``dist`` linked as its ``dist/``, its ``build/`` seeded with the C
    controller the clone's code builds (the same sources, so the same cache key)."""
    from plant.native.native_ctrl import cached_library_path
    from plant.sim import NATIVE_CACHE

    for source in REPO_ROOT.iterdir():
        if source.name.startswith(".") or source.name in NOT_COPIED or source.name.endswith(".egg-info"):
            continue
        if source.is_dir():
            shutil.copytree(source, folder / source.name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(source, folder / source.name)
    (folder / "dist").symlink_to(dist)
    library = cached_library_path(NATIVE_CACHE).parent
    shutil.copytree(library, folder / "build" / "native_ctrl" / library.name)
    return folder


def _workdir(tmp_path: Path, code: Path) -> Path:
    for name in (*LINKED, "dist"):
        (tmp_path / name).symlink_to(code / name)
    return tmp_path


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(REPO_ROOT)) for p in PAGES])
def test_every_example_runs_as_written(page, tmp_path, tmp_path_factory, built_all, monkeypatch):
    assert untyped_fences(page.read_text()) == [], "fences without a language (```text for output and pictures)"
    code = made_once(tmp_path_factory, "docs_code", lambda folder: _copy_code(folder, built_all.dist))
    monkeypatch.chdir(_workdir(tmp_path, code))
    for name, value in MODEL_ENV.items():
        monkeypatch.setenv(name, value)
    before = _visible(REPO_ROOT)
    document = SYBIL.parse(page)
    ran, skipped = 0, []
    for example in document:
        try:
            example.evaluate()
        except unittest.SkipTest as skip:
            assert str(skip).strip(), f"{page.name}:{example.line}: a skipped block must say why"
            skipped.append(example.line)
            continue
        ran += 1
    assert not (_visible(REPO_ROOT) - before), "an example wrote into the clone"


def _visible(folder):
    """A folder's entries without the caches that tests running beside this one may create and
    that are not an example's doing: dot-folders (.hypothesis, .pytest_cache) and Python's
    bytecode cache (``__pycache__/build.*.pyc``, written when a test first loads build.py)."""
    return {name for name in os.listdir(folder) if not name.startswith(".") and name != "__pycache__"}



def test_fences_without_a_language_are_found():
    assert untyped_fences("text\n\n```\npython -m scenarios list\n```\n\n```bash\nls\n```\n") == [3]


def test_a_failing_shell_example_fails_the_page(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    page = tmp_path / "page.md"
    page.write_text("```bash\npython -m scenarios run no_such_scenario --out runs\n```\n")
    with pytest.raises(Exception, match="exit 2"):
        for example in SYBIL.parse(page):
            example.evaluate()


def test_a_docs_test_mark_shortens_only_the_block_below_it(tmp_path):
    page = tmp_path / "page.md"
    page.write_text('<!-- docs-test: "6000" -> "40" -->\n```python\nSTEPS = 6000\n```\n\n```python\nOTHER = 6000\n```\n')
    examples = list(SYBIL.parse(page))
    assert [source(e) for e in examples] == ["STEPS = 40\n", "OTHER = 6000\n"]
