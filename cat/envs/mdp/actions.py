"""The action: incremental PD targets of the policy joints, clipped to soft joint limits (DESIGN §5).

Shared by the env and the deploy runtime (``cat.deploy``), so a policy drives both the same way.
"""

from __future__ import annotations

import torch


def soft_joint_limits(joint_range: torch.Tensor, factor: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(lower, upper) of the central ``factor`` of each joint's range; ``joint_range`` (nj, 2)."""
    mid, half = joint_range.mean(dim=-1), 0.5 * (joint_range[:, 1] - joint_range[:, 0]) * factor
    return mid - half, mid + half


def apply_actions(
    targets: torch.Tensor,
    actions: torch.Tensor,
    joint_ids: torch.Tensor,
    scale: float,
    lower: torch.Tensor,
    upper: torch.Tensor,
) -> None:
    """In place: ``targets[:, ids] <- clip(targets[:, ids] + scale * actions, lower[ids], upper[ids])``."""
    tgt = targets[:, joint_ids] + scale * actions
    targets[:, joint_ids] = torch.maximum(torch.minimum(tgt, upper[joint_ids]), lower[joint_ids])
