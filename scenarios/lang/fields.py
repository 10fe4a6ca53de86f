"""The problem collector and the field readers shared by scenario and campaign files.

Every reader takes the TOML table, the key, the field's full name (``push[1].t_s``) and
the :class:`Problems`; it returns the typed value, or the default after recording a
problem that names the field, its value and what is allowed. Nothing raises: a file's
problems are all collected and reported at once.
"""
from __future__ import annotations

import difflib
import math
import re
from typing import Any, Iterable, Mapping

from scenarios.lang.formatting import is_number, show

#: Scenario, arm and campaign names: they name output folders and samples.
NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_\-]*$")
NAME_PATTERN = "[a-z0-9][a-z0-9_-]*"
#: Longest name: a name becomes file names (``DIR/<name>/``, ``.<name>.replaced-<pid>``,
#: ``<arm>.mp4``), which file systems limit to 255 bytes; 100 leaves room for what is added.
MAX_NAME_CHARS = 100
#: Longest text of a value quoted in a problem (a huge list is shown cut, ending in ...).
MAX_SHOWN_CHARS = 80
#: How close a time must be to the grid (in grid steps) to count as on it.
GRID_TOL_STEPS = 1e-6
#: difflib similarity a misspelt key needs to be offered as "did you mean".
HINT_CUTOFF = 0.6


class Problems:
    """Collects problems; each names its field."""

    def __init__(self) -> None:
        self.items: list[str] = []

    def add(self, field: str, value: Any, why: str) -> None:
        self.items.append(f"{field} = {shown(value)}: {why}")

    def note(self, field: str, why: str) -> None:
        self.items.append(f"{field}: {why}")


def shown(value: Any) -> str:
    """``value`` as a problem quotes it, cut to :data:`MAX_SHOWN_CHARS`; a list or table
    is written only as far as it is shown (a 10^6-element list costs nothing)."""
    if isinstance(value, (list, tuple)) and len(value) > MAX_SHOWN_CHARS:
        value = list(value[:MAX_SHOWN_CHARS])
    text = show(value)
    return text if len(text) <= MAX_SHOWN_CHARS else text[:MAX_SHOWN_CHARS - 3] + "..."


def as_finite(v: Any) -> float | None:
    """A number (not a bool) as a finite double, or None (an int beyond the doubles'
    range, inf, nan, anything else)."""
    if not is_number(v):
        return None
    try:
        f = float(v)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


def did_you_mean(word: str, known: Iterable[str], otherwise: str, cutoff: float = HINT_CUTOFF) -> str:
    """``"; did you mean 'x'?"`` for the closest known word, else ``otherwise``."""
    close = difflib.get_close_matches(word, list(known), n=1, cutoff=cutoff)
    return f"; did you mean {close[0]!r}?" if close else otherwise


def unknown_keys(table: Mapping[str, Any], known: tuple[str, ...], prefix: str, probs: Problems) -> None:
    for key in table:
        if key not in known:
            probs.note(f"{prefix}{key}", "unknown key" + did_you_mean(key, known, f"; known keys: {', '.join(known)}"))


def _required(table, key, field, probs, required) -> bool:
    """True when ``key`` is in ``table``; notes a missing required key."""
    if key in table:
        return True
    if required:
        probs.note(field, "required")
    return False


def number(table, key, field, probs, *, required=False, default=None, gt=None, ge=None, le=None, lt=None):
    """A finite number as float, within the given bounds."""
    if not _required(table, key, field, probs, required):
        return default
    v = table[key]
    if not is_number(v):
        probs.add(field, v, "must be a number")
        return default
    if as_finite(v) is None:
        probs.add(field, v, "must be finite" if isinstance(v, float) else "must be a finite number (within +-1.8e308)")
        return default
    v = float(v)
    ok = True
    for bound, holds, op in ((gt, lambda b: v > b, ">"), (ge, lambda b: v >= b, ">="),
                             (le, lambda b: v <= b, "<="), (lt, lambda b: v < b, "<")):
        if bound is not None and not holds(bound):
            probs.add(field, v, f"must be {op} {bound:g}")
            ok = False
    return v if ok else default


def integer(table, key, field, probs, *, required=False, default=None, ge=None):
    if not _required(table, key, field, probs, required):
        return default
    v = table[key]
    if not isinstance(v, int) or isinstance(v, bool):
        probs.add(field, v, "must be an integer")
        return default
    if ge is not None and v < ge:
        probs.add(field, v, f"must be >= {ge}")
        return default
    return v


def string(table, key, field, probs, *, required=False, default=""):
    if not _required(table, key, field, probs, required):
        return default
    v = table[key]
    if not isinstance(v, str):
        probs.add(field, v, "must be a string")
        return default
    return v


def name(table, key, field, probs, why: str) -> str:
    """A required string matching :data:`NAME_RE` (``why``: what it names)."""
    v = string(table, key, field, probs, required=True)
    if isinstance(table.get(key), str) and not NAME_RE.match(v):
        probs.add(field, v, f"must match {NAME_PATTERN}{why}")
    elif len(v) > MAX_NAME_CHARS:
        probs.add(field, v, f"is {len(v)} characters long; at most {MAX_NAME_CHARS}{why}")
    return v


def vec3(table, key, field, probs, *, default=None):
    if key not in table:
        return default
    v = table[key]
    if not isinstance(v, list) or len(v) != 3 or not all(is_number(x) for x in v):
        probs.add(field, v, "must be a list of 3 numbers [x, y, z]")
        return default
    if not all(as_finite(x) is not None for x in v):
        probs.add(field, v, "must be finite")
        return default
    return (float(v[0]), float(v[1]), float(v[2]))


def table(doc, key, field, probs) -> dict | None:
    """The table ``[key]`` of ``doc``, or None (absent, or not a table: noted)."""
    if key not in doc:
        return None
    v = doc[key]
    if not isinstance(v, dict):
        probs.add(field, v, f"must be a table ([{key}])")
        return None
    return v


def table_list(doc, key, field, probs) -> list[dict]:
    if key not in doc:
        return []
    v = doc[key]
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        probs.add(field, v, f"must be an array of tables ([[{key}]])")
        return []
    return v


def on_grid(t: float, h: float) -> bool:
    """``t`` is a whole number of steps ``h``."""
    n = t / h
    return abs(n - round(n)) < GRID_TOL_STEPS
