"""Left/right mirror symmetry: the maps are involutions, agree with the env's own observations of a mirrored
state, and the physics of G1 is mirror-symmetric (a mirrored start driven by mirrored actions stays mirrored)."""

from __future__ import annotations

import torch

from cat.envs.config import EnvCfg, NoiseCfg
from cat.envs.symmetry import mirror_augment, mirror_state
from cat.envs.traversal_env import TraversalEnv


def _env(n: int = 2) -> TraversalEnv:
    return TraversalEnv(EnvCfg(num_envs=n, noise=NoiseCfg(enabled=False)), sim="mujoco", seed=5)


def _set_mirrored_pair(env: TraversalEnv, gen: torch.Generator) -> None:
    """World 0: a perturbed standing state; world 1: its mirror image (goal, gait clock and targets too)."""
    qpos = env.sim.qpos[:1].clone()
    qpos[0, :2] = torch.tensor([0.3, 0.2], dtype=qpos.dtype)
    yaw = torch.tensor(0.4)
    qpos[0, 3:7] = torch.tensor([torch.cos(yaw / 2), 0.0, 0.0, torch.sin(yaw / 2)], dtype=qpos.dtype)
    qpos[0, 7:] += 0.03 * torch.randn(qpos.shape[1] - 7, generator=gen, dtype=qpos.dtype)
    qvel = 0.05 * torch.randn(1, env.sim.qvel.shape[1], generator=gen, dtype=qpos.dtype)
    mq, mv = mirror_state(env, qpos, qvel)
    env.sim.reset(torch.tensor([0, 1]), torch.cat((qpos, mq)), torch.cat((qvel, mv)))
    env.goals[0] = torch.tensor([2.0, -0.7, 0.75])
    env.goals[1] = torch.tensor([2.0, 0.7, 0.75])
    env.phase[1] = torch.remainder(env.phase[0] + 0.5, 1.0)
    env.gait_freq[1] = env.gait_freq[0]
    tq, _ = mirror_state(env, torch.cat((qpos[:, :7], env.targets[:1].double()), -1), qvel)
    env.targets[0], env.targets[1] = env.targets[0], tq[0, 7:].float()
    env.actions[1] = env.mirror_map.mirror_actions(env.actions[:1])[0]
    env.step_count[:] = 0
    env._update_state()
    env._update_field()
    env._refresh_field_obs()
    env._compute_obs()


def test_mirror_is_an_involution():
    env = _env(4)
    obs = env.get_observations()
    actions = torch.randn(4, env.num_actions)
    m = env.mirror_map
    twice = m.mirror_obs(m.mirror_obs(obs))
    for group in obs.keys():
        torch.testing.assert_close(twice[group], obs[group])
        assert not torch.allclose(m.mirror_obs(obs)[group], obs[group])  # it does something
    torch.testing.assert_close(m.mirror_actions(m.mirror_actions(actions)), actions)
    aug_obs, aug_act = mirror_augment(env, obs, actions)
    assert aug_obs.batch_size[0] == 8 and aug_act.shape == (8, env.num_actions)
    torch.testing.assert_close(aug_act[4:], m.mirror_actions(actions))


def test_observation_of_mirrored_state_is_mirrored_observation():
    """Every term's map is checked against what the env computes for the mirrored world. Tolerance 5 mm: the
    torso query site (the torso IMU) sits 2.24 mm off the sagittal plane, so its mirror is 4.5 mm away."""
    env = _env()
    _set_mirrored_pair(env, torch.Generator().manual_seed(0))
    obs = env.get_observations()
    mirrored = env.mirror_map.mirror_obs(obs[:1])
    for group in obs.keys():
        torch.testing.assert_close(obs[group][1:], mirrored[group], atol=5e-3, rtol=1e-3)


def test_mirrored_actions_give_mirrored_trajectory():
    """50 control steps (1 s) of mirrored random actions. Tolerance: 1 cm / 0.02 rad in qpos, from the G1
    model's small left/right asymmetries (menagerie inertias) and contact-solver order effects."""
    env = _env()
    gen = torch.Generator().manual_seed(1)
    _set_mirrored_pair(env, gen)
    worst = 0.0
    phase = 2 * torch.pi * torch.rand(1, env.num_actions, generator=gen)
    for t in range(50):
        a = 0.05 * torch.sin(2 * torch.pi * t / 25 + phase)  # bounded targets: a 0.5 s random-phase wiggle
        env.step(torch.cat((a, env.mirror_map.mirror_actions(a))))
        assert (env.step_count == env.step_count[0]).all() and env.step_count[0] > 0, "a world fell and reset"
        mq, _ = mirror_state(env, env.sim.qpos[:1], env.sim.qvel[:1])
        worst = max(worst, float((mq[0] - env.sim.qpos[1]).abs().max()))
    assert worst < 0.02, f"mirror trajectories diverged by {worst:.4f}"


def test_mirror_averaged_policy_is_equivariant():
    """The walking prior averaged with its mirror image: the mirror of an observation gives the mirrored action,
    exactly, where the prior alone does not."""
    from cat.learning.runs import load_run_config
    from cat.run.policy import MirrorAveraged, load_policy

    env = _env(4)
    ckpt = "checkpoints/flat/model_770.pt"
    policy = load_policy(ckpt, env, load_run_config(ckpt))
    sym = MirrorAveraged(policy, env)
    m = env.mirror_map
    obs = env.get_observations()
    gen = torch.Generator().manual_seed(2)
    for group in obs.keys():
        obs[group] = obs[group] + 0.3 * torch.randn(obs[group].shape, generator=gen)
    with torch.inference_mode():
        gap = (policy(m.mirror_obs(obs)) - m.mirror_actions(policy(obs))).abs().max()
        torch.testing.assert_close(sym(m.mirror_obs(obs)), m.mirror_actions(sym(obs)), atol=1e-5, rtol=1e-5)
    assert gap > 1e-3, "the prior is already exactly symmetric: the test shows nothing"
