"""Scenes in the env: tiled obstacles collide, the field bank matches the mesh, specialists init from flat."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from cat.envs.config import EnvCfg
from cat.envs.scene_set import SceneSet, SceneSetError
from cat.envs.traversal_env import TraversalEnv
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import train


@pytest.fixture(scope="module")
def scene_env():
    scenes = SceneSet.typical("hurdle-crouch", num_envs=4, variants=2)
    return TraversalEnv(EnvCfg(num_envs=4, scene_kind="hurdle-crouch"), sim="mujoco", scenes=scenes, seed=1)


def test_episodes_start_in_their_tile(scene_env):
    ss = scene_env.scenes
    for i in range(4):
        s = int(ss.scene_of_env[i])
        lo, hi = ss.scenes[s].start_region + ss.offsets[s][:2]
        xy = scene_env.sim.qpos[i, :2].numpy()
        assert np.all(xy >= lo - 0.05) and np.all(xy <= hi + 0.05)
        np.testing.assert_allclose(scene_env.goals[i].numpy(), ss.scenes[s].goals[0] + ss.offsets[s], atol=1e-5)


def test_link_sdf_matches_mesh_distance(scene_env):
    """The bank's SDF at the 13 links agrees with trimesh's exact distance to the (shifted) scene mesh."""
    scene_env.step(torch.zeros(4, 12))
    for i in range(2):
        mesh = scene_env.scenes.mesh_for_env(i)
        pts = scene_env.state.link_pos[i].numpy().astype(np.float64)
        exact = -trimesh.proximity.signed_distance(mesh, pts)  # trimesh: positive inside
        got = scene_env.field.sdf[i].numpy()
        near = exact < 0.8  # the bank's SDF is exact up to its grid; far values may be truncated by the crop
        np.testing.assert_allclose(got[near], exact[near], atol=0.05)


def test_robot_inside_obstacle_reports_collision(scene_env):
    env, ss = scene_env, scene_env.scenes
    mesh = ss.mesh_for_env(0)
    # put the pelvis in the middle of the first obstacle part, upright
    centre = mesh.split(only_watertight=False)[0].centroid
    qpos, qvel = env.sim.qpos[:1].clone(), env.sim.qvel[:1].clone()
    qpos[0, 0], qpos[0, 1] = float(centre[0]), float(centre[1])
    env.sim.reset(torch.tensor([0]), qpos, qvel)
    env._update_state()
    assert env.state.collision[0]
    env.reset_idx(torch.arange(4))
    env._update_state()
    assert not env.state.collision.any()


def test_scene_dir_errors(tmp_path):
    with pytest.raises(SceneSetError, match="scene folder not found"):
        SceneSet.from_dir(tmp_path / "nope", num_envs=2)
    with pytest.raises(SceneSetError, match="no scenes"):
        SceneSet.from_dir(tmp_path, num_envs=2)


def test_specialist_initialises_from_flat_policy(tmp_path):
    """Flat and scene tasks share observation sizes, so a flat checkpoint initialises a specialist."""
    base = ["num_envs=8", "max_iterations=1", f"run_root={tmp_path}", "algo.num_steps_per_env=8"]
    flat = train(load_config(["task=flat", *base]))
    ckpt = sorted(flat.glob("model_*.pt"))[-1]
    spec = train(
        load_config(["task=hurdle_crouch", "task.scene_variants=2", "task.warmup_variants=0", f"init={ckpt}", *base])
    )
    assert sorted(spec.glob("model_*.pt"))
