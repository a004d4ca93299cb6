"""A scene set mixing typical, procedural and indoor grids: one bank, the right field per env."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cat.envs.scene_set import SceneSet
from cat.fields import Grid, sdf_from_occupancy
from cat.terrain import make_indoor, make_procedural, make_typical


@pytest.fixture(scope="module")
def mixed_dir(tmp_path_factory):
    """Three scene folders with three grid shapes (goals trimmed to two per scene to keep the test short)."""
    root = tmp_path_factory.mktemp("mixed")
    made = {
        "typical/hc": make_typical("hurdle-crouch", 0.5, 0),
        "procedural/p": make_procedural(0.3, 1),
        "indoor/i": make_indoor(2),
    }
    for name, scene in made.items():
        scene.goals = scene.goals[:2]
        scene.save(root / name)
    return root


@pytest.fixture(scope="module")
def mixed(mixed_dir):
    return SceneSet.from_dir(mixed_dir, num_envs=6)


def test_from_dir_over_mixed_shapes(mixed):
    ss = mixed
    shapes = {ss.bank.layouts[s].grid.shape for s in range(ss.bank.num_scenes)}
    assert len(shapes) == 3
    assert ss.bank.num_fields == sum(len(s.goals) for s in ss.scenes)
    rng = np.random.default_rng(0)
    for s, scene in enumerate(ss.scenes):
        g = scene.grid()
        grid = Grid(g.origin, g.voxel, g.shape)
        sdf = sdf_from_occupancy(scene.occupancy(), grid)
        ijk = rng.integers(0, grid.shape, (13, 3))
        pts = grid.index_to_world(ijk) + ss.offsets[s]  # voxel centres, in the scene's tile
        for i in ss.bank.fields_of(s):
            q = ss.bank.query(torch.tensor([i], dtype=torch.int32), torch.as_tensor(pts, dtype=torch.float32)[None])
            np.testing.assert_allclose(q.sdf[0].numpy(), sdf[tuple(ijk.T)], atol=1e-4)
            assert q.inside.all()
        goals = ss.bank.goals[list(ss.bank.fields_of(s))].numpy()
        np.testing.assert_allclose(goals, scene.goals + ss.offsets[s], atol=1e-5)


def test_field_ids_follow_scene_and_goal(mixed):
    ss = mixed
    gen = torch.Generator().manual_seed(0)
    ids = torch.arange(6)
    start, goal, _ = ss.sample_episode(ids, gen)
    fids = ss.field_ids(ids)
    for e in range(6):
        s = int(ss.scene_of_env[e])
        assert int(fids[e]) in ss.bank.fields_of(s)
        np.testing.assert_allclose(ss.bank.goals[fids[e]].numpy(), goal[e].numpy(), atol=1e-5)


def test_env_steps_in_a_mixed_set(mixed):
    """The env runs on a mixed set: procedural obstacles as height fields + boxes beside convex parts."""
    from cat.envs.config import EnvCfg
    from cat.envs.traversal_env import TraversalEnv

    env = TraversalEnv(EnvCfg(num_envs=6), sim="mujoco", scenes=mixed, seed=0)
    names = [env.sim.model.geom(i).name for i in range(env.sim.model.ngeom)]
    assert any("floor_" in n for n in names) and any("box_" in n for n in names)
    for _ in range(5):
        obs, rew, done, extras = env.step(torch.zeros(6, env.num_actions))
    assert torch.isfinite(rew).all() and torch.isfinite(obs["actor"]).all()


def test_mirrored_scenes_carry_mirrored_fields():
    """``mirror=True`` follows each scene with its mirror image: same kind and difficulty, and its fields are the
    original's reflected (SDF and the goal force at mirrored points, force y negated), built for the mirrored
    goal. The run config's ``task.mirror_scenes`` switches it on."""
    ss = SceneSet.typical("side-pass", num_envs=2, variants=2, seed=0, per_world=True, mirror=True)
    assert len(ss.scenes) == 4 and [s.difficulty for s in ss.scenes] == [0.0, 0.0, 1.0, 1.0]
    assert [bool(s.meta.get("mirrored")) for s in ss.scenes] == [False, True, False, True]
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(-0.4, 2.4, 64), rng.uniform(-0.9, 0.9, 64), rng.uniform(0.05, 1.4, 64)]
    flip = np.array([1.0, -1.0, 1.0])
    for s in (0, 2):
        (a,), (b,) = ss.bank.fields_of(s), ss.bank.fields_of(s + 1)
        qa = ss.bank.query(torch.tensor([a], dtype=torch.int32), torch.as_tensor(pts, dtype=torch.float32)[None])
        qb = ss.bank.query(torch.tensor([b], dtype=torch.int32), torch.as_tensor(pts * flip, dtype=torch.float32)[None])
        np.testing.assert_allclose(qb.sdf.numpy(), qa.sdf.numpy(), atol=1e-4)
        # the geodesic solver's sweep order is not mirror-symmetric: forces agree to ~0.5 % of their ~1-2 magnitude
        np.testing.assert_allclose(qb.force.numpy(), qa.force.numpy() * flip, atol=1e-2)
    from cat.learning.hydra_cfg import load_config

    assert load_config(["task=side_pass", "task.mirror_scenes=true"]).task.mirror_scenes
