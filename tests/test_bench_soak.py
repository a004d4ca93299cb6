"""The soak benchmark's instrumentation: wrapped terms record, count non-finite values and are restored."""

from __future__ import annotations

import torch

from cat.envs.bench_soak import _Recorder
from cat.envs.config import EnvCfg
from cat.envs.mdp import rewards as rew_terms
from cat.envs.mdp import terminations as term_terms
from cat.envs.traversal_env import TraversalEnv


def test_recorder_wraps_and_restores():
    env = TraversalEnv(EnvCfg(num_envs=4), sim="mujoco", seed=0)
    names = list(env.cfg.terminations.terms)
    original = {n: getattr(term_terms, n) for n in names}
    alive = rew_terms.alive
    with _Recorder(term_terms, names, "termination") as term, _Recorder(rew_terms, ["alive"], "reward") as rew:
        assert term_terms.fallen is not original["fallen"]
        env.step(torch.zeros(4, env.num_actions))
        assert set(term.last) == set(names) and all(v.shape == (4,) for v in term.last.values())
        assert rew.nonfinite == 0
        rew_terms.alive = lambda e: torch.full((4,), float("nan"))  # a term that breaks ...
        rew.saved["alive"] = rew_terms.alive
        rew.__enter__()  # ... is counted before the env's nan_to_num
        env.step(torch.zeros(4, env.num_actions))
        assert rew.nonfinite == 4
        rew.saved["alive"] = alive
    assert {n: getattr(term_terms, n) for n in names} == original and rew_terms.alive is alive
