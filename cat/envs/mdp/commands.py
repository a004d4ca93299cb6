"""The velocity command: a direction from a configured source, at a speed that slows down into the goal.

Sources (``CommandCfg.source``): ``field`` follows HumanoidPF at the root (ours); ``straight`` points along the
straight line from the root to the goal, so the tracking rewards read no field (the baselines and w/o R_field).
"""

from __future__ import annotations

import torch

from cat.envs.config import CommandCfg


def command_speed(distance: torch.Tensor, cfg: CommandCfg) -> torch.Tensor:
    """Commanded root speed [m/s] at horizontal goal ``distance`` [m].

    ``cfg.speed`` far away, decaying as (d / slow_radius)^slow_power inside ``slow_radius``. With power 1 a
    robot that tracks the command closes the last ``slow_radius`` exponentially (time constant
    slow_radius / speed) and so gets within the 0.1 m success radius in finite time.
    """
    return cfg.speed * torch.clamp(distance / cfg.slow_radius, max=1.0) ** cfg.slow_power


def field_direction(humanoid_pf: torch.Tensor, root_xy: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
    """Horizontal direction (n, 2) of F_H at the root (query link 0)."""
    return humanoid_pf[:, 0, :2]


def straight_direction(humanoid_pf: torch.Tensor, root_xy: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
    """Horizontal direction (n, 2) from the root to the goal; ignores the field."""
    return goals[:, :2] - root_xy


COMMAND_SOURCES = {"field": field_direction, "straight": straight_direction}


def command_source(name: str):
    """The direction function of ``CommandCfg.source``, or ``ValueError`` naming it and the valid sources."""
    if name not in COMMAND_SOURCES:
        raise ValueError(f"unknown command source {name!r}; valid: {', '.join(COMMAND_SOURCES)}")
    return COMMAND_SOURCES[name]


def velocity_command(direction: torch.Tensor, distance: torch.Tensor, cfg: CommandCfg) -> torch.Tensor:
    """(n, 2) command: the unit ``direction`` times ``command_speed(distance)``."""
    unit = direction / direction.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    return unit * command_speed(distance, cfg)[:, None]
