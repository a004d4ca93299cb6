"""Where the env gets HumanoidPF samples at the 13 query links.

``GoalField`` is the analytic field of an empty scene (flat ground: no obstacles, so the geodesic is the
Euclidean distance and U_rep = 0). ``BankField`` samples precomputed per-scene, per-goal fields from a
``cat.fields`` field bank.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class FieldSample:
    """Field values at query points: F = -grad U (N, K, 3), SDF d (N, K) and its gradient (N, K, 3), and how
    far (m) the farthest of an env's points lies outside its field's grid (N,): sideways or above it; below
    the grid is the floor and does not count. Reads outside are clamped to the grid's border values."""

    force: torch.Tensor
    sdf: torch.Tensor
    grad_sdf: torch.Tensor
    outside: torch.Tensor


class GoalField:
    """Empty-space HumanoidPF: F = eta (g - x)/|g - x|, d = ``free_sdf`` everywhere, grad d = 0."""

    def __init__(self, eta: float, free_sdf: float):
        self.eta = eta
        self.free_sdf = free_sdf

    def sample(self, points: torch.Tensor, goals: torch.Tensor, env_ids: torch.Tensor | None = None) -> FieldSample:
        """``points`` (n, K, 3) world positions, ``goals`` (n, 3) of all envs or of ``env_ids``."""
        delta = goals[:, None, :] - points
        force = self.eta * delta / delta.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        sdf = torch.full(points.shape[:-1], self.free_sdf, dtype=points.dtype, device=points.device)
        outside = torch.zeros(points.shape[0], dtype=points.dtype, device=points.device)  # unbounded field
        return FieldSample(force=force, sdf=sdf, grad_sdf=torch.zeros_like(points), outside=outside)
