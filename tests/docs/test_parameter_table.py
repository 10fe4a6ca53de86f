"""docs/fmus.md's parameter table is the one variable table's (fmu_src/core/avr_specs.py), as
``python build.py --parameter-table`` writes it: a parameter added, retired or changed in the
code without rewriting the page fails here."""
import pytest

from fmu_src.core.avr_specs import PARAM_SPECS
from fmu_src.packing.parameters import TABLE_BEGIN, TABLE_END, parameter_table, with_parameter_table
from support.paths import REPO_ROOT

PAGE = REPO_ROOT / "docs" / "fmus.md"


def test_docs_fmus_md_holds_the_generated_parameter_table():
    text = PAGE.read_text(encoding="utf-8")
    assert with_parameter_table(text) == text, "run `python build.py --parameter-table`"


def test_the_table_has_every_parameter_with_its_tier_and_no_retired_one():
    table = parameter_table()
    for spec in PARAM_SPECS:
        assert f"| `{spec.name}` | {spec.tier} |" in table
    for retired in ("error_deadzone_mps", "weight_norm_max", "overspeed_unlearn"):
        assert retired not in PAGE.read_text(encoding="utf-8")


def test_a_changed_table_is_rewritten_between_the_markers_only():
    page = f"head\n{TABLE_BEGIN}\n| old |\n{TABLE_END}\ntail\n"
    assert with_parameter_table(page) == f"head\n{TABLE_BEGIN}\n{parameter_table()}\n{TABLE_END}\ntail\n"
    with pytest.raises(ValueError, match="needs one"):
        with_parameter_table("no markers")
