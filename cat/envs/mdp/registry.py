"""The term registries, loaded: observation terms (``OBS_TERMS``, built-in and registered) and reward terms.

Every observation term is an ``ObsTerm`` declaration (``cat.envs.mdp.terms``): the built-in ones on their
functions in ``cat.envs.mdp.observations`` (imported here, so importing this module loads them), terms from
outside the package with ``register_observation`` (docs/extending.md). The observation groups
(``cat.envs.obs_groups``), symmetry (``cat.envs.symmetry``), the export metadata (``cat.deploy.metadata``) and
the deploy runtime (``cat.deploy.runtime``) read ``obs_term`` / ``OBS_TERMS`` only.

``register_reward`` adds a reward function; a run turns it on with a weight in ``task.rewards.extra``
(``RewardCfg.extra``: name -> weight), so registering alone changes no env. Built-in reward terms are the
functions of ``cat.envs.mdp.rewards`` with a float weight field in ``RewardCfg`` (their constants still share
``RewardParamsCfg``: shipped config.yaml files record that layout).
"""

from __future__ import annotations

from dataclasses import fields
from typing import TYPE_CHECKING

from cat.envs.mdp import observations as _builtin_observations  # noqa: F401  (declares the built-in terms)
from cat.envs.mdp import rewards as reward_module
from cat.envs.mdp.terms import OBS_TERMS, ObsTerm, TermFn, TermNoise, observation_term, register_observation

if TYPE_CHECKING:
    from cat.envs.config import RewardCfg

__all__ = [
    "OBS_TERMS",
    "REWARD_TERMS",
    "ObsTerm",
    "TermNoise",
    "active_rewards",
    "obs_term",
    "observation_term",
    "register_observation",
    "register_reward",
    "reward_fn",
]

REWARD_TERMS: dict[str, TermFn] = {}


def obs_term(name: str) -> ObsTerm:
    """The declaration of observation term ``name``, or ``ValueError`` naming it and listing the valid names."""
    term = OBS_TERMS.get(name)
    if term is None:
        raise ValueError(f"unknown observation term {name!r}; valid: {', '.join(sorted(OBS_TERMS))}")
    return term


def _builtin(module, name: str) -> bool:
    fn = getattr(module, name, None)
    return callable(fn) and getattr(fn, "__module__", "") == module.__name__


def register_reward(name: str, fn: TermFn) -> None:
    """Declare reward term ``name``: ``fn(env)`` -> (N,) per control step, before its weight. A run turns it on
    with ``task.rewards.extra.<name>=<weight>``."""
    if _builtin(reward_module, name) or name in {f.name for f in _reward_weights()}:
        raise ValueError(f"reward term {name!r} is built in (cat.envs.mdp.rewards)")
    old = REWARD_TERMS.get(name)
    if old is not None and old is not fn:
        raise ValueError(f"reward term {name!r} is already registered (by {old.__module__})")
    REWARD_TERMS[name] = fn


def _reward_weights():
    from cat.envs.config import RewardCfg

    return [f for f in fields(RewardCfg) if f.type == "float"]


def active_rewards(cfg: RewardCfg) -> dict[str, float]:
    """Name -> weight of every reward term with a non-zero weight: the built-in ones in ``RewardCfg``'s field
    order, then ``cfg.extra`` (registered terms) in its order."""
    out = {f.name: float(getattr(cfg, f.name)) for f in _reward_weights() if getattr(cfg, f.name) != 0.0}
    for name, weight in cfg.extra.items():
        if name not in REWARD_TERMS:
            valid = ", ".join(sorted(REWARD_TERMS)) or "none registered"
            raise ValueError(f"task.rewards.extra names unknown reward term {name!r}; registered: {valid}")
        if weight != 0.0:
            out[name] = float(weight)
    return out


def reward_fn(name: str) -> TermFn:
    """The function of reward term ``name``, looked up when called (the soak benchmark wraps the module's)."""
    fn = REWARD_TERMS.get(name)
    return fn if fn is not None else getattr(reward_module, name)
