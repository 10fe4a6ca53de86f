"""Reading scenario and campaign files: the one place a TOML file becomes a document.

:func:`read_toml` takes regular files only (a folder, a named pipe or a device is
refused by what it is before anything is read: a pipe would block the reader), of at
most :data:`MAX_FILE_BYTES`, in UTF-8, and turns every way of failing into one
:class:`~scenarios.errors.ScenarioError` naming the file. :func:`depth_problem` bounds
how deeply a document nests (:data:`MAX_DEPTH`): the validators, the campaign's copies
and the problem messages walk values recursively, and no key of either format nests
deeper than a few levels.
"""
from __future__ import annotations

import os
import stat
import tomllib
from pathlib import Path
from typing import Any

from scenarios.errors import ScenarioError

#: Largest scenario or campaign file, bytes: 100,000 ``[[command]]`` tables (the most a
#: schedule may hold, :data:`scenarios.lang.sections.MAX_SCHEDULE_POINTS`) take ~4 MB; tomllib
#: reads ~2.5 MB/s, so the largest file is read in seconds.
MAX_FILE_BYTES = 16 * 2**20
#: Deepest nesting of tables and arrays in a document. A campaign's deepest key,
#: ``[factors.pushes] values = [[{force_n = [..]}]]``, is 6 levels down; an inline
#: ``[base]`` scenario adds 1.
MAX_DEPTH = 16

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


def read_toml(path: str | Path, what: str = "scenario file") -> dict[str, Any]:
    """The TOML document in the regular file ``path`` (``what`` it should be, for the
    messages); ScenarioError with one problem naming the file otherwise."""
    path = Path(path)
    try:
        data = read_regular_file(path, what)
    except FileNotFoundError:
        raise ScenarioError([f"file not found: {path}"], source=str(path)) from None
    except OSError as exc:
        raise ScenarioError([f"cannot read: {exc.strerror or exc}"], source=str(path)) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError([f"not UTF-8 text (TOML files must be UTF-8): byte {exc.object[exc.start]:#04x} "
                             f"at offset {exc.start}"], source=str(path)) from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError([f"TOML syntax error: {exc}"], source=str(path)) from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise ScenarioError([f"TOML value not readable: {exc}"], source=str(path)) from None
    except RecursionError:  # tomllib parses nested arrays and inline tables recursively
        raise ScenarioError([f"a value is nested too deeply (more than {MAX_DEPTH} levels of tables and "
                             "arrays are allowed)"], source=str(path)) from None
    problem = depth_problem(doc)
    if problem:
        raise ScenarioError([problem], source=str(path))
    return doc


def read_regular_file(path: Path, what: str) -> bytes:
    """The bytes of ``path`` if it is a regular file of at most MAX_FILE_BYTES (else
    ScenarioError naming what it is); opened without blocking (a named pipe opens at
    once and is then refused by its kind). OSError when it cannot be opened or read."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        for test, kind in _KINDS:
            if test(mode):
                raise ScenarioError([f"is {kind}, not a {what}"], source=str(path))
        if not stat.S_ISREG(mode):
            raise ScenarioError([f"is not a regular file, not a {what}"], source=str(path))
        os.set_blocking(fd, True)
        chunks, size = [], 0
        while size <= MAX_FILE_BYTES:  # read, not st_size: a file may grow, /proc reports 0
            chunk = os.read(fd, min(1 << 20, MAX_FILE_BYTES + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > MAX_FILE_BYTES:
            raise ScenarioError([f"larger than {MAX_FILE_BYTES // 2**20} MiB: too large for a {what}"],
                                source=str(path))
        return b"".join(chunks)
    finally:
        os.close(fd)


def depth_problem(doc: Any) -> str | None:
    """Why ``doc`` (a TOML or JSON document) nests too deeply, or None.
    Walks the document with its own stack: any depth is measured without recursion."""
    stack = [(doc, 0)]
    while stack:
        value, depth = stack.pop()
        if depth > MAX_DEPTH:
            return f"a value is nested too deeply (more than {MAX_DEPTH} levels of tables and arrays are allowed)"
        if isinstance(value, dict):
            stack.extend((v, depth + 1) for v in value.values())
        elif isinstance(value, (list, tuple)):
            stack.extend((v, depth + 1) for v in value)
    return None
