"""Termination terms: boolean (N,) tensors; any true ends the episode as a failure."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv


def fallen(env: TraversalEnv) -> torch.Tensor:
    t = env.cfg.terminations
    low = env.state.root_pos[:, 2] < t.min_base_height
    tilted = env.state.gravity[:, 2] > -math.cos(t.max_tilt)  # projected gravity z = -cos(tilt)
    return low | tilted


def collided(env: TraversalEnv) -> torch.Tensor:
    if not env.cfg.terminations.on_collision:
        return torch.zeros(env.num_envs, dtype=torch.bool, device=env.device)
    return env.state.hard_collision


def non_finite(env: TraversalEnv) -> torch.Tensor:
    """Diverged physics (NaN/inf state) ends the episode instead of poisoning the batch."""
    return ~torch.isfinite(env.state.root_pos).all(dim=-1)


def left_field_grid(env: TraversalEnv) -> torch.Tensor:
    """A query link more than ``field_grid_margin`` outside its scene's field grid (sideways or above): the
    robot has left the scene, and the field there would be a clamped border value, not the field."""
    return env.field.outside > env.cfg.terminations.field_grid_margin
