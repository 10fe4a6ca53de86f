"""The one value formatter of the package: problems, claim checks, tables and reports.

:func:`show` writes a value the way a scenario file reads: booleans ``true``/``false``,
floats with a format spec (``g`` by default), strings quoted, lists as ``[a, b]``.
Each caller picks only what differs (the table's fixed decimals and ``yes``/``no``,
the report's ``null`` and 4 significant digits). Writing TOML files is
:mod:`scenarios.campaign.tomlw`'s job: it must round-trip every double (``repr``).
"""
from __future__ import annotations

from typing import Any

TRUE_FALSE = ("true", "false")
YES_NO = ("yes", "no")


def show(v: Any, float_format: str = "g", *, none: str = "None", bools: tuple[str, str] = TRUE_FALSE,
         quote: bool = True) -> str:
    """``v`` as text: ``float_format`` for floats (``"g"``, ``".3f"``), ``none`` for None,
    ``bools`` for True/False, strings as ``repr`` when ``quote``, lists and tuples as
    ``[a, b]``, tables as ``{...}``, anything else as ``str``."""
    if v is None:
        return none
    if isinstance(v, bool):
        return bools[0] if v else bools[1]
    if isinstance(v, float):
        return format(v, float_format)
    if isinstance(v, str):
        return repr(v) if quote else v
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(show(x, float_format, none=none, bools=bools, quote=quote) for x in v) + "]"
    if isinstance(v, dict):
        return "{...}"
    return str(v)


def is_number(v: Any) -> bool:
    """An int or float that is not a bool (TOML and JSON numbers)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)
