# ruff: noqa: UP018  (Warp kernels need int(0)/float(0.0) to declare mutable locals)
"""Field bank: many fields (scenes × goals) in one tensor, and the batched 13-link trilinear query.

All fields of a bank share ``shape`` and ``voxel``; each has its own origin (and goal). Env ``e`` reads
field ``field_idx[e]`` at its K link positions in one Warp kernel launch (one thread per env), on
the device of the bank tensor; inputs and outputs are torch tensors aliased with ``wp.from_torch``.

Out-of-grid rule: a point's continuous index is clamped to the span of voxel centres, i.e. it gets the
value of the nearest boundary sample ("clamp to edge"), and ``inside`` is False for it. Callers that
prefer "free space outside the window" can use ``inside`` to override (e.g. d = large, F = 0).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import torch
import warp as wp

from cat.fields._wp import get_device, run_concurrently
from cat.fields.config import FieldCfg
from cat.fields.field import CHANNELS, NUM_CHANNELS, Field
from cat.fields.grid import Grid
from cat.fields.humanoid_pf import humanoid_pf

vec8 = wp.types.vector(length=NUM_CHANNELS, dtype=wp.float32)


@wp.kernel
def _query_kernel(
    bank: wp.array(dtype=vec8),
    origins: wp.array(dtype=wp.vec3),
    field_idx: wp.array(dtype=wp.int32),
    points: wp.array(dtype=wp.vec3),
    links: int,
    nx: int,
    ny: int,
    nz: int,
    inv_voxel: float,
    out: wp.array(dtype=vec8),
    inside: wp.array(dtype=wp.bool),
):
    """One thread per env: trilinear interpolation of all channels at its ``links`` points."""
    e = wp.tid()
    f = field_idx[e]
    org = origins[f]
    sx = ny * nz
    fbase = f * nx * sx
    o1 = wp.where(nx > 1, sx, 0)
    o2 = wp.where(ny > 1, nz, 0)
    o3 = wp.where(nz > 1, 1, 0)
    hx = float(nx - 1)
    hy = float(ny - 1)
    hz = float(nz - 1)
    for l in range(links):
        t = e * links + l
        u = (points[t] - org) * inv_voxel
        if not (wp.isfinite(u[0]) and wp.isfinite(u[1]) and wp.isfinite(u[2])):
            u = wp.vec3(-1.0, -1.0, -1.0)  # NaN/inf point: grid corner value, inside = False
        inside[t] = (
            u[0] >= 0.0
            and u[1] >= 0.0
            and u[2] >= 0.0
            and u[0] <= float(nx)
            and u[1] <= float(ny)
            and u[2] <= float(nz)
        )
        # continuous index of voxel centres, clamped to the grid's centre span ("clamp to edge")
        cx = wp.clamp(u[0] - 0.5, 0.0, hx)
        cy = wp.clamp(u[1] - 0.5, 0.0, hy)
        cz = wp.clamp(u[2] - 0.5, 0.0, hz)
        i0 = wp.min(int(cx), wp.max(nx - 2, 0))
        j0 = wp.min(int(cy), wp.max(ny - 2, 0))
        k0 = wp.min(int(cz), wp.max(nz - 2, 0))
        fx = cx - float(i0)
        fy = cy - float(j0)
        fz = cz - float(k0)
        gx = 1.0 - fx
        gy = 1.0 - fy
        gz = 1.0 - fz
        b = fbase + i0 * sx + j0 * nz + k0
        c00 = gz * bank[b] + fz * bank[b + o3]
        c01 = gz * bank[b + o2] + fz * bank[b + o2 + o3]
        c10 = gz * bank[b + o1] + fz * bank[b + o1 + o3]
        c11 = gz * bank[b + o1 + o2] + fz * bank[b + o1 + o2 + o3]
        out[t] = gx * (gy * c00 + fy * c01) + fx * (gy * c10 + fy * c11)


@dataclass
class FieldSample:
    """Query result, torch tensors of shape (N, K, ...)."""

    values: torch.Tensor
    """(N, K, 8) all channels (see :data:`cat.fields.field.CHANNELS`)."""
    inside: torch.Tensor
    """(N, K) bool: the point lies in its field's grid box."""

    @property
    def force(self) -> torch.Tensor:
        return self.values[..., 0:3]

    @property
    def sdf(self) -> torch.Tensor:
        return self.values[..., 3]

    @property
    def grad_sdf(self) -> torch.Tensor:
        return self.values[..., 4:7]

    @property
    def geodesic(self) -> torch.Tensor:
        return self.values[..., 7]


class FieldBank:
    """(n_fields, nx, ny, nz, 8) float32 tensor of fields sharing shape and voxel, with per-field origins.

    On the CPU the query is memory-bound gathers on one core per launch; ``num_threads`` > 1 splits the
    envs over that many concurrent launches (Python threads; the launch releases the GIL)."""

    def __init__(
        self,
        data: torch.Tensor,
        origins: torch.Tensor,
        voxel: float,
        goals: torch.Tensor | None = None,
        num_threads: int | None = None,
    ):
        if data.ndim != 5 or data.shape[-1] != NUM_CHANNELS:
            raise ValueError(f"bank data must be (n_fields, nx, ny, nz, {NUM_CHANNELS}), got {tuple(data.shape)}")
        if origins.shape != (data.shape[0], 3):
            raise ValueError(f"origins must be ({data.shape[0]}, 3), got {tuple(origins.shape)}")
        self.data = data.to(torch.float32).contiguous()
        self.origins = origins.to(self.data.device, torch.float32).contiguous()
        self.voxel = float(voxel)
        self.goals = None if goals is None else goals.to(self.data.device, torch.float32)
        self.device = self.data.device
        self._wp_device = get_device("cpu" if self.device.type == "cpu" else f"cuda:{self.device.index or 0}")
        if num_threads is None:
            num_threads = min(2, os.cpu_count() or 1)
        self.num_threads = max(1, int(num_threads)) if self._wp_device.is_cpu else 1

    @property
    def num_fields(self) -> int:
        return int(self.data.shape[0])

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(s) for s in self.data.shape[1:4])

    def grid(self, i: int) -> Grid:
        return Grid(tuple(self.origins[i].tolist()), self.voxel, self.shape)

    @classmethod
    def from_fields(
        cls, fields: list[Field], device: str | torch.device = "cpu", num_threads: int | None = None
    ) -> FieldBank:
        """Stack built fields (same shape and voxel) into a bank on ``device``."""
        if not fields:
            raise ValueError("FieldBank needs at least one field")
        shape, voxel = fields[0].grid.shape, fields[0].grid.voxel
        for f in fields:
            if f.grid.shape != shape or not np.isclose(f.grid.voxel, voxel):
                raise ValueError("all fields of a bank must share grid shape and voxel size")
        data = torch.from_numpy(np.stack([f.data for f in fields])).to(device)
        origins = torch.tensor([f.grid.origin for f in fields], dtype=torch.float32, device=device)
        goals = torch.tensor(np.stack([f.goal for f in fields]), dtype=torch.float32, device=device)
        return cls(data, origins, voxel, goals, num_threads)

    def set_field(self, i: int, f: Field) -> None:
        """Replace field ``i`` in place (e.g. a rebuild for a clicked goal)."""
        if f.grid.shape != self.shape or not np.isclose(f.grid.voxel, self.voxel):
            raise ValueError("field grid does not match the bank's shape/voxel")
        self.data[i] = torch.from_numpy(f.data).to(self.device)
        self.origins[i] = torch.tensor(f.grid.origin, dtype=torch.float32, device=self.device)
        if self.goals is not None:
            self.goals[i] = torch.tensor(f.goal, dtype=torch.float32, device=self.device)

    def query(self, field_idx: torch.Tensor, points: torch.Tensor, out: FieldSample | None = None) -> FieldSample:
        """Trilinear values of all channels at ``points`` (N, K, 3) in fields ``field_idx`` (N,).

        Non-finite points get the value at the grid's first voxel and ``inside`` False. On the CPU a
        field index out of range raises IndexError (on CUDA it is the caller's job: no host sync here)."""
        if points.ndim != 3 or points.shape[-1] != 3:
            raise ValueError(f"points must be (N, K, 3), got {tuple(points.shape)}")
        n, k = points.shape[:2]
        if field_idx.shape != (n,):
            raise ValueError(f"field_idx must be ({n},), got {tuple(field_idx.shape)}")
        pts = points.to(self.device, torch.float32).contiguous()
        idx = field_idx.to(self.device, torch.int32).contiguous()
        if self.device.type == "cpu" and n > 0:  # an out-of-range field index would read foreign memory
            lo, hi = int(idx.min()), int(idx.max())
            if lo < 0 or hi >= self.num_fields:
                raise IndexError(f"field_idx out of range [0, {self.num_fields}): min {lo}, max {hi}")
        if out is None:
            out = FieldSample(
                torch.empty((n, k, NUM_CHANNELS), dtype=torch.float32, device=self.device),
                torch.empty((n, k), dtype=torch.bool, device=self.device),
            )
        nx, ny, nz = self.shape
        bank = wp.from_torch(self.data.view(-1, NUM_CHANNELS), dtype=vec8)
        origins = wp.from_torch(self.origins, dtype=wp.vec3)
        values = out.values.view(-1, NUM_CHANNELS)
        inside = out.inside.view(-1)

        def launch(e0: int, e1: int) -> None:
            if e1 <= e0:
                return
            wp.launch(
                _query_kernel,
                dim=e1 - e0,
                inputs=[
                    bank,
                    origins,
                    wp.from_torch(idx[e0:e1], dtype=wp.int32),
                    wp.from_torch(pts[e0:e1].view(-1, 3), dtype=wp.vec3),
                    k,
                    nx,
                    ny,
                    nz,
                    1.0 / self.voxel,
                    wp.from_torch(values[e0 * k : e1 * k], dtype=vec8),
                    wp.from_torch(inside[e0 * k : e1 * k], dtype=wp.bool),
                ],
                device=self._wp_device,
            )

        if self._wp_device.is_cuda:  # run on torch's current stream (no implicit sync, no race)
            with wp.ScopedStream(wp.stream_from_torch(self.device)):
                launch(0, n)
        else:
            parts = self.num_threads if n >= 256 else 1
            bounds = [n * t // parts for t in range(parts + 1)]
            run_concurrently(*[lambda t=t: launch(bounds[t], bounds[t + 1]) for t in range(parts)])
        return out

    def query_pf(
        self, field_idx: torch.Tensor, points: torch.Tensor, velocities: torch.Tensor, cfg: FieldCfg | None = None
    ) -> tuple[FieldSample, torch.Tensor]:
        """Query plus HumanoidPF at the links: (sample, F_H (N, K, 3)); link 0 is the root."""
        cfg = cfg or FieldCfg()
        s = self.query(field_idx, points)
        w0 = torch.full((points.shape[1],), cfg.w_other, dtype=torch.float32, device=self.device)
        w0[0] = cfg.w_root
        return s, humanoid_pf(s.force, s.grad_sdf, s.sdf, velocities.to(s.values), w0, cfg.lam)


__all__ = ["CHANNELS", "FieldBank", "FieldSample"]
