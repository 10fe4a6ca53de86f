"""The argument parser of every ``python -m scenarios...`` command line (:class:`Parser`).

* no abbreviations (``allow_abbrev=False``): ``--job 1`` is an unknown option, never ``--jobs``;
* an unknown option is reported by the (sub)command it was given to, with that command's usage
  and the closest option it has (``--jbos: unknown option; did you mean '--jobs'?``), exit 2.
  argparse itself hands a subcommand's unknown arguments up to the top parser, which prints its
  own usage.
"""
from __future__ import annotations

import argparse

from scenarios.lang.fields import did_you_mean


class Parser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` without abbreviations, whose subcommands (``add_subparsers``
    makes them of this class too) report their own unknown arguments."""

    def __init__(self, *args, **kwargs):
        kwargs["allow_abbrev"] = False
        super().__init__(*args, **kwargs)

    def parse_known_args(self, args=None, namespace=None):
        namespace, extras = super().parse_known_args(args, namespace)
        if extras:
            self.error(self._unknown(extras))
        return namespace, extras

    def _unknown(self, extras: list[str]) -> str:
        known = [s for action in self._actions for s in action.option_strings]
        options = [e for e in extras if e.startswith("-")]
        if not options:
            return f"unrecognized arguments: {' '.join(extras)}"
        names = [o.split("=", 1)[0] for o in options]
        return "; ".join(f"{n}: unknown option" + did_you_mean(n, known, "") for n in names)
