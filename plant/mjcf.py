"""Reading MJCF files safely: every file (and every file it includes) is checked before MuJoCo parses it."""
from __future__ import annotations

import os
import pathlib
import xml.parsers.expat

import mujoco

from plant.errors import ModelError


class _RefusedXml(Exception):
    """Raised from expat's handlers to stop at a DTD or an entity declaration."""


def _xml_includes(path: pathlib.Path, origin: str = "") -> list[tuple[str, int]]:
    """``(file, line)`` of every ``<include>`` in ``path``; ModelError if it cannot be read,
    is not well-formed XML or declares a DTD or entities (refused before MuJoCo sees it:
    MuJoCo's parser keeps unexpanded entity text, and an entity bomb is a denial of service)."""
    parser = xml.parsers.expat.ParserCreate()
    includes: list[tuple[str, int]] = []

    def refuse(*_args):
        raise _RefusedXml(f"line {parser.CurrentLineNumber}: a DTD or entity declaration; "
                          "MJCF files may not declare any")

    def element(name, attrs):
        if name == "include":
            includes.append((attrs.get("file", ""), parser.CurrentLineNumber))

    parser.StartDoctypeDeclHandler = refuse
    parser.EntityDeclHandler = refuse
    parser.StartElementHandler = element
    try:
        with open(path, "rb") as fh:
            parser.ParseFile(fh)
    except OSError as e:
        raise ModelError(f"cannot read model file {path}{origin}: {e.strerror or e}") from None
    except _RefusedXml as e:
        raise ModelError(f"cannot parse model file {path}{origin}: {e}") from None
    except xml.parsers.expat.ExpatError as e:
        raise ModelError(f"cannot parse model file {path}{origin}: not well-formed XML: {e}") from None
    return includes


def check_mjcf_file(path: pathlib.Path) -> None:
    """Check an MJCF file and the files it includes before MuJoCo parses them.

    Each file must be readable, well-formed XML without a DTD or entity declarations;
    includes are resolved as MuJoCo 3 does (the main file's folder first, then the
    including file's) and checked the same way. Raises :class:`ModelError` naming the
    file (and the include's line).
    """
    todo, seen = [(path, "")], set()
    while todo:
        f, origin = todo.pop()
        if os.path.realpath(f) in seen:
            continue
        seen.add(os.path.realpath(f))
        for name, line in _xml_includes(f, origin):
            where = f"{f}, line {line}"
            found = [c for c in (path.parent / name, f.parent / name) if name and c.is_file()]
            if not found:
                raise ModelError(f"model file {where}: <include file={name!r}>: no such file")
            todo.append((found[0], f" (included from {where})"))


def spec_from_file(path: pathlib.Path, what: str) -> mujoco.MjSpec:
    """``path`` checked by :func:`check_mjcf_file` and parsed; ModelError names the file and,
    for a missing one, the fix (``what`` is the model's kind: Menagerie, OSU or MJCF)."""
    if not path.is_file():
        hint = (" Fix: set CASSIE_OSU_XML to OSU's cassie.xml" if what == "OSU"
                else " Fix: pass an existing MJCF file, 'menagerie' or 'osu'")
        raise ModelError(f"{what} model file not found: {path}.{hint}")
    check_mjcf_file(path)
    try:
        return mujoco.MjSpec.from_file(str(path))
    except Exception as e:  # mujoco raises ValueError with the parser's message
        raise ModelError(f"cannot parse {what} model {path}: {e}") from e
