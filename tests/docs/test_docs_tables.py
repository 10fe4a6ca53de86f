"""The results tables of README.md and docs/ are what the committed data gives
(``python -m scenarios docs``), and the committed suite data is what the suite gives.

The first fails when anyone types into a generated table or changes ``docs/data/`` without
regenerating the pages; the last compares a complete suite run in the clone's ``runs/`` (CI's
README line 1 leaves one before line 2 runs the tests) with ``docs/data/suite.json``, exactly:
the loop's results are the same bits on every x86-64 machine with FMA3 (docs/results.md).
"""
import json
import shutil

import pytest

from scenarios import docs
from support.paths import REPO_ROOT


def test_every_page_equals_what_the_data_gives():
    assert docs.stale() == []


def test_every_generated_block_names_a_known_table_and_every_table_is_shown():
    shown = []
    for rel in docs.PAGES:
        shown += [m.group(1) for m in docs.BEGIN.finditer((REPO_ROOT / rel).read_text())]
    assert sorted(set(shown)) == sorted(docs.TABLES)


def _copy(tmp_path):
    for rel in docs.PAGES:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO_ROOT / rel, tmp_path / rel)
    data = tmp_path / "docs" / "data"
    shutil.copytree(docs.DATA_DIR, data, dirs_exist_ok=True)
    return data


def test_a_typed_number_and_a_changed_datum_are_each_found(tmp_path):
    data = _copy(tmp_path)
    readme = tmp_path / "README.md"
    text = readme.read_text()
    row = next(line for line in text.splitlines() if line.startswith("| `mass_20kg`"))
    readme.write_text(text.replace(row, row.replace("0.109", "0.100")))
    assert docs.stale(tmp_path) == [
        "README.md: table readme_suite differs from docs/data (run python -m scenarios docs)"]

    readme.write_text(text)
    study = (data / "robustness_study.csv").read_text().replace(",92.6,", ",93.6,")
    (data / "robustness_study.csv").write_text(study)
    assert docs.stale(tmp_path) == [
        "docs/results.md: table study differs from docs/data (run python -m scenarios docs)"]


def test_a_block_without_its_end_is_an_error_naming_the_page():
    with pytest.raises(docs.DocsError, match="README.md: table 'suite' has no"):
        docs.render_page("a\n<!-- table: suite -->\nb\n", {"suite": "x"}, "README.md")


def test_the_check_command_exits_1_on_a_stale_page_and_changes_nothing(tmp_path, monkeypatch):
    _copy(tmp_path)
    page = tmp_path / "docs" / "results.md"
    stale_text = page.read_text().replace("| `nominal` | adaptive |", "| `nominal` | adaptive (typed) |", 1)
    page.write_text(stale_text)
    monkeypatch.setattr(docs, "REPO_ROOT", tmp_path)
    from scenarios.cli import main

    assert main(["docs", "--check"]) == 1
    assert page.read_text() == stale_text
    assert main(["docs"]) == 0
    assert docs.stale(tmp_path) == []


def test_recording_an_incomplete_run_names_every_missing_scenario(tmp_path):
    with pytest.raises(docs.DocsError) as exc:
        docs.suite_data(tmp_path)
    assert "nominal/summary.json: missing" in str(exc.value)
    assert str(exc.value).count("missing") == len(json.loads(docs.SUITE_DATA.read_text())["scenarios"])


@pytest.mark.skipif(not all((REPO_ROOT / "runs" / s / "summary.json").is_file()
                            for s in json.loads(docs.SUITE_DATA.read_text())["scenarios"]),
                    reason="no complete suite run in runs/ (README line 1 writes one)")
def test_a_fresh_suite_run_gives_the_committed_data():
    fresh = docs.suite_data(REPO_ROOT / "runs")["scenarios"]
    committed = json.loads(docs.SUITE_DATA.read_text())["scenarios"]
    differ = [f"{s}.{arm}" for s in committed for arm in committed[s]["arms"]
              if fresh.get(s, {}).get("arms", {}).get(arm) != committed[s]["arms"][arm]]
    assert differ == [], ("these arms differ from docs/data/suite.json; if the change is intended, "
                          "python -m scenarios docs --record-suite runs")
    assert {s: v["verdict"] for s, v in fresh.items()} == {s: v["verdict"] for s, v in committed.items()}
