"""The term registries, loaded: observation terms (``OBS_TERMS``) and reward terms (``REWARD_TERMS``), built-in
and registered.

Every observation term is an ``ObsTerm`` declaration (``cat.envs.mdp.terms``): the built-in ones on their
functions in ``cat.envs.mdp.observations`` (imported here, so importing this module loads them), terms from
outside the package with ``register_observation`` (docs/extending.md). The observation groups
(``cat.envs.obs_groups``), symmetry (``cat.envs.symmetry``), the export metadata (``cat.deploy.metadata``) and
the deploy runtime (``cat.deploy.runtime``) read ``obs_term`` / ``OBS_TERMS`` only.

Every reward term is a ``RewardTerm``: the built-in ones on their functions in ``cat.envs.mdp.rewards``, terms
from outside with ``register_reward``. Their weights and constants are config: a built-in term's weight is its
``RewardCfg`` field, a registered one's is in ``task.rewards.extra`` (so registering alone changes no env); the
constants a term takes (its keyword parameters) are ``RewardCfg.params`` fields for the built-in ones (one shared
dataclass: shipped config.yaml files record that layout, and some constants are shared on purpose) and
``task.rewards.extra.<name>.params`` for registered ones. ``reward_terms`` resolves both into name -> (weight,
params), which the env calls as ``fn(env, **params) * weight``.
"""

from __future__ import annotations

from dataclasses import fields
from typing import TYPE_CHECKING

from cat.envs.mdp import observations as _builtin_observations  # noqa: F401  (declares the built-in terms)
from cat.envs.mdp import rewards as reward_module
from cat.envs.mdp.terms import (
    OBS_TERMS,
    REWARD_TERMS,
    ObsTerm,
    RewardTerm,
    TermFn,
    TermNoise,
    observation_term,
    register_observation,
    register_reward,
    reward_term,
)

if TYPE_CHECKING:
    from cat.envs.config import RewardCfg

__all__ = [
    "OBS_TERMS",
    "REWARD_TERMS",
    "ObsTerm",
    "RewardTerm",
    "TermNoise",
    "active_rewards",
    "obs_term",
    "observation_term",
    "register_observation",
    "register_reward",
    "reward_fn",
    "reward_params",
    "reward_term",
    "reward_terms",
]


def obs_term(name: str) -> ObsTerm:
    """The declaration of observation term ``name``, or ``ValueError`` naming it and listing the valid names."""
    term = OBS_TERMS.get(name)
    if term is None:
        raise ValueError(f"unknown observation term {name!r}; valid: {', '.join(sorted(OBS_TERMS))}")
    return term


def _builtin_rewards() -> list[str]:
    """Built-in reward terms in ``RewardCfg``'s field order (the order the env sums them in); ``ValueError`` for a
    field that is neither a declared term's weight nor a constant some term declares (it would be ignored)."""
    from cat.envs.config import RewardCfg

    constants = {p for t in REWARD_TERMS.values() for p in t.params} | {"params", "extra"}
    out = []
    for f in fields(RewardCfg):
        if _is_builtin(f.name):
            out.append(f.name)
        elif f.name not in constants:
            raise ValueError(
                f"RewardCfg.{f.name} is not a reward term declared in cat.envs.mdp.rewards (@reward_term) nor a "
                "constant one declares"
            )
    return out


def _is_builtin(name: str) -> bool:
    term = REWARD_TERMS.get(name)
    return term is not None and term.fn.__module__ == reward_module.__name__


def _extra_weight(name: str, entry) -> float:
    """The weight of a ``task.rewards.extra`` entry: a number, or a mapping ``{weight: w, params: {...}}``."""
    if isinstance(entry, int | float) and not isinstance(entry, bool):
        return float(entry)
    if hasattr(entry, "keys") and "weight" in entry and set(entry.keys()) <= {"weight", "params"}:
        return float(entry["weight"])
    raise ValueError(f"task.rewards.extra.{name} must be a weight or {{weight: <w>, params: {{...}}}}, got {entry!r}")


def active_rewards(cfg: RewardCfg) -> dict[str, float]:
    """Name -> weight of every reward term with a non-zero weight: the built-in ones in ``RewardCfg``'s field
    order, then ``cfg.extra`` (registered terms) in its order."""
    out = {name: float(getattr(cfg, name)) for name in _builtin_rewards() if getattr(cfg, name) != 0.0}
    for name, entry in cfg.extra.items():
        if _is_builtin(name):
            raise ValueError(f"task.rewards.extra names built-in reward term {name!r}; set task.rewards.{name}")
        if name not in REWARD_TERMS:
            valid = ", ".join(sorted(n for n in REWARD_TERMS if not _is_builtin(n))) or "none registered"
            raise ValueError(f"task.rewards.extra names unknown reward term {name!r}; registered: {valid}")
        weight = _extra_weight(name, entry)
        if weight != 0.0:
            out[name] = weight
    return out


def reward_fn(name: str) -> TermFn:
    """The function of reward term ``name``, a built-in one looked up in its module when called (the soak
    benchmark wraps the module's functions)."""
    return getattr(reward_module, name) if _is_builtin(name) else REWARD_TERMS[name].fn


def reward_params(cfg: RewardCfg, name: str) -> dict:
    """The constants reward term ``name`` is called with, by name. A built-in term's come from config:
    ``cfg.params.<p>``, or ``cfg.<p>`` for the few kept beside the weights (``field_vmf_uniform_offset``). A
    registered term's from ``cfg.extra.<name>.params``, else its signature's defaults; a constant with neither, or
    one the term does not take, is a ``ValueError`` naming it."""
    term = REWARD_TERMS[name]
    if _is_builtin(name):
        return {p: getattr(cfg.params, p) if hasattr(cfg.params, p) else getattr(cfg, p) for p in term.params}
    entry = cfg.extra.get(name)
    given = dict(entry.get("params") or {}) if hasattr(entry, "keys") else {}
    unknown = sorted(set(given) - set(term.params))
    if unknown:
        takes = ", ".join(term.params) or "none"
        raise ValueError(
            f"task.rewards.extra.{name}.params: {', '.join(unknown)} not taken by the term (takes: {takes})"
        )
    out = {**dict(term.defaults), **given}
    missing = [p for p in term.params if p not in out]
    if missing:
        raise ValueError(f"reward term {name!r} needs task.rewards.extra.{name}.params.{missing[0]} (no default)")
    return {p: out[p] for p in term.params}


def reward_terms(cfg: RewardCfg) -> dict[str, tuple[float, dict]]:
    """Name -> (weight, params) of every active reward term, in the order the env sums them: the env calls
    ``fn(env, **params) * weight``."""
    return {name: (weight, reward_params(cfg, name)) for name, weight in active_rewards(cfg).items()}
