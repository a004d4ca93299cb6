"""Observation and reward terms added from outside the package, without editing it (docs/extending.md).

``register_observation`` declares a term once: its function, its size (for the ONNX metadata), its mirror map
(for symmetry) and a note. The observation groups (``cat.envs.obs_groups``), the mirror map
(``cat.envs.symmetry``) and the export metadata (``cat.deploy.metadata``) read these beside the built-in terms.
``register_reward`` adds a reward function; a run turns it on with a weight in ``task.rewards.extra``
(``RewardCfg.extra``: name -> weight), so registering alone changes no env.

Registered observation terms carry no observation noise and are not computed by the click demo's runtime
(``cat.deploy.runtime.DEPLOYABLE_TERMS``). This is the extension point until the built-in terms move to one
registry too (issue 29, deliverable 1); today a built-in term is still declared across several files.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import torch

from cat.envs.mdp import observations as obs_module
from cat.envs.mdp import rewards as reward_module

if TYPE_CHECKING:
    from cat.envs.config import EnvCfg, RewardCfg
    from cat.envs.robot import RobotCfg
    from cat.envs.traversal_env import TraversalEnv

TermFn = Callable[["TraversalEnv"], torch.Tensor]
Mirror = tuple[list[int], list[float]]  # mirrored[:, i] = sign[i] * value[:, perm[i]] (cat.envs.symmetry)


@dataclass(frozen=True)
class ObsTerm:
    """A registered observation term: ``fn(env)`` -> (N, size)."""

    fn: TermFn
    size: Callable[[EnvCfg, RobotCfg], int]  # its width from the task and robot (export metadata)
    mirror: Mirror | None = None  # None: a policy reading it cannot use symmetry augmentation
    note: str = ""  # what it means, in the ONNX metadata


OBS_TERMS: dict[str, ObsTerm] = {}
REWARD_TERMS: dict[str, TermFn] = {}


def _builtin(module, name: str) -> bool:
    fn = getattr(module, name, None)
    return callable(fn) and getattr(fn, "__module__", "") == module.__name__


def register_observation(
    name: str,
    fn: TermFn,
    size: int | Callable[[EnvCfg, RobotCfg], int],
    mirror: Mirror | None = None,
    note: str = "",
) -> ObsTerm:
    """Declare observation term ``name`` (listed in a group's ``terms`` like a built-in one). Registering the
    same function again is a no-op; another function under a taken name is a ``ValueError``."""
    size_fn = size if callable(size) else (lambda task, robot, n=int(size): n)
    term = ObsTerm(fn, size_fn, mirror, note)
    if _builtin(obs_module, name):
        raise ValueError(f"observation term {name!r} is built in (cat.envs.mdp.observations)")
    old = OBS_TERMS.get(name)
    if old is not None and old.fn is not fn:
        raise ValueError(f"observation term {name!r} is already registered (by {old.fn.__module__})")
    if old is None:
        OBS_TERMS[name] = term
    return OBS_TERMS[name]


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
