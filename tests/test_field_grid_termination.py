"""Leaving the scene's field grid ends the episode (instead of reading clamped border values)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cat.envs.config import EnvCfg
from cat.envs.scene_set import BankField, SceneSet
from cat.envs.traversal_env import TraversalEnv
from cat.fields import FieldBank, FieldCfg, Grid, SceneFields


def test_outside_distance_per_env():
    grid = Grid((0.0, 0.0, 0.0), 0.1, (10, 10, 10))  # 1 m cube
    sf = SceneFields(
        grid,
        np.zeros((1, 3)),
        np.zeros((10, 10, 10, 4), np.float32),
        np.zeros((1, 10, 10, 10, 3), np.float32),
        FieldCfg(),
    )
    src = BankField(FieldBank.from_scenes([sf]), num_envs=5)
    pts = torch.tensor(
        [
            [[0.5, 0.5, 0.5], [0.1, 0.9, 0.2]],  # inside
            [[0.5, 0.5, 0.5], [1.3, 0.5, 0.5]],  # 0.3 m beyond +x
            [[0.5, 0.5, -0.2], [0.5, 0.5, 0.0]],  # below the grid: the floor, does not count
            [[0.5, 0.5, 1.2], [0.5, 0.5, 0.5]],  # 0.2 m above the top
            [[-0.3, -0.4, 0.5], [0.5, 0.5, 0.5]],  # 0.5 m off a corner
        ]
    )
    s = src.sample(pts, torch.zeros(5, 3))
    np.testing.assert_allclose(s.outside.numpy(), [0.0, 0.3, 0.0, 0.2, 0.5], atol=1e-6)


@pytest.fixture(scope="module")
def env():
    scenes = SceneSet.typical("side-pass", num_envs=3, variants=1)
    return TraversalEnv(EnvCfg(num_envs=3, scene_kind="side-pass"), sim="mujoco", scenes=scenes, seed=0)


def test_leaving_the_grid_ends_the_episode(env):
    assert "left_field_grid" in env.cfg.terminations.terms
    obs, rew, done, extras = env.step(torch.zeros(3, env.num_actions))
    assert not done.any() and (env.field.outside <= env.cfg.terminations.field_grid_margin).all()
    qpos, qvel = env.sim.qpos.clone(), env.sim.qvel.clone()
    lo, _ = env.scenes.bank.field_bounds(env.field_source.field_idx[:1])
    qpos[1, 0] = float(lo[0, 0]) - 0.6  # env 1's pelvis 0.6 m behind the grid, upright
    env.sim.reset(torch.tensor([1]), qpos[1:2], qvel[1:2])
    obs, rew, done, extras = env.step(torch.zeros(3, env.num_actions))
    assert done.tolist() == [0, 1, 0]
    assert extras["episode_end"]["env_ids"].tolist() == [1]
    assert not extras["time_outs"][1]  # a failure, not a truncation
