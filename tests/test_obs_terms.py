"""The observation-term registry (``cat/envs/mdp/terms.py``): every built-in term declared once and completely, its
noise scale in config; and the env contract (``cat/envs/mdp/context.py``): deployable terms read only what the
deploy runtime provides, and the runtime provides it."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import torch

from cat.envs.config import EnvCfg, NoiseCfg
from cat.envs.mdp import observations as obs_module
from cat.envs.mdp.context import CONTEXT_FIELDS, DEPLOY_STATE, SimState
from cat.envs.mdp.registry import OBS_TERMS
from cat.envs.obs_groups import term_names
from cat.envs.traversal_env import TraversalEnv

ODOMETRY_NOISE = {"odometry_xy", "odometry_yaw"}  # drift of field_block_odometry, not a term's value noise


def test_every_builtin_term_is_declared_completely():
    builtin = {name for name, t in OBS_TERMS.items() if t.fn.__module__ == obs_module.__name__}
    assert set(term_names(obs_module)) == builtin  # no public function of observations.py without a declaration
    assert all(OBS_TERMS[name].mirror is not None and OBS_TERMS[name].note for name in builtin)
    scales = {f.name for f in dataclasses.fields(NoiseCfg) if f.type == "float"} - ODOMETRY_NOISE
    noisy = {name for name in builtin if OBS_TERMS[name].noise is not None}
    assert scales <= noisy  # every NoiseCfg scale is a term declared with noise (new ones may use noise.extra)
    assert {"gyro", "field_block", "voxel_grid"} <= scales
    for name in noisy:
        shares = OBS_TERMS[name].noise.shares
        assert shares is None or OBS_TERMS[shares].noise is not None, name


def test_deployable_terms_read_only_the_contract():
    """Each deployable term gives the same from a context holding only ``CONTEXT_FIELDS`` and the ``DEPLOY_STATE``
    fields of the state (the others NaN, as the runtime has them) as from the env itself."""
    env = TraversalEnv(EnvCfg(num_envs=2, noise=NoiseCfg(enabled=False)), sim="mujoco", seed=1)
    gen = torch.Generator().manual_seed(0)
    for _ in range(3):
        env.step(0.3 * torch.randn(2, env.num_actions, generator=gen))
    hidden = {}
    for f in dataclasses.fields(SimState):
        if f.name not in DEPLOY_STATE:
            value = getattr(env.state, f.name)
            hidden[f.name] = torch.zeros_like(value) if value.dtype == torch.bool else torch.full_like(value, torch.nan)
    ctx = SimpleNamespace(**{f: getattr(env, f) for f in CONTEXT_FIELDS})
    ctx.state = dataclasses.replace(env.state, **hidden)
    deployable = [name for name, t in OBS_TERMS.items() if t.deployable]
    assert {"gyro", "joint_pos", "goal_command", "field_block", "field_block_odometry"} <= set(deployable)
    for name in deployable:
        torch.testing.assert_close(OBS_TERMS[name].fn(ctx), OBS_TERMS[name].fn(env), rtol=0, atol=0, msg=name)


def test_the_runtime_provides_the_contract():
    from cat.deploy.policy import PolicySpec
    from cat.deploy.runtime import DeployCfg, Runtime
    from cat.deploy.scenes import load_scene

    rt = Runtime(load_scene("flat"), PolicySpec("hold", EnvCfg()), DeployCfg(realtime=False))
    missing = [f for f in CONTEXT_FIELDS if not hasattr(rt, f)]
    assert not missing
    for f in DEPLOY_STATE:
        assert torch.isfinite(getattr(rt.state, f)).all(), f
    assert rt.observation()["actor"].shape == (1, rt.layout.obs_dim)


def test_a_declared_deployable_term_reaches_the_runtime_and_its_layout():
    """A term declared ``deployable`` from outside the package is computed by the deploy runtime and described
    in its layout metadata, with no change to the runtime (it reads the registry)."""
    from cat.deploy.policy import PolicySpec
    from cat.deploy.runtime import DeployCfg, Runtime
    from cat.deploy.scenes import load_scene
    from cat.envs.config import ObsGroupCfg, default_obs_groups
    from cat.envs.mdp.registry import register_observation

    def tilt(env) -> torch.Tensor:
        return env.state.gravity[:, :2].norm(dim=-1, keepdim=True)

    register_observation("tilt_test", tilt, 1, ([0], [1.0]), "test term", deployable=True)
    try:
        groups = {**default_obs_groups(), "student": ObsGroupCfg(terms=["gyro", "tilt_test"], history=2)}
        spec = PolicySpec("hold", EnvCfg(observations=groups), obs_groups=["student"])
        rt = Runtime(load_scene("flat"), spec, DeployCfg(realtime=False))
        x = rt.observation()["student"]
        assert x.shape == (1, 2 * 4)
        torch.testing.assert_close(x[:, 3:4], tilt(rt))
        terms = rt.layout.observation["student"]["terms"]
        assert [(t["name"], t["size"]) for t in terms] == [("gyro", 3), ("tilt_test", 1)]
        assert terms[1]["note"] == "test term" and rt.layout.obs_dim == 8
    finally:
        OBS_TERMS.pop("tilt_test", None)
