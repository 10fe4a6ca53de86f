"""Every repository path, ``python -m scenarios`` subcommand and flag, FMU and campaign that
README.md and docs/ name exists: a renamed file, a dropped flag or a retired campaign fails
here, not in a user's terminal."""
import argparse
import re

import pytest

from scenarios.campaign.spec import builtin_campaigns
from scenarios.cli import build_parser
from support.paths import REPO_ROOT

PAGES = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]
IDS = [str(p.relative_to(REPO_ROOT)) for p in PAGES]
#: A repository path: starts at one of the clone's top-level entries.
PATH = re.compile(r"(?<![\w./-])((?:fmu_src|plant|scenarios|tests|benchmarks|docs|\.ci)/[\w./*<>-]*[\w/*>]"
                  r"|build\.py|pyproject\.toml|CHANGELOG\.md)")
#: What build.py writes (the FMUs and SSPs a page may name as products).
PRODUCT = re.compile(r"\b((?:AdaptiveVelocityRegulator|CassiePlant|CommandSource|CassieAVR)\w*\.(?:fmu|ssp))\b")
COMMAND = re.compile(r"python -m scenarios ([a-z-]+)([^`\n]*)")


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _text(page):
    # a path written with a placeholder (<scenario>, NAME, *) names a pattern, not a file
    return page.read_text()


@pytest.mark.parametrize("page", PAGES, ids=IDS)
def test_every_repository_path_exists(page):
    missing = []
    for m in PATH.finditer(_text(page)):
        path = m.group(1).rstrip("./")
        if any(c in path for c in "<>*{}") or path.startswith(("docs/data/suite.tmp",)):
            continue
        if not (REPO_ROOT / path).exists() and not list(REPO_ROOT.glob(path)):
            missing.append(path)
    assert missing == []


@pytest.mark.parametrize("page", PAGES, ids=IDS)
def test_every_subcommand_and_flag_exists(page):
    subs = _subparsers()
    problems = []
    for m in COMMAND.finditer(_text(page)):
        sub, rest = m.group(1), m.group(2)
        if sub not in subs:
            problems.append(f"python -m scenarios {sub}: no such subcommand")
            continue
        flags = {o for a in subs[sub]._actions for o in a.option_strings}
        problems += [f"python -m scenarios {sub} {f}: no such flag"
                     for f in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", rest.split("#")[0]) if f not in flags]
    assert problems == []


@pytest.mark.parametrize("page", PAGES, ids=IDS)
def test_every_campaign_named_in_a_command_exists(page):
    known = set(builtin_campaigns())
    named = re.findall(r"python -m scenarios campaign ([\w./-]+)", _text(page))
    assert [n for n in named if n not in known and not (REPO_ROOT / n).exists()
            and n not in ("FILE.toml", "my.toml", "NAME")] == []


def test_every_product_named_is_one_build_py_writes(built_all):
    made = {p.name for p in built_all.dist.rglob("*")}
    named = {m.group(1) for page in PAGES for m in PRODUCT.finditer(_text(page))}
    assert sorted(n for n in named if n not in made and "_container" not in n) == []


def test_the_checks_see_what_they_check():
    text = "`scenarios/no_such.py` and python -m scenarios run --no-such-flag"
    assert [m.group(1) for m in PATH.finditer(text)] == ["scenarios/no_such.py"]
    assert COMMAND.search(text).group(1) == "run"
    assert "--render" in {o for a in _subparsers()["run"]._actions for o in a.option_strings}
