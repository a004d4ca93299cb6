"""``init=`` across observation layouts: a method whose observation differs from the prior's starts from the
prior's weights where the layouts agree (issue 31's equal-budget protocol: every Table I row from one prior).

A PPO checkpoint of the same layout loads strictly, as before. When the prior's actor or critic reads other
observation terms than this run's (``method=wo_obs_field`` from the ``ours`` walking prior: the field block
replaced by the elevation map), :func:`init_from_prior` builds each model's state from the prior's:

* every tensor whose name and shape agree is copied (hidden layers, output layer, action std);
* the first linear layer: the input columns of every observation term both layouts read (same name, same width,
  same layout config such as the map grid) are copied, the columns of the new terms are **zero**, the prior's
  columns of terms this run does not read are dropped;
* the observation normaliser: shared columns copied (and its sample count); new columns get the mean and
  variance of the env's current observations, the variance at least the term's observation noise (what the
  prior saw of a column it read as a constant; ``warm_start`` then re-centres those that go off in its probe).

Dropping a prior column is the prior reading that term at its normaliser mean (a normalised 0): a flat-ground
``ours`` prior saw the free-space field block, so the initialised policy acts as the prior does on flat ground,
whatever the new terms read (``tests/test_layout_init.py``). PPO then learns the new columns from zero.

The prior's term widths come from this env for the shared terms; one prior-only term's width is what is left of
the prior's input; more than one cannot be sized (an error). Anything else that differs (hidden sizes, number of
actions, observation history) is one ``CheckpointError`` naming it. What was copied, zeroed and dropped is logged.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import torch

from cat.checkpoint_io import CheckpointError, read_checkpoint
from cat.envs.config import EnvCfg, ObsGroupCfg
from cat.envs.obs_groups import group_layout, groups_layout, resolve_groups
from cat.run.config_file import load_run_config

log = logging.getLogger(__name__)

MODELS = {"actor": "actor_state_dict", "critic": "critic_state_dict"}
NORM_KEYS = ("obs_normalizer._mean", "obs_normalizer._var", "obs_normalizer._std")
NORM_FLOOR = 1e-6  # variance floor of a new column on a noise-free group (warm_start.MIN_STD squared)


@dataclass
class Block:
    """One observation term's run of input columns: ``width`` columns from ``start``."""

    term: str
    start: int
    width: int

    @property
    def cols(self) -> range:
        return range(self.start, self.start + self.width)


@dataclass
class ModelInit:
    """What :func:`partial_state` did to one model (logged by :func:`init_from_prior`)."""

    copied: list[str] = field(default_factory=list)  # tensors copied whole
    shared: list[Block] = field(default_factory=list)  # this run's blocks whose columns came from the prior
    new: list[Block] = field(default_factory=list)  # this run's blocks started at zero weight
    dropped: list[Block] = field(default_factory=list)  # the prior's blocks this run does not read

    def line(self, name: str) -> str:
        def terms(blocks: list[Block]) -> str:
            return ", ".join(f"{b.term}[{b.width}]" for b in blocks) or "none"

        n = sum(b.width for b in self.shared)
        return (
            f"{name}: {len(self.copied)} tensors copied; first layer and normaliser: {n} shared columns "
            f"({terms(self.shared)}), new columns zeroed: {terms(self.new)}, prior columns dropped: "
            f"{terms(self.dropped)}"
        )


def blocks(names: list[str]) -> list[Block]:
    """Runs of equal term names in a per-column name list (``ObservationGroups.term_columns``)."""
    out: list[Block] = []
    for i, name in enumerate(names):
        if out and out[-1].term == name and out[-1].start + out[-1].width == i:
            out[-1].width += 1
        else:
            out.append(Block(name, i, 1))
    return out


def model_terms(task: EnvCfg, groups: list[str], what: str) -> list[str]:
    """The terms a model reads (its observation groups' resolved terms, concatenated); history refused."""
    resolved = resolve_groups(task.observations)
    terms: list[str] = []
    for g in groups:
        if g not in resolved:
            raise CheckpointError(f"{what}: observation group {g!r} is not in its config")
        if task.observations[g].history > 1:
            raise CheckpointError(
                f"{what}: group {g!r} stacks history={task.observations[g].history}; an init across observation "
                "layouts supports history 1 only"
            )
        terms += resolved[g]
    return terms


def term_layout(task: EnvCfg, term: str) -> tuple:
    """The config that fixes one term's width and meaning, as its declaration states it (``ObsTerm.layout``: the
    map grid of a map term, the field switch of the field block): two layouts share a term only where this
    agrees."""
    one = replace(task, observations={"x": ObsGroupCfg(terms=[term])})
    return tuple(group_layout(one, "x")[2:])


def prior_blocks(terms: list[str], width: int, known: dict[str, int], what: str) -> list[Block]:
    """The prior's blocks from its term list and input ``width``; ``known`` widths from this env, one unknown
    term sized by what is left."""
    unknown = [t for t in terms if t not in known]
    rest = width - sum(known[t] for t in terms if t in known)
    if len(unknown) > 1:
        raise CheckpointError(
            f"{what}: cannot size the prior's terms {unknown} (this run reads none of them); an init across layouts "
            "needs at most one prior-only term per model"
        )
    if (unknown and rest < 1) or (not unknown and rest != 0):
        raise CheckpointError(
            f"{what}: the prior's input is {width} wide, its terms {terms} do not fit the widths this env gives them"
        )
    out, start = [], 0
    for t in terms:
        w = known.get(t, rest)
        out.append(Block(t, start, w))
        start += w
    return out


def partial_state(
    prior: dict[str, torch.Tensor],
    fresh: dict[str, torch.Tensor],
    old: list[Block],
    new: list[Block],
    what: str,
) -> tuple[dict[str, torch.Tensor], ModelInit]:
    """A state dict for a model whose fresh state is ``fresh`` and input blocks ``new``, from the prior's state
    ``prior`` of input blocks ``old`` (same names = same term). New columns: zero weight; the normaliser keeps
    ``fresh``'s values there (set from observations by the caller)."""
    report = ModelInit()
    if set(prior) != set(fresh):
        extra = sorted(set(prior) ^ set(fresh))
        raise CheckpointError(f"{what}: the prior's network differs in its tensors ({', '.join(extra[:3])})")
    first = first_linear(fresh)
    by_term = {b.term: b for b in old}
    src: list[int] = []
    dst: list[int] = []
    for b in new:
        p = by_term.get(b.term)
        if p is None:
            report.new.append(b)
            continue
        if p.width != b.width:
            raise CheckpointError(f"{what}: term {b.term} is {p.width} wide in the prior and {b.width} here")
        report.shared.append(b)
        src += list(p.cols)
        dst += list(b.cols)
    if not src:
        raise CheckpointError(f"{what}: the prior and this run share no observation term")
    report.dropped = [p for p in old if p.term not in {b.term for b in new}]
    src_t, dst_t = torch.tensor(src), torch.tensor(dst)
    out: dict[str, torch.Tensor] = {}
    for key, value in fresh.items():
        p = prior[key]
        if key == first:
            w = torch.zeros_like(value)
            if p.shape[0] != value.shape[0]:
                raise CheckpointError(f"{what}: {key} has {p.shape[0]} units in the prior, {value.shape[0]} here")
            w[:, dst_t] = p[:, src_t].to(w)
            out[key] = w
        elif key in NORM_KEYS:
            v = value.clone()
            v[:, dst_t] = p[:, src_t].to(v)
            out[key] = v
        elif p.shape != value.shape:
            raise CheckpointError(
                f"{what}: {key} is {tuple(p.shape)} in the prior and {tuple(value.shape)} here; only the input "
                "columns may differ (same hidden sizes and actions)"
            )
        else:
            out[key] = p.clone().to(value)
            report.copied.append(key)
    return out, report


def first_linear(state: dict[str, torch.Tensor]) -> str:
    """The key of the first linear layer's weight of an rsl_rl ``MLPModel`` state (``mlp.<k>.weight``)."""
    keys = [k for k, v in state.items() if k.startswith("mlp.") and k.endswith(".weight") and v.dim() == 2]
    return min(keys, key=lambda k: int(k.split(".")[1]))


def _noise_var(env, group: str, term: str) -> float:
    """Variance of the observation noise ``group`` reads ``term`` with (its floor for a new column)."""
    cfg = env.cfg
    if not (cfg.noise.enabled and cfg.observations[group].noise):
        return NORM_FLOOR
    scale = getattr(cfg.noise, term, None)
    if isinstance(scale, bool) or not isinstance(scale, int | float):
        scale = cfg.noise.extra.get(term, 0.0) if hasattr(cfg.noise, "extra") else 0.0
    return max(float(scale) ** 2 / 3.0, NORM_FLOOR)  # U(-s, s)


def _model_groups(model) -> list[str]:
    return list(model.obs_groups)


def init_from_prior(alg, env, path: str) -> dict[str, ModelInit]:
    """Load the prior ``path`` into PPO's actor and critic: strictly when its layouts equal this env's, else by
    :func:`partial_state`. Returns the per-model reports of a partial init (empty for a strict one)."""
    ckpt = read_checkpoint(path)
    models = {name: m for name in MODELS if (m := getattr(alg, f"_raw_{name}", getattr(alg, name, None)))}
    try:
        prior_cfg = load_run_config(path)
    except CheckpointError:
        prior_cfg = None  # a bare model file: only a strict load can tell whether it fits
    if prior_cfg is None or all(
        groups_layout(prior_cfg.task, list(prior_cfg.algo.obs_groups.get(n, [])))
        == groups_layout(env.cfg, _model_groups(m))
        for n, m in models.items()
    ):
        _strict(alg, ckpt, path)
        return {}
    reports = {}
    obs = env.get_observations()
    for name, model in models.items():
        what = f"init={path} ({name})"
        groups = _model_groups(model)
        if name not in prior_cfg.algo.obs_groups:
            raise CheckpointError(f"{what}: the prior's config has no {name} observation set")
        new_cols = [t for g in groups for t in env.observation_groups.term_columns(env, g)]
        new = blocks(new_cols)
        prior_terms = model_terms(prior_cfg.task, list(prior_cfg.algo.obs_groups[name]), what)
        model_terms(env.cfg, groups, what)  # history refused here too
        state = ckpt[MODELS[name]]
        width = state[first_linear(state)].shape[1]
        known = {b.term: b.width for b in new}
        for t in set(prior_terms) & set(known):
            if term_layout(prior_cfg.task, t) != term_layout(env.cfg, t):
                raise CheckpointError(
                    f"{what}: term {t} has another layout in the prior ({term_layout(prior_cfg.task, t)}) than "
                    f"here ({term_layout(env.cfg, t)})"
                )
        old = prior_blocks(prior_terms, width, known, what)
        fresh = {k: v.detach().clone() for k, v in model.state_dict().items()}
        out, report = partial_state(state, fresh, old, new, what)
        _fill_new_columns(out, report.new, env, groups, obs)
        model.load_state_dict(out, strict=True)
        reports[name] = report
        log.info("init: %s", report.line(name))
    return reports


def _fill_new_columns(state: dict[str, torch.Tensor], new: list[Block], env, groups: list[str], obs) -> None:
    """Normaliser statistics of the new columns from the env's current observations (variance floored at the
    term's noise)."""
    if not new or "obs_normalizer._mean" not in state:
        return
    x = torch.cat([obs[g] for g in groups], dim=-1).to(state["obs_normalizer._mean"])
    group_of = {t: g for g in groups for t in env.observation_groups.term_columns(env, g)}
    for b in new:
        cols = list(b.cols)
        var = x[:, cols].var(dim=0, unbiased=False).clamp_min(_noise_var(env, group_of[b.term], b.term))
        state["obs_normalizer._mean"][0, cols] = x[:, cols].mean(dim=0)
        state["obs_normalizer._var"][0, cols] = var
        state["obs_normalizer._std"][0, cols] = var.sqrt()


def _strict(alg, ckpt: dict, path: str) -> None:
    """rsl_rl's strict load of actor and critic (the prior's layout is this run's)."""
    try:
        alg.load(ckpt, {"actor": True, "critic": True}, True)
    except RuntimeError as err:
        raise CheckpointError(f"init={path} does not fit this run's networks: {str(err).splitlines()[0]}") from err
