"""Reward terms as declared objects (``cat/envs/mdp/rewards.py``, ``@reward_term``): every weight of ``RewardCfg``
is a declared term, every constant of ``RewardCfg.params`` is a keyword parameter of some term, and each term
reads its constants from its arguments only; ``reward_terms`` gives name -> (weight, params)."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from cat.envs.config import RewardCfg, RewardParamsCfg
from cat.envs.mdp import rewards as reward_module
from cat.envs.mdp.registry import REWARD_TERMS, active_rewards, reward_params, reward_terms
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


def test_each_term_reads_its_constants_from_its_arguments():
    """Each built-in term on a hurdle env (the foot-clearance look-ahead and the field heading gate on) gives the
    value the env summed, called with only the constants ``reward_terms`` resolved, while ``env.cfg.rewards`` is
    gone (a term reading the reward config itself would fail); a changed constant changes the value (the
    arguments are what the term reads)."""
    overrides = ["task=hurdle_crouch", "sim=mujoco", "num_envs=2", "task.scene_variants=2"]
    env = make_env(load_config([*overrides, "task.rewards.params.foot_clearance_lookahead=0.3"]))
    gen = torch.Generator().manual_seed(0)
    for _ in range(3):
        env.step(0.3 * torch.randn(2, env.num_actions, generator=gen))
    full = env.cfg.rewards
    assert full.params.heading_gate == "field" and full.params.foot_clearance_lookahead > 0
    expected = {name: REWARD_TERMS[name].fn(env, **reward_params(full, name)) for name in sorted(BUILTIN)}
    env.cfg.rewards = None
    try:
        for name in sorted(BUILTIN):
            params = reward_params(full, name)
            assert set(params) == set(REWARD_TERMS[name].params)
            torch.testing.assert_close(REWARD_TERMS[name].fn(env, **params), expected[name], rtol=0, atol=0, msg=name)
    finally:
        env.cfg.rewards = full
    sigma = reward_params(full, "track_velocity")["velocity_sigma"]
    assert not torch.equal(reward_module.track_velocity(env, 4 * sigma), expected["track_velocity"])


def test_a_registered_term_takes_its_constants_from_extra():
    """A term registered from outside: its constants come from ``extra.<name>.params``, else its signature's
    defaults; an unknown constant, one with no value, or a malformed entry is one clear error."""
    from cat.envs.mdp import terms

    def lean(env, target: float, scale: float = 2.0):
        return torch.full((1,), target * scale)

    terms.register_reward("lean", lean)
    try:
        assert REWARD_TERMS["lean"].params == ("target", "scale")
        cfg = dataclasses.replace(RewardCfg(), extra={"lean": {"weight": -1.0, "params": {"target": 0.7}}})
        assert reward_terms(cfg)["lean"] == (-1.0, {"target": 0.7, "scale": 2.0})
        with pytest.raises(ValueError, match=r"needs task.rewards.extra.lean.params.target"):
            reward_terms(dataclasses.replace(cfg, extra={"lean": -1.0}))
        with pytest.raises(ValueError, match=r"extra.lean.params: tilt not taken by the term \(takes: target, scale\)"):
            reward_terms(dataclasses.replace(cfg, extra={"lean": {"weight": 1.0, "params": {"target": 1, "tilt": 2}}}))
        with pytest.raises(ValueError, match="must be a weight or"):
            reward_terms(dataclasses.replace(cfg, extra={"lean": "heavy"}))
        with pytest.raises(ValueError, match="constants must be named parameters"):
            terms.register_reward("lean_args", lambda env, *rest: rest)
    finally:
        terms.REWARD_TERMS.pop("lean", None)
