"""The per-link HumanoidPF observation block, one function shared by the env and the deploy runtime (live field).

Kept out of ``observations`` so it is not mistaken for an observation term (terms take the env).
"""

from __future__ import annotations

import torch

from cat.envs.config import FieldObsCfg
from cat.envs.math_utils import rotate_yaw_inverse


def field_obs(
    yaw: torch.Tensor, f_h: torch.Tensor, grad_sdf: torch.Tensor, sdf: torch.Tensor, cfg: FieldObsCfg
) -> torch.Tensor:
    """(N, K, 7) block that the ``field_block`` term reads: F_H and grad d in the yaw-only frame, d clipped to
    ``cfg.sdf_clip``. ``yaw`` (N,), ``f_h`` / ``grad_sdf`` (N, K, 3), ``sdf`` (N, K)."""
    clip = cfg.sdf_clip
    fh = rotate_yaw_inverse(yaw, f_h)
    grad = rotate_yaw_inverse(yaw, grad_sdf)
    return torch.cat((fh, grad, sdf.clamp(-clip, clip).unsqueeze(-1)), dim=-1)
