"""``docs/method.md`` (the one description of the method) as HTML for the FMUs' documentation
pages, so the page and the document never drift.

A deliberately small Markdown subset, the one ``docs/method.md`` uses: ``#``/``##`` headings
(rendered one level down, under the page's own ``<h1>``), paragraphs, ``- `` lists (continuation
lines indented), fenced code blocks and inline ``code``.  Anything else is kept as text.
"""
from __future__ import annotations

import html
import re
from pathlib import Path

METHOD_MD = Path(__file__).resolve().parents[2] / "docs" / "method.md"
FENCE = "```"
_INLINE_CODE = re.compile(r"`([^`]+)`")


def _inline(text: str) -> str:
    """Escaped text with `code` spans as <code>."""
    parts = _INLINE_CODE.split(text)
    return "".join(f"<code>{html.escape(p)}</code>" if i % 2 else html.escape(p) for i, p in enumerate(parts))


def _blocks(lines: list[str]):
    """(kind, lines) blocks: "heading1"/"heading2", "code", "list" (one entry per item), "paragraph"."""
    i = 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            i += 1
        elif line.startswith(FENCE):
            end = lines.index(FENCE, i + 1)
            yield "code", lines[i + 1:end]
            i = end + 1
        elif line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            yield f"heading{level}", [line[level:].strip()]
            i += 1
        else:
            block = []
            while i < len(lines) and lines[i].strip() and not lines[i].startswith((FENCE, "#")):
                block.append(lines[i])
                i += 1
            if block[0].startswith("- "):
                items = []
                for item_line in block:
                    if item_line.startswith("- "):
                        items.append(item_line[2:].strip())
                    else:
                        items[-1] += " " + item_line.strip()
                yield "list", items
            else:
                yield "paragraph", [" ".join(part.strip() for part in block)]


def render(markdown: str) -> str:
    """The HTML of ``markdown`` (the subset above), headings one level down."""
    out = []
    for kind, lines in _blocks(markdown.splitlines()):
        if kind.startswith("heading"):
            level = int(kind[len("heading"):]) + 1
            out.append(f"<h{level}>{_inline(lines[0])}</h{level}>")
        elif kind == "code":
            out.append("<pre>" + html.escape("\n".join(lines)) + "</pre>")
        elif kind == "list":
            out.append("<ul>\n" + "\n".join(f"<li>{_inline(item)}</li>" for item in lines) + "\n</ul>")
        else:
            out.append(f"<p>{_inline(lines[0])}</p>")
    return "\n".join(out) + "\n"


def method_html() -> str:
    """``docs/method.md`` rendered."""
    return render(METHOD_MD.read_text(encoding="utf-8"))
