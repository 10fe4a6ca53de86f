"""The built-in campaign files (``scenarios/campaigns/``) and the variants each names, read
with tomllib alone: the command line lists them in its help without importing the campaign
machinery (its scenario checks load MuJoCo)."""
from __future__ import annotations

import tomllib
from pathlib import Path

CAMPAIGN_DIR = Path(__file__).resolve().parents[1] / "campaigns"


def builtin_campaigns() -> list[str]:
    return sorted(p.stem for p in CAMPAIGN_DIR.glob("*.toml"))


def variant_names(doc: dict) -> list[str]:
    """The names of a campaign document's ``[variants.NAME]`` tables, its ``default_variant``
    marked ``(default)``; [] without variants (or with a ``variants`` that is no table: the
    campaign's validation names that)."""
    variants = doc.get("variants")
    if not isinstance(variants, dict):
        return []
    return [f"{n} (default)" if n == doc.get("default_variant") else n for n in variants]


def listing() -> str:
    """``"envelope, robustness_random (variants: ramp (default), control), smoke"``: every
    built-in campaign with its variants (a file that does not parse is listed bare: running
    it reports why)."""
    out = []
    for name in builtin_campaigns():
        try:
            variants = variant_names(tomllib.loads((CAMPAIGN_DIR / f"{name}.toml").read_text()))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            variants = []
        out.append(f"{name} (variants: {', '.join(variants)})" if variants else name)
    return ", ".join(out)
