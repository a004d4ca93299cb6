# ruff: noqa: UP018  (Warp kernels need int(0)/float(0.0) to declare mutable locals)
"""Smallest scene SDF over point sets fixed on rigid bodies: one fused Warp kernel per query.

A :class:`BodyPoints` holds, per body, groups of points in the body's frame (e.g. the surface samples of each
collision geom, or a capsule's axis), each group with a bounding sphere and an offset: the group stands for the
points inflated by that radius (a capsule is its axis inflated by its radius), so its SDF is d − offset.
:func:`min_sdf_kernel` rotates and translates each body's points by the body pose and returns the smallest
trilinear d − offset of the world's scene over them, reading the bank's d grid directly (no point buffer, no
per-point query output). One thread per world on the CPU (a Warp CPU launch
runs its threads one after another: fewer, longer threads cost less), one per (world, body) on CUDA.

Semantics are the bank query's (:mod:`cat.fields._bank_kernel`): the same trilinear interpolation of the voxel
centres, and a point outside its scene's grid box (or non-finite) is clear (+inf). A group whose bounding-sphere
centre lies at d >= its cull distance (or outside the grid box by at least that much) is skipped: its points
cannot be near an obstacle. The cull distances are the caller's (radius + margin + slack).

No ``from __future__ import annotations`` here: Warp reads the annotations of the kernel built in a closure.
"""

import functools
from dataclasses import dataclass

import torch
import warp as wp

from cat.fields._bank_kernel import block_address, grid_cell, grid_contains, grid_strides, trilinear


@dataclass
class BodyPoints:
    """Point groups on B rigid bodies (torch tensors on the bank's device; group ``g`` belongs to one body).

    Body ``b`` owns groups ``body_start[b]:body_start[b+1]``; group ``g`` owns points
    ``group_start[g]:group_start[g+1]``. Groups are therefore stored body by body."""

    points: torch.Tensor
    """(P, 3) float32, body frame."""
    group_start: torch.Tensor
    """(G + 1,) int32."""
    body_start: torch.Tensor
    """(B + 1,) int32."""
    centre: torch.Tensor
    """(G, 3) float32: bounding-sphere centre of each group, body frame."""
    cull: torch.Tensor
    """(G,) float32: the group is skipped when d at its centre is >= this (radius + offset + margin + slack)."""
    offset: torch.Tensor
    """(G,) float32: the group's points inflated by this radius (0: the points themselves)."""

    @property
    def num_bodies(self) -> int:
        return int(self.body_start.shape[0]) - 1

    @classmethod
    def from_groups(
        cls,
        groups: list[torch.Tensor],
        group_body: list[int],
        centre: torch.Tensor,
        cull: list[float],
        device: torch.device,
        offset: list[float] | None = None,
    ) -> tuple["BodyPoints", list[int]]:
        """Pack ``groups[g]`` (K_g, 3) of body ``group_body[g]``, bounding-sphere centre ``centre[g]``, cull
        distance ``cull[g]`` and inflation ``offset[g]`` (default 0). Returns the packing and the order of the
        groups in it (stable sort by body)."""
        offset = [0.0] * len(groups) if offset is None else offset
        order = sorted(range(len(groups)), key=lambda g: group_body[g])
        nb = max(group_body) + 1 if groups else 0
        counts = torch.tensor([len(groups[g]) for g in order], dtype=torch.int64)
        per_body = torch.bincount(torch.tensor(group_body, dtype=torch.int64), minlength=nb)
        zero = torch.zeros(1, dtype=torch.int64)
        pts = [groups[g].to(torch.float32).cpu() for g in order]
        i32, f32 = dict(dtype=torch.int32, device=device), dict(dtype=torch.float32, device=device)
        return (
            cls(
                points=torch.cat(pts).to(**f32).contiguous(),
                group_start=torch.cat((zero, counts.cumsum(0))).to(**i32),
                body_start=torch.cat((zero, per_body.cumsum(0))).to(**i32),
                centre=centre[order].to(**f32).contiguous(),
                cull=torch.tensor([cull[g] for g in order], **f32),
                offset=torch.tensor([offset[g] for g in order], **f32),
            ),
            order,
        )


@functools.cache
def min_sdf_kernel(scalar: type, channels: int = 4) -> wp.Kernel:
    """The fused (world, body) min-SDF kernel for bank storage type ``scalar`` (float32 / float16) whose scene
    blocks hold ``channels`` values per voxel, d first (4: the bank's d, ∇d; 1: its contact SDF); math in float32."""
    v4 = wp.types.vector(length=channels, dtype=scalar)
    scene_bytes = wp.types.type_size_in_bytes(v4)

    @wp.func
    def trilinear_d(sd: wp.array(dtype=v4), u: wp.vec3, nx: int, ny: int, nz: int, o: wp.vec3i) -> wp.float32:
        """d at continuous grid index ``u``: the bank query's interpolation (voxel centres, clamp to edge)."""
        b, fr = grid_cell(u, nx, ny, nz)
        x = o[0]
        y = o[1]
        z = o[2]
        return trilinear(
            float(sd[b][0]), float(sd[b + z][0]), float(sd[b + y][0]), float(sd[b + y + z][0]),
            float(sd[b + x][0]), float(sd[b + x + z][0]), float(sd[b + x + y][0]), float(sd[b + x + y + z][0]), fr,
        )  # fmt: skip

    @wp.kernel(module="unique")
    def min_sdf(
        scene_ptr: wp.uint64,
        scene_offset: wp.array(dtype=wp.int64),
        scene_shape: wp.array(dtype=wp.vec3i),
        scene_origin: wp.array(dtype=wp.vec3),
        scene_inv_voxel: wp.array(dtype=wp.float32),
        field_scene: wp.array(dtype=wp.int32),
        field_idx: wp.array(dtype=wp.int32),
        world_order: wp.array(dtype=wp.int32),
        body_pos: wp.array(dtype=wp.vec3),
        body_quat: wp.array(dtype=wp.vec4),
        num_bodies: int,
        split_bodies: int,
        body_start: wp.array(dtype=wp.int32),
        group_start: wp.array(dtype=wp.int32),
        centre: wp.array(dtype=wp.vec3),
        cull: wp.array(dtype=wp.float32),
        offset: wp.array(dtype=wp.float32),
        points: wp.array(dtype=wp.vec3),
        use_cull: int,
        out: wp.array(dtype=wp.float32),
    ):
        """Thread t: world ``world_order[t]``, all its bodies (``split_bodies`` 0), or world
        ``world_order[t / num_bodies]``, body ``t % num_bodies`` (1); per body the min over its unculled groups
        of the trilinear d at its points less the group's offset."""
        t = wp.tid()
        wi = t
        b0 = int(0)
        b1 = num_bodies
        if split_bodies != 0:
            wi = t / num_bodies
            b0 = t % num_bodies
            b1 = b0 + 1
        w = world_order[wi]
        s = field_scene[field_idx[w]]
        shp = scene_shape[s]
        nx = shp[0]
        ny = shp[1]
        nz = shp[2]
        sd = wp.array(
            ptr=block_address(scene_ptr, scene_offset[s], wp.int64(wp.static(scene_bytes))),
            shape=(nx * ny * nz,),
            dtype=v4,
        )
        org = scene_origin[s]
        inv = scene_inv_voxel[s]
        o = grid_strides(nx, ny, nz)
        for b in range(b0, b1):
            q = body_quat[w * num_bodies + b]  # (w, x, y, z), unit
            qw = q[0]
            x = q[1]
            y = q[2]
            z = q[3]
            rot = wp.mat33(
                1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - qw * z), 2.0 * (x * z + qw * y),
                2.0 * (x * y + qw * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - qw * x),
                2.0 * (x * z - qw * y), 2.0 * (y * z + qw * x), 1.0 - 2.0 * (x * x + y * y),
            )  # fmt: skip
            pos = body_pos[w * num_bodies + b]
            best = float(wp.inf)
            for g in range(body_start[b], body_start[b + 1]):
                k0 = group_start[g]
                k1 = group_start[g + 1]
                off = offset[g]
                if use_cull != 0:  # d at the bounding-sphere centre (outside the grid: distance to the grid box)
                    u = (pos + rot * centre[g] - org) * inv
                    if not (wp.isfinite(u[0]) and wp.isfinite(u[1]) and wp.isfinite(u[2])):
                        k1 = k0  # a non-finite pose touches nothing
                    else:
                        ex = wp.max(wp.max(-u[0], u[0] - float(nx)), 0.0)
                        ey = wp.max(wp.max(-u[1], u[1] - float(ny)), 0.0)
                        ez = wp.max(wp.max(-u[2], u[2] - float(nz)), 0.0)
                        d = wp.sqrt(ex * ex + ey * ey + ez * ez) / inv
                        if d == 0.0:
                            d = trilinear_d(sd, u, nx, ny, nz, o)
                        if d >= cull[g]:
                            k1 = k0
                for k in range(k0, k1):
                    u = (pos + rot * points[k] - org) * inv
                    if grid_contains(u, nx, ny, nz):  # also False for NaN: a non-finite point is clear
                        best = wp.min(best, trilinear_d(sd, u, nx, ny, nz, o) - off)
            out[w * num_bodies + b] = best

    return min_sdf


__all__ = ["BodyPoints", "min_sdf_kernel"]
