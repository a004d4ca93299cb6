"""The soak benchmark's instrumentation: wrapped reward terms count non-finite values and are restored; the env
names the termination terms that ended each episode."""

from __future__ import annotations

import torch

from cat.bench.soak import _Recorder
from cat.envs.config import EnvCfg
from cat.envs.mdp import rewards as rew_terms
from cat.envs.traversal_env import TraversalEnv


def test_recorder_wraps_and_restores():
    env = TraversalEnv(EnvCfg(num_envs=4), sim="mujoco", seed=0)
    alive = rew_terms.alive
    with _Recorder(rew_terms, ["alive"]) as rew:
        assert rew_terms.alive is not alive
        env.step(torch.zeros(4, env.num_actions))
        assert rew.nonfinite == 0
        rew_terms.alive = lambda e: torch.full((4,), float("nan"))  # a term that breaks ...
        rew.saved["alive"] = rew_terms.alive
        rew.__enter__()  # ... is counted before the env's nan_to_num
        env.step(torch.zeros(4, env.num_actions))
        assert rew.nonfinite == 4
        rew.saved["alive"] = alive
    assert rew_terms.alive is alive
    with _Recorder(rew_terms, list(env.reward_names)) as every:  # terms with constants: called with their params
        env.step(torch.zeros(4, env.num_actions))
        assert every.nonfinite == 0


def test_termination_causes_survive_the_reset():
    """Robots lying on their side have fallen: the step that ends their episodes flags ``fallen`` and the flags
    outlive the reset (which re-evaluates the fall rule on the new state), and the episode log names the cause."""
    env = TraversalEnv(EnvCfg(num_envs=4), sim="mujoco", seed=0)
    qpos, qvel = env.sim.qpos.clone(), torch.zeros_like(env.sim.qvel)
    qpos[:2, 3:7] = torch.tensor([0.7071, 0.7071, 0.0, 0.0])  # envs 0 and 1 rolled 90 degrees about x
    env.sim.reset(torch.arange(4), qpos, qvel)
    _, _, done, extras = env.step(torch.zeros(4, env.num_actions))
    assert done[:2].all() and not done[2:].any()
    assert env.termination_flags["fallen"][:2].all() and not env.termination_flags["fallen"][2:].any()
    assert extras["log"]["Episode_Termination/fallen"] == 1.0
    assert extras["log"]["Episode_Termination/time_out"] == 0.0
