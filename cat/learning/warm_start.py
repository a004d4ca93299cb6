"""Warm start from a prior (``init=``) when the new task shows the network inputs the prior never saw vary.

A flat-ground prior sees the HumanoidPF block of free space: SDF 1 and ∇d 0 at every link, so its observation
normaliser learned a mean of 1 and a standard deviation of the injected noise (0.03) for those columns. In a
scene the same columns read 0.3 or -0.8: 20-60 normalised units, and the prior's first layer turns them into
garbage actions (it falls within half a second of the first step). ``adapt_to_new_inputs`` finds such columns
on the new env's observations, re-centres their normaliser statistics there, and zeroes their first-layer
weights: the network then acts exactly as the prior did, and PPO learns what the new inputs mean from their
gradients instead of unlearning the garbage.
"""

from __future__ import annotations

import logging

import torch
from tensordict import TensorDict

log = logging.getLogger(__name__)

UNSEEN_Z = 6.0
"""A column is new to the prior when some observation lies this many of the prior's standard deviations off."""


def unseen_columns(mean: torch.Tensor, std: torch.Tensor, x: torch.Tensor, z: float = UNSEEN_Z) -> torch.Tensor:
    """(D,) bool: columns of ``x`` (N, D) with a value more than ``z`` prior std's from the prior mean."""
    return ((x - mean) / std.clamp_min(1e-8)).abs().amax(dim=0) > z


def adapt_model(model, x: torch.Tensor, z: float = UNSEEN_Z) -> int:
    """Re-centre and detach the unseen input columns of one rsl_rl ``MLPModel`` (normaliser + first linear layer)
    on observations ``x`` (N, D) of its input; returns how many columns changed."""
    norm = getattr(model, "obs_normalizer", None)
    first = next((m for m in model.mlp if isinstance(m, torch.nn.Linear)), None)
    if norm is None or not hasattr(norm, "_mean") or first is None:
        return 0
    cols = unseen_columns(norm._mean[0], norm._std[0], x, z)
    if not cols.any():
        return 0
    with torch.no_grad():
        var = x[:, cols].var(dim=0, unbiased=False).clamp_min(1e-4)
        norm._mean[0, cols] = x[:, cols].mean(dim=0)
        norm._var[0, cols] = var
        norm._std[0, cols] = var.sqrt()
        first.weight[:, cols] = 0.0
    return int(cols.sum())


def _model_input(model, obs: TensorDict) -> torch.Tensor:
    return torch.cat([obs[g] for g in model.obs_groups], dim=-1)


def adapt_to_new_inputs(alg, obs: TensorDict) -> None:
    """Apply ``adapt_model`` to PPO's actor and critic on the env's current observations ``obs``."""
    for name in ("actor", "critic"):
        model = getattr(alg, name, None)
        if model is None:
            continue
        n = adapt_model(model, _model_input(model, obs))
        if n:
            log.info("init: %d %s inputs the prior never saw vary start at zero weight (re-centred)", n, name)
