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
    """Field values at query points: F = -grad U (N, K, 3), SDF d (N, K) and its gradient (N, K, 3)."""

    force: torch.Tensor
    sdf: torch.Tensor
    grad_sdf: torch.Tensor


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
        return FieldSample(force=force, sdf=sdf, grad_sdf=torch.zeros_like(points))
