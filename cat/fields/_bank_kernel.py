# ruff: noqa: UP018  (Warp kernels need int(0)/float(0.0) to declare mutable locals)
"""Warp kernel of the field-bank query: trilinear d, ∇d (stored once per scene) and F (stored per goal).

F is stored as float32 / float16 like d, or (the ``compact`` storage) as int8 mantissas with a shared exponent.

Storage is two flat buffers. A scene's block (``vec4``: d, ∇d) and a field's block (``vec3``: F) are found
from the buffer's 64-bit base address plus an int64 element offset (:func:`block_address`); inside a block
the index is at most one grid's voxel count. No index therefore wraps however many voxels the bank holds
(a single flat int32 index wraps past 2^31 voxels, ≈ 3,400 fields of 125×125×40).
"""

import functools
from typing import Any

import warp as wp

vec7 = wp.types.vector(length=7, dtype=wp.float32)
"""Query output per point: F (3), d, ∇d (3)."""


@wp.func
def block_address(ptr: wp.uint64, offset: wp.int64, elem_bytes: wp.int64) -> wp.uint64:
    """Address of element ``offset`` of a buffer starting at ``ptr`` (exact 64-bit arithmetic)."""
    return ptr + wp.uint64(offset) * wp.uint64(elem_bytes)


@wp.func
def grid_contains(u: wp.vec3, nx: int, ny: int, nz: int) -> bool:
    """Whether continuous grid index ``u`` lies in the ``nx × ny × nz`` grid's box (False for NaN)."""
    return u[0] >= 0.0 and u[1] >= 0.0 and u[2] >= 0.0 and u[0] <= float(nx) and u[1] <= float(ny) and u[2] <= float(nz)


@wp.func
def grid_strides(nx: int, ny: int, nz: int) -> wp.vec3i:
    """Flat-index steps to the next voxel along x, y, z; 0 on a one-voxel axis (its two corners coincide)."""
    return wp.vec3i(wp.where(nx > 1, ny * nz, 0), wp.where(ny > 1, nz, 0), wp.where(nz > 1, 1, 0))


@wp.func
def grid_cell(u: wp.vec3, nx: int, ny: int, nz: int):
    """The trilinear cell of continuous grid index ``u``: flat index of its lower corner and the fractions along
    x, y, z. Values sit at voxel centres; outside the centres' span the grid is clamped to its edge."""
    cx = wp.clamp(u[0] - 0.5, 0.0, float(nx - 1))
    cy = wp.clamp(u[1] - 0.5, 0.0, float(ny - 1))
    cz = wp.clamp(u[2] - 0.5, 0.0, float(nz - 1))
    i0 = wp.min(int(cx), wp.max(nx - 2, 0))
    j0 = wp.min(int(cy), wp.max(ny - 2, 0))
    k0 = wp.min(int(cz), wp.max(nz - 2, 0))
    return (i0 * ny + j0) * nz + k0, wp.vec3(cx - float(i0), cy - float(j0), cz - float(k0))


@wp.func
def trilinear(
    c000: Any, c001: Any, c010: Any, c011: Any, c100: Any, c101: Any, c110: Any, c111: Any, fr: wp.vec3
) -> Any:
    """Blend of a cell's eight corner values (``c<ijk>``: +x, +y, +z corner when 1) at fractions ``fr``
    (:func:`grid_cell`); for scalars and vectors alike."""
    gz = 1.0 - fr[2]
    s00 = gz * c000 + fr[2] * c001
    s01 = gz * c010 + fr[2] * c011
    s10 = gz * c100 + fr[2] * c101
    s11 = gz * c110 + fr[2] * c111
    gy = 1.0 - fr[1]
    return (1.0 - fr[0]) * (gy * s00 + fr[1] * s01) + fr[0] * (gy * s10 + fr[1] * s11)


@wp.kernel
def block_address_kernel(
    ptr: wp.uint64, offsets: wp.array(dtype=wp.int64), elem_bytes: wp.int64, out: wp.array(dtype=wp.uint64)
):
    """``out[i] = block_address(ptr, offsets[i], elem_bytes)`` (tests the arithmetic without memory reads)."""
    i = wp.tid()
    out[i] = block_address(ptr, offsets[i], elem_bytes)


@functools.cache
def query_kernel(scalar: type, goal_scalar: type) -> wp.Kernel:
    """The bank query for d, ∇d stored as ``scalar`` (``wp.float32`` or ``wp.float16``) and F as ``goal_scalar``:
    the same type, or ``wp.int8`` for 3 mantissas and a shared power-of-two exponent (the ``compact`` storage,
    ``cat.fields.bank.Storage``); math in float32."""
    shared_exponent = goal_scalar == wp.int8
    v4 = wp.types.vector(length=4, dtype=scalar)
    v3 = wp.types.vector(length=4, dtype=wp.int8) if shared_exponent else wp.types.vector(length=3, dtype=scalar)
    scene_bytes = wp.types.type_size_in_bytes(v4)
    goal_bytes = wp.types.type_size_in_bytes(v3)

    @wp.func
    def load_f(fd: wp.array(dtype=v3), i: int) -> wp.vec3:
        """F of voxel ``i`` in float32."""
        if wp.static(shared_exponent):
            q = fd[i]
            return wp.vec3(float(q[0]), float(q[1]), float(q[2])) * wp.pow(2.0, float(q[3]))
        else:
            return wp.vec3(fd[i])

    @wp.kernel(module="unique")
    def query(
        scene_ptr: wp.uint64,
        goal_ptr: wp.uint64,
        scene_offset: wp.array(dtype=wp.int64),
        scene_shape: wp.array(dtype=wp.vec3i),
        scene_origin: wp.array(dtype=wp.vec3),
        scene_inv_voxel: wp.array(dtype=wp.float32),
        field_scene: wp.array(dtype=wp.int32),
        field_offset: wp.array(dtype=wp.int64),
        field_idx: wp.array(dtype=wp.int32),
        points: wp.array(dtype=wp.vec3),
        links: int,
        out: wp.array(dtype=vec7),
        inside: wp.array(dtype=wp.bool),
    ):
        """One thread per (env, link): trilinear interpolation of F, d and ∇d at ``points[t]``."""
        t = wp.tid()
        f = field_idx[t / links]
        s = field_scene[f]
        shp = scene_shape[s]
        nx = shp[0]
        ny = shp[1]
        nz = shp[2]
        n = nx * ny * nz
        sd = wp.array(
            ptr=block_address(scene_ptr, scene_offset[s], wp.int64(wp.static(scene_bytes))), shape=(n,), dtype=v4
        )
        fd = wp.array(
            ptr=block_address(goal_ptr, field_offset[f], wp.int64(wp.static(goal_bytes))), shape=(n,), dtype=v3
        )
        u = (points[t] - scene_origin[s]) * scene_inv_voxel[s]
        if not (wp.isfinite(u[0]) and wp.isfinite(u[1]) and wp.isfinite(u[2])):
            u = wp.vec3(-1.0, -1.0, -1.0)  # NaN/inf point: grid corner value, inside = False
        inside[t] = grid_contains(u, nx, ny, nz)
        b, fr = grid_cell(u, nx, ny, nz)
        o = grid_strides(nx, ny, nz)
        x = o[0]
        y = o[1]
        z = o[2]
        sv = trilinear(
            wp.vec4(sd[b]), wp.vec4(sd[b + z]), wp.vec4(sd[b + y]), wp.vec4(sd[b + y + z]),
            wp.vec4(sd[b + x]), wp.vec4(sd[b + x + z]), wp.vec4(sd[b + x + y]), wp.vec4(sd[b + x + y + z]), fr,
        )  # fmt: skip
        fv = trilinear(
            load_f(fd, b), load_f(fd, b + z), load_f(fd, b + y), load_f(fd, b + y + z),
            load_f(fd, b + x), load_f(fd, b + x + z), load_f(fd, b + x + y), load_f(fd, b + x + y + z), fr,
        )  # fmt: skip
        out[t] = vec7(fv[0], fv[1], fv[2], sv[0], sv[1], sv[2], sv[3])

    return query
