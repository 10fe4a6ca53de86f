"""Campaign files, sampling, the campaign folder and the statistics, without simulation (fast).

- the built-in campaigns validate; a bad campaign lists every problem at once, each
  naming its field; a factor range the scenario format does not allow is reported once
  against the factor (the base probed at the extremes);
- draws: same seed -> same samples; Latin hypercube strata; grid x draws; randint
  bounds; step snapping; per-factor streams (adding a factor leaves the others alone);
- every sample's TOML reads back to the same document and loads as a scenario;
- the folder refuses another campaign, this one without --resume, a foreign folder, a
  second writer; resume keeps only complete samples; a line cut short is dropped;
- Wilson interval, quantiles, paired comparison on hand-made rows.
"""
from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from scenarios.errors import ScenarioError
from scenarios.lang import spec as scenario_spec
from scenarios.campaign import analysis, sampling, spec, tomlw
from scenarios.campaign.store import CampaignDir, CampaignDirError, TIMING_COLUMNS
from support.paths import REPO_ROOT
from support.smoke_campaign import campaign_in_process

BASE = """
name = "c"
samples = 8
seed = 11
base = "nominal"
duration_s = 2.0
compare = ["adaptive", "pd_only"]
"""


def campaign(text: str, base_dir: Path | None = None) -> spec.Campaign:
    return spec.parse_campaign(tomllib.loads(text), source="test.toml", base_dir=base_dir or REPO_ROOT)


def problems_of(text: str) -> list[str]:
    with pytest.raises(ScenarioError) as info:
        campaign(text)
    return info.value.problems


# --------------------------------------------------------------------------- validation
@pytest.mark.parametrize("name", ["robustness", "smoke"])
def test_builtin_campaigns_validate_and_their_samples_load(name, tmp_path):
    c = spec.load_campaign(spec.resolve_campaign(name))
    texts = sampling.build_samples(c)
    assert len(texts) == c.n_samples
    for sid in list(texts)[:5]:  # the loader itself, from a file, as `scenarios run` reads it
        (tmp_path / f"{sid}.toml").write_text(texts[sid])
        s = scenario_spec.load_scenario(tmp_path / f"{sid}.toml")
        assert s.name == sid and [a.name for a in s.arms] == ["adaptive", "pd_only"]


def test_robustness_matches_the_issue():
    c = spec.load_campaign(spec.resolve_campaign("robustness"))
    f = {x.name: x for x in c.factors}
    assert c.n_samples == 60 and c.base_doc["duration_s"] == 30.0
    assert (f["torso_mass_kg"].low, f["torso_mass_kg"].high) == (10.33, 25.0)
    assert (f["torso_com_offset_x_m"].low, f["torso_com_offset_x_m"].high) == (-0.1, 0.1)
    assert (f["joint_damping_scale"].low, f["joint_damping_scale"].high) == (1.0, 10.0)
    assert (f["vx_des"].low, f["vx_des"].high) == (0.2, 1.0)
    assert f["seed"].dist == "randint"


def test_bad_campaign_lists_every_problem_naming_fields():
    probs = problems_of("""
name = "Bad Name"
samples = 0
seed = -1
retries = 11
base = "nominall"
bogus = 1
[factors.torso_mass]
dist = "uniform"
[factors.joint_damping_scale]
dist = "normal"
[factors.vx_des]
dist = "uniform"
low = 0.5
high = 0.2
[factors.seed]
dist = "uniform"
low = 1
high = 3
[factors.terrain]
dist = "choice"
values = ["flat", 3]
weights = [1.0]
""")
    text = "\n".join(probs)
    for needle in ("name = 'Bad Name'", "samples = 0", "seed = -1", "retries = 11", "base = 'nominall'",
                   "did you mean 'nominal'", "bogus: unknown key", "factors.torso_mass: unknown factor",
                   "did you mean 'torso_mass_kg'", "factors.joint_damping_scale.dist = 'normal'",
                   "factors.vx_des.high = 0.2: must be > low = 0.5",
                   "factors.seed.dist = 'uniform': an integer factor takes randint",
                   "factors.terrain.values[1] = 3", "factors.terrain.weights"):
        assert needle in text, (needle, probs)


def test_factor_range_checked_by_the_scenario_rules_once():
    probs = problems_of(BASE + """
[factors.joint_damping_scale]
dist = "uniform"
low = 1.0
high = 12.0
[factors.regulator.learning_rate]
dist = "choice"
values = [0.0001, 0.5]
[factors.push_t_s]
dist = "uniform"
low = 0.5
high = 1.0
""")
    assert len(probs) == 3, probs
    assert probs[0] == ("factors.joint_damping_scale = 12: gives an invalid scenario: perturbation: "
                        "joint_damping_scale=12.0 is out of range [0, 10]")  # the plant's range
    assert "factors.regulator.learning_rate = 0.5" in probs[1] and "must be a finite number in [" in probs[1]
    assert "factors.push_t_s: needs a base with a [[push]]" in probs[2]


def test_base_inline_and_file_and_problems_of_the_base(tmp_path):
    inline = campaign("""
name = "c"
samples = 2
seed = 1
[base]
duration_s = 1.0
seed = 4
[[base.command]]
t_s = 0.0
vx_des = 0.4
[factors.vx_des]
dist = "grid"
values = [0.3, 0.6]
""")
    assert inline.base_ref == "inline" and inline.n_samples == 4 and inline.arm_names() == ["adaptive"]
    (tmp_path / "b.toml").write_text((scenario_spec.SUITE_DIR / "push_fwd_30n.toml").read_text())
    from_file = campaign(BASE.replace('"nominal"', '"b.toml"').replace("duration_s = 2.0", "duration_s = 4.0") + """
[factors.push_force_x_n]
dist = "uniform"
low = 10.0
high = 40.0
""", base_dir=tmp_path)
    assert from_file.base_ref == str(tmp_path / "b.toml") and "claim" not in from_file.base_doc
    probs = problems_of(BASE.replace('duration_s = 2.0', 'duration_s = 2.001') + """
[factors.seed]
dist = "randint"
low = 1
high = 2
""")
    assert probs == ["base: duration_s = 2.001: must be a whole number of communication steps (0.005 s)"]


# --------------------------------------------------------------------------- sampling
FACTORS = """
[factors.torso_mass_kg]
dist = "lhs"
low = 10.33
high = 25.0
[factors.torso_com_offset_x_m]
dist = "lhs"
low = -0.1
high = 0.1
[factors.joint_damping_scale]
dist = "uniform"
low = 1.0
high = 10.0
step = 0.5
[factors.seed]
dist = "randint"
low = 1
high = 3
[factors.terrain]
dist = "choice"
values = ["flat", {max_height_m = 0.05, max_slope_deg = 5.0, seed = 2}]
weights = [3.0, 1.0]
"""


def test_same_seed_same_samples_other_seed_others():
    a, b = sampling.draw(campaign(BASE + FACTORS)), sampling.draw(campaign(BASE + FACTORS))
    assert a == b
    c = sampling.draw(campaign(BASE.replace("seed = 11", "seed = 12") + FACTORS))
    assert [s.values for s in a] != [s.values for s in c]


def test_latin_hypercube_one_sample_per_stratum_and_bounds():
    samples = sampling.draw(campaign(BASE + FACTORS))
    n = len(samples)
    for name, (lo, hi) in {"torso_mass_kg": (10.33, 25.0), "torso_com_offset_x_m": (-0.1, 0.1)}.items():
        v = np.array([s.values[name] for s in samples])
        strata = np.floor((v - lo) / (hi - lo) * n).astype(int)
        assert sorted(strata) == list(range(n)), name
    for s in samples:
        assert 1 <= s.values["seed"] <= 3 and isinstance(s.values["seed"], int)
        d = s.values["joint_damping_scale"]
        assert 1.0 <= d <= 10.0 and abs((d - 1.0) / 0.5 - round((d - 1.0) / 0.5)) < 1e-9


def test_randint_reaches_both_ends_and_choice_follows_weights():
    c = campaign(BASE.replace("samples = 8", "samples = 400") + FACTORS)
    samples = sampling.draw(c)
    seeds = {s.values["seed"] for s in samples}
    assert seeds == {1, 2, 3}
    flat = sum(s.values["terrain"] == "flat" for s in samples) / len(samples)
    assert abs(flat - 0.75) < 0.07  # 400 draws of p = 0.75: 3 standard deviations = 0.065


def test_each_factor_has_its_own_stream():
    a = sampling.draw(campaign(BASE + FACTORS))
    b = sampling.draw(campaign(BASE + FACTORS + """
[factors.vy_des]
dist = "uniform"
low = -0.1
high = 0.1
"""))
    for sa, sb in zip(a, b):
        assert {k: v for k, v in sb.values.items() if k != "vy_des"} == sa.values


def test_grid_crosses_every_cell_with_the_same_draws():
    c = campaign(BASE.replace("samples = 8", "samples = 3") + """
[factors.torso_mass_kg]
dist = "uniform"
low = 11.0
high = 20.0
[factors.vx_des]
dist = "grid"
values = [0.3, 0.6]
[factors.regulator.adaptation_enabled]
dist = "grid"
values = [true, false]
""")
    samples = sampling.draw(c)
    assert c.n_samples == len(samples) == 12
    assert [s.id for s in samples] == [f"s{i:04d}" for i in range(12)]
    cells = [(s.values["vx_des"], s.values["regulator.adaptation_enabled"]) for s in samples]
    assert cells[::3] == [(0.3, True), (0.3, False), (0.6, True), (0.6, False)]
    masses = [s.values["torso_mass_kg"] for s in samples]
    assert masses[0:3] == masses[3:6] == masses[9:12]


def test_sample_documents_apply_every_factor_and_round_trip():
    c = campaign(BASE.replace('"nominal"', '"push_fwd_30n"').replace("duration_s = 2.0", "duration_s = 4.0") + """
[factors.torso_com_offset_x_m]
dist = "uniform"
low = -0.05
high = 0.05
[factors.vx_des]
dist = "uniform"
low = 0.2
high = 0.8
[factors.push_t_s]
dist = "uniform"
low = 1.0
high = 1.5
[factors.push_force_y_n]
dist = "choice"
values = [-20.0, 20.0]
[factors.regulator.learning_rate]
dist = "uniform"
low = 0.00001
high = 0.0001
""")
    for sample in sampling.draw(c):
        text = sampling.sample_text(c, sample)
        doc = tomllib.loads(text)
        s = scenario_spec.parse_scenario(doc)
        v = sample.values
        assert s.torso_com_offset_m[0] == v["torso_com_offset_x_m"]
        assert s.commands[0].vx_des == v["vx_des"]
        assert s.pushes[0].t_s == v["push_t_s"] == s.perturbation_t_s and abs(v["push_t_s"] / 0.005 - round(v["push_t_s"] / 0.005)) < 1e-9
        assert s.pushes[0].force_n == (30.0, v["push_force_y_n"], 0.0)
        assert s.arm("adaptive").overrides_dict()["learning_rate"] == v["regulator.learning_rate"]
        assert s.arm("pd_only").overrides_dict()["adaptation_enabled"] is False
        assert s.claim is None and s.name == sample.id and "campaign" in s.tags


def test_toml_writer_round_trips_awkward_values():
    doc = {"name": "x", "description": 'quote " and \\ and \u00e9\nnewline', "f": 1e-05, "big": 1.5e300,
           "neg": -0.0, "b": False, "l": [1, 2.5, True], "t": {"a key": 1, "k": [0.1]},
           "arr": [{"x": 1, "inl": {"p": 0.5}}, {"x": 2}]}
    assert tomllib.loads(tomlw.dumps(doc, header="line 1\nline 2")) == doc
    with pytest.raises(ValueError, match="non-finite"):
        tomlw.dumps({"x": float("nan")})


# --------------------------------------------------------------------------- the folder
def _dir(root: Path, texts=None) -> CampaignDir:
    texts = texts or {"s0000": "a", "s0001": "b"}
    return CampaignDir(root, "c", texts, ["adaptive", "pd_only"], ["torso_mass_kg"])


def _row(sample, arm, status="complete", wall=1.0):
    return {"sample": sample, "arm": arm, "torso_mass_kg": 12.0, "status": status, "fell": False,
            "steady_state_error_vx": 0.01, "wall_s": wall}


def test_folder_refuses_other_campaign_rerun_without_resume_foreign_and_second_writer(tmp_path):
    d = _dir(tmp_path / "out")
    d.open(resume=False, campaign_file=None)
    with pytest.raises(CampaignDirError, match="another campaign process"):
        _dir(tmp_path / "out").open(resume=True, campaign_file=None)
    d.finish()
    d.close()
    with pytest.raises(CampaignDirError, match="already holds this campaign.*--resume"):
        _dir(tmp_path / "out").open(resume=False, campaign_file=None)
    for resume in (False, True):
        with pytest.raises(CampaignDirError, match="holds a different campaign"):
            _dir(tmp_path / "out", {"s0000": "a", "s0001": "changed"}).open(resume=resume, campaign_file=None)
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "notes.txt").write_text("mine")
    with pytest.raises(CampaignDirError, match="not empty and holds no campaign"):
        _dir(tmp_path / "foreign").open(resume=True, campaign_file=None)
    assert (tmp_path / "foreign" / "notes.txt").read_text() == "mine"


def test_resume_keeps_complete_samples_drops_the_rest_and_torn_lines(tmp_path):
    d = _dir(tmp_path)
    d.open(resume=False, campaign_file=None)
    d.append([_row("s0001", "adaptive"), _row("s0001", "pd_only")])
    d.append([_row("s0000", "adaptive"), _row("s0000", "pd_only", status="failed")])
    d.close()
    with open(d.csv_path, "a") as fh:
        fh.write("s0000,adaptive,12.0,compl")  # a crash in the middle of a line
    again = _dir(tmp_path)
    again.open(resume=True, campaign_file=None)
    assert again.complete_samples() == {"s0001"}
    assert [(r["sample"], r["arm"]) for r in again.rows()] == [("s0001", "adaptive"), ("s0001", "pd_only")]
    again.append([_row("s0000", "pd_only", wall=2.0), _row("s0000", "adaptive", wall=2.0)])
    again.finish()  # sorted by sample, then arm order
    assert [(r["sample"], r["arm"]) for r in again.rows()] == [
        ("s0000", "adaptive"), ("s0000", "pd_only"), ("s0001", "adaptive"), ("s0001", "pd_only")]
    assert set(TIMING_COLUMNS) <= set(again.cols)


def test_cli_refuses_invalid_campaign_and_foreign_folder(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(BASE + "[factors.joint_damping_scale]\ndist = \"uniform\"\nlow = 0.5\nhigh = 20.0\n")
    # one real process: the exit status a shell sees; the other calls run the same main() in this one
    cmd = [sys.executable, "-m", "scenarios", "campaign"]
    r = subprocess.run(cmd + [str(bad), "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "factors.joint_damping_scale = 20" in r.stderr and not (tmp_path / "o").exists()
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "x").write_text("")
    rc, _, err = campaign_in_process(capsys, "smoke", "--out", str(tmp_path / "taken"))
    assert rc == 2 and "holds no campaign" in err
    rc, listed, _ = campaign_in_process(capsys, "smoke", "--dry-run")
    assert rc == 0 and len(listed.splitlines()) == 5
    # --seed: the same design on other samples; the same seed, the same samples
    rc, other, _ = campaign_in_process(capsys, "smoke", "--dry-run", "--seed", "8")
    assert rc == 0 and len(other.splitlines()) == 5
    assert other.splitlines()[0] == listed.splitlines()[0] and other != listed
    assert campaign_in_process(capsys, "smoke", "--dry-run", "--seed", "8")[1] == other
    rc, _, err = campaign_in_process(capsys, "smoke", "--dry-run", "--seed", "-1")
    assert rc == 2 and "--seed -1: must be within [0, " in err


PARENT = BASE + """
[factors.torso_mass_kg]
dist = "uniform"
low = 11.0
high = 20.0
[factors.joint_damping_scale]
dist = "uniform"
low = 1.0
high = 3.0
[factors.link_mass_scale.left-shin]
dist = "uniform"
low = 0.8
high = 1.2
"""


def test_extends_lays_a_campaign_over_another(tmp_path):
    (tmp_path / "parent.toml").write_text(PARENT)
    (tmp_path / "child.toml").write_text("""extends = "parent.toml"
name = "child"
seed = 12
compare = ["adaptive"]
[factors.torso_mass_kg]  # a factor's table replaces the parent's whole
dist = "choice"
values = [12.0, 14.0]
[factors.link_mass_scale.right-shin]  # a table of factors merges: left-shin stays
dist = "uniform"
low = 0.9
high = 1.1
""")
    c = spec.load_campaign(tmp_path / "child.toml")
    p = spec.load_campaign(tmp_path / "parent.toml")
    assert (c.name, c.seed, c.samples, c.arm_names()) == ("child", 12, 8, ["adaptive"])
    f = {x.name: x for x in c.factors}
    assert (f["torso_mass_kg"].dist, f["torso_mass_kg"].values, f["torso_mass_kg"].low) == ("choice", (12.0, 14.0), None)
    assert f["joint_damping_scale"] == {x.name: x for x in p.factors}["joint_damping_scale"]
    assert {"link_mass_scale.left-shin", "link_mass_scale.right-shin"} <= set(f)
    # the run folder keeps the campaign as one file, which loads to the same campaign
    assert c.resolved_text.startswith(f"# {tmp_path / 'child.toml'} (extends = 'parent.toml')")
    assert p.resolved_text is None
    (tmp_path / "one.toml").write_text(c.resolved_text)
    one = spec.load_campaign(tmp_path / "one.toml")
    assert one.factors == c.factors and one.base_doc == c.base_doc and one.seed == 12
    d = CampaignDir(tmp_path / "run", "child", {"s0000": "a"}, ["adaptive"], ["torso_mass_kg"])
    d.open(resume=False, campaign_file=tmp_path / "child.toml", campaign_text=c.resolved_text)
    d.close()
    assert (tmp_path / "run" / "campaign.toml").read_text() == c.resolved_text
    # a chain: a grandchild over the child; base's relative file resolves where it was written
    (tmp_path / "sub").mkdir()
    (tmp_path / "base.toml").write_text((REPO_ROOT / "scenarios" / "suite" / "nominal.toml").read_text())
    (tmp_path / "child.toml").write_text('extends = "parent.toml"\nname = "child"\nbase = "base.toml"\n')
    (tmp_path / "sub" / "grand.toml").write_text('extends = "../child.toml"\nname = "grand"\nsamples = 2\n')
    g = spec.load_campaign(tmp_path / "sub" / "grand.toml")
    assert (g.name, g.samples) == ("grand", 2) and Path(g.base_ref).resolve() == (tmp_path / "base.toml").resolve()
    # drop: the parent's keys removed before the laying over
    (tmp_path / "dropper.toml").write_text('extends = "parent.toml"\nname = "dropper"\n'
                                          'drop = ["factors.joint_damping_scale", "factors.link_mass_scale.left-shin"]\n')
    d = spec.load_campaign(tmp_path / "dropper.toml")
    assert [f.name for f in d.factors] == ["torso_mass_kg"]


def test_extends_problems_are_named(tmp_path):
    def found(text, where=tmp_path):
        with pytest.raises(ScenarioError) as info:
            spec.parse_campaign(tomllib.loads(text), source="t.toml", base_dir=where)
        return info.value.problems
    assert any("extends = 'robustness_randon'" in p and "no such campaign" in p and "robustness_random" in p
               for p in found('extends = "robustness_randon"\nname = "x"\n'))
    assert any("extends = 'nope.toml'" in p for p in found('extends = "nope.toml"\nname = "x"\n'))
    assert any("extends: a campaign that extends another gives its own name" in p
               for p in found('extends = "smoke"\n'))
    assert any("extends = 3" in p for p in found('extends = 3\nname = "x"\n'))
    (tmp_path / "a.toml").write_text('extends = "b.toml"\nname = "a"\n')
    (tmp_path / "b.toml").write_text('extends = "a.toml"\nname = "b"\n')
    assert any("extends itself: a.toml -> b.toml -> a.toml" in p for p in found('extends = "a.toml"\nname = "x"\n'))
    assert any("drop = 'factors.nope': is not a key of smoke" in p
               for p in found('extends = "smoke"\nname = "x"\ndrop = ["factors.nope", "seed"]\n', where=spec.CAMPAIGN_DIR))
    assert any("drop = ['seed']" in p and "give extends too" in p for p in found('name = "x"\ndrop = ["seed"]\n'))
    assert any("drop = 'seed'" in p and "must be a list" in p
               for p in found('extends = "smoke"\nname = "x"\ndrop = "seed"\n', where=spec.CAMPAIGN_DIR))
    # a problem of the laid-over whole names its field
    assert any("samples = 0" in p for p in found('extends = "smoke"\nname = "x"\nsamples = 0\n',
                                                   where=spec.CAMPAIGN_DIR))


STUDY = BASE + 'default_variant = "one"\n' + PARENT[len(BASE):] + """
[variants.one]
seed = 21
[variants.two]
seed = 22
compare = ["adaptive"]
drop = ["factors.joint_damping_scale"]
[variants.two.factors.torso_mass_kg]  # a factor's table replaces the file's whole
dist = "choice"
values = [12.0, 14.0]
"""


def test_variants_are_the_file_with_one_variant_laid_over_it(tmp_path):
    (tmp_path / "study.toml").write_text(STUDY)
    one, default = spec.load_campaign(tmp_path / "study.toml", "one"), spec.load_campaign(tmp_path / "study.toml")
    assert default == one  # default_variant
    assert (one.name, one.variant, one.seed, one.samples, one.arm_names()) == ("c_one", "one", 21, 8, ["adaptive", "pd_only"])
    assert {f.name for f in one.factors} == {"torso_mass_kg", "joint_damping_scale", "link_mass_scale.left-shin"}
    two = spec.load_campaign(tmp_path / "study.toml", "two")
    assert (two.name, two.variant, two.seed, two.arm_names()) == ("c_two", "two", 22, ["adaptive"])
    f = {x.name: x for x in two.factors}
    assert set(f) == {"torso_mass_kg", "link_mass_scale.left-shin"}
    assert (f["torso_mass_kg"].dist, f["torso_mass_kg"].values, f["torso_mass_kg"].low) == ("choice", (12.0, 14.0), None)
    # the run folder keeps the variant as one file (no variants left), which loads to the same campaign
    assert two.resolved_text.startswith(f"# {tmp_path / 'study.toml'} (variant 'two'), resolved into one file\n")
    doc = tomllib.loads(two.resolved_text)
    assert "variants" not in doc and "default_variant" not in doc and doc["name"] == "c_two"
    (tmp_path / "one.toml").write_text(two.resolved_text)
    again = spec.load_campaign(tmp_path / "one.toml")
    assert (again.name, again.factors, again.base_doc, again.seed, again.variant) == \
        (two.name, two.factors, two.base_doc, two.seed, None)
    assert sampling.build_samples(again) == sampling.build_samples(two)
    # a campaign laid over a study (extends) keeps its variants
    (tmp_path / "child.toml").write_text('extends = "study.toml"\nname = "kid"\n[variants.two]\nseed = 23\n')
    kid = spec.load_campaign(tmp_path / "child.toml", "two")
    assert (kid.name, kid.seed, kid.arm_names()) == ("kid_two", 23, ["adaptive"])
    assert kid.resolved_text.startswith(f"# {tmp_path / 'child.toml'} (extends = 'study.toml', variant 'two')")


def test_variant_problems_are_named_and_listed_at_once():
    def found(text, variant=None):
        with pytest.raises(ScenarioError) as info:
            spec.parse_campaign(tomllib.loads(text), source="t.toml", base_dir=REPO_ROOT, variant=variant)
        return info.value.problems
    assert found(STUDY, "tow") == ["variant = 'tow': no such variant of 'c'; did you mean 'two'?; variants: one (default), two"]
    assert found(STUDY, "xyz") == ["variant = 'xyz': no such variant of 'c'; variants: one (default), two"]
    assert found(BASE + FACTORS, "one") == ["variant = 'one': 'c' has no variants (no [variants.NAME] tables)"]
    assert found(STUDY.replace('default_variant = "one"', 'default_variant = "three"'), "two") == [
        "default_variant = 'three': must name one of the variants: one, two"]
    assert found(STUDY.replace('default_variant = "one"\n', '')) == [
        "default_variant: required with [variants]: the variant run without one named (one, two)"]
    assert found(BASE + 'default_variant = "one"\n' + FACTORS) == [
        "default_variant = 'one': names one of the [variants.NAME] tables: give them too"]
    assert any("variants = 3" in p and "must be a table of [variants.NAME] tables" in p
               for p in found(BASE.replace('name = "c"', 'name = "c"\nvariants = 3') + FACTORS))
    bad = found(STUDY + '[variants.Two]\nseed = 1\n[variants.one.bogus]\n', "one")
    assert "variants.Two = 'Two': the name must match [a-z0-9][a-z0-9_-]* (it names the campaign)" in bad
    assert any(p.startswith("variants.one.bogus: unknown key") for p in bad)
    named = found(STUDY.replace("seed = 21", 'seed = 21\nname = "x"\ndrop = ["factors.nope"]'), "one")
    assert any(p.startswith("variants.one.name: unknown key") for p in named)
    assert "variants.one.drop = 'factors.nope': is not a key of 'c'" in named
    # a problem of the laid-over whole names its field
    assert any("samples = 0" in p for p in found(STUDY.replace("seed = 22", "seed = 22\nsamples = 0"), "two"))


# --------------------------------------------------------------------------- statistics
def test_wilson_interval_and_quantile():
    lo, hi = analysis.wilson(0, 10)
    assert lo == 0.0 and abs(hi - 0.2775) < 1e-3  # the textbook value for 0/10
    lo, hi = analysis.wilson(5, 10)
    assert abs(lo - 0.2366) < 1e-3 and abs(hi - 0.7634) < 1e-3
    assert analysis.wilson(0, 0) is None
    vals = [3.0, 1.0, 4.0, 1.0, 5.0]
    for q in (0.0, 0.5, 0.9, 1.0):
        assert analysis.quantile(vals, q) == pytest.approx(float(np.quantile(vals, q)))


def test_arm_stats_and_paired_comparison():
    def r(sample, arm, fell, sse, status="complete"):
        return {"sample": sample, "arm": arm, "status": status, "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None if fell else sse, "steady_state_error_vy": None if fell else 0.01,
                "convergence_time_s": 2.0 if sse is not None and sse < 0.05 else None}
    rows = [r("a", "adaptive", False, 0.02), r("a", "pd_only", False, 0.05),
            r("b", "adaptive", True, None), r("b", "pd_only", False, 0.04),
            r("c", "adaptive", False, 0.03), r("c", "pd_only", True, None),
            r("d", "adaptive", False, 0.06), r("d", "pd_only", False, 0.01),
            r("e", "adaptive", None, None, status="failed"), r("e", "pd_only", False, 0.02)]
    s = analysis.arm_stats(rows, "adaptive")
    assert (s["complete"], s["failed"], s["fell"], s["walked"]) == (4, 1, 1, 3)
    assert s["fall_rate"] == 0.25 and s["steady_state_error_vx"]["p50"] == 0.03
    assert s["converged"] == 2
    p = analysis.paired(rows, "adaptive", "pd_only")
    assert p["n"] == 4 and p["only_a_fell"] == ["b"] and p["only_b_fell"] == ["c"]
    assert p["both_walked"] == 2 and p["a_lower_vx"] == 1 and p["a_lower_vy"] == 0 and p["median_diff_vy"] == 0.0
    assert [x[0] for x in p["not_better"]] == ["b", "d"]
    assert [w["sample"] for w in analysis.worst(rows, "adaptive", 2)] == ["b", "d"]


def test_paired_verdicts_never_falls_where_pd_walks_and_beats_pd():
    def r(sample, arm, fell, sse):
        return {"sample": sample, "arm": arm, "status": "complete", "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None if fell else sse, "steady_state_error_vy": None if fell else 0.01,
                "convergence_time_s": None}
    # 19 wins (one by a PD fall), one sample both fell (no contest): 19/19 contested
    rows = [x for i in range(18) for x in (r(f"w{i}", "adaptive", False, 0.02), r(f"w{i}", "pd_only", False, 0.1))]
    rows += [r("pf", "adaptive", False, 0.03), r("pf", "pd_only", True, None),
             r("bf", "adaptive", True, None), r("bf", "pd_only", True, None)]
    v = analysis.verdicts(rows, "adaptive", "pd_only")
    assert v["never_falls_where_b_walks"] and v["beats"] and (v["wins"], v["contested"]) == (19, 19)
    assert v["win_ci"][1] == 1.0 and abs(v["win_ci"][0] - 0.8235) < 1e-3  # exact 95 % for 19/19: (0.8235, 1]
    lo, hi = v["median_diff_ci"]
    assert lo == hi == pytest.approx(-0.08)
    # one sample where adaptive falls and PD walks, one where PD is better: both verdicts fail
    rows += [r("af", "adaptive", True, None), r("af", "pd_only", False, 0.1),
             r("pb", "adaptive", False, 0.2), r("pb", "pd_only", False, 0.1)]
    v = analysis.verdicts(rows, "adaptive", "pd_only")
    assert not v["never_falls_where_b_walks"] and v["only_a_fell"] == ["af"]
    assert (v["wins"], v["contested"]) == (19, 21) and v["beats"]  # 19/21 = 90.5 % >= 90 %
    rows += [r("pb2", "adaptive", False, 0.3), r("pb2", "pd_only", False, 0.1)]
    v = analysis.verdicts(rows, "adaptive", "pd_only")
    assert (v["wins"], v["contested"]) == (19, 22) and not v["beats"]  # 86.4 %
    assert [x[0] for x in v["not_won"]] == ["af", "pb", "pb2"]


def test_replicated_verdicts_judge_each_sample_over_its_paired_replicas():
    def r(sample, arm, fell, err):
        return {"sample": sample, "arm": arm, "status": "complete", "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None if fell else 9.0,  # not the metric compared below
                "settled_error_vx": None if fell else err, "steady_state_error_vy": None, "convergence_time_s": None}
    a_arms, b_arms = ("ad", "ad_2", "ad_3"), ("pd", "pd_2", "pd_3")

    def sample(name, a, b):  # a, b: per replica None (fell) or the settled error
        return [r(name, x, e is None, e) for x, e in zip(a_arms, a)] + \
               [r(name, y, e is None, e) for y, e in zip(b_arms, b)]
    rows = (sample("won", (0.01, 0.02, 0.5), (0.1, 0.1, 0.1))  # 2 of 3 pairs won
            + sample("lost", (0.01, 0.5, 0.5), (0.1, 0.1, 0.1))  # 1 of 3
            + sample("pd_falls", (None, 0.2, 0.2), (None, None, 0.1))  # pairs: no contest, won, lost: 1 of 2
            + sample("both_fall", (None, None, None), (None, None, None))  # no contest
            + sample("ad_edge", (None, 0.01, 0.01), (0.1, 0.1, 0.1))  # fell on 1 of 3, PD on none: 2 of 3 won
            + sample("ad_falls", (None, None, 0.01), (0.1, 0.1, 0.1))  # fell on 2 of 3 where PD walked on all
            + sample("pd_once", (None, None, None), (None, 0.1, 0.1)))  # fell on 3 of 3, PD on 1 of 3
    v = analysis.verdicts(rows, "ad", "pd", metric="settled_error_vx", replicas_a=a_arms[1:], replicas_b=b_arms[1:])
    assert v["replicas"] == 3 and v["n"] == 7 and v["contested"] == 6
    assert v["wins"] == 2 and [x[0] for x in v["not_won"]] == ["ad_falls", "lost", "pd_falls", "pd_once"]
    assert ("pd_falls", 1, 2, 1, 2) in v["not_won"]  # (sample, pairs won, contested, falls of a, falls of b)
    # the same majority reading for both arms: PD-only falling on one replica of three does
    # not excuse adaptive falling on all three; PD-only falling on most (pd_falls) does
    assert v["only_a_fell"] == ["ad_falls", "pd_once"] and not v["never_falls_where_b_walks"]
    assert v["a_fell_some"] == [("ad_edge", 1), ("ad_falls", 2)]
    # pooled over the 10 pairs both walked: -0.09 five times, -0.08, 0.1, 0.4 three times
    assert v["median_diff"] == pytest.approx(-0.085)
    # one replica per arm is the unreplicated verdict; the metric is the one named
    one = analysis.verdicts(rows, "ad", "pd", metric="settled_error_vx")
    assert one["replicas"] == 1 and one["only_a_fell"] == ["ad_edge", "ad_falls"]
    assert analysis.verdicts(rows, "ad", "pd")["median_diff"] == 0.0  # steady_state_error_vx: 9.0 both
    with pytest.raises(ValueError, match="pair by position"):
        analysis.verdicts(rows, "ad", "pd", replicas_a=a_arms[1:], replicas_b=b_arms[1:2])


def test_mcnemar_exact_matches_the_binomial_test():
    # values of a two-sided exact binomial test with p = 1/2 (scipy.stats.binomtest)
    assert analysis.mcnemar_exact(4, 11) == pytest.approx(0.11846923828125)
    assert analysis.mcnemar_exact(0, 6) == pytest.approx(0.03125)
    assert analysis.mcnemar_exact(3, 3) == 1.0 and analysis.mcnemar_exact(0, 0) is None


def test_chance_level_of_never_falls_swaps_the_runs_of_each_pair():
    """The chance level of the "never falls where b walks" reading: each pair's two runs
    swapped with probability 1/2. Tolerances: 2000 swaps give a standard error of
    sqrt(0.25 / 2000) = 0.011 on a rate of 1/2; 0.04 is over 3.5 of them."""
    swapped = analysis.swapped_only_a_fell
    # concordant pairs only (both fell or both walked): no swap changes anything
    assert swapped([([True, False, True], [True, False, True])] * 4, 0) == {
        "mean": 0.0, "low": 0.0, "high": 0.0, "at_least_observed": 1.0}
    # a fell on 5 of 5, b on none: a swap gives a Binomial(5, 1/2) falls, b the rest; listed iff a >= 3
    one = swapped([([True] * 5, [False] * 5)], 1)
    assert one["mean"] == pytest.approx(0.5, abs=0.04) and one["at_least_observed"] == pytest.approx(0.5, abs=0.04)
    # ten such samples: the count is Binomial(10, 1/2), 5 on average
    ten = swapped([([True] * 5, [False] * 5)] * 10, 10)
    assert ten["mean"] == pytest.approx(5.0, abs=0.15) and 1.0 <= ten["low"] <= 3.0 and 7.0 <= ten["high"] <= 9.0
    assert ten["at_least_observed"] < 0.01  # 10 of 10: 1/1024 by chance
    assert swapped([([True] * 5, [False] * 5)] * 10, 10) == ten  # fixed seed
    assert swapped([], 0) is None
    # in the verdicts, beside the count it qualifies
    rows = [{"sample": f"s{i}", "arm": arm, "status": "complete", "fell": fell, "steady_state_error_vx": 0.1}
            for i in range(3) for arm, fell in (("ad", i == 0), ("pd", False))]
    v = analysis.verdicts(rows, "ad", "pd")
    assert v["only_a_fell"] == ["s0"] and v["only_a_fell_null"]["mean"] == pytest.approx(0.5, abs=0.04)


def test_fall_agreement_counts_falls_against_the_reference_arm():
    def r(sample, arm, fell):
        return {"sample": sample, "arm": arm, "status": "complete", "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None if fell else 0.05, "steady_state_error_vy": None,
                "convergence_time_s": None}
    falls = {"s1": (True, False, False), "s2": (False, True, True), "s3": (True, True, False),
             "s4": (False, False, True), "s5": (False, True, False)}
    rows = [r(s, arm, f) for s, fs in falls.items() for arm, f in zip(("adaptive", "pd_only", "pd_gain"), fs)]
    rows.append({**r("s6", "adaptive", True), "status": "failed"})  # not paired
    got = {g["arm"]: g for g in analysis.fall_agreement(rows, "pd_only", ["adaptive", "pd_only", "pd_gain"])}
    assert set(got) == {"adaptive", "pd_gain"}
    assert got["adaptive"]["only_arm_fell"] == ["s1"] and got["adaptive"]["only_b_fell"] == ["s2", "s5"]
    assert got["pd_gain"]["only_arm_fell"] == ["s4"] and got["pd_gain"]["only_b_fell"] == ["s3", "s5"]
    assert got["adaptive"]["n"] == 5 and got["adaptive"]["p_value"] == 1.0


def test_report_tables_every_arm_against_the_second_on_falls(tmp_path):
    from scenarios.campaign import report

    def r(sample, arm, fell):
        return {"sample": sample, "arm": arm, "status": "complete", "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None if fell else 0.05, "steady_state_error_vy": None,
                "convergence_time_s": None, "run_dir": None}
    falls = {"s1": (True, False, False), "s2": (False, True, True), "s3": (False, True, False)}
    arms = ["adaptive", "pd_only", "pd_gain"]
    rows = [r(s, arm, f) for s, fs in falls.items() for arm, f in zip(arms, fs)]
    data = analysis.CampaignData(tmp_path, {"name": "t", "n_samples": 3, "arms": arms}, rows, [])
    text = report.render(data, [])
    assert "| adaptive | 3 | 1 | 2 | 1 | s1 |" in text
    assert "| pd_gain | 3 | 0 | 1 | 1 | none |" in text
    two = report.render(analysis.CampaignData(tmp_path, {"name": "t", "n_samples": 3, "arms": arms[:2]},
                                              [x for x in rows if x["arm"] != "pd_gain"], []), [])
    assert "McNemar" not in two  # one pair only: the verdicts say it all


def test_report_gives_the_replicated_verdicts_and_every_sample_not_won(tmp_path):
    from scenarios.campaign import report

    def r(sample, arm, fell, err):
        return {"sample": sample, "arm": arm, "status": "complete", "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None if fell else 0.05, "steady_state_error_vy": None,
                "settled_error_vx": None if fell else err, "convergence_time_s": None, "run_dir": None}
    arms = ["adaptive", "pd_only", "adaptive_k2", "pd_k2"]
    outcomes = {"s1": (0.01, 0.1, 0.01, 0.1), "s2": (None, 0.1, None, 0.1), "s3": (0.2, 0.1, 0.01, 0.1)}
    rows = [r(s, arm, e is None, e) for s, es in outcomes.items() for arm, e in zip(arms, es)]
    manifest = {"name": "t", "n_samples": 3, "arms": arms, "seed": 2022, "metric": "settled_error_vx",
                "replicas": {"adaptive": ["adaptive_k2"], "pd_only": ["pd_k2"]}}
    text = report.render(analysis.CampaignData(tmp_path, manifest, rows, []), [])
    assert "3 samples (drawn from seed 2022) x 4 arms" in text
    assert "runs adaptive and pd_only 2 times each" in text and "adaptive, adaptive_k2 against pd_only, pd_k2" in text
    assert "never falls where pd_only walks: FAIL** (samples where adaptive fell on more than half of the 2 replicas and pd_only on fewer than half" in text
    assert "s2 (2/2)" in text
    assert "beats pd_only on >= 90 % of paired samples: FAIL** (1 of 3 samples" in text
    # s3: 1 of 2 pairs won is not more than half; the table gives both arms' mean settled error
    assert "| [s3](samples/s3.toml) | 1/2 | 0/2 | 0/2 | 0.105 | 0.100 |" in text
    assert "| [s2](samples/s2.toml) | 0/2 | 2/2 | 0/2 | - | 0.100 |" in text


def test_report_judges_a_draw_over_its_grounds(tmp_path):
    """replicate_over: samples s0..s5 are 2 draws on 3 grounds; the verdicts take each draw
    over its grounds (draw s0: s0, s2, s4; draw s1: s1, s3, s5)."""
    from scenarios.campaign import report

    def r(sample, arm, fell, err):
        return {"sample": sample, "arm": arm, "status": "complete", "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None, "steady_state_error_vy": None,
                "settled_error_vx": None if fell else err, "convergence_time_s": None, "run_dir": None}
    # draw 0: adaptive falls on the first ground only; draw 1: adaptive falls on two grounds, PD on none
    outcomes = {"s0000": (None, 0.1), "s0002": (0.01, 0.1), "s0004": (0.01, 0.1),
                "s0001": (None, 0.1), "s0003": (None, 0.1), "s0005": (0.01, 0.1)}
    rows = [r(s, arm, e is None, e) for s, es in outcomes.items() for arm, e in zip(("adaptive", "pd_only"), es)]
    manifest = {"name": "t", "n_samples": 6, "arms": ["adaptive", "pd_only"], "seed": 1, "metric": "settled_error_vx",
                "replicas": {}, "replicate_over": {"factor": "floor_terrain_seed", "draws": 2, "cells": [3], "index": 0}}
    data = analysis.CampaignData(tmp_path, manifest, rows, [])
    assert data.replicas("adaptive") == ["adaptive@1", "adaptive@2"]
    text = report.render(data, [])
    assert "Each random draw runs on the 3 values of the grid factor `floor_terrain_seed`" in text
    assert ("never falls where pd_only walks: FAIL** (samples where adaptive fell on more than half of the 3 "
            "replicas and pd_only on fewer than half: 1 of 2") in text
    assert "[s0001](samples/s0001.toml)" in text and "s0000 (1/3)" in text
    # chance lists draw s1 (two of its three pairs: only adaptive fell) when neither is swapped: 1 in 4
    assert "Chance level: with the two runs of each pair swapped at random (2000 times)" in text
    assert "beats pd_only on >= 90 % of paired samples: FAIL** (1 of 2 samples" in text


def test_report_gives_the_never_reading_of_every_arm_against_the_reference(tmp_path):
    """With replicas, the report lists for every arm (a control arm too) the draws the
    "never falls where pd_only walks" reading lists, beside that reading's chance level."""
    from scenarios.campaign import report

    def r(sample, arm, fell):
        return {"sample": sample, "arm": arm, "status": "complete", "fell": fell, "t_fall_s": 3.0 if fell else None,
                "steady_state_error_vx": None, "steady_state_error_vy": None,
                "settled_error_vx": None if fell else 0.05, "convergence_time_s": None, "run_dir": None}
    arms = ["adaptive", "pd_only", "pd_gain"]
    # 2 draws on 3 grounds (draw 0: s0000, s0002, s0004; draw 1: s0001, s0003, s0005). pd_gain
    # falls on two grounds of draw 1 where pd_only walks; adaptive falls once where pd_only does.
    falls = {"s0000": (False, False, False), "s0002": (True, True, False), "s0004": (False, False, False),
             "s0001": (False, False, True), "s0003": (False, False, True), "s0005": (False, False, False)}
    rows = [r(s, arm, f) for s, fs in falls.items() for arm, f in zip(arms, fs)]
    manifest = {"name": "t", "n_samples": 6, "arms": arms, "seed": 1, "metric": "settled_error_vx", "replicas": {},
                "replicate_over": {"factor": "floor_terrain_seed", "draws": 2, "cells": [3], "index": 0}}
    text = report.render(analysis.CampaignData(tmp_path, manifest, rows, []), [])
    assert 'The "never falls where pd_only walks" reading for every arm against pd_only' in text
    rows_of = {x.split(" | ")[0]: x for x in text.splitlines() if x.startswith(("| adaptive | 2 | ", "| pd_gain | 2 | "))}
    assert rows_of["| adaptive"].startswith("| adaptive | 2 | 0 | ") and rows_of["| adaptive"].endswith("| none |")
    # pd_gain: draw s0001 listed; swapping its two runs of each pair lists it when neither of the
    # two falling pairs is swapped: 1 in 4 on average, and at least one listed in 1 of 4 swaps
    line = rows_of["| pd_gain"]
    assert line.startswith("| pd_gain | 2 | 1 | ") and line.endswith("| s0001 |")
    mean, share = float(line.split(" | ")[3].split(" ")[0]), float(line.split("; ")[1].split(" %")[0])
    # (the mean is printed to one decimal; 2000 swaps put the share within 3 points of 25 %)
    assert mean in (0.2, 0.3) and share == pytest.approx(25, abs=3)
    # without replicas the verdicts' own reading is the single run's, and no such table is given
    flat = {**manifest, "replicate_over": None}
    assert "reading for every arm" not in report.render(analysis.CampaignData(tmp_path, flat, rows, []), [])


def _nominal_doc() -> dict:
    return tomllib.loads((REPO_ROOT / "scenarios" / "suite" / "nominal.toml").read_text())


def test_campaign_metric_and_replicas_are_checked_up_front():
    doc = {"name": "c", "samples": 2, "seed": 1, "base": "nominal", "compare": ["adaptive", "pd_only", "a2", "p2"],
           "factors": {"torso_mass_kg": {"dist": "uniform", "low": 12.0, "high": 14.0}},
           "metric": "sse", "replicas": {"adaptive": ["a2", "nope"], "pd_only": "p2", "rl_hzd": ["p2"]}}
    doc_arms = [{"name": "a2", "regulator": {"Kp_x": 0.09}},
                {"name": "p2", "regulator": {"adaptation_enabled": False, "Kp_x": 0.09}}]
    with pytest.raises(ScenarioError) as exc:
        spec.parse_campaign({**doc, "base": {**_nominal_doc(), "arm": doc_arms}})
    found = exc.value.problems
    assert any("metric = 'sse'" in p and "steady_state_error_vx, settled_error_vx" in p for p in found)
    assert any("replicas.adaptive = 'nope'" in p and "not an arm of compare" in p for p in found)
    assert any("replicas.pd_only = 'p2'" in p and "non-empty list" in p for p in found)
    assert any("replicas.rl_hzd" in p and "not an arm of compare" in p for p in found)
    # unequal replica counts of the verdicts' arms, reported with an unrelated problem too
    with pytest.raises(ScenarioError) as exc:
        spec.parse_campaign({**doc, "base": {**_nominal_doc(), "arm": doc_arms}, "metric": "settled_error_vx",
                             "replicas": {"adaptive": ["a2"]}, "retries": 99})
    assert any("give both the same number" in p for p in exc.value.problems)
    assert any("retries = 99" in p for p in exc.value.problems)
    # an arm twice: one problem
    with pytest.raises(ScenarioError) as exc:
        spec.parse_campaign({**doc, "base": {**_nominal_doc(), "arm": doc_arms}, "metric": "settled_error_vx",
                             "replicas": {"adaptive": ["a2", "a2"], "pd_only": ["p2", "pd_only"]}})
    assert [p for p in exc.value.problems if "replicas." in p] == [
        "replicas.adaptive = 'a2': is already a replica", "replicas.pd_only = 'pd_only': is already an arm with replicas"]
    c = spec.parse_campaign({**doc, "base": {**_nominal_doc(), "arm": doc_arms}, "metric": "settled_error_vx",
                             "replicas": {"adaptive": ["a2"], "pd_only": ["p2"]}})
    assert c.analysis_settings() == {"seed": 1, "metric": "settled_error_vx",
                                     "replicas": {"adaptive": ["a2"], "pd_only": ["p2"]}, "replicate_over": None,
                                     "confirm_runs": 0}


GROUND_FACTORS = """
[factors.torso_mass_kg]
dist = "uniform"
low = 11.0
high = 20.0
[factors.model]
dist = "grid"
values = ["menagerie", "osu"]
[factors.floor_terrain_seed]
dist = "grid"
values = [7, 8, 9]
"""


def grounds(top: str = 'replicate_over = "floor_terrain_seed"\n', factors: str = GROUND_FACTORS) -> str:
    """3 draws x 2 models x 3 grounds; ``top``: top-level keys (before the tables)."""
    return BASE.replace("samples = 8", "samples = 3") + top + factors


def test_replicate_over_names_a_grid_factor_and_excludes_replicas():
    found = problems_of(grounds('replicate_over = "torso_mass_kg"\n'))
    assert found == ["replicate_over = 'torso_mass_kg': must name a grid factor of at least two values "
                     "(model, floor_terrain_seed)"]
    assert any("replicate_over = 'nope'" in p for p in problems_of(grounds('replicate_over = "nope"\n')))
    one_value = grounds(factors=GROUND_FACTORS.replace("values = [7, 8, 9]", "values = [7]"))
    assert any("replicate_over = 'floor_terrain_seed': must name a grid factor of at least two values (model)" in p
               for p in problems_of(one_value))
    both = grounds() + '[replicas]\nadaptive = ["pd_only"]\n'
    assert any("give [replicas] or replicate_over, not both" in p for p in problems_of(both))
    c = campaign(grounds())
    over = c.analysis_settings()["replicate_over"]
    assert over == {"factor": "floor_terrain_seed", "draws": 3, "cells": [2, 3],
                    "index": [f.name for f in c.grid].index("floor_terrain_seed"), "redraw": []}


def test_replicate_over_regroups_each_draw_over_the_factor_values():
    c = campaign(grounds())
    samples = sampling.draw(c)
    assert len(samples) == 18  # 3 draws x 2 models x 3 grounds
    over = c.analysis_settings()["replicate_over"]
    rows = [{"sample": s.id, "arm": arm, "status": "complete", "values": s.values}
            for s in samples for arm in ("adaptive", "pd_only")]
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in analysis.regroup(rows, over["draws"], over["cells"], over["index"]):
        groups.setdefault((r["sample"], r["arm"].split("@")[0]), []).append(r)
    assert len(groups) == 3 * 2 * 2  # draws x models x arms
    by_id = {s.id: s.values for s in samples}
    for (name, arm), members in groups.items():
        assert sorted(m["arm"] for m in members) == [arm, f"{arm}@1", f"{arm}@2"]
        # one draw on one model: everything but the ground is the same
        assert len({(m["values"]["model"], m["values"]["torso_mass_kg"]) for m in members}) == 1
        assert {m["arm"]: m["values"]["floor_terrain_seed"] for m in members} == {arm: 7, f"{arm}@1": 8, f"{arm}@2": 9}
        assert by_id[name]["floor_terrain_seed"] == 7 and by_id[name]["model"] == members[0]["values"]["model"]


NUISANCE_FACTOR = """
[factors.joint_damping_scale]
dist = "uniform"
low = 1.0
high = 3.0
"""


def test_redraw_names_random_factors_and_needs_replicate_over():
    over = 'replicate_over = "floor_terrain_seed"\n'
    found = problems_of(grounds('redraw = ["torso_mass_kg"]\n'))
    assert found == ["redraw = ['torso_mass_kg']: redraws factors per value of replicate_over: give replicate_over too"]
    found = problems_of(grounds(over + 'redraw = ["model", "nope", "torso_mass_kg", "torso_mass_kg"]\n'))
    allowed = "must be one of the campaign's uniform, randint or choice factors (torso_mass_kg)"
    assert found == [f"redraw = 'model': {allowed}", f"redraw = 'nope': {allowed}",
                     "redraw = 'torso_mass_kg': is listed twice"]
    assert problems_of(grounds(over + 'redraw = "torso_mass_kg"\n')) == [
        "redraw = 'torso_mass_kg': must be a list of the campaign's uniform, randint or choice factors (torso_mass_kg)"]
    # reported beside an unrelated problem of the same file
    found = problems_of(grounds(over + 'redraw = ["nope"]\nretries = 99\n'))
    assert any(p.startswith("redraw = 'nope'") for p in found) and any("retries = 99" in p for p in found)


def test_redraw_gives_each_replica_its_own_draw_of_the_nuisance():
    """Each draw on 3 grounds: torso_mass_kg drawn anew on grounds 8 and 9, joint_damping_scale
    not; the first ground keeps the draws the campaign has without redraw."""
    plain = sampling.draw(campaign(grounds(factors=GROUND_FACTORS + NUISANCE_FACTOR)))
    c = campaign(grounds('replicate_over = "floor_terrain_seed"\nredraw = ["torso_mass_kg"]\n',
                         GROUND_FACTORS + NUISANCE_FACTOR))
    assert c.redraw == ("torso_mass_kg",) and c.analysis_settings()["replicate_over"]["redraw"] == ["torso_mass_kg"]
    samples = sampling.draw(c)
    assert [s.values for s in samples] == [s.values for s in sampling.draw(c)]  # same seed, same draws
    over = c.analysis_settings()["replicate_over"]
    rows = [{"sample": s.id, "arm": "adaptive", "values": s.values} for s in samples]
    groups: dict[str, list[dict]] = {}
    for r in analysis.regroup(rows, over["draws"], over["cells"], over["index"]):
        groups.setdefault(r["sample"], []).append(r["values"])
    plain_by_id = {s.id: s.values for s in plain}
    masses_by_ground: dict[int, list[float]] = {}
    for name, members in groups.items():
        assert len(members) == 3
        assert members[0] == plain_by_id[name]  # the first ground: as without redraw
        assert len({m["joint_damping_scale"] for m in members}) == 1  # not redrawn: one robot
        assert len({m["model"] for m in members}) == 1
        masses = [m["torso_mass_kg"] for m in members]
        assert len(set(masses)) == 3 and all(11.0 <= x <= 20.0 for x in masses)
        for m in members:
            masses_by_ground.setdefault(m["floor_terrain_seed"], []).append(m["torso_mass_kg"])
    # the redrawn column is one per ground, shared by the other grid cells (both models)
    for ground, masses in masses_by_ground.items():
        assert len(set(masses)) == 3, ground


def test_the_folder_records_the_report_settings_and_a_resume_follows_the_campaign_file(tmp_path):
    settings = {"metric": "settled_error_vx", "replicas": {"adaptive": ["a2"], "pd_only": ["p2"]}}
    d = CampaignDir(tmp_path, "c", {"s0000": "a"}, ["adaptive", "pd_only"], ["torso_mass_kg"], settings)
    d.open(resume=False, campaign_file=None)
    d.finish()
    d.close()
    assert analysis.load(tmp_path).metric == "settled_error_vx"
    assert analysis.load(tmp_path).replicas("pd_only") == ["p2"]
    d = CampaignDir(tmp_path, "c", {"s0000": "a"}, ["adaptive", "pd_only"], ["torso_mass_kg"],
                    {"metric": "steady_state_error_vx", "replicas": {}})
    d.open(resume=True, campaign_file=None)
    d.close()
    data = analysis.load(tmp_path)
    assert data.metric == "steady_state_error_vx" and data.replicas("pd_only") == []


def test_a_folder_written_with_other_columns_is_refused_naming_them(tmp_path):
    d = _dir(tmp_path)
    d.open(resume=False, campaign_file=None)
    d.close()
    csv_path = tmp_path / "campaign.csv"
    header, *rest = csv_path.read_text().splitlines()
    csv_path.write_text("\n".join([header.replace(",settled_error_vx", ""), *rest]) + "\n")
    with pytest.raises(CampaignDirError, match="missing: settled_error_vx; not expected: none"):
        _dir(tmp_path).open(resume=True, campaign_file=None)
