"""A small TOML writer for scenario documents (tomllib only reads).

Handles what scenario files hold: strings, booleans, integers, finite floats, arrays
of those, tables (``[terrain]``, ``[regulator]``), arrays of tables (``[[command]]``,
``[[push]]``, ``[[arm]]``) and inline tables inside those. Floats are written with
``repr`` (the shortest text that reads back to the same double). Every document is
read back with ``tomllib`` and compared before it is returned.
"""
from __future__ import annotations

import json
import math
import re
import tomllib
from typing import Any, Mapping

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE_KEY.match(k) else json.dumps(k)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"cannot write a non-finite float ({v}) to a scenario file")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, Mapping) for x in v)


def dumps(doc: Mapping[str, Any], header: str = "") -> str:
    """TOML text for ``doc``; ``header`` lines become ``#`` comments on top."""
    lines = [f"# {h}".rstrip() for h in header.splitlines()]
    scalars = {k: v for k, v in doc.items() if not isinstance(v, Mapping) and not _is_table_array(v)}
    tables = {k: v for k, v in doc.items() if isinstance(v, Mapping)}
    arrays = {k: v for k, v in doc.items() if _is_table_array(v)}
    lines += [f"{_key(k)} = {_value(v)}" for k, v in scalars.items()]
    for k, t in tables.items():
        lines += ["", f"[{_key(k)}]"] + [f"{_key(kk)} = {_value(vv)}" for kk, vv in t.items()]
    for k, items in arrays.items():
        for t in items:
            lines += ["", f"[[{_key(k)}]]"] + [f"{_key(kk)} = {_value(vv)}" for kk, vv in t.items()]
    text = "\n".join(lines) + "\n"
    if tomllib.loads(text) != _plain(doc):
        raise ValueError("the TOML writer did not round-trip this document")  # pragma: no cover
    return text


def _plain(v: Any) -> Any:
    """``doc`` as tomllib would give it back (tuples as lists, mappings as dicts)."""
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v
