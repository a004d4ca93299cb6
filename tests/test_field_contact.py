"""``sim.obstacles=field``: contact judged from the scene SDF (cat/envs/field_contact.py), real MuJoCo throughout.

A constructed pose 2 cm inside a wall is in contact and 1 cm clear is not (in both modes); the judgement's
agreement with physical contact over random-action rollouts of every typical type; one model for any number of
scenes; evaluation of a field-trained run is physical.
"""

from __future__ import annotations

import logging

import mujoco
import numpy as np
import pytest
import torch

from cat.envs.config import EnvCfg
from cat.envs.field_contact import FieldContact, FieldContactCfg, body_poses, fill_contact_sdf, geom_surface_points
from cat.envs.math_utils import quat_to_matrix
from cat.envs.robot import home_qpos
from cat.envs.scene_set import SceneSet, scene_fields
from cat.envs.traversal_env import TraversalEnv
from cat.terrain import TYPICAL_KINDS, Scene
from cat.terrain.mujoco_export import obstacle_geom_ids
from cat.terrain.primitives import box

log = logging.getLogger(__name__)
FACE_X = 0.2  # wall face on a voxel face of the scene grid (origin x -1.0, 4 cm voxels): the SDF is exact there
G = mujoco.mjtGeom


def wall_scene(face_x: float = FACE_X) -> Scene:
    """A wall filling x >= ``face_x`` (0.4 m thick, 2 m wide, 1.6 m tall), goal behind the robot."""
    return Scene(
        mesh=box((face_x, -1.0, 0.0), (face_x + 0.4, 1.0, 1.6)),
        bounds=np.array([[-1.0, -1.2, 0.0], [1.8, 1.2, 1.8]]),
        start=np.array([-0.5, 0.0, 0.75]),
        goals=np.array([[-0.8, 0.0, 0.75]]),
        kind="wall",
    )


def wall_env(obstacles: str, faces=(FACE_X,), sim: str = "mujoco", per_world: bool = True) -> TraversalEnv:
    scenes = [wall_scene(f) for f in faces]
    n = len(scenes)
    sset = SceneSet(scenes, [scene_fields(s, None, None) for s in scenes], n, per_world=per_world)
    return TraversalEnv(EnvCfg(num_envs=n), sim=sim, scenes=sset, obstacles=obstacles)


def front_x(fc: FieldContact, sens: torch.Tensor) -> float:
    """World 0: the largest x the judged shapes reach (judged points' x + their inflation: exact for a capsule or a
    sphere, and for a box, whose corners are samples)."""
    pos, quat = fc.poses(sens)
    rot = quat_to_matrix(quat)[0]
    return max(
        float((pos[0, b, 0] + (p @ rot[b].T)[:, 0]).max() + off)
        for p, b, off in zip(fc.geom_points, fc.geom_body.tolist(), fc.geom_offset.tolist(), strict=True)
    )


def pose_at(env: TraversalEnv, x: float) -> None:
    """Every world: the home pose, root at (x, 0), facing +x; sensors (and contacts) recomputed."""
    n = env.num_envs
    qpos = torch.tensor(home_qpos(env.robot), dtype=torch.float64).repeat(n, 1)
    qpos[:, 0] = x
    env.sim.reset(torch.arange(n), qpos, torch.zeros(n, env.sim.model.nv, dtype=torch.float64))
    env._update_state()


def front_offset(env: TraversalEnv) -> float:
    """x of the robot's frontmost collision surface (as judged) relative to its root, in the home pose."""
    pose_at(env, 0.0)
    return front_x(env.field_contact, env.sim.sensordata.float())


@pytest.mark.parametrize("gtype,size", [(G.mjGEOM_SPHERE, (0.07, 0, 0)), (G.mjGEOM_CAPSULE, (0.045, 0.075, 0)),
                                        (G.mjGEOM_BOX, (0.09, 0.03, 0.008))])  # fmt: skip
def test_surface_points_lie_on_and_cover_the_geom(gtype, size):
    spacing = 0.03
    pts = geom_surface_points(gtype, np.array(size), spacing)
    r = size[0]
    if gtype == G.mjGEOM_SPHERE:
        dist = np.abs(np.linalg.norm(pts, axis=1) - r)
        probe = np.random.default_rng(0).normal(size=(500, 3))
        probe = r * probe / np.linalg.norm(probe, axis=1, keepdims=True)
    elif gtype == G.mjGEOM_CAPSULE:
        h = size[1]
        axis = np.c_[np.zeros(len(pts)), np.zeros(len(pts)), np.clip(pts[:, 2], -h, h)]
        dist = np.abs(np.linalg.norm(pts - axis, axis=1) - r)
        rng = np.random.default_rng(0)
        d = rng.normal(size=(300, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        caps = np.c_[np.zeros(300), np.zeros(300), np.sign(d[:, 2]) * h] + r * d  # the hemispherical caps
        a, z = rng.uniform(0, 2 * np.pi, 300), rng.uniform(-h, h, 300)
        probe = np.r_[caps, np.c_[r * np.cos(a), r * np.sin(a), z]]  # and the cylinder between them
    else:
        half = np.array(size)
        dist = np.min(np.abs(np.abs(pts) - half), axis=1)  # on some face
        assert np.all(np.abs(pts) <= half + 1e-9)
        rng = np.random.default_rng(0)
        probe = rng.uniform(-half, half, (600, 3))
        k = rng.integers(0, 3, 600)
        probe[np.arange(600), k] = np.sign(rng.uniform(-1, 1, 600)) * half[k]
    assert dist.max() < 1e-6
    gap = np.linalg.norm(probe[:, None] - pts[None], axis=-1).min(axis=1)
    assert gap.max() <= spacing  # every surface point is within one spacing of a sample


def test_pose_two_cm_inside_a_wall_is_contact_and_one_cm_clear_is_not():
    field, physical = wall_env("field"), wall_env("physical")
    margin = field.field_contact.cfg.margin
    assert -0.02 < margin < 0.01  # the documented margin separates the two poses
    dx = front_offset(field)
    for depth, expect in ((0.02, True), (-0.01, False)):
        x = FACE_X + depth - dx
        for env in (field, physical):
            pose_at(env, x)
            assert bool(env.state.collision[0]) is expect, (env.obstacles, depth)
        front = front_x(field.field_contact, field.sim.sensordata.float())
        assert abs(front - (FACE_X + depth)) < 1e-4  # the pose is what the test says
    assert field.sim.model.ngeom < physical.sim.model.ngeom  # the field world holds no wall


def test_one_model_serves_worlds_of_different_scenes():
    """Two scenes (wall at 0.2 m, wall at 1.4 m): one floor-only model; each world judged by its own scene."""
    one, two = wall_env("field"), wall_env("field", faces=(FACE_X, 1.4))
    assert one.world_models is None and two.world_models is None
    assert one.sim.model.nbuffer == two.sim.model.nbuffer  # model memory does not grow with the scene count
    assert len(obstacle_geom_ids(two.sim.model)) == 0
    dx = front_offset(two)
    pose_at(two, FACE_X + 0.02 - dx)  # the same pose in both worlds
    assert two.state.collision.tolist() == [True, False]
    tiles = wall_env("field", faces=(FACE_X, 1.4), per_world=False)  # tiles: scenes side by side, same model
    assert tiles.sim.model.nbuffer == one.sim.model.nbuffer


def test_reward_termination_and_trial_read_the_field_judgement():
    """The same pose in two worlds, one 2 cm into its wall: the collision reward, the collision termination and the
    trial's collided flag (success rule, curriculum outcome) follow the field judgement, world by world."""
    env = wall_env("field", faces=(FACE_X, 1.4))
    env.cfg.terminations.on_collision = True
    env.auto_reset = False
    pose_at(env, FACE_X + 0.02 - front_offset(env))
    env.step(torch.zeros(env.num_envs, env.num_actions))
    assert env.state.collision.tolist() == [True, False]
    assert env.termination_flags["collided"].tolist() == [True, False]
    assert env.trial.collided.tolist() == [True, False]
    assert env.episode_sums["collision"][0] < 0 and env.episode_sums["collision"][1] == 0
    assert not env.episode_success(torch.tensor([0])).item()


def test_warp_backend_judges_the_same_contact():
    """sim=warp (Warp's CPU device) in field mode: the one model steps, the pose sensors give the same judgement."""
    env = wall_env("field", faces=(FACE_X, 1.4), sim="warp")
    ref = wall_env("field", faces=(FACE_X, 1.4))
    x = FACE_X + 0.02 - front_offset(ref)
    for e in (env, ref):
        pose_at(e, x)
    assert env.state.collision.tolist() == ref.state.collision.tolist() == [True, False]
    for _ in range(3):
        env.step(torch.zeros(env.num_envs, env.num_actions))
    assert torch.isfinite(env.sim.qpos).all()


@pytest.mark.parametrize("sim", ["mujoco", "warp"])
def test_backends_keep_the_pose_sensors_of_every_substep(sim):
    """``sim.obstacles=field`` judges every substep: the backend keeps the body pose readings at the start of each
    physics step (s_0 = the state before the control step, as a reset to it reads them; the last = sensordata);
    after a reset every substep holds the reset reading; snapshots carry them."""
    env = wall_env("field", faces=(FACE_X, FACE_X - 0.1), sim=sim)
    s, tol = env.sim, dict(atol=1e-5, rtol=0) if sim == "warp" else dict(atol=1e-12, rtol=0)
    cols = s.substep_columns
    assert env.field_contact.cfg.substeps and len(cols) == 7 * len(env.field_contact.bodies)
    assert s.substep_sensordata.shape == (2, s.decimation, len(cols))
    torch.testing.assert_close(s.substep_sensordata, s.sensordata[:, cols].unsqueeze(1).expand(-1, s.decimation, -1))
    q0, v0 = s.qpos.clone(), s.qvel.clone()
    s.step(torch.tensor(home_qpos(env.robot)[7:], dtype=torch.float32).repeat(2, 1) + 0.3)
    sub = s.substep_sensordata.clone()
    torch.testing.assert_close(sub[:, -1], s.sensordata[:, cols], **tol)
    assert (sub[:, 1] - sub[:, 0]).abs().max() > 1e-6  # the substeps differ: the robot moved
    state = s.get_state()
    s.reset(torch.arange(2), q0, v0)
    torch.testing.assert_close(s.sensordata[:, cols], sub[:, 0], **tol)
    torch.testing.assert_close(s.substep_sensordata, s.sensordata[:, cols].unsqueeze(1).expand_as(sub))
    s.set_state(state)
    torch.testing.assert_close(s.substep_sensordata, sub)


@pytest.fixture(scope="module")
def agreement() -> dict[str, dict[str, tuple[int, int, int, int]]]:
    """Per typical type and judgement: (steps, physical contact steps, field-only, physical-only) over random-action
    rollouts of 16 envs x 50 steps from the env's own episode starts, physical obstacles. The field judgement is
    made on the same states, as training makes it (``FieldContactCfg.substeps``): at the start of every physics
    substep, where the contact sensors are read (body poses by forward kinematics of the backend's substep
    states). Judgements: ``mesh`` (the default: the contact SDF) and ``field`` (the fields' d). Culled and
    unculled judge alike on every state, and the fused kernel as its torch reference on d."""
    out = {}
    for kind in TYPICAL_KINDS:
        sset = SceneSet.typical(kind, 16, variants=2)
        env = TraversalEnv(EnvCfg(num_envs=16), scenes=sset, seed=0)
        env.auto_reset = False
        sim = env.sim
        assert sim._table is None or len(sim._class_worlds()) == 1  # one rollout: _out_state holds every world
        judges = {m: FieldContact(sim.model, env.robot, FieldContactCfg(sdf=m)) for m in ("mesh", "field")}
        fill_contact_sdf(sset, judges["mesh"].cfg)
        full = FieldContact(sim.model, env.robot, FieldContactCfg())
        full.cull = False
        margin, idx = FieldContactCfg().margin, env.field_source.field_idx
        g = torch.Generator().manual_seed(1)
        phys, field = [], {m: [] for m in judges}
        for _ in range(50):
            before = sim.qpos.numpy().copy()
            env.step(0.5 * torch.randn(16, env.num_actions, generator=g))
            qadr = sim._qadr  # the state at the start of substep k: before the step (k = 0), after substep k
            states = [before] + [sim._out_state[:, k, qadr : qadr + sim.model.nq] for k in range(sim.decimation - 1)]
            touching = {m: torch.zeros(16, dtype=torch.bool) for m in judges}
            for q in states:
                pos, quat = body_poses(sim.model, judges["mesh"].bodies, q)
                sdf = {m: j.body_sdf(sset.bank, idx, pos, quat) < margin for m, j in judges.items()}
                assert torch.equal(sdf["mesh"], full.body_sdf(sset.bank, idx, pos, quat) < margin)
                ref = judges["field"].body_sdf_torch(sset.bank, idx, pos, quat)  # the fused kernel's reference
                assert torch.equal(sdf["field"], ref < margin)
                for m in judges:
                    touching[m] |= sdf[m].any(-1)
            phys.append(env.state.collision.clone())
            for m in judges:
                field[m].append(touching[m])
        p = torch.cat(phys)
        out[kind] = {}
        for m in judges:
            f = torch.cat(field[m])
            out[kind][m] = (len(p), int(p.sum()), int((f & ~p).sum()), int((p & ~f).sum()))
            log.info("%s (%s): steps=%d physical=%d field_only=%d physical_only=%d", kind, m, *out[kind][m])
    return out


@pytest.mark.parametrize("sdf", ["mesh", "field"])
def test_field_judgement_sees_the_contacts(agreement, sdf):
    """Either judgement is not trivially 'free': most physical contacts are seen, few are invented."""
    counts = [v[sdf] for v in agreement.values()]
    steps, contacts = sum(c[0] for c in counts), sum(c[1] for c in counts)
    field_only, physical_only = sum(c[2] for c in counts), sum(c[3] for c in counts)
    assert contacts > 0.02 * steps
    assert physical_only < 0.5 * contacts and field_only < 0.5 * contacts


def test_the_contact_sdf_agrees_better_than_the_fields_d(agreement):
    """Over all typical types, the default judgement (contact SDF) disagrees with physical contact on fewer than
    half the steps the fields' d does (measured 2026-12-05: 5 against 36 of 6,400 steps)."""
    wrong = {m: sum(v[m][2] + v[m][3] for v in agreement.values()) for m in ("mesh", "field")}
    assert wrong["mesh"] < 0.5 * wrong["field"], wrong


def test_field_agrees_with_physical_contact_on_99_percent_of_steps(agreement):
    """Per typical type, the default judgement (capsule axes and sphere centres at d - radius, the contact SDF,
    every substep, +1 mm) agrees with physical contact on >= 99 % of steps. Measured 2026-12-05: 5 disagreeing
    steps of 6,400 (hurdle-crouch 0 / 1, side-hurdle-crouch 1 / 2, side-hurdle 1 / 0 field-only / physical-only, the
    other five types none); worst type 99.6 %."""
    worst = {k: 1.0 - (v["mesh"][2] + v["mesh"][3]) / v["mesh"][0] for k, v in agreement.items()}
    assert min(worst.values()) >= 0.99, worst


def slab_scene() -> Scene:
    """A slab at shin height across the start region: every trial starts in physical contact with it."""
    return Scene(
        mesh=box((-0.9, -0.6, 0.25), (-0.1, 0.6, 0.31)),
        bounds=np.array([[-1.5, -1.2, 0.0], [1.5, 1.2, 1.8]]),
        start=np.array([-0.5, 0.0, 0.75]),
        goals=np.array([[1.0, 0.0, 0.75]]),
        kind="slab",
    )


@pytest.fixture(scope="module")
def field_run(tmp_path_factory):
    """A 1-iteration hurdle-crouch run trained with sim.obstacles=field, and a folder with the slab scene."""
    from omegaconf import OmegaConf

    from cat.learning.hydra_cfg import load_config
    from cat.learning.runs import train

    root = tmp_path_factory.mktemp("field_run")
    cfg = load_config(
        ["task=hurdle_crouch", "num_envs=8", "max_iterations=1", f"run_root={root}", "algo.num_steps_per_env=8"]
        + ["task.scene_variants=1", "task.warmup_variants=0", "sim.obstacles=field"]
    )
    run = train(cfg)
    assert OmegaConf.load(run / "config.yaml").sim.obstacles == "field"
    slab_scene().save(root / "slab" / "s0")
    return run, root / "slab"


def test_evaluation_of_a_field_trained_run_is_physical(field_run, caplog, monkeypatch):
    """play.py on a run whose config.yaml says sim.obstacles=field: physical obstacles, real contacts counted
    (per-body contact sensors exist only in a physical world: FirstContacts refuses a field env)."""
    import cat.learning.play as play_mod
    from cat.learning.play import PlayCfg, play_trials

    run, slab = field_run
    built = []
    make = play_mod.make_eval_env

    def recording(*args, **kw):  # the real make_eval_env; only remembers the env it built
        built.append(make(*args, **kw))
        return built[-1]

    monkeypatch.setattr(play_mod, "make_eval_env", recording)
    play = PlayCfg(checkpoint=str(run), episodes=2, scene_dir=str(slab), contacts=True, clearance=True, time_s=0.2)
    with caplog.at_level(logging.INFO, logger="cat.eval.runner"):
        played = play_trials(play)
    results, first = played.results, played.first_contacts
    assert all(c < 0.0 for c in played.clearance)  # the shins start inside the slab
    assert [e.obstacles for e in built] == ["physical"]
    assert len(obstacle_geom_ids(built[0].sim.model)) > 0  # the slab is geometry in the evaluation world
    assert all(r.collided for r in results) and all(b is not None for b in first)
    assert "trained with sim.obstacles=field: evaluation builds physical obstacles" in caplog.text


def test_click_demo_of_a_field_trained_run_counts_physical_contacts(field_run, caplog, capsys):
    """The headless click demo with the field-trained checkpoint, toes in a wall at the start: contacts counted."""
    import re

    from cat.deploy.cli import main

    run, slab = field_run
    ckpt = sorted(run.glob("model_*.pt"))[-1]
    folder = slab.parent / "wall_at_toes"
    wall_scene(face_x=-0.5 + 0.12 - 0.03).save(folder)  # the toes (0.12 m ahead of the root) 3 cm into the wall
    with caplog.at_level(logging.INFO, logger="cat.deploy.runtime"):
        code = main([f"scene={folder}", f"checkpoint={ckpt}", "goal=-0.9,0.8", "time_limit=0.3", "realtime=false"])
    assert code == 0
    m = re.search(r"collisions=(\d+)", capsys.readouterr().out)
    assert m is not None and int(m.group(1)) >= 1
    assert "trained with sim.obstacles=field: the demo simulates physical obstacles" in caplog.text


@pytest.mark.parametrize("mode", ["field", "physical"])
def test_bench_train_on_a_scene_set_prints_its_line(mode, tmp_path, capsys):
    """``scripts/bench.py train --scenes N --obstacles MODE`` at a tiny size (generated scenes, or a folder)."""
    import importlib.util
    import re
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("bench_script", Path(__file__).parents[1] / "scripts" / "bench.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    args = ["train", "--scenes", "2", "--obstacles", mode, "--num-envs", "8", "--iterations", "1", "--seconds", "0.2"]
    if mode == "physical":
        for i, face in enumerate((FACE_X, 1.4)):
            wall_scene(face).save(tmp_path / f"w{i}")
        args += ["--scene-dir", str(tmp_path)]
    assert bench.main([*args, "algo.num_steps_per_env=4", "torch_threads=1"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    pattern = (
        rf"case=train scenes=2 obstacles={mode} num_envs=8 env_steps_per_s=(\d+) raw_flat_env_steps_per_s=(\d+) "
        r"ratio=([\d.]+) field_storage=float32 bank_mb=(\d+) peak_rss_mb=(\d+) "
        r"rss_mb=start:\d+,scenes:\d+,bank:\d+,env:\d+,train:\d+"
    )
    m = re.fullmatch(pattern, line)
    assert m is not None, line
    assert int(m.group(1)) > 0 and int(m.group(2)) > 0 and int(m.group(5)) > int(m.group(4))


def test_bench_soak_on_a_scene_folder_in_field_mode_prints_its_counts(tmp_path, capsys):
    """``bench.py soak --scene-dir D --obstacles field --field-storage compact`` at a tiny size: random actions
    through floor-only worlds, its line counts non-finite values, states and MuJoCo's own resets."""
    import re

    from cat.bench.soak import main as soak

    for i, face in enumerate((FACE_X, 1.4)):
        wall_scene(face).save(tmp_path / f"w{i}")
    soak(
        ["steps=64", "--envs", "4", "--scene-dir", str(tmp_path), "--obstacles", "field"]
        + ["--field-storage", "compact"]
    )
    line = capsys.readouterr().out.strip().splitlines()[-1]
    pattern = (
        r"case=soak steps=64 nonfinite=0 nonfinite_state=0 auto_resets=0 resets=(\d+) by_cause=\S* envs=4 "
        r"sim=mujoco layout=tiles obstacles=field scenes=2 field_storage=compact seconds=\d+"
    )
    assert re.fullmatch(pattern, line), line
