"""Tests of plant.model: loading both Cassie models, perturbations and terrain."""
import math

import mujoco
import numpy as np
import pytest

from plant import model as plant_model
from plant.errors import ModelError, PerturbationError
from plant.constants import ACTUATOR_NAMES, HOME_KEY, JOINT_NAMES, PELVIS_BODY
from plant.terrain import TERRAIN_GEOM, TerrainSpec, generate_terrain, terrain_height_at, terrain_max_slope_deg
from plant.perturbation import Perturbation
from plant.model import load_model, menagerie_root, menagerie_xml_path, model_summary, osu_model_path

SOURCES = ("menagerie", "osu")


@pytest.fixture(scope="module")
def nominal():
    return {src: load_model(src) for src in SOURCES}


def _hfield(model):
    """Compiled terrain heights (world z, m) as (nrow, ncol), its spacing (m) and geom id."""
    gid = model.geom(TERRAIN_GEOM).id
    hid = model.geom_dataid[gid]
    nrow, ncol = model.hfield_nrow[hid], model.hfield_ncol[hid]
    adr = model.hfield_adr[hid]
    h = model.hfield_data[adr:adr + nrow * ncol].reshape(nrow, ncol).astype(np.float64)
    h = model.geom_pos[gid, 2] + h * model.hfield_size[hid, 2]
    return h, 2 * model.hfield_size[hid, 0] / (ncol - 1), gid


# ------------------------------------------------------------------ loading


@pytest.mark.parametrize("src", SOURCES)
def test_models_load_with_names_masses_and_home(nominal, src):
    m = nominal[src]
    for n in JOINT_NAMES:
        assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) >= 0, n
    for n in ACTUATOR_NAMES:
        assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) >= 0, n
    assert {"left-hip-roll", "right-foot"} <= set(ACTUATOR_NAMES)
    assert m.body(PELVIS_BODY).mass[0] == pytest.approx(10.33)
    assert m.body_mass.sum() == pytest.approx(33.3, abs=0.05)  # README: 33.3 kg (33.312)
    assert m.opt.timestep == pytest.approx(0.0005)
    assert (m.nq, m.nv, m.nu) == (35, 32, 10)
    key = m.key(HOME_KEY)
    assert key.qpos.shape == (m.nq,)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, key.id)
    mujoco.mj_forward(m, d)
    assert np.all(np.isfinite(d.qacc))
    s = model_summary(m)
    assert s["pelvis_mass_kg"] == pytest.approx(10.33) and s["has_terrain"] is False
    assert (s["nq"], s["nv"], s["nu"], s["timestep_s"]) == (35, 32, 10, 0.0005)


def test_osu_home_matches_menagerie_home(nominal):
    # Same qpos layout (free joint vs 3 slides + ball both give x y z qw qx qy qz).
    np.testing.assert_allclose(nominal["osu"].key(HOME_KEY).qpos,
                               nominal["menagerie"].key(HOME_KEY).qpos, atol=1e-12)


def test_menagerie_is_scene_with_floor(nominal):
    m = nominal["menagerie"]
    assert m.geom("floor").type[0] == mujoco.mjtGeom.mjGEOM_PLANE
    assert terrain_height_at(m, 3.0, -2.0) == 0.0


def test_osu_path_default_and_env(monkeypatch, tmp_path):
    monkeypatch.delenv("CASSIE_OSU_XML", raising=False)
    assert osu_model_path().parts[-4:] == ("shared", "cassie", "osu", "cassie.xml")
    assert osu_model_path().is_file()
    missing = tmp_path / "nope.xml"
    monkeypatch.setenv("CASSIE_OSU_XML", str(missing))
    assert osu_model_path() == missing
    with pytest.raises(ModelError, match="CASSIE_OSU_XML") as e:
        load_model("osu")
    assert str(missing) in str(e.value)


def test_bad_path_and_non_cassie_file(tmp_path):
    with pytest.raises(ModelError, match="not found"):
        load_model(tmp_path / "missing.xml")
    other = tmp_path / "ball.xml"
    other.write_text('<mujoco><worldbody><body name="b"><freejoint/>'
                     '<geom size="0.1"/></body></worldbody></mujoco>')
    with pytest.raises(ModelError, match="left-hip-roll") as e:
        load_model(other)
    assert "cassie-pelvis" in str(e.value)
    broken = tmp_path / "broken.xml"
    broken.write_text("<mujoco><worldbody>")
    with pytest.raises(ModelError, match="cannot parse"):
        load_model(broken)


def test_menagerie_root_defaults_to_the_shared_copy(monkeypatch, tmp_path):
    """One default, in the loader: unset MENAGERIE_ROOT means ../shared/cassie/menagerie if it
    exists (the offline copy beside the repo), else the mujoco-menagerie cache (None)."""
    shared = plant_model._SHARED_CASSIE / "menagerie"
    monkeypatch.delenv("MENAGERIE_ROOT", raising=False)
    assert menagerie_root() == shared and shared.is_dir()
    assert menagerie_xml_path() == shared / "agility_cassie" / "scene.xml"
    assert load_model("menagerie").nu == 10
    monkeypatch.setenv("MENAGERIE_ROOT", str(tmp_path))
    assert menagerie_root() == tmp_path  # the environment wins
    monkeypatch.delenv("MENAGERIE_ROOT")
    monkeypatch.setattr(plant_model, "_SHARED_CASSIE", tmp_path / "no-such-folder")
    assert menagerie_root() is None


def test_menagerie_missing_root(monkeypatch, tmp_path):
    monkeypatch.setenv("MENAGERIE_ROOT", str(tmp_path))
    with pytest.raises(ModelError, match="MENAGERIE_ROOT"):
        load_model("menagerie")


# ------------------------------------------------------------------ perturbations

_CHECKED = ("body_mass", "body_inertia", "body_ipos", "body_iquat", "dof_damping",
            "dof_armature", "jnt_stiffness", "jnt_range", "geom_size", "geom_pos",
            "actuator_gear", "qpos0", "key_qpos")


def _assert_unchanged_except(nom, per, allowed):
    """Every array in _CHECKED equal, except entries listed in `allowed` {name: index}."""
    for name in _CHECKED:
        a, b = getattr(nom, name).copy(), getattr(per, name).copy()
        if name in allowed:
            a[allowed[name]] = b[allowed[name]]
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert per.opt.timestep == nom.opt.timestep


@pytest.mark.parametrize("src", SOURCES)
def test_mass_perturbation(nominal, src):
    nom = nominal[src]
    per = load_model(src, Perturbation(torso_mass_kg=15.0))
    i = per.body(PELVIS_BODY).id
    assert per.body_mass[i] == 15.0
    np.testing.assert_allclose(per.body_inertia[i], nom.body_inertia[i] * 15.0 / 10.33)
    _assert_unchanged_except(nom, per, {"body_mass": i, "body_inertia": i})
    assert per.body_subtreemass[0] == pytest.approx(33.312 + 15.0 - 10.33)  # mj_setConst ran
    assert model_summary(per)["total_mass_kg"] == pytest.approx(37.982)


def test_com_offset_and_damping(nominal):
    nom = nominal["osu"]
    per = load_model("osu", Perturbation(torso_com_offset_m=(0.05, -0.02, 0.1)))
    i = per.body(PELVIS_BODY).id
    np.testing.assert_allclose(per.body_ipos[i], nom.body_ipos[i] + (0.05, -0.02, 0.1))
    _assert_unchanged_except(nom, per, {"body_ipos": i})

    per = load_model("osu", Perturbation(joint_damping_scale=2.5))
    np.testing.assert_allclose(per.dof_damping, 2.5 * nom.dof_damping)
    assert per.dof_damping.max() > 0
    _assert_unchanged_except(nom, per, {"dof_damping": slice(None)})

    per = load_model("osu", Perturbation())  # the default changes nothing
    _assert_unchanged_except(nom, per, {})


def _model_bytes(model) -> bytes:
    buf = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return buf.tobytes()


@pytest.mark.parametrize("src", SOURCES)
def test_a_perturbed_copy_is_the_compiled_perturbed_model_byte_for_byte(nominal, src):
    """plant.model.perturbed_copy (what a run uses instead of compiling each arm's model again)
    gives load_perturbed's model, every byte (mj_saveModel), and leaves the base model alone."""
    base = nominal[src]
    before = _model_bytes(base)
    cases = [None, Perturbation(torso_mass_kg=15.0),
             Perturbation(torso_added_mass_kg=4.0, torso_com_offset_m=(0.05, -0.02, 0.1), joint_damping_scale=2.5),
             Perturbation(floor_friction=0.6, slope_deg=5.0, cross_slope_deg=-3.0,
                          link_mass_scale=(("left-hip-pitch", 1.3),), link_mass_kg=(("right-shin", 0.7),))]
    for pert in cases:
        copied, applied = plant_model.perturbed_copy(base, pert, src)
        compiled, applied_compiled = plant_model.load_perturbed(src, pert)
        assert copied is not base and _model_bytes(copied) == _model_bytes(compiled), pert
        assert applied == applied_compiled
    assert _model_bytes(base) == before
    with pytest.raises(ValueError, match="use load_perturbed"):
        plant_model.perturbed_copy(base, Perturbation(terrain=TerrainSpec(max_height_m=0.02, max_slope_deg=5.0, seed=1)), src)
    with pytest.raises(PerturbationError, match="joint_damping_scale"):
        plant_model.perturbed_copy(base, Perturbation(joint_damping_scale=-1.0), src)


@pytest.mark.parametrize("src", SOURCES)
def test_a_terrain_model_from_the_checked_base_is_the_compiled_one_byte_for_byte(nominal, src):
    """plant.model.perturbed_with_terrain (one compile, from the checked base model) gives
    load_perturbed's model (two compiles), every byte, for both terrains the random campaign
    draws and one with the other perturbations; the base model is left alone."""
    base = nominal[src]
    before = _model_bytes(base)
    cases = [Perturbation(terrain=TerrainSpec(max_height_m=0.2, max_slope_deg=15.0, seed=3)),
             Perturbation(terrain=TerrainSpec(max_height_m=0.34, max_slope_deg=20.0, seed=41)),
             Perturbation(torso_mass_kg=21.0, torso_com_offset_m=(0.03, -0.05, 0.0), joint_damping_scale=3.0,
                          floor_friction=0.7, link_mass_scale=(("left-shin", 1.2),),
                          terrain=TerrainSpec(max_height_m=0.1, max_slope_deg=10.0, seed=7))]
    for pert in cases:
        once, applied = plant_model.perturbed_with_terrain(base, pert, src)
        twice, applied_twice = plant_model.load_perturbed(src, pert)
        assert _model_bytes(once) == _model_bytes(twice), pert
        assert applied == applied_twice
    assert _model_bytes(base) == before
    with pytest.raises(ValueError, match="use perturbed_copy"):
        plant_model.perturbed_with_terrain(base, Perturbation(torso_mass_kg=15.0), src)


def test_validation_lists_every_problem():
    with pytest.raises(PerturbationError) as e:
        Perturbation(torso_mass_kg=-1, joint_damping_scale=20).validate()
    msg = str(e.value)
    assert "torso_mass_kg" in msg and "(0, 100] kg" in msg
    assert "joint_damping_scale" in msg and "[0, 10]" in msg
    assert len(e.value.problems) == 2
    assert isinstance(e.value, ValueError)

    bad = Perturbation(torso_mass_kg=float("nan"), torso_com_offset_m=(0.6, 0.0, -0.7),
                       terrain=TerrainSpec(max_height_m=2.0, max_slope_deg=0.0, seed=-3,
                                           resolution_m=0.001))
    problems = bad.problems()
    for field in ("torso_mass_kg", "torso_com_offset_m[x]", "torso_com_offset_m[z]",
                  "terrain.max_height_m", "terrain.max_slope_deg", "terrain.seed",
                  "terrain.resolution_m"):
        assert any(p.startswith(field) for p in problems), (field, problems)
    assert len(problems) == 7
    assert "com_offset_m[y]" not in " ".join(problems)
    with pytest.raises(PerturbationError, match="terrain.max_height_m"):
        load_model("osu", bad)
    with pytest.raises(PerturbationError, match="torso_com_offset_m"):
        Perturbation(torso_com_offset_m=(0.1, 0.2)).validate()
    with pytest.raises(PerturbationError, match="samples per side"):
        TerrainSpec(0.1, 10, 0, size_m=100, resolution_m=0.02).validate()
    Perturbation(torso_mass_kg=100, joint_damping_scale=0,
                 terrain=TerrainSpec(1.0, 45.0, 0)).validate()  # bounds are inclusive


def test_nominal_flag_and_sequence_offset():
    assert Perturbation().is_nominal
    p = Perturbation(torso_com_offset_m=[0, 0, 0])
    assert p.is_nominal and p.torso_com_offset_m == (0, 0, 0) and hash(p) == hash(Perturbation())
    p = Perturbation(torso_com_offset_m=np.array([0.1, 0.0, 0.0]))
    assert not p.is_nominal and isinstance(p.torso_com_offset_m, tuple)
    p.validate()
    assert not Perturbation(torso_mass_kg=10.33).is_nominal


# ------------------------------------------------------------------ terrain

SPEC = TerrainSpec(max_height_m=0.3, max_slope_deg=15.0, seed=3)


@pytest.fixture(scope="module")
def terrain_models():
    return {src: load_model(src, Perturbation(terrain=SPEC)) for src in SOURCES}


def test_terrain_is_deterministic(terrain_models):
    a = generate_terrain(SPEC)
    assert a.tobytes() == generate_terrain(SPEC).tobytes()
    b = generate_terrain(TerrainSpec(0.3, 15.0, seed=4))
    assert a.shape == b.shape and not np.array_equal(a, b)
    again = load_model("osu", Perturbation(terrain=SPEC))
    assert (again.hfield_data.tobytes() == terrain_models["osu"].hfield_data.tobytes()
            == terrain_models["menagerie"].hfield_data.tobytes())


@pytest.mark.parametrize("spec", [
    SPEC, TerrainSpec(0.05, 3.0, 11, size_m=5.0),
    TerrainSpec(1.0, 30.0, 7, size_m=10.0, resolution_m=0.1),
    # small field for a tall, gentle terrain: the generator's final scale-down
    # branch is what enforces the slope here (peak ~0.45 m instead of 1 m)
    TerrainSpec(1.0, 10.0, 5, size_m=6.0)])
def test_terrain_slope_and_height_bounds(spec):
    m = load_model("osu", Perturbation(terrain=spec))
    h, dx, _ = _hfield(m)
    n = round(2 * spec.size_m / spec.resolution_m) + 1
    assert h.shape == (n, n) and dx == pytest.approx(spec.resolution_m)
    tan_max = math.tan(math.radians(spec.max_slope_deg))
    # Tolerance: hfield_data is float32; each stored sample is within 1 ulp of the
    # generator's float64 value (eps32 * peak, peak <= max_height_m), so a difference
    # of two samples divided by dx errs by at most 2 * eps32 * max_height_m / dx
    # (hypot of two such: 2*sqrt(2)); 4x that is a safe bound, ~1e-5 or less here.
    tol = 4 * np.finfo(np.float32).eps * spec.max_height_m / dx
    sx = np.abs(np.diff(h, axis=1)) / dx  # neighbours along x
    sy = np.abs(np.diff(h, axis=0)) / dx  # neighbours along y
    assert sx.max() <= tan_max + tol and sy.max() <= tan_max + tol
    # Steepest gradient of any surface patch through a cell's 4 corners (either
    # triangulation or bilinear): one x edge and one y edge of the cell.
    grad = np.hypot(np.maximum(sx[:-1], sx[1:]), np.maximum(sy[:, :-1], sy[:, 1:]))
    assert grad.max() <= tan_max + tol
    assert grad.max() > 0.5 * tan_max  # the field does use the slope budget
    assert h.min() >= 0.0 and h.max() <= spec.max_height_m * (1 + 1e-6)
    assert h.max() > 0.4 * spec.max_height_m
    assert terrain_max_slope_deg(m) <= spec.max_slope_deg + 1e-3


@pytest.mark.parametrize("src", SOURCES)
def test_terrain_flat_patch_floor_removed_home_valid(terrain_models, nominal, src):
    m = terrain_models[src]
    h, dx, gid = _hfield(m)
    coords = -SPEC.size_m + dx * np.arange(h.shape[0])
    inside = np.hypot(coords[None, :], coords[:, None]) <= SPEC.flat_radius_m
    assert inside.sum() > 1000 and np.all(h[inside] == 0.0)
    assert terrain_height_at(m, 0.0, 0.0) == 0.0
    assert terrain_height_at(m, 0.7 * SPEC.flat_radius_m, 0.0) == 0.0
    planes = (m.geom_type == mujoco.mjtGeom.mjGEOM_PLANE) & (m.geom_bodyid == 0)
    assert not planes.any() and m.ngeom == nominal[src].ngeom
    assert m.geom_conaffinity[gid] == 15 and m.geom_condim[gid] == 3
    assert m.nkey == 1 and m.key(HOME_KEY).qpos.shape == (m.nq,)
    np.testing.assert_array_equal(m.key_qpos, nominal[src].key_qpos)
    s = model_summary(m)
    assert s["has_terrain"] and s["terrain"]["max_height_m"] <= SPEC.max_height_m


def test_terrain_height_at_matches_ray(terrain_models):
    m = terrain_models["menagerie"]
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    h, dx, gid = _hfield(m)
    rng = np.random.default_rng(0)
    hit = np.zeros(1, np.int32)
    for x, y in rng.uniform(-15.0, 15.0, (50, 2)):
        dist = mujoco.mj_ray(m, d, np.array([x, y, 5.0]), np.array([0.0, 0.0, -1.0]),
                             None, 1, -1, hit)
        assert hit[0] == gid
        # MuJoCo collides with 2 triangles per cell; bilinear differs by at most a
        # quarter of the cell's twist h00 - h10 - h01 + h11.
        j, i = int((x + SPEC.size_m) / dx), int((y + SPEC.size_m) / dx)
        twist = abs(h[i, j] - h[i, j + 1] - h[i + 1, j] + h[i + 1, j + 1])
        assert terrain_height_at(m, x, y) == pytest.approx(5.0 - dist, abs=twist / 4 + 1e-5)
    assert terrain_height_at(m, 1e3, 0.0) == terrain_height_at(m, SPEC.size_m, 0.0)  # clamped
    with pytest.raises(ValueError, match="finite"):
        terrain_height_at(m, float("nan"), 0.0)


@pytest.mark.parametrize("src", SOURCES)
def test_physics_on_terrain(terrain_models, src):
    """Released from home (at the origin and on a raised spot), Cassie lands on the hfield."""
    m = terrain_models[src]
    gid = m.geom(TERRAIN_GEOM).id
    pelvis = m.body(PELVIS_BODY).id
    d = mujoco.MjData(m)
    for x, y in ((0.0, 0.0), (6.0, -4.0)):
        mujoco.mj_resetDataKeyframe(m, d, m.key(HOME_KEY).id)
        ground = max(terrain_height_at(m, x + a, y + b)
                     for a in (-0.4, 0.0, 0.4) for b in (-0.4, 0.0, 0.4))
        d.qpos[:3] += (x, y, ground + 0.005)  # both bases: qpos[0:3] = pelvis x y z
        touched = False
        for _ in range(200):
            mujoco.mj_step(m, d)
            geoms = d.contact.geom[:d.ncon]
            touched |= bool(np.any(geoms == gid))
            assert np.all(d.contact.dist[:d.ncon] > -0.01)  # no sinking in
        assert touched, (src, x, y)
        assert d.xpos[pelvis, 2] - terrain_height_at(m, *d.xpos[pelvis, :2]) > 0.6
