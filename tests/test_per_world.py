"""Per-world scenes (``sim.per_world_scenes``): each world holds only its own scene's obstacles, an env changes
scene at reset by swapping its world's model, domain randomisation draws pool members, snapshots restore."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch
from mujoco import batch

from cat.envs.config import EnvCfg
from cat.envs.scene import COLLISION_SENSOR
from cat.envs.scene_models import WorldModels, build_scene_models, layout_classes
from cat.envs.scene_set import SceneSet, SceneSetError, scene_fields
from cat.envs.sim import check_backend
from cat.envs.sim.layout import PAD_BODY, SceneModelError, data_layout
from cat.envs.sim.mujoco_backend import MujocoBackend
from cat.envs.traversal_env import TraversalEnv
from cat.terrain import typical_variants
from cat.terrain.mujoco_export import obstacle_geom_ids

KINDS = ("side-crouch", "hurdle-pass", "hurdle-crouch")  # 3, 3 and 2 convex parts
FREE, WALL = 0, 1  # scene indices: side-crouch is free around SPOT, hurdle-pass has its side wall there
SPOT = (0.4, 0.6)  # xy (scene frame) inside hurdle-pass's side wall (x 0.35-1.7, y >= 0.5)


@pytest.fixture(scope="module")
def scenes():
    return [typical_variants(k, 1, 0)[0] for k in KINDS]


@pytest.fixture(scope="module")
def fields(scenes):
    return [scene_fields(s, None, None) for s in scenes]


def make_env(scenes, fields, n=4, dr=False, seed=0, per_world=True):
    cfg = EnvCfg(num_envs=n)
    cfg.curriculum.enabled = False  # scenes stay where the tests put them
    cfg.domain_rand.enabled = dr
    cfg.domain_rand.pool_size = 4
    return TraversalEnv(cfg, scenes=SceneSet(scenes, fields, n, per_world=per_world), seed=seed)


@pytest.fixture(scope="module")
def env(scenes, fields):
    return make_env(scenes, fields)


def _occupied(scene, lo, hi) -> bool:
    g, occ = scene.grid(), scene.occupancy()
    org = np.asarray(g.origin)
    i0 = np.floor((np.asarray(lo) - org) / g.voxel).astype(int).clip(0)
    i1 = np.ceil((np.asarray(hi) - org) / g.voxel).astype(int)
    return bool(occ[i0[0] : i1[0], i0[1] : i1[1], i0[2] : i1[2]].any())


def _place(env, scene_ids) -> None:
    """Reset envs 0..k-1 at SPOT, facing +x, in ``scene_ids``."""
    k = len(scene_ids)
    start = torch.tensor([SPOT] * k, dtype=torch.float32)
    goal = torch.tensor([[2.0, 0.0, 0.75]] * k)
    env.reset_to(
        torch.arange(k), start, torch.zeros(k), goal, torch.tensor(scene_ids), torch.zeros(k, dtype=torch.long)
    )


def test_scene_models_share_one_mjdata_layout(scenes, robot_cfg):
    models = build_scene_models(robot_cfg, scenes)
    assert len({data_layout(m) for m in models}) == 1  # padded to one class
    b = batch.Batch(models[0], nsim=len(models), nthread=1)
    b.set_models(models)  # MuJoCo's own check that they give MjData one layout
    for m in models:  # the pad geoms collide with nothing
        pad = [g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body(PAD_BODY).id]
        assert pad and not m.geom_contype[pad].any() and not m.geom_conaffinity[pad].any()
    separate = build_scene_models(robot_cfg, scenes, group_ratio=1.0)  # a class per geom count: no padding
    assert len({data_layout(m) for m in separate}) == len({m.ngeom for m in separate}) == 2


def test_layout_classes_group_by_geom_count():
    assert layout_classes([30, 31, 500, 32, 41, 620, 36], 1.25) == [[0, 1, 3, 6], [4], [2, 5]]
    assert layout_classes([5, 5], 1.0) == [[0, 1]]


def test_scene_with_other_state_size_is_named(scenes, robot_cfg, monkeypatch):
    import cat.envs.scene_models as sm

    real = sm.add_obstacles_to_spec

    def with_a_door(spec, scene, **kw):  # a hinged obstacle: not static, one more dof
        real(spec, scene, **kw)
        if scene is scenes[1]:
            door = spec.worldbody.add_body(name="door", pos=[5, 5, 1])
            door.add_joint(type=mujoco.mjtJoint.mjJNT_HINGE)
            door.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.1, 0.1, 0.1])

    monkeypatch.setattr(sm, "add_obstacles_to_spec", with_a_door)
    with pytest.raises(SceneModelError, match=r"scene 1 \('hurdle-pass'.*nq 37 != 36"):
        build_scene_models(robot_cfg, scenes)


def test_padding_and_layout_classes_do_not_change_physics(scenes, robot_cfg):
    """Worlds on padded models (one rollout) step exactly like worlds on unpadded ones (a rollout per class)."""
    runs = []
    for ratio in (1.25, 1.0):
        models = build_scene_models(robot_cfg, scenes, group_ratio=ratio)
        sim = MujocoBackend(models[0], 3, 4, nthread=2, max_sensors=(COLLISION_SENSOR,))
        sim.set_model_table(models)
        sim.assign_models(torch.arange(3), torch.tensor([2, 0, 1]))
        assert sim.num_layouts == (1 if ratio > 1 else 2)
        qpos = sim.qpos.clone()
        qpos[:, 0] = torch.tensor([0.0, 0.3, 0.5])
        qpos[2, 1] = 0.45  # world 2 leans on hurdle-pass's side wall (y >= 0.5)
        sim.reset(torch.arange(3), qpos, sim.qvel.clone())
        rng = torch.Generator().manual_seed(0)
        for _ in range(10):
            sim.step(sim.qpos[:, 7:] + 0.2 * torch.rand(3, models[0].nu, generator=rng, dtype=torch.float64))
        runs.append((sim.qpos.clone(), sim.sensordata.clone()))
        assert sim.sensor(COLLISION_SENSOR)[:, 0].tolist()[2] > 0
    torch.testing.assert_close(runs[0][0], runs[1][0], rtol=0, atol=0)
    torch.testing.assert_close(runs[0][1], runs[1][1], rtol=0, atol=0)


def test_world_touches_only_its_own_scene(env, scenes):
    assert not _occupied(scenes[FREE], (SPOT[0] - 0.45, SPOT[1] - 0.45, 0), (SPOT[0] + 0.45, SPOT[1] + 0.45, 1.5))
    assert _occupied(scenes[WALL], (SPOT[0] - 0.05, SPOT[1] - 0.05, 0.3), (SPOT[0] + 0.05, SPOT[1] + 0.05, 1.0))
    assert np.all(env.scenes.offsets == 0.0)  # every scene in its own frame
    _place(env, [FREE, WALL])
    contact = env.sim.sensor(COLLISION_SENSOR)[:2, 0]
    assert contact[0] == 0 and contact[1] > 0  # the same spot: scene FREE's world has nothing there
    assert env.state.collision.tolist()[:2] == [False, True]
    sdf_free, sdf_wall = env.field.sdf[0].clone(), env.field.sdf[1].clone()
    assert sdf_free.min() > 0.2 and sdf_wall.min() < 0.0
    pf = env.humanoid_pf[:2].clone()

    _place(env, [WALL, FREE])  # each env changes scene at reset: contacts and field follow
    contact = env.sim.sensor(COLLISION_SENSOR)[:2, 0]
    assert contact[0] > 0 and contact[1] == 0
    assert env.state.collision.tolist()[:2] == [True, False]
    assert env.field.sdf[0].min() < 0.0 and env.field.sdf[1].min() > 0.2
    assert not torch.allclose(env.humanoid_pf[0], pf[0]) and not torch.allclose(env.humanoid_pf[1], pf[1])
    models = env.world_models.models
    assert env.sim.model_ids[:2].tolist() == [WALL, FREE]
    assert env.sim._shared_models[0] is models[WALL] and env.sim._shared_models[1] is models[FREE]
    bank = env.scenes.bank
    expected = bank.query(env.field_source.field_idx[:2], env.state.link_pos[:2]).sdf
    torch.testing.assert_close(env.field.sdf[:2], expected)


def test_reset_moves_worlds_to_their_scene_model(env):
    env.scenes.assign_scenes(torch.arange(4), torch.tensor([2, 2, 1, 0]))  # as the curriculum does
    env.reset_idx(torch.arange(4))
    assert env.sim.model_ids.tolist() == [2, 2, 1, 0]  # pool of 1 without domain randomisation


def test_domain_randomisation_draws_pool_members_and_snapshot_restores(scenes, fields):
    n = 8
    env = make_env(scenes, fields, n=n, dr=True, seed=3)
    wm = env.world_models
    assert wm.pool == 4 and len(wm.models) == 3 * 4
    assert len(set(env.kp[:, 0].tolist())) > 1  # worlds see different gains
    for i in range(n):  # each world's model carries the gains and masses its env observes
        m = env.sim._shared_models[i]
        s, k = divmod(int(env.sim.model_ids[i]), wm.pool)
        assert s == int(env.scenes.scene_of_env[i])
        torch.testing.assert_close(env.dr_scales[i], wm.scales[s, k])
        np.testing.assert_allclose(m.actuator_gainprm[:, 0], env.kp[i].double().numpy(), rtol=1e-6)
        np.testing.assert_allclose(-m.actuator_biasprm[:, 2], env.kd[i].double().numpy(), rtol=1e-6)
        np.testing.assert_allclose(m.body_mass, wm._mass0[s] * float(wm.scales[s, k, 2]))

    actions = torch.rand(40, n, env.num_actions, generator=torch.Generator().manual_seed(1)) * 2 - 1
    for a in actions[:10]:
        env.step(a)
    snap, rng, torch_rng = env.get_state(), env.generator.get_state(), torch.get_rng_state()  # as runs.py saves
    assert "model_ids" in snap["sim"] and "world_model_scales" in snap
    first = [env.step(a)[:3] for a in actions[10:]]
    assert sum(int(d.sum()) for *_, d in first) > 0  # some worlds reset (and drew pool members) after the snapshot

    other = make_env(scenes, fields, n=n, dr=True, seed=11)  # another pool and other assignments
    assert not torch.equal(other.world_models.scales, wm.scales)
    other.set_state(snap)
    other.generator.set_state(rng)
    torch.set_rng_state(torch_rng)  # observation noise
    assert torch.equal(other.world_models.scales, wm.scales)
    assert torch.equal(other.sim.model_ids, snap["sim"]["model_ids"])
    for (obs, rew, _), a in zip(first, actions[10:], strict=True):
        obs2, rew2 = other.step(a)[:2]
        torch.testing.assert_close(rew2, rew, rtol=0, atol=0)
        for key in obs.keys():
            torch.testing.assert_close(obs2[key], obs[key], rtol=0, atol=0)


def test_snapshots_do_not_cross_layouts(scenes, fields, env):
    tiles = make_env(scenes, fields, n=4, per_world=False)
    with pytest.raises(ValueError, match="per-world"):
        tiles.set_state(env.get_state())
    with pytest.raises(ValueError, match="lacks world_model_scales"):
        env.set_state(tiles.get_state())


def test_per_world_backends(scenes, fields):
    check_backend("mujoco")
    check_backend("warp")  # slot model: tests/test_warp_slots.py
    with pytest.raises(ValueError, match="unknown sim backend"):
        check_backend("bullet")
    with pytest.raises(SceneSetError, match="one model per scene"):
        SceneSet(scenes, fields, 2, per_world=True).add_to_spec(mujoco.MjSpec())


def test_pool_memory_is_per_scene_not_per_env(scenes, robot_cfg):
    models = build_scene_models(robot_cfg, scenes)
    wm = WorldModels(models, robot_cfg, pool=4)
    assert len(wm.models) == 12 and wm.nbytes == sum(m.nbuffer for m in wm.models)
    assert wm.models[0] is models[0] and wm.models[1] is not models[0]


def test_run_config_switch():
    from cat.learning.hydra_cfg import load_config
    from cat.learning.runs import make_env as make_run_env

    cfg = load_config(
        [
            "task=hurdle_crouch",
            "num_envs=4",
            "task.scene_variants=2",
            "task.warmup_variants=0",
            "sim.per_world_scenes=true",
        ]
    )
    env = make_run_env(cfg)
    assert env.scenes.per_world and np.all(env.scenes.offsets == 0.0)
    wm = env.world_models
    assert torch.equal(env.sim.model_ids // wm.pool, env.scenes.scene_of_env)
    assert not load_config(["task=hurdle_crouch"]).sim.per_world_scenes  # tiles by default


def test_ghost_obstacles_in_every_table_model(scenes, fields):
    from cat.envs.scene import GHOST_SOLREF

    cfg = EnvCfg(num_envs=2, ghost_obstacles=True)
    cfg.domain_rand.enabled, cfg.domain_rand.pool_size = True, 2
    env = TraversalEnv(cfg, scenes=SceneSet(scenes, fields, 2, per_world=True), seed=0)
    for m in env.world_models.models:  # every scene's pool member: obstacle contacts counted, no force
        obstacle = obstacle_geom_ids(m)
        assert len(obstacle) and np.allclose(m.geom_solref[obstacle], GHOST_SOLREF)
    _place(env, [WALL, FREE])
    assert env.state.collision.tolist() == [True, False]


def test_cell_bodies_change_no_physics(robot_cfg, monkeypatch):
    """Obstacle geoms spread over the 4 × 4 cell bodies step exactly like the same geoms on one body (MuJoCo C),
    and the collision sensor counts the same contacts."""
    import cat.envs.scene_models as sm
    from cat.envs.robot import home_qpos
    from cat.terrain import make_procedural

    scene = make_procedural(0.3, 1)  # height-field tiles and boxes, touched from this start
    cells = sm.build_scene_models(robot_cfg, [scene])[0]
    monkeypatch.setattr(sm, "OBSTACLE_CELLS", None)
    one = sm.build_scene_models(robot_cfg, [scene])[0]
    geoms = obstacle_geom_ids(cells)
    assert len(geoms) == len(obstacle_geom_ids(one)) > 0
    assert len(np.unique(cells.geom_bodyid[geoms])) > 4 and len(np.unique(one.geom_bodyid[obstacle_geom_ids(one)])) == 1
    q0 = home_qpos(robot_cfg)
    q0[:2] = (1.1, -2.8)
    runs = []
    for m in (cells, one):
        d = mujoco.MjData(m)
        d.qpos[:] = q0
        mujoco.mj_forward(m, d)
        rng, qs, touches = np.random.default_rng(0), [], 0
        for _ in range(40):
            d.ctrl[:] = q0[7:] + 0.1 * rng.uniform(size=m.nu)
            for _ in range(robot_cfg.decimation):
                mujoco.mj_step(m, d)
            qs.append(d.qpos.copy())
            touches += int(d.sensor(COLLISION_SENSOR).data[0])
        runs.append((np.array(qs), touches))
    assert runs[0][1] == runs[1][1] > 0  # the robot touched the obstacles, and both models counted it alike
    np.testing.assert_allclose(runs[0][0], runs[1][0], atol=1e-10)
