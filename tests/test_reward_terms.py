"""Reward terms as declared objects (``cat/envs/mdp/rewards.py``, ``@reward_term``): every weight of ``RewardCfg``
is a declared term, every constant of ``RewardCfg.params`` is read by a term that declares it, and each term reads
no constant it does not declare; ``reward_terms`` gives name -> (weight, params)."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import pytest
import torch

from cat.envs.config import RewardCfg, RewardParamsCfg
from cat.envs.mdp import rewards as reward_module
from cat.envs.mdp.registry import REWARD_TERMS, active_rewards, reward_terms
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import make_env

BUILTIN = {name for name, t in REWARD_TERMS.items() if t.fn.__module__ == reward_module.__name__}


def test_every_weight_and_constant_belongs_to_a_declared_term():
    weights = {f.name for f in dataclasses.fields(RewardCfg) if isinstance(f.default, float)}
    assert weights == BUILTIN
    declared = {p for name in BUILTIN for p in REWARD_TERMS[name].params}
    constants = {f.name for f in dataclasses.fields(RewardParamsCfg)}
    assert constants <= declared  # no constant that no term reads
    assert declared <= constants | {f.name for f in dataclasses.fields(RewardCfg)}  # none declared that is not config


def test_reward_terms_pairs_each_weight_with_its_constants():
    cfg = RewardCfg()
    view = reward_terms(cfg)
    assert list(view) == list(active_rewards(cfg))
    assert view["track_velocity"] == (1.5, {"velocity_sigma": 0.25})
    assert view["sdf_barrier"] == (-2.0, {"barrier_margin": 0.05, "barrier_width": 0.02})
    assert view["field_vmf"][1] == {"field_vmf_uniform_offset": True}
    with pytest.raises(ValueError, match="built-in reward term 'alive'"):
        active_rewards(dataclasses.replace(cfg, extra={"alive": 1.0}))


def test_each_term_reads_only_its_declared_constants():
    """Each built-in term on a hurdle env (the foot-clearance look-ahead and the field heading gate on) gives the
    same value when ``env.cfg.rewards`` holds only the constants it declares (an undeclared read would fail)."""
    overrides = ["task=hurdle_crouch", "sim=mujoco", "num_envs=2", "task.scene_variants=2"]
    env = make_env(load_config([*overrides, "task.rewards.params.foot_clearance_lookahead=0.3"]))
    gen = torch.Generator().manual_seed(0)
    for _ in range(3):
        env.step(0.3 * torch.randn(2, env.num_actions, generator=gen))
    full = env.cfg.rewards
    assert full.params.heading_gate == "field" and full.params.foot_clearance_lookahead > 0
    for name in sorted(BUILTIN):
        params = REWARD_TERMS[name].params
        inner = {p: getattr(full.params, p) for p in params if hasattr(full.params, p)}
        outer = {p: getattr(full, p) for p in params if not hasattr(full.params, p)}
        expected = REWARD_TERMS[name].fn(env)
        env.cfg.rewards = SimpleNamespace(params=SimpleNamespace(**inner), **outer)
        try:
            torch.testing.assert_close(REWARD_TERMS[name].fn(env), expected, rtol=0, atol=0, msg=name)
        finally:
            env.cfg.rewards = full
