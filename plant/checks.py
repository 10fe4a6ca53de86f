"""Range checks shared by the perturbation specs (:mod:`plant.terrain`, :mod:`plant.perturbation`).

Each spec lists every problem at once (``problems()``, one string each naming the field
and its allowed range) and raises them together (:meth:`Checked.validate`).
"""
from __future__ import annotations

import numbers

from plant.errors import PerturbationError


def is_real(x) -> bool:
    """True for a real number that is not a bool."""
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def check_range(problems: list[str], name: str, value, lo: float, hi: float,
                unit: str, lo_open: bool) -> None:
    """Append a problem naming ``name`` and its allowed range unless lo <(=) value <= hi."""
    rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]{(' ' + unit) if unit else ''}"
    if not is_real(value):
        problems.append(f"{name}={value!r} must be a real number in {rng}")
        return
    ok = (lo < value if lo_open else lo <= value) and value <= hi  # NaN fails both
    if not ok:
        problems.append(f"{name}={value!r} is out of range {rng}")


class Checked:
    """Mixin: :meth:`validate` raises the ``problems()`` of the spec, all at once."""

    def problems(self) -> list[str]:
        raise NotImplementedError

    def validate(self) -> None:
        """Raise :class:`PerturbationError` listing every problem (``.problems``), if any."""
        found = self.problems()
        if found:
            err = PerturbationError(
                f"invalid perturbation, {len(found)} problem(s): " + "; ".join(found))
            err.problems = list(found)
            raise err
