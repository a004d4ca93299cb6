"""Terms as declared objects: one ``ObsTerm`` per observation term holds everything the code knows about it; one
``RewardTerm`` per reward term names the constants it takes (its keyword parameters).

An observation term is a function ``fn(env) -> (N, size)`` plus its declaration (mjlab's pattern: a term is a
function and a config): its width, how observation noise reads it, its left/right mirror map, whether a deployed
robot can compute it, its clip and meaning (export metadata) and the config that fixes its width (checkpoint
layouts).
The observation groups (``cat.envs.obs_groups``), symmetry (``cat.envs.symmetry``), the export metadata
(``cat.deploy.metadata``) and the deploy runtime (``cat.deploy.runtime``) all read ``OBS_TERMS``.

Built-in terms are declared with ``@observation_term(...)`` on their function (``cat.envs.mdp.observations``);
terms from outside the package with ``register_observation`` (the same registry). Reward terms likewise:
``@reward_term()`` in ``cat.envs.mdp.rewards``, ``register_reward`` from outside; a reward term is
``fn(env, **params)``, its weight and constants config (``RewardCfg``; ``cat.envs.mdp.registry.reward_terms`` gives
name -> (weight, params), what the env calls it with). Consumers import
``cat.envs.mdp.registry``, which loads the built-in ones. This module imports nothing from the env.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import torch

if TYPE_CHECKING:
    from cat.envs.config import EnvCfg
    from cat.envs.robot import RobotCfg
    from cat.envs.traversal_env import TraversalEnv

TermFn = Callable[["TraversalEnv"], torch.Tensor]
Mirror = tuple[list[int], list[float]]  # mirrored[:, i] = sign[i] * value[:, perm[i]] (cat.envs.symmetry)
SizeFn = Callable[["EnvCfg", "RobotCfg"], int]
MirrorFn = Callable[["EnvCfg", "RobotCfg"], Mirror]


@dataclass(frozen=True)
class TermNoise:
    """How observation noise reads a term in a group with ``noise: true``; the scale is config
    (``NoiseCfg.<term>``, or ``NoiseCfg.extra[<term>]`` for a term without a field; zero: no noise).

    ``uniform``: U(-s, s) added to every value. ``flip``: each {0, 1} value reads flipped with probability s.
    ``shares``: another term whose draw this one reuses (one reading placed two ways, e.g. the field block at the
    true links and at the links as the drifting odometry places them)."""

    kind: Literal["uniform", "flip"] = "uniform"
    shares: str | None = None


@dataclass(frozen=True)
class ObsTerm:
    """One observation term: its function and everything the groups, symmetry, export and deploy read."""

    fn: TermFn
    size: SizeFn  # its width from the task and robot (export metadata; the tests check it against the env)
    noise: TermNoise | None = None  # None: read without noise in every group
    mirror: MirrorFn | None = None  # None: a policy reading it cannot use symmetry augmentation
    deployable: bool = False  # a robot computes it: reads only the TermContext (cat.envs.mdp.context); the deploy
    # runtime refuses policies reading other terms
    clip: Callable[[EnvCfg], float] | None = None  # the term's own clip (export metadata; ``note`` says what)
    layout: Callable[[EnvCfg], tuple] | None = None  # config that fixes its width / meaning (checkpoint layouts)
    note: str = ""  # what it means, in the ONNX metadata


OBS_TERMS: dict[str, ObsTerm] = {}
"""Every observation term by name, the built-in ones first in declaration order (``cat.envs.mdp.registry``
guarantees they are loaded)."""


def _const_size(n: int) -> SizeFn:
    return lambda task, robot: n


def _const_mirror(m: Mirror) -> MirrorFn:
    perm, sign = list(m[0]), [float(s) for s in m[1]]
    return lambda task, robot: (perm, sign)


def register_observation(
    name: str,
    fn: TermFn,
    size: int | SizeFn,
    mirror: Mirror | MirrorFn | None = None,
    note: str = "",
    *,
    noise: TermNoise | None = None,
    deployable: bool = False,
    clip: Callable[[EnvCfg], float] | None = None,
    layout: Callable[[EnvCfg], tuple] | None = None,
) -> ObsTerm:
    """Declare observation term ``name`` (listed by name in a group's ``terms``). ``size`` and ``mirror`` are
    constants or functions of ``(task, robot)``. Registering the same function again is a no-op; another
    function under a taken name is a ``ValueError``."""
    old = OBS_TERMS.get(name)
    if old is not None:
        if old.fn is fn:
            return old
        owner = getattr(old.fn, "__module__", "?")
        where = "built in (cat.envs.mdp.observations)" if owner == "cat.envs.mdp.observations" else f"by {owner}"
        raise ValueError(f"observation term {name!r} is already registered {where}")
    term = ObsTerm(
        fn=fn,
        size=size if callable(size) else _const_size(int(size)),
        noise=noise,
        mirror=mirror if (mirror is None or callable(mirror)) else _const_mirror(mirror),
        deployable=deployable,
        clip=clip,
        layout=layout,
        note=note,
    )
    OBS_TERMS[name] = term
    return term


def observation_term(
    size: int | SizeFn,
    *,
    noise: TermNoise | None = None,
    mirror: Mirror | MirrorFn | None = None,
    deployable: bool = False,
    clip: Callable[[EnvCfg], float] | None = None,
    layout: Callable[[EnvCfg], tuple] | None = None,
    note: str = "",
) -> Callable[[TermFn], TermFn]:
    """Decorator form of ``register_observation`` under the function's name (the built-in terms' declaration);
    the function is returned unchanged."""

    def declare(fn: TermFn) -> TermFn:
        register_observation(
            fn.__name__,
            fn,
            size,
            mirror,
            note,
            noise=noise,
            deployable=deployable,
            clip=clip,
            layout=layout,
        )
        return fn

    return declare


@dataclass(frozen=True)
class RewardTerm:
    """One reward term: ``fn(env, **params)`` -> (N,) per control step, before its weight. ``params`` are the
    names of its keyword parameters (read off the signature: the term's constants, filled from config by
    ``cat.envs.mdp.registry.reward_terms``), ``defaults`` those of them the signature gives a value."""

    fn: TermFn
    params: tuple[str, ...] = ()
    defaults: tuple[tuple[str, object], ...] = ()
    note: str = ""


REWARD_TERMS: dict[str, RewardTerm] = {}
"""Every reward term by name, the built-in ones first in declaration order."""


def _signature_params(name: str, fn: TermFn) -> tuple[tuple[str, ...], tuple[tuple[str, object], ...]]:
    """The constants of ``fn(env, *, a, b=1.0)``: its parameters after the env, and the defaults among them."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError) as err:
        raise ValueError(f"reward term {name!r}: cannot read the signature of {fn!r} ({err})") from None
    ps = list(sig.parameters.values())
    if not ps or ps[0].kind not in (ps[0].POSITIONAL_ONLY, ps[0].POSITIONAL_OR_KEYWORD):
        raise ValueError(f"reward term {name!r}: its function must take the env as its first argument")
    rest = ps[1:]
    bad = [p.name for p in rest if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD, p.POSITIONAL_ONLY)]
    if bad:
        raise ValueError(f"reward term {name!r}: constants must be named parameters, not {', '.join(bad)}")
    return tuple(p.name for p in rest), tuple((p.name, p.default) for p in rest if p.default is not p.empty)


def register_reward(name: str, fn: TermFn, note: str = "") -> RewardTerm:
    """Declare reward term ``name``: ``fn(env, **constants)``. A run turns a registered one on with
    ``task.rewards.extra.<name>=<weight>`` (or ``{weight: w, params: {...}}``: its constants, defaults from the
    signature). Registering the same function again is a no-op; another function under a taken name is a
    ``ValueError``."""
    old = REWARD_TERMS.get(name)
    if old is not None:
        if old.fn is fn:
            return old
        owner = getattr(old.fn, "__module__", "?")
        if owner == "cat.envs.mdp.rewards":
            raise ValueError(f"reward term {name!r} is built in (cat.envs.mdp.rewards)")
        raise ValueError(f"reward term {name!r} is already registered (by {owner})")
    params, defaults = _signature_params(name, fn)
    term = REWARD_TERMS[name] = RewardTerm(fn, params, defaults, note)
    return term


def reward_term(note: str = "") -> Callable[[TermFn], TermFn]:
    """Decorator form of ``register_reward`` under the function's name (the built-in terms' declaration)."""

    def declare(fn: TermFn) -> TermFn:
        register_reward(fn.__name__, fn, note)
        return fn

    return declare
