"""The traversal env against rsl_rl's VecEnv contract, on the MuJoCo C backend."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict

from cat.envs.config import EnvCfg
from cat.envs.math_utils import rotate_yaw_inverse
from cat.envs.mdp.terminations import fallen
from cat.envs.traversal_env import TraversalEnv


@pytest.fixture(scope="module")
def env():
    return TraversalEnv(EnvCfg(num_envs=8), sim="mujoco", seed=3)


def test_vecenv_contract(env):
    assert env.num_actions == 12
    assert env.max_episode_length == math.ceil(20.0 / 0.02)
    obs = env.get_observations()
    assert isinstance(obs, TensorDict) and set(obs.keys()) == {"actor", "critic"}
    assert obs["actor"].shape[0] == 8 and obs["critic"].shape[1] > obs["actor"].shape[1]
    obs2, rew, dones, extras = env.step(torch.zeros(8, 12))
    assert obs2["actor"].shape == obs["actor"].shape
    assert rew.shape == (8,) and torch.isfinite(rew).all()
    assert dones.shape == (8,)
    assert extras["time_outs"].shape == (8,) and extras["time_outs"].dtype == torch.bool


def test_time_out_auto_resets(env):
    env.episode_length_buf[:] = env.max_episode_length - 1  # the runner sets this attribute
    _, _, dones, extras = env.step(torch.zeros(8, 12))
    assert dones.all() and extras["time_outs"].all()
    assert (env.episode_length_buf == 0).all()
    assert "Metrics/success_rate" in extras["log"] and "Episode_Reward/alive" in extras["log"]


def test_fall_terminates_and_resets(env):
    qpos, qvel = env.sim.qpos[:1].clone(), env.sim.qvel[:1].clone()
    qpos[0, 2] = 0.3  # lying on its back
    qpos[0, 3:7] = torch.tensor([math.cos(math.pi / 4), 0.0, -math.sin(math.pi / 4), 0.0], dtype=qpos.dtype)
    env.sim.reset(torch.tensor([0]), qpos, qvel)
    _, _, dones, extras = env.step(torch.zeros(8, 12))
    assert dones[0] == 1 and not extras["time_outs"][0]
    assert extras["episode_end"]["fell"][0]
    assert env.sim.qpos[0, 2] > 0.7  # back to standing


def test_incremental_targets_respect_soft_limits(env):
    for _ in range(30):
        env.step(torch.ones(8, 12))
    ids = env.policy_ids
    assert (env.targets[:, ids] <= env.soft_upper[ids] + 1e-6).all()
    assert (env.targets[:, ids] >= env.soft_lower[ids] - 1e-6).all()


def test_field_block_points_to_goal_on_flat_ground(env):
    """On empty ground F_H at every link is parallel to (goal - link); the obs holds it in the yaw frame."""
    env.step(torch.zeros(8, 12))
    env._refresh_field_obs()
    fh = env.humanoid_pf
    delta = env.goals[:, None, :] - env.state.link_pos
    cos = torch.nn.functional.cosine_similarity(fh, delta, dim=-1)
    assert (cos > 0.999).all()
    root_obs = env.field_obs_buf[:, 0, :3]
    expected = rotate_yaw_inverse(env.state.yaw, fh[:, 0])
    torch.testing.assert_close(root_obs, expected)
    # root has priority weight 1, the others 0.5 (same distance term on flat ground)
    ratio = fh.norm(dim=-1)[:, 1:] / fh.norm(dim=-1)[:, :1]
    assert torch.allclose(ratio, torch.full_like(ratio, 0.5), atol=0.05)


def test_domain_randomisation_changes_gains():
    cfg = EnvCfg(num_envs=4)
    cfg.domain_rand.enabled = True
    env = TraversalEnv(cfg, sim="mujoco", seed=0)
    kp = torch.stack([torch.as_tensor(m.actuator_gainprm[:, 0]) for m in env.sim._models])
    assert kp.std(dim=0).max() > 0  # worlds differ
    torch.testing.assert_close(env.kp.double(), kp)


def test_pushes_kick_the_root_by_the_configured_speed():
    """Same seed and actions with pushes on and off: after the push the root velocities differ by exactly the
    kick, whose horizontal size lies in ``push.speed`` (fails if pushes do nothing)."""
    envs = []
    for enabled in (True, False):
        cfg = EnvCfg(num_envs=4)
        cfg.push.enabled = enabled
        cfg.push.interval_s = (0.01, 0.015)  # due at the first step
        cfg.push.speed = (0.3, 0.6)
        envs.append(TraversalEnv(cfg, sim="mujoco", seed=0))
    pushed, plain = envs
    for env in envs:
        env.step(torch.zeros(4, 12))
    kick = (pushed.sim.qvel[:, :2] - plain.sim.qvel[:, :2]).norm(dim=-1)
    assert ((kick > 0.3 - 1e-6) & (kick < 0.6 + 1e-6)).all(), kick
    torch.testing.assert_close(pushed.sim.qvel[:, 2:], plain.sim.qvel[:, 2:])


def test_unknown_term_names_are_rejected():
    cfg = EnvCfg(num_envs=2)
    cfg.observations["actor"].terms.append("elevation_mapp")
    with pytest.raises(ValueError, match="unknown observation term 'elevation_mapp'; valid: .*field_block"):
        TraversalEnv(cfg)
    cfg = EnvCfg(num_envs=2)
    cfg.terminations.terms = ["fallen", "tripped"]
    with pytest.raises(ValueError, match="unknown termination term 'tripped'"):
        TraversalEnv(cfg)


def test_tilt_beyond_limit_terminates():
    env = TraversalEnv(EnvCfg(num_envs=2), sim="mujoco", seed=0)
    qpos, qvel = env.sim.qpos[:1].clone(), env.sim.qvel[:1].clone()
    tilt = 1.2  # rad about x, pelvis kept high so only the tilt check can fire
    qpos[0, 2] = 1.5
    qpos[0, 3:7] = torch.tensor([math.cos(tilt / 2), math.sin(tilt / 2), 0.0, 0.0], dtype=qpos.dtype)
    env.sim.reset(torch.tensor([0]), qpos, qvel)
    env._update_state()
    assert fallen(env).tolist() == [True, False]
