"""Campaign factors for what robustness studies randomize: the model, floor friction and
shape, link masses, seeded command profiles and several seeded random pushes; and the
built-in robustness_random campaign built on them."""
from __future__ import annotations

import tomllib

import pytest

from fmu_src.core.avr_specs import PARAM_BY_NAME, PARAM_SPECS
from scenarios.campaign import analysis, sampling, spec
from scenarios.errors import ScenarioError
from scenarios.lang.fields import Problems
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


def test_robustness_random_campaign_is_what_the_issue_asks():
    c = spec.load_campaign(spec.resolve_campaign("robustness_random"))
    assert c.n_samples >= 100
    gains = ("095", "105", "090", "110")
    assert c.arm_names() == ["adaptive", "pd_only", "rl_hzd", *(f"adaptive_kpx_{g}" for g in gains),
                             *(f"pd_kpx_{g}" for g in gains)]
    # the verdicts: five paired replicas per sample, on the settled error
    assert c.metric == "settled_error_vx"
    assert dict(c.replicas) == {"adaptive": tuple(f"adaptive_kpx_{g}" for g in gains),
                                "pd_only": tuple(f"pd_kpx_{g}" for g in gains)}
    names = {f.name for f in c.factors}
    for needed in ("model", "floor_friction", "torso_mass_kg", "torso_com_offset_x_m", "torso_com_offset_y_m",
                   "joint_damping_scale", "floor", "command_profile", "random_pushes", "random_pushes_count",
                   "link_mass_scale.left-hip-pitch", "seed"):
        assert needed in names
    samples = sampling.draw(c)
    texts = sampling.build_samples(c, samples[:10])
    s = scenario_spec.parse_scenario(tomllib.loads(texts[samples[0].id]), check_plant=False)
    assert s.duration_s == 25.0 and s.random_pushes is not None and s.command_profile is not None
    # replica i of adaptive and of PD-only: the same Kp_x, the same command reference and
    # network seed (the sample's), and nothing else changed
    arms = {a.name: dict(a.overrides) for a in s.arms}
    base = arms["adaptive"]
    assert base["command_accel_limit_mps2"] == 0.5 and "Kp_x" not in base
    assert arms["pd_only"] == {**base, "adaptation_enabled": False}
    for g in gains:
        kp = int(g) / 1000
        assert arms[f"adaptive_kpx_{g}"] == {**base, "Kp_x": pytest.approx(kp)}
        assert arms[f"pd_kpx_{g}"] == {**base, "adaptation_enabled": False, "Kp_x": pytest.approx(kp)}


def resolved(name: str) -> dict:
    """A built-in campaign's document with its extends resolved."""
    probs = Problems()
    doc, _ = spec.extended(tomllib.loads(spec.resolve_campaign(name).read_text()), spec.CAMPAIGN_DIR, probs)
    assert not probs.items, probs.items
    return doc


def _first_sample_regulator_overrides(name: str) -> list[dict]:
    """The regulator settings of the regulated arms (all but RL-HZD) of campaign ``name``'s
    first sample, as its parsed scenario carries them."""
    c = spec.load_campaign(spec.resolve_campaign(name))
    s = scenario_spec.parse_scenario(tomllib.loads(sampling.build_samples(c, sampling.draw(c)[:1]).popitem()[1]),
                                     check_plant=False)
    return [dict(a.overrides) for a in s.arms if a.name != "rl_hzd"]


# Each variant campaign: (its file, the file it varies, the regulator setting it adds, as
# its description spells it, the settings its regulator arms then carry).
VARIANTS = [
    ("robustness_random_settled", "robustness_random", ("learn_settled_steps", 3, "learn_settled_steps = 3"),
     {"learn_settled_steps": 3, "learning_rate": None}),
    ("robustness_random_settled_lr2", "robustness_random_settled", ("learning_rate", 2e-6, "learning_rate = 2e-6"),
     {"learn_settled_steps": 3, "learning_rate": 2e-6}),
]


@pytest.mark.parametrize("variant, parent, added, carried", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_variant_campaigns_differ_from_their_parent_by_one_regulator_setting(variant, parent, added, carried):
    """A variant differs from the file it varies only by its name, description and one
    setting on every regulator arm: the same samples, so their PD-only and RL-HZD rows are
    the same runs (learning settings do not act with adaptation off)."""
    key, value, spelled = added
    raw = tomllib.loads(spec.resolve_campaign(variant).read_text())
    assert raw["extends"] == parent and set(raw) == {"extends", "name", "description", "base"}
    base, var = resolved(parent), resolved(variant)
    assert var.pop("name") == variant and base.pop("name") == parent
    assert spelled in var.pop("description")
    base.pop("description")
    assert var["base"]["regulator"].pop(key) == value
    assert var == base
    regulated = _first_sample_regulator_overrides(variant)
    for name, expected in carried.items():
        assert {o.get(name) for o in regulated} == {expected}, name


def samples_by_draw(c: spec.Campaign) -> dict[str, list]:
    """A replicated campaign's samples grouped by random draw (the report's grouping,
    :func:`analysis.regroup`): ``{draw's sample id: [its sample on each replica value]}``."""
    over = c.analysis_settings()["replicate_over"]
    rows = [{"sample": s.id, "arm": "adaptive", "values": s} for s in sampling.draw(c)]
    draws: dict[str, list] = {}
    for r in analysis.regroup(rows, over["draws"], over["cells"], over["index"]):
        draws.setdefault(r["sample"], []).append(r["values"])
    return draws


def test_robustness_random_grounds_walks_each_robot_of_the_lr2_campaign_on_five_grounds():
    """The same factors and regulator settings as robustness_random_settled_lr2 (another
    seed), the terrain seed a grid of five the verdicts replicate over; three arms."""
    raw = tomllib.loads(spec.resolve_campaign("robustness_random_grounds").read_text())
    assert raw["extends"] == "robustness_random_settled_lr2" and raw["drop"] == ["replicas", "base.arm"]
    grounds, lr2 = resolved("robustness_random_grounds"), resolved("robustness_random_settled_lr2")
    assert "replicas" not in grounds and "arm" not in grounds["base"] and "arm" in lr2["base"]
    assert grounds["factors"].pop("floor_terrain_seed") == {"dist": "grid", "values": [1, 2, 3, 4, 5]}
    lr2["factors"].pop("floor_terrain_seed")
    assert grounds["factors"] == lr2["factors"]
    assert grounds["base"]["regulator"] == lr2["base"]["regulator"]
    assert grounds["seed"] not in (2021, 2022, 2023, 2024)  # a set no setting was chosen on
    c = spec.load_campaign(spec.resolve_campaign("robustness_random_grounds"))
    assert c.arm_names() == ["adaptive", "pd_only", "rl_hzd"] and c.replicas == ()
    assert c.replicate_over == "floor_terrain_seed" and c.samples == 100 and c.n_samples == 500
    draws = samples_by_draw(c)
    assert len(draws) == 100
    for samples in draws.values():
        members = [m.values for m in samples]
        assert sorted(v["floor_terrain_seed"] for v in members) == [1, 2, 3, 4, 5]
        rest = [{k: x for k, x in v.items() if k != "floor_terrain_seed"} for v in members]
        assert all(x == rest[0] for x in rest)


def test_robustness_random_nuisance_gives_each_of_a_robots_five_runs_its_own_ground_and_pushes():
    """robustness_random_grounds with random_pushes_seed redrawn per ground, learning 8
    settled steps after a command change (another seed): every run of a draw is the same
    robot on another ground under other pushes, so a flat or sloped floor no longer
    repeats one walk five times."""
    raw = tomllib.loads(spec.resolve_campaign("robustness_random_nuisance").read_text())
    assert raw["extends"] == "robustness_random_grounds" and raw["redraw"] == ["random_pushes_seed"]
    nuisance, grounds = resolved("robustness_random_nuisance"), resolved("robustness_random_grounds")
    assert nuisance["factors"] == grounds["factors"]
    assert nuisance["base"]["regulator"].pop("learn_settled_steps") == 8  # 3 in grounds
    grounds["base"]["regulator"].pop("learn_settled_steps")
    assert nuisance["base"] == grounds["base"]
    assert nuisance["seed"] not in (2021, 2022, 2023, 2024, 2025, 2026)  # a set no setting was chosen on
    c = spec.load_campaign(spec.resolve_campaign("robustness_random_nuisance"))
    assert c.arm_names() == ["adaptive", "pd_only", "rl_hzd"] and c.replicate_over == "floor_terrain_seed"
    assert c.redraw == ("random_pushes_seed",) and c.n_samples == 500
    draws = samples_by_draw(c)
    assert len(draws) == 100
    flat = 0
    for members in draws.values():
        values = [m.values for m in members]
        assert sorted(v["floor_terrain_seed"] for v in values) == [1, 2, 3, 4, 5]
        assert len({v["random_pushes_seed"] for v in values}) == 5
        nuisance_keys = ("floor_terrain_seed", "random_pushes_seed")
        rest = [{k: x for k, x in v.items() if k not in nuisance_keys} for v in values]
        assert all(x == rest[0] for x in rest)
        if "terrain" not in values[0]["floor"]:
            flat += 1
            # the five scenarios differ in their pushes (the walks differ, though the floor is one)
            pushes = [tuple(scenario_spec.parse_scenario(sampling.sample_document(c, m), source=m.id,
                                                         base_dir=c.base_dir).pushes) for m in members]
            assert len(set(pushes)) == 5
    assert 40 <= flat <= 75  # flat or sloped floors: weights 6 of 10 in lr2's floor factor


def test_robustness_random_start_gives_each_run_its_own_start_nuisance():
    """robustness_random_nuisance with a push of at most 3 N per axis at 1 s on the pelvis,
    drawn anew on every run with the pushes (another seed): each of a robot's five runs is
    its own walk from the start, and adaptive and PD-only of a run get the same one."""
    raw = tomllib.loads(spec.resolve_campaign("robustness_random_start").read_text())
    assert raw["extends"] == "robustness_random_nuisance"
    assert raw["redraw"] == ["random_pushes_seed", "push_force_x_n", "push_force_y_n"]
    start, nuisance = resolved("robustness_random_start"), resolved("robustness_random_nuisance")
    added = {k: start["factors"].pop(k) for k in ("push_force_x_n", "push_force_y_n")}
    assert added == {k: {"dist": "uniform", "low": -3.0, "high": 3.0} for k in added}
    assert start["factors"] == nuisance["factors"]
    assert start["base"].pop("push") == [{"t_s": 1.0, "force_n": [0.0, 0.0, 0.0], "duration_s": 0.1}]
    assert start["base"] == nuisance["base"]  # the regulator settings too
    assert start["seed"] not in (2021, 2022, 2023, 2024, 2025, 2026, 2027)  # no setting or design chosen on it
    c = spec.load_campaign(spec.resolve_campaign("robustness_random_start"))
    assert c.arm_names() == ["adaptive", "pd_only", "rl_hzd"] and c.n_samples == 500
    draws = samples_by_draw(c)
    assert len(draws) == 100
    redrawn = ("floor_terrain_seed", "random_pushes_seed", "push_force_x_n", "push_force_y_n")
    for i, members in enumerate(draws.values()):
        values = [m.values for m in members]
        forces = [(v["push_force_x_n"], v["push_force_y_n"]) for v in values]
        assert len(set(forces)) == 5 and all(-3.0 <= f <= 3.0 for xy in forces for f in xy)
        rest = [{k: x for k, x in v.items() if k not in redrawn} for v in values]
        assert all(x == rest[0] for x in rest)
        if i < 3:  # the parsed scenarios carry it: one pelvis push at 1 s, before the random ones
            for m, (fx_n, fy_n) in zip(members, forces):
                sc = scenario_spec.parse_scenario(sampling.sample_document(c, m), source=m.id, base_dir=c.base_dir)
                first = [p for p in sc.pushes if p.t_s == 1.0]
                assert [(p.force_n, p.duration_s, p.body) for p in first] == [((fx_n, fy_n, 0.0), 0.1, "cassie-pelvis")]
                assert all(p.t_s >= 3.0 for p in sc.pushes if p is not first[0])


def _start_plus_one_setting(name: str, key: str) -> tuple[dict, object]:
    """Campaign ``name`` resolved, and the value of its regulator setting ``key``, checking
    that without that setting it is robustness_random_start but for its name, description
    and seed (its own set)."""
    variant, start = resolved(name), resolved("robustness_random_start")
    variant.pop("confirm_runs", None)  # how the verdict is decided, not what runs (test below)
    value = variant["base"]["regulator"].pop(key)
    assert {k: v for k, v in variant.items() if k not in ("name", "description", "seed")} == \
        {k: v for k, v in start.items() if k not in ("name", "description", "seed")}
    return variant, value


def test_robustness_random_ramp_is_the_start_campaign_learning_on_slow_ramps():
    """robustness_random_start with learn_ramp_max_mps2 = 0.25 on the regulator arms and
    nothing else changed, on a seed no setting or design was chosen on; its limit is above the
    ramps of the command profiles it draws (at most the vx range over one hold) and below the
    command reference's rate limit (so a step still waits); the parsed arms carry it."""
    ramp, limit = _start_plus_one_setting("robustness_random_ramp", "learn_ramp_max_mps2")
    assert ramp["seed"] not in (2021, 2022, 2023, 2024, 2025, 2026, 2027, 2028, 2029, 2030, 2031)
    profiles = ramp["factors"]["command_profile"]["values"]
    steepest = max((p["vx_des"][1] - p["vx_des"][0]) / p["hold_s"] for p in profiles if p["shape"] == "ramped")
    assert steepest < limit < ramp["base"]["regulator"]["command_accel_limit_mps2"]
    regulated = _first_sample_regulator_overrides("robustness_random_ramp")
    assert len(regulated) == 2 and all(o["learn_ramp_max_mps2"] == 0.25 and o["learn_settled_steps"] == 8
                                       for o in regulated)


def test_robustness_random_ramp_decides_never_by_a_40_run_confirmation_stage():
    """Its listed draws run again on 40 fresh grounds, numbered on from the five of every
    draw (floor_terrain_seed 6..45); the control campaign inherits the stage."""
    for name in ("robustness_random_ramp", "robustness_random_control"):
        c = spec.load_campaign(spec.resolve_campaign(name))
        assert c.confirm_runs == 40 and c.replicate_over == "floor_terrain_seed"
        assert c.analysis_settings()["confirm_runs"] == 40
    c = spec.load_campaign(spec.resolve_campaign("robustness_random_ramp"))
    first = next(s for s in sampling.draw(c) if s.values["floor_terrain_seed"] == 1)
    _, fresh, _ = sampling.confirmation(c, [first.id])
    assert [s.values["floor_terrain_seed"] for s in fresh] == list(range(6, 46))


def test_robustness_random_control_runs_a_nudged_pd_only_in_place_of_rl_hzd():
    """robustness_random_ramp with one change of arms on its own set: RL-HZD is replaced by
    PD-only with Kp_x 5 % up, and nothing else differs, so the control arm meets the same
    samples as adaptive and PD-only; parsed, it is PD-only's settings with that one gain."""
    control, ramp = resolved("robustness_random_control"), resolved("robustness_random_ramp")
    assert control.pop("compare") == ["adaptive", "pd_only", "pd_kpx_105"] and ramp.pop("compare")[2] == "rl_hzd"
    assert control["base"].pop("arm") == [{"name": "pd_kpx_105", "regulator": {"adaptation_enabled": False, "Kp_x": 0.105},
                                           "description": "PD-only with Kp_x = 0.105 (5 % above the default 0.1)"}]
    assert "arm" not in ramp["base"]
    assert {k: v for k, v in control.items() if k not in ("name", "description", "seed")} == \
        {k: v for k, v in ramp.items() if k not in ("name", "description", "seed")}
    assert control["seed"] not in range(2021, 2033)
    adaptive, pd_only, nudged = _first_sample_regulator_overrides("robustness_random_control")
    assert pd_only["adaptation_enabled"] is False and "Kp_x" not in pd_only  # the FMU's default:
    assert PARAM_BY_NAME["Kp_x"].default == 0.1  # 0.105 is 5 % above it
    assert nudged == {**pd_only, "Kp_x": 0.105} and "adaptation_enabled" not in adaptive  # on by default
