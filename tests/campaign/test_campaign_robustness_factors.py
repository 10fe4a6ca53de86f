"""Campaign factors for what robustness studies randomize: the model, floor friction and
shape, link masses, seeded command profiles and several seeded random pushes; and the
built-in robustness_random study built on them, one file with its variants (ramp, control,
default_rule), each equal to the campaign it replaces (frozen from git commit e24b83a)."""
from __future__ import annotations

import functools
import hashlib
import json
import tomllib
from pathlib import Path

import pytest

from fmu_src.core.avr_specs import PARAM_BY_NAME, PARAM_SPECS
from scenarios.campaign import analysis, sampling, spec, store
from scenarios.cli import main as cli_main
from scenarios.errors import ScenarioError
from scenarios.lang import spec as scenario_spec
from support.paths import REPO_ROOT

BASE = """
name = "c"
samples = 12
seed = 5
base = "nominal"
duration_s = 6.0
compare = ["adaptive", "pd_only"]
"""
FACTORS = """
[factors.model]
dist = "choice"
values = ["menagerie", "osu"]
[factors.floor_friction]
dist = "uniform"
low = 0.5
high = 1.0
[factors.floor]
dist = "choice"
values = ["flat", { slope_deg = 4.0 }, { terrain = { max_height_m = 0.1, max_slope_deg = 10.0, seed = 0 } }]
[factors.floor_terrain_seed]
dist = "randint"
low = 1
high = 50
[factors.link_mass_scale.left-shin]
dist = "uniform"
low = 0.8
high = 1.2
[factors.command_profile]
dist = "choice"
values = [{ shape = "ramped", seed = 0, hold_s = 2.0, vx_des = [0.2, 0.8] }]
[factors.command_profile_seed]
dist = "randint"
low = 1
high = 1000
[factors.random_pushes]
dist = "choice"
values = [{ count = 1, seed = 0, t_s = [1.0, 5.0], magnitude_n = [10.0, 20.0], duration_s = 0.1 }]
[factors.random_pushes_count]
dist = "randint"
low = 1
high = 3
[factors.random_pushes_seed]
dist = "randint"
low = 1
high = 1000
"""


def campaign(text: str) -> spec.Campaign:
    return spec.parse_campaign(tomllib.loads(text), source="test.toml", base_dir=REPO_ROOT)


def test_new_factors_reach_every_sample():
    c = campaign(BASE + FACTORS)
    samples = sampling.draw(c)
    texts = sampling.build_samples(c, samples)  # every sample passes the scenario loader
    models, floors, counts = set(), set(), set()
    for sample in samples:
        s = scenario_spec.parse_scenario(tomllib.loads(texts[sample.id]), check_plant=False)
        v = sample.values
        models.add(s.model)
        assert s.model == v["model"] and s.floor_friction == v["floor_friction"]
        assert [(lm.body, lm.scale) for lm in s.link_masses] == [("left-shin", v["link_mass_scale.left-shin"])]
        assert s.command_profile.seed == v["command_profile_seed"] and s.command_profile.shape == "ramped"
        assert [c_.t_s for c_ in s.commands] == [0.0, 2.0, 4.0]
        assert len(s.pushes) == v["random_pushes_count"] == s.random_pushes.count
        assert s.random_pushes.seed == v["random_pushes_seed"]
        counts.add(len(s.pushes))
        if v["floor"] == "flat":
            assert s.terrain is None and s.slope_deg == 0.0
        elif "slope_deg" in v["floor"]:
            assert s.terrain is None and s.slope_deg == 4.0
        else:
            assert s.terrain.seed == v["floor_terrain_seed"] and s.terrain.max_height_m == 0.1
        floors.add(str(v["floor"]))
    assert models == {"menagerie", "osu"} and len(floors) == 3 and counts == {1, 2, 3}


def test_new_factors_checked_up_front_naming_the_factor():
    with pytest.raises(ScenarioError) as exc:
        campaign(BASE + """
[factors.model]
dist = "choice"
values = ["menagerie", "cassie3"]
[factors.floor]
dist = "choice"
values = ["flat", { bumps = 1 }]
""")
    found = exc.value.problems  # the kinds of values first; the ranges once the file is well-formed
    assert any("factors.model.values[1]" in p and '"menagerie" or "osu"' in p for p in found)
    assert any("factors.floor.values[1]" in p and "slope_deg, cross_slope_deg or terrain" in p for p in found)
    with pytest.raises(ScenarioError) as exc:
        campaign(BASE + """
[factors.floor_friction]
dist = "uniform"
low = 0.5
high = 2.5
[factors.floor]
dist = "choice"
values = ["flat", { slope_deg = 30.0 }]
[factors.link_mass_scale.left-wing]
dist = "uniform"
low = 0.8
high = 1.2
""")
    found = exc.value.problems
    assert any("factors.floor_friction = 2.5" in p and "(0, 2]" in p for p in found)
    assert any("factors.floor" in p and "slope_deg=30.0" in p and "[-15, 15]" in p for p in found)
    assert any("factors.link_mass_scale.left-wing" in p and "no such body" in p for p in found)


STUDY = "robustness_random"
#: The shipped variants, the default first.
SHIPPED = ("ramp", "control", "default_rule")
#: Today's chain frozen at e24b83a (how: its "_about"): the variants that replace a file there.
FROZEN = json.loads((Path(__file__).parent / "robustness_random_e24b83a.json").read_text())
#: The seeds of every set the study's designs and settings were chosen or run on (2021-2035).
USED_SEEDS = range(2021, 2036)


@functools.cache
def study(variant: str) -> spec.Campaign:
    """A shipped variant of the study, loaded once per test process (each load probes every
    factor's extremes on the base: seconds)."""
    return spec.load_campaign(spec.resolve_campaign(STUDY), variant=variant)


def document(variant: str) -> dict:
    """A variant's effective campaign document (its run folder's campaign.toml)."""
    text = study(variant).resolved_text
    assert text.startswith(f"# {spec.CAMPAIGN_DIR / (STUDY + '.toml')} (variant {variant!r}), resolved into one file\n")
    return tomllib.loads(text)


def without_prose(doc: dict) -> dict:
    """``doc`` without its descriptions and its base's name: prose that no sample carries (the
    sample texts name the campaign and the sample, not the base), rewritten because today's
    named the retired files."""
    out = {k: v for k, v in doc.items() if k != "description"}
    out["base"] = {k: v for k, v in doc["base"].items() if k not in ("name", "description")}
    return out


def draws_sha256(c: spec.Campaign) -> str:
    return hashlib.sha256(json.dumps([[s.id, s.values] for s in sampling.draw(c)], sort_keys=True).encode()).hexdigest()


@pytest.mark.parametrize("variant", sorted(set(FROZEN) - {"_about"}))
def test_each_variant_is_the_campaign_it_replaces_field_for_field(variant):
    """ramp and control resolve to today's robustness_random_ramp / _control (their extends
    chain at e24b83a) in every field but the prose, draw the same samples and write the same
    scenario texts (so the same runs, and --resume of a folder run from the old file)."""
    then = FROZEN[variant]
    now = document(variant)
    assert now["name"] == then["document"]["name"] == f"{STUDY}_{variant}"
    assert without_prose(now) == without_prose(then["document"])
    c = study(variant)
    assert c.variant == variant and c.n_samples == then["n_samples"]
    assert draws_sha256(c) == then["draws_sha256"]
    assert store.fingerprint(sampling.build_samples(c, sampling.draw(c)[:10])) == then["first_10_samples_fingerprint"]


def test_the_study_ships_its_variants_and_runs_ramp_by_default():
    raw = tomllib.loads(spec.resolve_campaign(STUDY).read_text())
    assert tuple(raw["variants"]) == SHIPPED and raw["default_variant"] == "ramp"
    assert spec.load_campaign(spec.resolve_campaign(STUDY)).resolved_text == study("ramp").resolved_text
    # the regulator settings of the design in one table of the file, which default_rule drops
    assert raw["base"]["regulator"] == {"command_accel_limit_mps2": 0.5, "learn_settled_steps": 8,
                                        "learning_rate": 2e-6, "learn_ramp_max_mps2": 0.25}
    assert all("regulator" not in t.get("base", {}) for t in raw["variants"].values())
    # each variant on a set of its own, none of the sets anything was chosen on
    seeds = {v: study(v).seed for v in SHIPPED}
    assert seeds == {"ramp": 2032, "control": 2033, "default_rule": 2036}
    assert seeds["default_rule"] not in USED_SEEDS
    # the retired files are gone: the study is one file
    assert [n for n in spec.builtin_campaigns() if n.startswith(STUDY)] == [STUDY]


def test_default_rule_is_the_ramp_design_with_the_regulators_defaults():
    """The same design as ramp (factors, arms, replicas, confirmation stage), without the four
    regulator settings: the parsed arms carry no regulator override but PD-only's switch."""
    ramp, rule = document("ramp"), document("default_rule")
    assert rule.pop("name") == f"{STUDY}_default_rule" and rule.pop("seed") == 2036
    assert "regulator" in ramp["base"] and "regulator" not in rule["base"]
    ramp["base"].pop("regulator")
    ramp.pop("name"), ramp.pop("seed")
    assert without_prose(rule) == without_prose(ramp)
    adaptive, pd_only = _first_sample_regulator_overrides(study("default_rule"))
    assert adaptive == {} and pd_only == {"adaptation_enabled": False}


def _first_sample_regulator_overrides(c: spec.Campaign) -> list[dict]:
    """The regulator settings of the regulated arms (all but RL-HZD) of ``c``'s first sample,
    as its parsed scenario carries them, but the network seed (the sample's own draw)."""
    first = sampling.draw(c)[0]
    s = scenario_spec.parse_scenario(tomllib.loads(sampling.build_samples(c, [first])[first.id]), check_plant=False)
    arms = [dict(a.overrides) for a in s.arms if a.name != "rl_hzd"]
    assert all(o.pop("seed") == first.values["seed"] for o in arms)
    return arms


def samples_by_draw(c: spec.Campaign) -> dict[str, list]:
    """A replicated campaign's samples grouped by random draw (the report's grouping,
    :func:`analysis.regroup`): ``{draw's sample id: [its sample on each replica value]}``."""
    over = c.analysis_settings()["replicate_over"]
    rows = [{"sample": s.id, "arm": "adaptive", "values": s} for s in sampling.draw(c)]
    draws: dict[str, list] = {}
    for r in analysis.regroup(rows, over["draws"], over["cells"], over["index"]):
        draws.setdefault(r["sample"], []).append(r["values"])
    return draws


def test_the_study_walks_each_robot_five_times_each_run_its_own_ground_pushes_and_start():
    """100 random draws, each on floor_terrain_seed 1..5 (the verdicts' replicas) with its
    random pushes and its start nuisance (a push of at most 3 N per axis at 1 s on the pelvis)
    drawn anew per run; everything else is the draw's. A flat or sloped floor (no field) thus
    still gives five different walks; adaptive and PD-only of a run get the same nuisance."""
    c = study("ramp")
    assert c.arm_names() == ["adaptive", "pd_only", "rl_hzd"] and c.replicas == ()
    assert c.replicate_over == "floor_terrain_seed" and c.samples == 100 and c.n_samples == 500
    assert c.redraw == ("random_pushes_seed", "push_force_x_n", "push_force_y_n") and c.metric == "settled_error_vx"
    names = {f.name for f in c.factors}
    for needed in ("model", "floor_friction", "torso_mass_kg", "torso_com_offset_x_m", "torso_com_offset_y_m",
                   "joint_damping_scale", "floor", "command_profile", "random_pushes", "random_pushes_count",
                   "link_mass_scale.left-hip-pitch", "seed"):
        assert needed in names
    draws = samples_by_draw(c)
    assert len(draws) == 100
    redrawn = ("floor_terrain_seed", "random_pushes_seed", "push_force_x_n", "push_force_y_n")
    flat = 0
    for i, members in enumerate(draws.values()):
        values = [m.values for m in members]
        assert sorted(v["floor_terrain_seed"] for v in values) == [1, 2, 3, 4, 5]
        assert len({v["random_pushes_seed"] for v in values}) == 5
        forces = [(v["push_force_x_n"], v["push_force_y_n"]) for v in values]
        assert len(set(forces)) == 5 and all(-3.0 <= f <= 3.0 for xy in forces for f in xy)
        rest = [{k: x for k, x in v.items() if k not in redrawn} for v in values]
        assert all(x == rest[0] for x in rest)
        flat += "terrain" not in values[0]["floor"]
        if i < 3:  # the parsed scenarios carry it: one pelvis push at 1 s, before the random ones
            for m, (fx_n, fy_n) in zip(members, forces):
                sc = scenario_spec.parse_scenario(sampling.sample_document(c, m), source=m.id, base_dir=c.base_dir)
                first = [p for p in sc.pushes if p.t_s == 1.0]
                assert [(p.force_n, p.duration_s, p.body) for p in first] == [((fx_n, fy_n, 0.0), 0.1, "cassie-pelvis")]
                assert all(p.t_s >= 3.0 for p in sc.pushes if p is not first[0])
    assert 40 <= flat <= 75  # flat or sloped floors: weights 6 of 10 in the floor factor


def test_the_ramp_settings_reach_the_regulated_arms_and_the_ramp_limit_sits_between_the_ramps_and_the_reference():
    """Its learn_ramp_max_mps2 is above the ramps of the command profiles it draws (at most
    the vx range over one hold) and below the command reference's rate limit (so a step still
    waits); adaptive and PD-only carry the four settings."""
    ramp = document("ramp")
    limit = ramp["base"]["regulator"]["learn_ramp_max_mps2"]
    profiles = ramp["factors"]["command_profile"]["values"]
    steepest = max((p["vx_des"][1] - p["vx_des"][0]) / p["hold_s"] for p in profiles if p["shape"] == "ramped")
    assert steepest < limit < ramp["base"]["regulator"]["command_accel_limit_mps2"]
    adaptive, pd_only = _first_sample_regulator_overrides(study("ramp"))
    settings = {"command_accel_limit_mps2": 0.5, "learn_settled_steps": 8, "learning_rate": 2e-6,
                "learn_ramp_max_mps2": 0.25}
    assert adaptive == settings and pd_only == {**settings, "adaptation_enabled": False}


@pytest.mark.parametrize("variant", SHIPPED)
def test_every_variant_decides_never_by_a_40_run_confirmation_stage(variant):
    """Its listed draws run again on 40 fresh grounds, numbered on from the five of every
    draw (floor_terrain_seed 6..45)."""
    c = study(variant)
    assert c.confirm_runs == 40 and c.replicate_over == "floor_terrain_seed"
    assert c.analysis_settings()["confirm_runs"] == 40
    first = next(s for s in sampling.draw(c) if s.values["floor_terrain_seed"] == 1)
    _, fresh, _ = sampling.confirmation(c, [first.id])
    assert [s.values["floor_terrain_seed"] for s in fresh] == list(range(6, 46))


def test_control_runs_a_nudged_pd_only_in_place_of_rl_hzd():
    """ramp with one change of arms on its own set: RL-HZD is replaced by PD-only with Kp_x
    5 % up, and nothing else differs, so the control arm meets the same samples as adaptive
    and PD-only; parsed, it is PD-only's settings with that one gain."""
    control, ramp = document("control"), document("ramp")
    assert control.pop("compare") == ["adaptive", "pd_only", "pd_kpx_105"] and ramp.pop("compare")[2] == "rl_hzd"
    assert control["base"].pop("arm") == [{"name": "pd_kpx_105", "regulator": {"adaptation_enabled": False, "Kp_x": 0.105},
                                           "description": "PD-only with Kp_x = 0.105 (5 % above the default 0.1)"}]
    assert "arm" not in ramp["base"]
    assert {k: v for k, v in control.items() if k not in ("name", "description", "seed")} == \
        {k: v for k, v in ramp.items() if k not in ("name", "description", "seed")}
    adaptive, pd_only, nudged = _first_sample_regulator_overrides(study("control"))
    assert pd_only["adaptation_enabled"] is False and "Kp_x" not in pd_only  # the FMU's default:
    assert PARAM_BY_NAME["Kp_x"].default == 0.1  # 0.105 is 5 % above it
    assert nudged == {**pd_only, "Kp_x": 0.105} and "adaptation_enabled" not in adaptive  # on by default


def test_the_campaign_command_takes_a_variant_and_lists_them(capsys):
    """--variant picks a variant (dry run: its samples), an unknown one is refused before
    anything runs (exit 2) with the allowed ones listed, and --help lists every built-in
    campaign and the study's variants."""
    def cli(*args):
        rc = cli_main(["campaign", *args])
        return rc, *capsys.readouterr()
    rc, out, err = cli(STUDY, "--variant", "contrl", "--workers", "0", "--dry-run")
    assert rc == 2 and out == ""
    assert "variant = 'contrl': no such variant of 'robustness_random'; did you mean 'control'?; variants: " \
           "ramp (default), control, default_rule" in err
    assert "--workers 0: must be >= 1" in err  # every problem at once
    rc, out, err = cli(STUDY, "--variant", "default_rule", "--dry-run")
    assert rc == 0, err
    assert [line.split()[0] for line in out.splitlines()[1:]] == [s.id for s in sampling.draw(study("default_rule"))]
    with pytest.raises(SystemExit):
        cli("--help")
    usage = " ".join(capsys.readouterr().out.split())
    for name in spec.builtin_campaigns():
        assert name in usage
    assert "robustness_random (variants: ramp (default), control, default_rule)" in usage
