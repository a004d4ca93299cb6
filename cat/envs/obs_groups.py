"""Observation groups by name: any number of groups (``actor``, ``critic``, ``teacher``, ``student``, ...) built
from term lists in ``EnvCfg.observations``, each with its own noise switch, so baselines and distillation only
change config.

A group's terms are the functions of ``cat.envs.mdp.observations`` named in its list, concatenated in order,
after the resolved terms of the group it ``extends``. Every term is evaluated once per step and shared by the
groups that list it; groups with ``noise: true`` read it with ``NoiseCfg``'s per-term noise, drawn once per step
and term, so every noisy group sees the same reading (one sensor, one reading: a distillation teacher with
``noise: true`` labels from exactly what the student observes); terms in ``SHARED_NOISE`` use the draw of the
term they are another placement of. A group with ``history: H`` > 1 reads its last
H vectors (noisy as observed), oldest first.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

import torch
from tensordict import TensorDict

from cat.envs.config import PRIVILEGED_TERMS, EnvCfg, ObsGroupCfg
from cat.envs.mdp import observations as obs_terms
from cat.envs.mdp.registry import OBS_TERMS

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv

FLIP_NOISE_TERMS = frozenset({"voxel_grid"})  # occupancy in {0, 1}: noise flips cells instead of adding to them
# terms that are one reading placed two ways share its noise draw: the HumanoidPF block at the true links and at
# the links as the drifting odometry places them (a teacher reading the first labels with the student's error)
SHARED_NOISE = {"field_block_odometry": "field_block"}


def lookup_term(module, name: str, kind: str, registered: Mapping[str, Callable] | None = None) -> Callable:
    """A term function of ``module`` (or of ``registered``: name -> function, terms added outside the package) by
    name, or ``ValueError`` naming it and listing the valid names."""
    if registered and name in registered:
        return registered[name]
    fn = getattr(module, name, None)
    if fn is None or name.startswith("_") or not callable(fn) or getattr(fn, "__module__", "") != module.__name__:
        valid = term_names(module) + sorted(registered or ())
        raise ValueError(f"unknown {kind} term {name!r}; valid: {', '.join(valid)}")
    return fn


def observation_fns(module=obs_terms) -> dict[str, Callable]:
    """Observation terms registered outside the package (``cat.envs.mdp.registry``), when ``module`` is the
    built-in one."""
    return {k: t.fn for k, t in OBS_TERMS.items()} if module is obs_terms else {}


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


class ObservationGroups:
    """Builds the env's observation ``TensorDict`` from the configured groups."""

    def __init__(self, cfg: EnvCfg, module=obs_terms):
        self.cfg = cfg
        self.groups = resolve_groups(cfg.observations)
        self.noisy = {name: bool(g.noise) for name, g in cfg.observations.items()}
        names = dict.fromkeys(t for terms in self.groups.values() for t in terms)
        self.fns = {t: lookup_term(module, t, "observation", observation_fns(module)) for t in names}
        self.history = {name: int(g.history) for name, g in cfg.observations.items()}
        for name, h in self.history.items():
            if h < 1:
                raise ValueError(f"observation group {name!r} has history={h}; must be >= 1")
        self.buffers: dict[str, torch.Tensor] = {}  # group -> (n, H, D) for groups with history > 1
        self._fresh: torch.Tensor | None = None  # envs whose history restarts at the next compute

    def reset(self, env_ids: torch.Tensor) -> None:
        """Restart the history of ``env_ids`` (filled with their next observation)."""
        if self._fresh is not None:
            self._fresh[env_ids] = True

    def term_columns(self, env: TraversalEnv, group: str) -> list[str]:
        """The term name of every column of ``group`` (history steps repeat the terms, oldest first)."""
        one = [name for name in self.groups[group] for _ in range(self.fns[name](env).shape[-1])]
        return one * self.history[group]

    def uses(self, *terms: str) -> bool:
        """Whether any group lists one of ``terms``."""
        return any(t in self.fns for t in terms)

    def compute(self, env: TraversalEnv) -> TensorDict:
        """Every group for all envs; each term evaluated once, its noise drawn once (at its first noisy group, in
        group and term order) and shared by every noisy group."""
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
                scale = getattr(noise, name, 0.0)
                if self.noisy[group] and noise.enabled and scale > 0:
                    if name not in noisy_values:
                        source = SHARED_NOISE.get(name, name)
                        u = draws.get(source)
                        if u is None or u.shape != value.shape:
                            u = draws[source] = torch.rand(value.shape, device=value.device)
                        noisy_values[name] = _noisy(name, value, scale, u)
                    value = noisy_values[name]
                parts.append(value)
            out[group] = self._stack(group, torch.cat(parts, dim=-1))
        if self._fresh is not None:
            self._fresh[:] = False
        return TensorDict(out, batch_size=[env.num_envs], device=env.device)

    def _stack(self, group: str, value: torch.Tensor) -> torch.Tensor:
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
        self.buffers[group] = buf
        return buf.flatten(1)

    def state_dict(self) -> dict[str, torch.Tensor]:
        """History buffers (empty when no group has history): part of the env snapshot."""
        return {k: v.clone() for k, v in self.buffers.items()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.buffers = {k: v.clone() for k, v in state.items()}


def noise_std(name: str, scale: float) -> float:
    """Std of the noise ``_noisy`` adds to term ``name`` at ``scale``: uniform U(-s, s) has s/sqrt(3); a flip with
    probability p of a {0, 1} cell changes it by +-1 with probability p, std sqrt(p(1 - p)) about its mean."""
    if name in FLIP_NOISE_TERMS:
        return math.sqrt(scale * (1.0 - scale))
    return scale / math.sqrt(3.0)


def _noisy(name: str, value: torch.Tensor, scale: float, u: torch.Tensor) -> torch.Tensor:
    """``value`` read with noise of ``scale`` from uniform draws ``u`` in [0, 1): U(-s, s) added, or cells
    flipped with probability s."""
    if name in FLIP_NOISE_TERMS:
        return torch.where(u < scale, 1.0 - value, value)
    return value + scale * (2 * u - 1)


def group_layout(task: EnvCfg, group: str = "actor") -> tuple:
    """What fixes a group's input width and meaning: its resolved terms, in order, whether the field block is
    live, and the perception grid sizes of the map terms it lists (a checkpoint plays only on its own layout)."""
    terms = resolve_groups(task.observations).get(group, [])
    layout: tuple = (tuple(terms), bool(task.field_obs.enabled))
    history = task.observations[group].history if group in task.observations else 1
    if history > 1:
        layout += (("history", history),)
    if {"elevation_map", "ground_map", "overhead_map"} & set(terms):
        hm = task.perception.height_map
        layout += (("height_map", hm.length, hm.width, hm.resolution, hm.forward_offset),)
    if "voxel_grid" in terms:
        vg = task.perception.voxel_grid
        layout += (("voxel_grid", vg.length, vg.width, vg.height, vg.resolution, vg.forward_offset),)
    return layout


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
