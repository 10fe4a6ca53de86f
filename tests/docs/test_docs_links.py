"""Every relative link in the README and the docs/ pages points to a file that exists, and a
link to a heading (`page.md#anchor`) to a heading that exists, with GitHub's anchor rule."""
import re
from pathlib import Path

import pytest
from support.paths import REPO_ROOT

PAGES = [REPO_ROOT / "README.md", REPO_ROOT / "scenarios" / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]
_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
_EXTERNAL = re.compile(r"^[a-z][a-z0-9+.-]*:", re.IGNORECASE)  # http:, https:, mailto:, ...


def _prose(text: str) -> list[str]:
    """The lines outside fenced code blocks, with inline code spans removed (links there are code)."""
    lines, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(re.sub(r"`[^`]*`", "", line))
    return lines


def links(page: Path) -> list[str]:
    """Every link target in the page's prose, in order."""
    return [m.group(1) for line in _prose(page.read_text(encoding="utf-8")) for m in _LINK.finditer(line)]


def _prose_with_code(text: str) -> list[str]:
    """The lines outside fenced code blocks, inline code kept (its text is part of a heading's anchor)."""
    lines, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
        elif not fenced:
            lines.append(line)
    return lines


def anchors(page: Path) -> set[str]:
    """GitHub's anchors for the page's headings: lower case, punctuation dropped, spaces as '-',
    a repeated heading numbered -1, -2, ..."""
    result, counts = set(), {}
    for line in _prose_with_code(page.read_text(encoding="utf-8")):
        m = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            slug = re.sub(r"[^\w\- ]", "", m.group(1).lower()).replace(" ", "-")
            n = counts.get(slug, 0)
            counts[slug] = n + 1
            result.add(slug if n == 0 else f"{slug}-{n}")
    return result


def broken_links(page: Path) -> list[str]:
    """Each relative link of the page whose file or heading does not exist, with why."""
    broken = []
    for target in links(page):
        if _EXTERNAL.match(target):
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(f"{target}: no file {file}")
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            broken.append(f"{target}: {file.name} has no heading with anchor #{anchor}")
    return broken


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO_ROOT)))
def test_every_relative_link_resolves(page):
    assert broken_links(page) == []


def test_a_broken_link_is_found(tmp_path):
    """The check itself: a missing file, a missing heading and a missing image are each reported;
    links inside code are not links."""
    (tmp_path / "other.md").write_text("# A heading: with `code`\n", encoding="utf-8")
    (tmp_path / "fig.png").write_bytes(b"png")
    page = tmp_path / "page.md"
    page.write_text("[ok](other.md#a-heading-with-code) ![ok](fig.png) [web](https://example.org/x)\n"
                    "[gone](missing.md) [bad anchor](other.md#nothing) ![gone](fig2.png)\n"
                    "`[in code](nowhere.md)`\n```\n[in a block](nowhere.md)\n```\n", encoding="utf-8")
    assert [b.split(":")[0] for b in broken_links(page)] == ["missing.md", "other.md#nothing", "fig2.png"]
    assert len(links(REPO_ROOT / "README.md")) >= 10  # the real pages are read too
