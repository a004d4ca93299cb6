"""Odometry drift of a deployed robot's pose estimate, for the ``field_block_odometry`` observation term.

A robot reads HumanoidPF at the links it places with its odometry pose (LiDAR-inertial odometry registered to
its own map), not at its true links. The error of that pose is a planar rigid transform (dx, dy, dyaw) of the
whole body about the root, modelled per env as a random walk (Brownian motion) started at zero when the episode
starts (odometry is initialised at the start pose): over a time step dt each axis gains N(0, sigma^2 dt), so its
std after T seconds is sigma sqrt(T). The constants are ``NoiseCfg.odometry_xy`` [m/sqrt(s)] and
``NoiseCfg.odometry_yaw`` [rad/sqrt(s)] (docs/distillation.md).
"""

from __future__ import annotations

import torch


class OdometryDrift:
    """(N, 3) pose error (dx, dy, dyaw) of N envs: world-frame offset of the root [m] and heading error [rad]."""

    def __init__(self, num_envs: int, sigma_xy: float, sigma_yaw: float, device):
        self.sigma = torch.tensor([sigma_xy, sigma_xy, sigma_yaw], dtype=torch.float32)
        self.error = torch.zeros(num_envs, 3, dtype=torch.float32, device=device)

    def reset(self, env_ids: torch.Tensor) -> None:
        """Odometry initialised at the start pose: no error."""
        self.error[env_ids] = 0.0

    def advance(self, dt: torch.Tensor, generator: torch.Generator) -> None:
        """Random-walk step of every env over ``dt`` (N,) seconds, drawn from ``generator`` (the env's, on CPU)."""
        noise = torch.randn(self.error.shape, generator=generator, dtype=torch.float32)
        step = noise * self.sigma * dt.detach().to("cpu", torch.float32).clamp_min(0.0).sqrt()[:, None]
        self.error += step.to(self.error.device)

    def displace(
        self, root_pos: torch.Tensor, yaw: torch.Tensor, link_pos: torch.Tensor, env_ids: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Links and heading as the odometry sees them: (link - root) rotated by dyaw about the root, shifted by
        (dx, dy); heading yaw + dyaw. ``root_pos`` (n, 3), ``yaw`` (n,), ``link_pos`` (n, K, 3) of all envs or of
        ``env_ids``. Written as offsets from the true links, so a zero error gives them back bit for bit."""
        err = self.error if env_ids is None else self.error[env_ids]
        rel = link_pos - root_pos[:, None, :]
        shift = self.rotate_offset(err[:, 2], rel)
        shift[..., 0] += err[:, None, 0]
        shift[..., 1] += err[:, None, 1]
        return link_pos + shift, yaw + err[:, 2]

    def rotate(self, v: torch.Tensor, env_ids: torch.Tensor | None = None) -> torch.Tensor:
        """World vectors ``v`` (n, K, 3) expressed in the odometry's world frame (rotated by dyaw about z)."""
        err = self.error if env_ids is None else self.error[env_ids]
        return v + self.rotate_offset(err[:, 2], v)

    @staticmethod
    def rotate_offset(angle: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """(R(angle) - I) v for vectors ``v`` (n, K, 3) and angles (n,) about z; exactly zero at angle 0."""
        c, s = (-2.0 * torch.sin(0.5 * angle) ** 2)[:, None], torch.sin(angle)[:, None]  # cos - 1, accurate near 0
        x, y = v[..., 0], v[..., 1]
        return torch.stack((c * x - s * y, s * x + c * y, torch.zeros_like(x)), dim=-1)
