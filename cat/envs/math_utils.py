"""Small batched rotation helpers (quaternions are MuJoCo's w, x, y, z)."""

from __future__ import annotations

import torch


def quat_rotate_inverse(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate vectors ``v`` (..., 3) by the inverse of unit quaternions ``q`` (..., 4)."""
    w, xyz = q[..., :1], q[..., 1:]
    t = 2.0 * torch.cross(xyz, v, dim=-1)
    return v - w * t + torch.cross(xyz, t, dim=-1)


def yaw_from_quat(q: torch.Tensor) -> torch.Tensor:
    """Heading angle of unit quaternions (..., 4)."""
    w, x, y, z = q.unbind(-1)
    return torch.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def rotate_yaw_inverse(yaw: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Express world vectors ``v`` (N, ..., 3) in the yaw-only frame of each env (yaw (N,))."""
    c, s = torch.cos(yaw), torch.sin(yaw)
    shape = (-1,) + (1,) * (v.dim() - 2)
    c, s = c.view(shape), s.view(shape)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return torch.stack((c * x + s * y, -s * x + c * y, z), dim=-1)


def yaw_quat(yaw: torch.Tensor) -> torch.Tensor:
    """Quaternions (N, 4) of pure rotations about z."""
    h = 0.5 * yaw
    zeros = torch.zeros_like(h)
    return torch.stack((torch.cos(h), zeros, zeros, torch.sin(h)), dim=-1)


def wrap_to_pi(a: torch.Tensor) -> torch.Tensor:
    return torch.remainder(a + torch.pi, 2 * torch.pi) - torch.pi


def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) in MuJoCo's (w, x, y, z) order."""
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        (
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ),
        dim=-1,
    ).reshape(*q.shape[:-1], 3, 3)  # fmt: skip
