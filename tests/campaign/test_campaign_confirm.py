"""The confirmation stage of "never falls where b walks" (``confirm_runs``).

- ``confirm_runs`` is checked up front, every problem naming the field and its range;
- the stage runs each listed draw on fresh values of ``replicate_over`` (past the largest),
  its ``redraw`` factors drawn anew and everything else as drawn, the verdicts' two arms only;
- the test: one-sided exact McNemar on the fresh pairs, Holm over the listed draws; an
  incomplete stage never passes; the report says which draws are confirmed;
- through the real CLI on a real Dask cluster and real simulations: an arm that falls
  within a second (stance hip roll pulled 0.4 rad off) is listed and confirmed, the
  verdict FAILs, and ``--resume`` runs nothing again; an arm that walks lists nothing and
  no stage runs.
"""
from __future__ import annotations

import csv
import json
import subprocess
import tomllib
from pathlib import Path

import pytest

from scenarios.campaign import analysis, report, sampling, spec
from scenarios.campaign.store import CampaignDir
from support.paths import REPO_ROOT
from support.smoke_campaign import run_campaign

from test_campaign_spec import BASE, GROUND_FACTORS, NUISANCE_FACTOR, campaign, problems_of  # noqa: E402

#: test_campaign_spec's grounds (3 draws x 2 models x floor_terrain_seed 7, 8, 9) with the
#: torso mass redrawn per ground; ``{top}``: more top-level keys.
GROUNDS = (BASE.replace("samples = 8", "samples = 3") + 'replicate_over = "floor_terrain_seed"\n'
           'redraw = ["torso_mass_kg"]\n{top}\n' + GROUND_FACTORS + NUISANCE_FACTOR)


# --------------------------------------------------------------------------- the field
def test_confirm_runs_is_checked_up_front_naming_the_field_and_its_range():
    assert campaign(GROUNDS.format(top="confirm_runs = 4")).confirm_runs == 4
    assert campaign(GROUNDS.format(top="")).confirm_runs == 0
    for value, why in [("0", "must be >= 1"), ("1001", "must be <= 1000"), ("true", "must be an integer"),
                       ("2.5", "must be an integer")]:
        assert problems_of(GROUNDS.format(top=f"confirm_runs = {value}")) == [f"confirm_runs = {value}: {why}"]
    no_over = GROUNDS.format(top="confirm_runs = 5").replace('replicate_over = "floor_terrain_seed"\n', "")
    no_over = no_over.replace('redraw = ["torso_mass_kg"]\n', "")
    assert problems_of(no_over) == ["confirm_runs = 5: runs listed draws on fresh values of replicate_over: "
                                    "give replicate_over too"]
    on_models = GROUNDS.format(top="confirm_runs = 4").replace('replicate_over = "floor_terrain_seed"',
                                                               'replicate_over = "model"')
    assert problems_of(on_models) == [
        "confirm_runs = 4: the fresh runs take the values after the largest of replicate_over = 'model'; its values "
        "['menagerie', 'osu'] are not all integers"]
    one_arm = GROUNDS.format(top="confirm_runs = 4").replace('compare = ["adaptive", "pd_only"]',
                                                             'compare = ["adaptive"]')
    assert problems_of(one_arm) == ["confirm_runs = 4: confirms the verdicts of the first two arms of compare; "
                                    "compare has 1"]
    # every problem at once: beside an unrelated one
    found = problems_of(GROUNDS.format(top="confirm_runs = 0\nretries = 99"))
    assert "confirm_runs = 0: must be >= 1" in found and any("retries = 99" in p for p in found)
    # the folder's manifest carries it (the report reads it there)
    assert campaign(GROUNDS.format(top="confirm_runs = 4")).analysis_settings()["confirm_runs"] == 4


# --------------------------------------------------------------------------- the stage's samples
def test_the_stage_runs_each_listed_draw_on_fresh_grounds_with_a_fresh_nuisance():
    c = campaign(GROUNDS.format(top="confirm_runs = 4"))
    main = sampling.draw(c)  # 3 draws x 2 models x 3 grounds; a draw is named by its sample on ground 7
    firsts = [s for s in main if s.values["floor_terrain_seed"] == 7]
    listed = [firsts[0].id, firsts[4].id]  # a draw on menagerie and one on osu
    stage, samples, of = sampling.confirmation(c, listed)
    assert stage.arm_names() == ["adaptive", "pd_only"] and stage.confirm_runs == 0
    assert sorted(of.values()) == sorted(listed * 4) and set(of) == {s.id for s in samples}
    assert sorted(of) == sorted(f"{d}_c{j}" for d in listed for j in (1, 2, 3, 4))  # fresh run j of draw d
    main_masses = {s.values["torso_mass_kg"] for s in main}
    by_id = {s.id: s.values for s in main}
    for d in listed:
        fresh = [s.values for s in samples if of[s.id] == d]
        assert [v["floor_terrain_seed"] for v in fresh] == [10, 11, 12, 13]  # past the largest, 9
        for v in fresh:  # the same robot: every factor as drawn but the ground and the redrawn mass
            assert {k: x for k, x in v.items() if k not in ("floor_terrain_seed", "torso_mass_kg")} == \
                   {k: x for k, x in by_id[d].items() if k not in ("floor_terrain_seed", "torso_mass_kg")}
        masses = [v["torso_mass_kg"] for v in fresh]
        assert len(set(masses)) == 4 and not set(masses) & main_masses and all(11.0 <= m <= 20.0 for m in masses)
    # deterministic; its samples are valid scenarios of the two arms only
    assert sampling.confirmation(c, listed)[1] == samples
    for text in sampling.build_samples(stage, samples).values():
        assert tomllib.loads(text)["compare"] == ["adaptive", "pd_only"]
    with pytest.raises(ValueError, match="does not name a draw"):
        sampling.confirmation(c, [next(s.id for s in main if s.values["floor_terrain_seed"] == 8)])


def test_the_stage_keeps_only_the_arm_definitions_of_the_verdicts_arms():
    text = GROUNDS.format(top="confirm_runs = 2").replace(
        'compare = ["adaptive", "pd_only"]', 'compare = ["adaptive", "pd_only", "pd_gain"]')
    text += '[[base.arm]]\nname = "pd_gain"\nregulator = { adaptation_enabled = false, Kp_x = 0.105 }\n'
    text = text.replace('base = "nominal"\n', "")
    base = tomllib.loads((REPO_ROOT / "scenarios" / "suite" / "nominal.toml").read_text())
    base.pop("claim")
    doc = tomllib.loads(text)
    doc["base"] = {**base, "arm": doc["base"]["arm"]}
    c = spec.parse_campaign(doc, source="test.toml", base_dir=REPO_ROOT)
    first = next(s for s in sampling.draw(c) if s.values["floor_terrain_seed"] == 7)
    stage, samples, _ = sampling.confirmation(c, [first.id])
    docs = [tomllib.loads(t) for t in sampling.build_samples(stage, samples).values()]
    assert all(d["compare"] == ["adaptive", "pd_only"] and "arm" not in d for d in docs)


# --------------------------------------------------------------------------- the test
def _row(sample: str, arm: str, fell: bool, status: str = "complete") -> dict:
    return {"sample": sample, "arm": arm, "status": status, "fell": fell}


def _stage_rows(splits: dict[str, list[tuple[bool, bool]]]) -> tuple[list[dict], dict[str, str]]:
    rows, of = [], {}
    for d, pairs in splits.items():
        for j, (fa, fb) in enumerate(pairs):
            sid = f"{d}_{j:02d}"
            of[sid] = d
            rows += [_row(sid, "adaptive", fa), _row(sid, "pd_only", fb)]
    return rows, of


def test_a_listed_draw_is_confirmed_by_its_fresh_runs_beyond_chance_holm_over_the_draws():
    only_a, only_b, both, none = (True, False), (False, True), (True, True), (False, False)
    assert analysis.one_sided_exact(6, 0) == 1 / 64 and analysis.one_sided_exact(0, 0) == 1.0
    assert analysis.one_sided_exact(3, 3) == pytest.approx(42 / 64)
    # s1: 6 pairs only adaptive fell, 0 the other way (p = 1/64 <= 0.05 / 2): confirmed.
    # s2: 3 against 3 and two where both fell: a coin flip, not confirmed.
    rows, of = _stage_rows({"s1": [only_a] * 6 + [none] * 2, "s2": [only_a] * 3 + [only_b] * 3 + [both] * 2})
    c = analysis.confirmation(["s1", "s2"], rows, of, "adaptive", "pd_only", runs=8)
    assert c["complete"] and c["confirmed"] == ["s1"] and not c["holds"]
    d1, d2 = c["draws"]
    assert (d1["a_fell"], d1["b_fell"], d1["only_a"], d1["only_b"]) == (6, 0, 6, 0)
    assert (d2["a_fell"], d2["b_fell"], d2["only_a"], d2["only_b"]) == (5, 5, 3, 3)
    # 5 against 0 (p = 1/32) passes 0.05 alone but not Holm's first step over two draws (0.025)
    rows, of = _stage_rows({"s1": [only_a] * 5 + [none] * 3, "s2": [none] * 8})
    c = analysis.confirmation(["s1", "s2"], rows, of, "adaptive", "pd_only", runs=8)
    assert c["confirmed"] == [] and c["holds"]
    assert analysis.confirmation(["s1"], rows, of, "adaptive", "pd_only", runs=8)["confirmed"] == ["s1"]
    # a failed run leaves the stage incomplete: no PASS; a draw already confirmed still FAILs
    rows, of = _stage_rows({"s1": [none] * 8})
    rows[0]["status"] = "failed"
    c = analysis.confirmation(["s1"], rows, of, "adaptive", "pd_only", runs=8)
    assert not c["complete"] and not c["holds"] and c["draws"][0]["runs"] == 7
    rows, of = _stage_rows({"s1": [only_a] * 7})
    c = analysis.confirmation(["s1"], rows, of, "adaptive", "pd_only", runs=8)
    assert not c["complete"] and c["confirmed"] == ["s1"]
    assert analysis.holm([0.01, 0.04, 0.03], 0.05) == [True, False, False]
    assert analysis.holm([0.01, 0.02, 0.04], 0.05) == [True, True, True]


def _write_stage(root: Path, rows: list[dict], of: dict[str, str], listed: list[str], runs: int) -> None:
    d = CampaignDir(root / analysis.CONFIRM_DIR, "c_confirm", {s: s for s in of}, ["adaptive", "pd_only"], [],
                    {"confirm_of": of, "listed": listed, "runs": runs})
    d.open(resume=False, campaign_file=None)
    d.append(rows)
    d.finish()
    d.close()


def test_the_report_gives_the_confirmed_verdict_and_every_listed_draws_fresh_runs(tmp_path):
    """Two draws on three grounds; draw s0001 listed (adaptive fell on 2 of 3, pd_only on none)."""
    def r(sample, arm, fell):
        return {"sample": sample, "arm": arm, "status": "complete", "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None, "steady_state_error_vy": None,
                "settled_error_vx": None if fell else 0.05, "convergence_time_s": None, "run_dir": None}
    falls = {"s0000": (False, False), "s0002": (False, False), "s0004": (False, False),
             "s0001": (True, False), "s0003": (True, False), "s0005": (False, False)}
    rows = [r(s, arm, f) for s, fs in falls.items() for arm, f in zip(("adaptive", "pd_only"), fs)]
    manifest = {"name": "t", "n_samples": 6, "arms": ["adaptive", "pd_only"], "seed": 1, "metric": "settled_error_vx",
                "replicas": {}, "confirm_runs": 6,
                "replicate_over": {"factor": "floor_terrain_seed", "draws": 2, "cells": [3], "index": 0}}

    def render(root: Path, stage: dict | None = None, rows=rows) -> str:
        root.mkdir()
        if stage is not None:
            _write_stage(root, *_stage_rows(stage), ["s0001"], 6)
        return report.render(analysis.CampaignData(root, manifest, rows, []), [])

    head = "**Verdict: adaptive never falls where pd_only walks, confirmed on 6 fresh runs of each listed draw: "
    text = render(tmp_path / "none_run")
    assert "Screen of the majority reading: draws listed (samples where adaptive fell" in text
    assert "**Verdict: adaptive never falls where pd_only walks: " not in text  # the screen is no verdict
    assert head + "INCOMPLETE** (confirmed: none;" in text and "0 of 6 fresh pairs (none run)" in text
    text = render(tmp_path / "fail", {"s0001": [(True, False)] * 6})
    assert head + "FAIL** (confirmed: s0001;" in text
    assert "| s0001 | 6/6 | 6 | 0 | 6 | 0 | 0.0156 | yes |" in text
    text = render(tmp_path / "pass", {"s0001": [(True, False)] * 2 + [(False, True)] * 2 + [(False, False)] * 2})
    assert head + "PASS** (confirmed: none;" in text and "| s0001 | 6/6 | 2 | 2 | 2 | 2 | 0.688 | no |" in text
    # nothing listed: PASS without a stage
    text = render(tmp_path / "quiet", rows=[{**x, "fell": False} for x in rows])
    assert head + "PASS** (the screen lists no draw;" in text


# --------------------------------------------------------------------------- real runs
WAIT_S = 600.0  # bound of each CLI call; ~25 runs of 2 s, each well under 2 s of wall on 2 cores

REAL = """
name = "confirm_real"
description = "a draw on three grounds, listed draws confirmed on six fresh ones"
base = "base.toml"
duration_s = 2.0
compare = ["{first}", "pd_only"]
samples = 1
seed = 5
replicate_over = "floor_terrain_seed"
redraw = ["push_force_y_n"]
confirm_runs = 6

[factors.torso_mass_kg]
dist = "uniform"
low = 12.0
high = 13.0
[factors.push_force_y_n]  # a small push at 0.5 s, drawn anew on each ground
dist = "uniform"
low = -3.0
high = 3.0
[factors.floor_terrain_seed]
dist = "grid"
values = [1, 2, 3]
"""
PUSH = """
[[push]]
t_s = 0.5
force_n = [0.0, 0.0, 0.0]
duration_s = 0.1
"""
ROLLED = """
[[arm]]
name = "rolled"
description = "stance hip roll pulled 0.4 rad off: falls within a second"
regulator = { adaptation_enabled = false, Kp_roll = 3.0, roll_des = 0.4 }
"""


def _real_campaign(tmp_path: Path, first: str) -> Path:
    """The nominal scenario with a push at 0.5 s (and the arm ``rolled``) as the base."""
    nominal = (REPO_ROOT / "scenarios" / "suite" / "nominal.toml").read_text()
    base = nominal[:nominal.index("[claim]")] + PUSH + (ROLLED if first == "rolled" else "")
    (tmp_path / "base.toml").write_text(base)
    path = tmp_path / f"{first}.toml"
    path.write_text(REAL.format(first=first))
    return path


def _run(args, tmp_path: Path, built_fmu: Path) -> subprocess.CompletedProcess:
    return run_campaign([*args, "--workers", 2, "--no-plots"], tmp_path, built_fmu, timeout=WAIT_S)


def _csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_a_real_arm_that_falls_where_pd_only_walks_is_listed_and_confirmed(tmp_path, built_fmu):
    out = tmp_path / "out"
    r = _run([_real_campaign(tmp_path, "rolled"), "--out", out], tmp_path, built_fmu)
    assert r.returncode == 0, r.stderr[-3000:]
    main = _csv(out / "campaign.csv")
    assert len(main) == 3 * 2 and all(x["status"] == "complete" for x in main)
    assert {x["arm"]: x["fell"] for x in main if x["sample"] == "s0000"} == {"rolled": "true", "pd_only": "false"}
    stage = _csv(out / analysis.CONFIRM_DIR / "campaign.csv")
    assert len(stage) == 6 * 2 and all(x["status"] == "complete" for x in stage)
    assert sorted({x["floor_terrain_seed"] for x in stage}) == ["4", "5", "6", "7", "8", "9"]
    manifest = json.loads((out / analysis.CONFIRM_DIR / "campaign.json").read_text())
    assert manifest["listed"] == ["s0000"] and set(manifest["confirm_of"].values()) == {"s0000"}
    assert all(x["fell"] == ("true" if x["arm"] == "rolled" else "false") for x in stage)
    text = (out / "campaign.md").read_text()
    assert ("**Verdict: rolled never falls where pd_only walks, confirmed on 6 fresh runs of each listed draw: "
            "FAIL** (confirmed: s0000;") in text
    assert list((tmp_path / "systemp").iterdir()) == []
    # resumed: nothing runs again, nothing is lost
    before = (out / analysis.CONFIRM_DIR / "campaign.csv").read_text()
    r = _run([_real_campaign(tmp_path, "rolled"), "--out", out, "--resume"], tmp_path, built_fmu)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "3 of 3 samples complete, 0 to run" in r.stderr
    assert (out / analysis.CONFIRM_DIR / "campaign.csv").read_text() == before
    # a stage folder without its manifest (cut short while created) is refused, never overwritten
    (out / analysis.CONFIRM_DIR / "campaign.json").unlink()
    main_rows = (out / "campaign.csv").read_text()
    r = _run([_real_campaign(tmp_path, "rolled"), "--out", out, "--resume"], tmp_path, built_fmu)
    assert r.returncode == 2 and "remove it to run the stage afresh" in r.stderr, r.stderr[-3000:]
    assert (out / analysis.CONFIRM_DIR / "campaign.csv").read_text() == before
    assert (out / "campaign.csv").read_text() == main_rows


def test_a_real_arm_that_walks_lists_no_draw_and_runs_no_stage(tmp_path, built_fmu):
    out = tmp_path / "out"
    r = _run([_real_campaign(tmp_path, "adaptive"), "--out", out], tmp_path, built_fmu)
    assert r.returncode == 0, r.stderr[-3000:]
    assert not (out / analysis.CONFIRM_DIR).exists()
    assert "the screen lists no draw where adaptive fell and pd_only walked" in r.stderr
    assert ("**Verdict: adaptive never falls where pd_only walks, confirmed on 6 fresh runs of each listed draw: "
            "PASS** (the screen lists no draw;") in (out / "campaign.md").read_text()
