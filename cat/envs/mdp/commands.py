"""The velocity command: speed along HumanoidPF at the root, slowing down into the goal."""

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
