"""Observation groups by name: any number of groups (``actor``, ``critic``, ``teacher``, ``student``, ...) built
from term lists in ``EnvCfg.observations``, each with its own noise switch, so baselines and distillation only
change config.

A group's terms are the observation terms named in its list (their declarations: ``cat.envs.mdp.registry``),
concatenated in order, after the resolved terms of the group it ``extends``. Every term is evaluated once per step
and shared by the groups that list it; groups with ``noise: true`` read it with its declared noise
(``TermNoise``) at ``NoiseCfg``'s scale, drawn once per step and term, so every noisy group sees the same reading
(one sensor, one reading: a distillation teacher with ``noise: true`` labels from exactly what the student
observes); a term whose noise ``shares`` another's uses that term's draw. A group with ``history: H`` > 1 reads
its last H vectors (noisy as observed), oldest first. The deploy runtime builds its groups with this class too
(noise off), so a robot stacks history exactly as the env does.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import torch
from tensordict import TensorDict

from cat.envs.config import PRIVILEGED_TERMS, EnvCfg, NoiseCfg, ObsGroupCfg
from cat.envs.mdp.registry import OBS_TERMS, obs_term

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv


def lookup_term(module, name: str, kind: str) -> Callable:
    """A term function of ``module`` by name (termination terms; observation terms are declared:
    ``cat.envs.mdp.registry.obs_term``), or ``ValueError`` naming it and listing the valid names."""
    fn = getattr(module, name, None)
    if fn is None or name.startswith("_") or not callable(fn) or getattr(fn, "__module__", "") != module.__name__:
        raise ValueError(f"unknown {kind} term {name!r}; valid: {', '.join(term_names(module))}")
    return fn


def term_names(module) -> list[str]:
    """Public functions defined in ``module`` (the valid term names)."""
    return sorted(
        k
        for k, v in vars(module).items()
        if callable(v) and not k.startswith("_") and k[0].islower() and getattr(v, "__module__", "") == module.__name__
    )


def resolve_groups(groups: dict[str, ObsGroupCfg]) -> dict[str, list[str]]:
    """Group name -> full term list (``extends`` expanded), in config order; one-line ``ValueError`` on bad input."""
    if not groups:
        raise ValueError("task.observations defines no observation group")
    out: dict[str, list[str]] = {}

    def resolve(name: str, chain: tuple[str, ...]) -> list[str]:
        if name in out:
            return out[name]
        if name in chain:
            raise ValueError(f"observation groups extend each other in a cycle: {' -> '.join(chain + (name,))}")
        group = groups[name]
        parent: list[str] = []
        if group.extends:
            if group.extends not in groups:
                raise ValueError(
                    f"observation group {name!r} extends unknown group {group.extends!r}; groups: {', '.join(groups)}"
                )
            parent = resolve(group.extends, chain + (name,))
        terms = parent + list(group.terms)
        if not terms:
            raise ValueError(f"observation group {name!r} has no terms")
        dup = sorted({t for t in terms if terms.count(t) > 1})
        if dup:
            raise ValueError(f"observation group {name!r} lists term {dup[0]!r} more than once")
        out[name] = terms
        return terms

    for name in groups:
        resolve(name, ())
    return {name: out[name] for name in groups}


def noise_scale(noise: NoiseCfg, name: str) -> float:
    """Scale of term ``name``'s noise in a noisy group: ``NoiseCfg.<name>``, else ``NoiseCfg.extra[name]``, else
    zero; zero for a term declared without noise."""
    term = OBS_TERMS.get(name)
    if term is None or term.noise is None:
        return 0.0
    value = getattr(noise, name, None)
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return float(noise.extra.get(name, 0.0))


class ObservationGroups:
    """Builds the observation ``TensorDict`` of the configured groups (the env's, or a robot's: ``groups`` the
    policy reads, ``noise=False``)."""

    def __init__(self, cfg: EnvCfg, groups: list[str] | None = None, noise: bool = True):
        self.cfg = cfg
        resolved = resolve_groups(cfg.observations)
        missing = [g for g in groups or () if g not in resolved]
        if missing:
            raise ValueError(f"unknown observation group {missing[0]!r}; groups: {', '.join(resolved)}")
        self.groups = resolved if groups is None else {g: resolved[g] for g in groups}
        self.noisy = {name: noise and bool(cfg.observations[name].noise) for name in self.groups}
        names = dict.fromkeys(t for terms in self.groups.values() for t in terms)
        self.terms = {t: obs_term(t) for t in names}
        self.fns = {t: term.fn for t, term in self.terms.items()}
        for name in cfg.noise.extra:
            if name not in OBS_TERMS or OBS_TERMS[name].noise is None:
                raise ValueError(f"task.noise.extra names {name!r}, not an observation term declared with noise")
        self.history = {name: int(cfg.observations[name].history) for name in self.groups}
        for name, h in self.history.items():
            if h < 1:
                raise ValueError(f"observation group {name!r} has history={h}; must be >= 1")
        self.buffers: dict[str, torch.Tensor] = {}  # group -> (n, H, D) for groups with history > 1
        self._fresh: torch.Tensor | None = None  # envs whose history restarts at the next compute

    def reset(self, env_ids: torch.Tensor | None = None) -> None:
        """Restart the history of ``env_ids`` (every env: None), filled with their next observation."""
        if env_ids is None:
            self.buffers = {}
        elif self._fresh is not None:
            self._fresh[env_ids] = True

    def term_columns(self, env: TraversalEnv, group: str) -> list[str]:
        """The term name of every column of ``group`` (history steps repeat the terms, oldest first)."""
        one = [name for name in self.groups[group] for _ in range(self.fns[name](env).shape[-1])]
        return one * self.history[group]

    def uses(self, *terms: str) -> bool:
        """Whether any group lists one of ``terms``."""
        return any(t in self.fns for t in terms)

    def compute(self, env: TraversalEnv, commit: bool = True) -> TensorDict:
        """Every group for all envs; each term evaluated once, its noise drawn once (at its first noisy group, in
        group and term order) and shared by every noisy group. ``commit=False``: the histories do not move on
        (the deploy runtime's look at the observation between control steps)."""
        values: dict[str, torch.Tensor] = {}
        noisy_values: dict[str, torch.Tensor] = {}
        draws: dict[str, torch.Tensor] = {}  # U[0, 1) per noise source (a term, or the one it shares with)
        noise = self.cfg.noise
        out = {}
        for group, terms in self.groups.items():
            parts = []
            for name in terms:
                if name not in values:
                    values[name] = self.fns[name](env)
                value = values[name]
                spec = self.terms[name].noise
                scale = noise_scale(noise, name)
                if self.noisy[group] and noise.enabled and scale > 0:
                    if name not in noisy_values:
                        source = spec.shares or name
                        u = draws.get(source)
                        if u is None or u.shape != value.shape:
                            u = draws[source] = torch.rand(value.shape, device=value.device)
                        noisy_values[name] = _noisy(name, value, scale, u)
                    value = noisy_values[name]
                parts.append(value)
            out[group] = self._stack(group, torch.cat(parts, dim=-1), commit)
        if self._fresh is not None and commit:
            self._fresh[:] = False
        return TensorDict(out, batch_size=[env.num_envs], device=env.device)

    def _stack(self, group: str, value: torch.Tensor, commit: bool = True) -> torch.Tensor:
        h = self.history[group]
        if h == 1:
            return value
        buf = self.buffers.get(group)
        if buf is None:  # first compute: every env starts its history here
            if self._fresh is None:
                self._fresh = torch.zeros(value.shape[0], dtype=torch.bool, device=value.device)
            buf = value[:, None].repeat(1, h, 1)
        else:
            buf = torch.cat((buf[:, 1:], value[:, None]), dim=1)
            fresh = self._fresh
            buf[fresh] = value[fresh][:, None].expand(-1, h, -1)
        if commit:
            self.buffers[group] = buf
        return buf.flatten(1)

    def state_dict(self) -> dict[str, torch.Tensor]:
        """History buffers (empty when no group has history): part of the env snapshot."""
        return {k: v.clone() for k, v in self.buffers.items()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.buffers = {k: v.clone() for k, v in state.items()}


def _flips(name: str) -> bool:
    term = OBS_TERMS.get(name)
    return term is not None and term.noise is not None and term.noise.kind == "flip"


def noise_std(name: str, scale: float) -> float:
    """Std of the noise ``_noisy`` adds to term ``name`` at ``scale``: uniform U(-s, s) has s/sqrt(3); a flip with
    probability p of a {0, 1} cell changes it by +-1 with probability p, std sqrt(p(1 - p)) about its mean."""
    if _flips(name):
        return math.sqrt(scale * (1.0 - scale))
    return scale / math.sqrt(3.0)


def _noisy(name: str, value: torch.Tensor, scale: float, u: torch.Tensor) -> torch.Tensor:
    """``value`` read with noise of ``scale`` from uniform draws ``u`` in [0, 1): U(-s, s) added, or cells
    flipped with probability s."""
    if _flips(name):
        return torch.where(u < scale, 1.0 - value, value)
    return value + scale * (2 * u - 1)


def group_layout(task: EnvCfg, group: str = "actor") -> tuple:
    """What fixes a group's input width and meaning: its resolved terms, in order, whether the field block is
    live, and the config its terms declare as fixing their width (``ObsTerm.layout``: perception grid sizes), in
    declaration order (a checkpoint plays only on its own layout)."""
    terms = resolve_groups(task.observations).get(group, [])
    layout: tuple = (tuple(terms), bool(task.field_obs.enabled))
    history = task.observations[group].history if group in task.observations else 1
    if history > 1:
        layout += (("history", history),)
    listed = set(terms)
    extra = [t.layout(task) for name, t in OBS_TERMS.items() if name in listed and t.layout is not None]
    return layout + tuple(dict.fromkeys(extra))


def groups_layout(task: EnvCfg, groups: list[str]) -> tuple:
    """``group_layout`` of each of ``groups`` in order: what a network reading them concatenated depends on."""
    return tuple(group_layout(task, g) for g in groups)


def upgrade_legacy_observations(raw_task: dict) -> dict:
    """A run config's ``task`` mapping with the pre-groups observation layout translated to named groups.

    Runs written before named groups stored ``observations: {actor: [terms], privileged: [terms]}`` and the env
    built ``actor`` (noisy) and ``critic`` = actor terms + privileged (clean); this returns the same groups in
    today's form, so those checkpoints keep loading. Other mappings are returned unchanged.
    """
    obs = raw_task.get("observations")
    if not isinstance(obs, dict) or not isinstance(obs.get("actor"), list):
        return raw_task
    unknown = sorted(set(obs) - {"actor", "privileged"})
    if unknown:
        raise ValueError(f"old-style task.observations has unknown key {unknown[0]!r}; valid: actor, privileged")
    task = copy.deepcopy(raw_task)
    task["observations"] = {
        "actor": {"terms": list(obs["actor"]), "extends": "", "noise": True},
        "critic": {"terms": list(obs.get("privileged", PRIVILEGED_TERMS)), "extends": "actor", "noise": False},
    }
    return task
