"""Warm start from a prior (``init=``) when the new task shows the network inputs the prior never saw vary.

A flat-ground prior sees the HumanoidPF block of free space: SDF 1 and ∇d 0 at every link, so its observation
normaliser learned a mean of 1 and a standard deviation of the injected noise (0.03) for those columns. In a
scene the same columns read 0.3 or -0.8: 20-60 normalised units, and the prior's first layer turns them into
garbage actions (it falls within half a second of the first step). ``adapt_to_new_inputs`` finds such columns
on the new env's observations, re-centres their normaliser statistics there, and zeroes their first-layer
weights: the network then acts exactly as the prior did, and PPO learns what the new inputs mean from their
gradients instead of unlearning the garbage.

Some columns only go off once the robot is somewhere the reset poses are not: the head's SDF under a ceiling,
a foot's ∇d at a bar. ``adapt_to_new_inputs`` therefore also rolls the (adapted) prior out for a few seconds
(``PROBE_STEPS``, upright rows only) and adapts every column that goes off on the way, with statistics over the
whole probe; the env is then reset, so training starts from fresh episodes. The probe only touches columns the
prior saw as a constant (its normaliser's std no larger than the column's observation noise): proprioception in
a new place has heavy tails too (a knee reading 15 σ off for a few rows), and zeroing those would cut the
prior's balance, while a column that was pure noise to the prior carried nothing it could have used.
"""

from __future__ import annotations

import logging
import math

import torch
from tensordict import TensorDict

from cat.envs.obs_groups import noise_scale, noise_std

log = logging.getLogger(__name__)

UNSEEN_Z = 6.0
"""A column is new to the prior when some observation lies this many of the prior's standard deviations off."""


def unseen_columns(mean: torch.Tensor, std: torch.Tensor, x: torch.Tensor, z: float = UNSEEN_Z) -> torch.Tensor:
    """(D,) bool: columns of ``x`` (N, D) with a value more than ``z`` prior std's from the prior mean."""
    return ((x - mean) / std.clamp_min(1e-8)).abs().amax(dim=0) > z


def adapt_model(model, x: torch.Tensor, z: float = UNSEEN_Z) -> int:
    """Re-centre and detach the unseen input columns of one rsl_rl ``MLPModel`` (normaliser + first linear layer)
    on observations ``x`` (N, D) of its input; returns how many columns changed."""
    return int(_adapt(model, x, z).sum())


def _adapt(model, x: torch.Tensor, z: float = UNSEEN_Z, allowed: torch.Tensor | None = None) -> torch.Tensor:
    """``adapt_model``'s work, limited to the ``allowed`` (D,) columns; returns the (D,) mask it changed."""
    norm = getattr(model, "obs_normalizer", None)
    first = next((m for m in model.mlp if isinstance(m, torch.nn.Linear)), None)
    if norm is None or not hasattr(norm, "_mean") or first is None:
        return torch.zeros(x.shape[-1], dtype=torch.bool)
    cols = unseen_columns(norm._mean[0], norm._std[0], x, z)
    if allowed is not None:
        cols &= allowed
    if not cols.any():
        return cols
    with torch.no_grad():
        var = x[:, cols].var(dim=0, unbiased=False).clamp_min(1e-4)
        norm._mean[0, cols] = x[:, cols].mean(dim=0)
        norm._var[0, cols] = var
        norm._std[0, cols] = var.sqrt()
        first.weight[:, cols] = 0.0
    return cols


def _model_input(model, obs: TensorDict) -> torch.Tensor:
    return torch.cat([obs[g] for g in model.obs_groups], dim=-1)


PROBE_STEPS = 200
"""Control steps of the probe rollout (4 s at 50 Hz: a walking prior crosses a typical scene's course)."""
PROBE_STRIDE = 4
"""Every how many probe steps the observations are kept (the statistics need no more)."""
NOISE_MARGIN = 1.3
"""A probe column counts as constant to the prior up to this many times its noise std (see below)."""
MIN_STD = 1e-3
"""Noise-free columns: the prior's std at or below this means it saw a constant."""
UPRIGHT = 0.3
"""Probe rows are kept only while the robot is upright (tilt below this, in rad, and pelvis above the fall
height): a stumbling prior reads proprioception far off too, and those columns are not new to it."""


def _models(alg) -> dict:
    return {name: m for name in ("actor", "critic") if (m := getattr(alg, name, None)) is not None}


def probe_inputs(env, alg, steps: int = PROBE_STEPS, stride: int = PROBE_STRIDE) -> dict[str, torch.Tensor]:
    """Each model's inputs (rows, D) seen while the actor (deterministic) drives ``env`` for ``steps`` steps."""
    models = _models(alg)
    obs = env.get_observations()
    seen = {name: [_model_input(m, obs)] for name, m in models.items()}
    with torch.no_grad():  # not inference_mode: the env's buffers stay writable for training
        for k in range(1, steps + 1):
            obs, _, _, _ = env.step(models["actor"](obs))
            if k % stride == 0:
                rows = _upright(env)
                for name, m in models.items():
                    seen[name].append(_model_input(m, obs)[rows])
    return {name: torch.cat(xs) for name, xs in seen.items()}


def _upright(env) -> torch.Tensor:
    s = env.state
    low = env.cfg.terminations.min_base_height + 0.2
    return (s.gravity[:, 2] < -math.cos(UPRIGHT)) & (s.root_pos[:, 2] > low)  # projected gravity z = -cos(tilt)


def _constant_in_prior(env, model) -> torch.Tensor:
    """(D,) mask of the columns the prior saw as a constant: its normaliser std no larger than the std of the
    observation noise of the column's term (``obs_groups.noise_std``), times ``NOISE_MARGIN``."""
    noise = env.cfg.noise
    floor = []
    for g in model.obs_groups:
        noisy = noise.enabled and bool(env.cfg.observations[g].noise)
        for term in env.observation_groups.term_columns(env, g):
            floor.append(noise_std(term, noise_scale(noise, term)) if noisy else 0.0)
    floor = torch.tensor(floor).clamp_min(MIN_STD) * NOISE_MARGIN
    return model.obs_normalizer._std[0] <= floor


def adapt_to_new_inputs(alg, env, steps: int = PROBE_STEPS) -> None:
    """Apply ``adapt_model`` to PPO's actor and critic: first on the env's current observations, then on a probe
    rollout of the adapted prior (``probe_inputs``); finally reset every env so training starts afresh."""
    models = _models(alg)
    obs = env.get_observations()
    allowed = {name: _constant_in_prior(env, m) for name, m in models.items()}
    changed = {name: _adapt(m, _model_input(m, obs), allowed=allowed[name]) for name, m in models.items()}
    if steps > 0:
        for name, x in probe_inputs(env, alg, steps).items():
            changed[name] |= _adapt(models[name], x, allowed=allowed[name])
        env.reset_idx(torch.arange(env.num_envs, device=env.device))
    for name, mask in changed.items():
        if n := int(mask.sum()):
            log.info("init: %d %s inputs the prior never saw vary start at zero weight (re-centred)", n, name)
