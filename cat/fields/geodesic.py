# ruff: noqa: UP018  (Warp kernels need int(0)/float(0.0) to declare mutable locals)
"""Geodesic distance to a goal through free space: a 3-D Eikonal solve |∇T| = 1 on the voxel grid.

One discretisation (second-order upwind, 6-neighbour, Sethian 1999 §9): along each axis the upwind
neighbour value ``T1`` enters as ``(T − T1)² / h²``, or, when the next voxel along the same direction is
also known with ``T2 ≤ T1``, as ``(9/4)(T − (4 T1 − T2)/3)² / h²``. Voxels within
``FieldCfg.goal_init_radius`` voxels of the goal (and visible from it) start at their exact Euclidean
distance, which removes the point-source error of the first steps. Two solvers share that update:

* ``"fmm"`` — fast marching in a *single* Warp thread with a circular bucket queue of width h/16
  (an "untidy" priority queue, Yatziv et al. 2006: O(1) push/pop instead of a heap's cache-missing
  O(log N); measured ~3× faster here at unchanged accuracy). Tentative values use the first-order
  update, each accepted voxel gets the second-order one. The right choice on the CPU, where a Warp
  launch runs on one core anyway.
* ``"iterative"`` — parallel Jacobi relaxation until no value changes (a fast-iterative-method style
  scheme), one thread per voxel; the choice on CUDA. Converges to the same values within float tolerance.

Blocked voxels (obstacles) and free voxels that the front never reaches are ``+inf``.
"""

from __future__ import annotations

import logging
import threading

import numpy as np
import warp as wp

from cat.fields._wp import get_device
from cat.fields.grid import Grid

log = logging.getLogger(__name__)

_INF = 1.0e20
PAD = 2
"""Solver arrays are padded by 2 blocked voxels per side: no bounds checks in the stencils."""
_NUM_BUCKETS = 256
_BUCKETS_PER_VOXEL = 16.0
# voxel states (uint8 flag array): blocked (obstacle / padding), unknown, tentative (queued), accepted
_BLOCKED = 0
_FAR_STATE = 1
_TRIAL = 2
_DONE = 3


@wp.func
def _axis_term(T: wp.array(dtype=float), idx: int, s: int) -> wp.vec2:
    """Upwind term along one axis (stride ``s``) as (coefficient a, value b); b = INF when inactive."""
    tm = T[idx - s]
    tp = T[idx + s]
    t1 = tm
    t2 = T[idx - 2 * s]
    if tp < tm:
        t1 = tp
        t2 = T[idx + 2 * s]
    if t1 >= float(0.5 * _INF):
        return wp.vec2(1.0, float(_INF))
    if t2 <= t1:
        return wp.vec2(2.25, (4.0 * t1 - t2) / 3.0)
    return wp.vec2(1.0, t1)


@wp.func
def _solve(T: wp.array(dtype=float), idx: int, sx: int, sy: int, h: float) -> float:
    """Second-order upwind Eikonal update of padded voxel ``idx`` from the known values in ``T``."""
    t0 = _axis_term(T, idx, sx)
    t1 = _axis_term(T, idx, sy)
    t2 = _axis_term(T, idx, 1)
    a0 = t0[0]
    b0 = t0[1]
    a1 = t1[0]
    b1 = t1[1]
    a2 = t2[0]
    b2 = t2[1]
    if b1 < b0:
        ta = a0
        tb = b0
        a0 = a1
        b0 = b1
        a1 = ta
        b1 = tb
    if b2 < b1:
        ta = a1
        tb = b1
        a1 = a2
        b1 = b2
        a2 = ta
        b2 = tb
    if b1 < b0:
        ta = a0
        tb = b0
        a0 = a1
        b0 = b1
        a1 = ta
        b1 = tb
    if b0 >= float(0.5 * _INF):
        return float(_INF)
    t = b0 + h / wp.sqrt(a0)
    if t > b1:
        sa = a0 + a1
        sb = a0 * b0 + a1 * b1
        sc = a0 * b0 * b0 + a1 * b1 * b1 - h * h
        disc = sb * sb - sa * sc
        if disc >= 0.0:
            t = (sb + wp.sqrt(disc)) / sa
            if t > b2:
                sa3 = sa + a2
                sb3 = sb + a2 * b2
                sc3 = sc + a2 * b2 * b2
                disc3 = sb3 * sb3 - sa3 * sc3
                if disc3 >= 0.0:
                    t = (sb3 + wp.sqrt(disc3)) / sa3
    return t


@wp.func
def _solve1(T: wp.array(dtype=float), idx: int, sx: int, sy: int, h: float) -> float:
    """First-order upwind update (cheap): used for tentative values."""
    b0 = wp.min(T[idx - sx], T[idx + sx])
    b1 = wp.min(T[idx - sy], T[idx + sy])
    b2 = wp.min(T[idx - 1], T[idx + 1])
    lo = wp.min(b0, b1)
    hi = wp.max(b0, b1)
    c0 = wp.min(lo, b2)
    c2 = wp.max(hi, b2)
    c1 = wp.max(lo, wp.min(hi, b2))
    t = c0 + h
    if t > c1:
        d = c0 - c1
        t = 0.5 * (c0 + c1 + wp.sqrt(2.0 * h * h - d * d))
        if t > c2:
            s3 = c0 + c1 + c2
            q3 = c0 * c0 + c1 * c1 + c2 * c2
            t = (s3 + wp.sqrt(wp.max(s3 * s3 - 3.0 * (q3 - h * h), 0.0))) / 3.0
    return t


@wp.kernel
def _fmm_kernel(
    T: wp.array(dtype=float),
    flag: wp.array(dtype=wp.uint8),
    seeds: wp.array(dtype=int),
    head: wp.array(dtype=int),
    node: wp.array(dtype=int),
    sx: int,
    sy: int,
    h: float,
    inv_delta: float,
    second_order: int,
    overflow: wp.array(dtype=int),
):
    """Whole fast march in one thread with a circular bucket queue (untidy priority queue).

    ``T`` holds the current values (seeds exact and accepted on entry, INF where unknown). Tentative
    values come from the cheap first-order update; when a voxel is accepted its final value is the
    second-order update from its (by then accepted) neighbours. Bucket width is ``1/inv_delta`` (h/16):
    voxels are accepted in order of T up to that width, which perturbs the result far below the
    discretisation error while making push/pop O(1). Entries are lazy: a voxel re-pushed into a lower
    bucket leaves a stale entry that is skipped when popped. 256 buckets (``& 255``)."""
    nb_buckets = head.shape[0]
    cap = node.shape[0] // 2
    for b in range(nb_buckets):
        head[b] = -1
    top = int(0)
    live = int(0)
    cb = int(0)
    ns = seeds.shape[0]
    s = int(0)
    idx = int(0)
    while True:
        if s < ns:
            idx = seeds[s]
            s += 1
        else:
            if live == 0:
                break
            while head[cb & 255] < 0:
                cb += 1
            slot = cb & 255
            nd = head[slot]
            head[slot] = node[2 * nd + 1]
            live -= 1
            idx = node[2 * nd]
            if flag[idx] != wp.uint8(_TRIAL):
                continue
            flag[idx] = wp.uint8(_DONE)
            if second_order != 0:
                # final value: the second-order update from the (now mostly accepted) neighbours
                T[idx] = wp.min(T[idx], _solve(T, idx, sx, sy, h))
        for nb in range(6):
            off = int(1)
            if nb < 2:
                off = sx
            elif nb < 4:
                off = sy
            if nb % 2 == 0:
                off = -off
            m = idx + off
            fm = flag[m]
            if fm == wp.uint8(_FAR_STATE) or fm == wp.uint8(_TRIAL):
                tn = _solve1(T, m, sx, sy, h)
                told = T[m]
                if tn < told:
                    T[m] = tn
                    kb = wp.clamp(int(tn * inv_delta), cb, cb + nb_buckets - 1)
                    # a tentative voxel whose bucket does not change keeps its queue entry (the
                    # order inside a bucket is arbitrary anyway): no new node
                    if fm == wp.uint8(_FAR_STATE) or kb < wp.max(int(told * inv_delta), cb):
                        if top >= cap:
                            overflow[0] = 1
                            return
                        flag[m] = wp.uint8(_TRIAL)
                        slot = kb & 255
                        node[2 * top] = m
                        node[2 * top + 1] = head[slot]
                        head[slot] = top
                        top += 1
                        live += 1


@wp.kernel
def _jacobi_kernel(
    T_in: wp.array(dtype=float),
    T_out: wp.array(dtype=float),
    flag: wp.array(dtype=wp.uint8),
    sx: int,
    sy: int,
    h: float,
    tol: float,
    changed: wp.array(dtype=int),
):
    """One parallel relaxation sweep over the padded grid: T_out = min(T_in, update(T_in))."""
    idx = wp.tid()
    t_old = T_in[idx]
    t_new = t_old
    if flag[idx] == wp.uint8(_FAR_STATE):
        t = _solve(T_in, idx, sx, sy, h)
        if t < t_old:
            t_new = t
            if t_old - t > tol * wp.max(t, h):
                wp.atomic_add(changed, 0, 1)
    T_out[idx] = t_new


def goal_seeds(free: np.ndarray, grid: Grid, goal, radius_vox: float) -> tuple[np.ndarray, np.ndarray]:
    """Free voxels near ``goal`` with a clear straight line to it, and their exact distances.

    Raises ValueError if the goal lies outside the grid box or inside an obstacle voxel."""
    goal = np.asarray(goal, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(goal)):
        raise ValueError(f"goal must be finite, got {goal}")
    if not grid.contains(goal):
        raise ValueError(f"goal {goal.tolist()} is outside the grid box [{list(grid.origin)}, {grid.upper.tolist()}]")
    gi = np.minimum(grid.world_to_index(goal), np.asarray(grid.shape) - 1)
    if not free[tuple(gi)]:
        raise ValueError(f"goal {goal.tolist()} is inside an obstacle (voxel {gi.tolist()} is blocked)")
    r = int(np.ceil(radius_vox)) + 1
    lo = np.maximum(gi - r, 0)
    hi = np.minimum(gi + r + 1, grid.shape)
    idx = np.stack(np.meshgrid(*[np.arange(lo[a], hi[a]) for a in range(3)], indexing="ij"), -1).reshape(-1, 3)
    centres = grid.index_to_world(idx)
    dist = np.linalg.norm(centres - goal, axis=1)
    keep = (dist <= radius_vox * grid.voxel) | np.all(idx == gi, axis=1)
    idx, centres, dist = idx[keep], centres[keep], dist[keep]
    # line of sight: sample the segment goal → centre every quarter voxel
    ts = np.linspace(0.0, 1.0, int(np.ceil(radius_vox * 4)) + 2)
    pts = goal + ts[None, :, None] * (centres - goal)[:, None, :]
    pidx = np.clip(grid.world_to_index(pts), 0, np.asarray(grid.shape) - 1)
    visible = free[pidx[..., 0], pidx[..., 1], pidx[..., 2]].all(axis=1)
    idx, dist = idx[visible], dist[visible]
    lin = np.ravel_multi_index(tuple(idx.T), grid.shape)
    return lin.astype(np.int32), dist.astype(np.float32)


def padded_shape(grid: Grid) -> tuple[int, int, int]:
    return tuple(int(n) + 2 * PAD for n in grid.shape)


def unpad(a: np.ndarray, grid: Grid) -> np.ndarray:
    """Interior (grid.shape) view of a flat padded solver array."""
    return a.reshape(padded_shape(grid))[PAD:-PAD, PAD:-PAD, PAD:-PAD]


def geodesic_padded_wp(
    free_np: np.ndarray,
    grid: Grid,
    goal,
    device,
    radius_vox: float = 4.0,
    method: str = "auto",
    max_iters: int | None = None,
) -> wp.array:
    """Geodesic distance (m) as a flat *padded* Warp float array (≥ 1e19: unreachable or blocked)."""
    if method == "auto":
        method = "iterative" if device.is_cuda else "fmm"
    if method not in ("fmm", "iterative"):
        raise ValueError(f"unknown geodesic method {method!r} (fmm | iterative | auto)")
    if not 0.0 <= radius_vox <= _NUM_BUCKETS / _BUCKETS_PER_VOXEL - 3.0:
        raise ValueError(f"goal_init_radius must be in [0, {_NUM_BUCKETS / _BUCKETS_PER_VOXEL - 3.0}] voxels")
    seeds, seed_d = goal_seeds(free_np, grid, goal, radius_vox)
    pshape = padded_shape(grid)
    n = int(np.prod(pshape))
    sx, sy = pshape[1] * pshape[2], pshape[2]
    flag_np = np.zeros(pshape, dtype=np.uint8)
    flag_np[PAD:-PAD, PAD:-PAD, PAD:-PAD] = free_np.astype(np.uint8) * _FAR_STATE
    flag_np = flag_np.reshape(-1)
    seeds_p = np.ravel_multi_index(tuple(s + PAD for s in np.unravel_index(seeds, grid.shape)), pshape)
    flag_np[seeds_p] = _DONE
    T_np = np.full(n, _INF, dtype=np.float32)
    T_np[seeds_p] = seed_d
    T = wp.array(T_np, dtype=float, device=device)
    flag = wp.array(flag_np, dtype=wp.uint8, device=device)
    h = float(grid.voxel)
    if method == "fmm":
        ws = _FmmWorkspace.get(n, device)
        seeds_wp = wp.array(seeds_p.astype(np.int32), dtype=int, device=device)
        inputs = [T, flag, seeds_wp, ws["head"], ws["node"], sx, sy, h]
        wp.launch(_fmm_kernel, dim=1, inputs=[*inputs, _BUCKETS_PER_VOXEL / h, 1, ws["overflow"]], device=device)
        if int(ws["overflow"].numpy()[0]):  # cannot happen (capacity bound); guard against silent garbage
            raise RuntimeError("fast marching queue overflow")
        return T
    T2 = wp.clone(T)
    changed = wp.zeros(1, dtype=int, device=device)
    max_iters = max_iters or 8 * sum(grid.shape)
    for it in range(0, max_iters, 2):
        changed.zero_()
        for src, dst in ((T, T2), (T2, T)):
            wp.launch(_jacobi_kernel, dim=n, inputs=[src, dst, flag, sx, sy, h, 1e-6, changed], device=device)
        if it % 8 == 6 and int(changed.numpy()[0]) == 0:
            break
    else:
        log.warning("iterative geodesic did not converge in %d sweeps", max_iters)
    return T


class _FmmWorkspace:
    """Bucket-queue storage, cached per (padded size, device)."""

    _local = threading.local()  # per thread: concurrent builds must not share scratch arrays

    @classmethod
    def get(cls, n: int, device) -> dict:
        key = (n, str(device))
        cache = getattr(cls._local, "cache", {})
        ws = cache.get(key)
        if ws is None:
            cap = 6 * n + 1  # a voxel is pushed at most once per accepted neighbour
            ws = {
                "head": wp.empty(_NUM_BUCKETS, dtype=int, device=device),
                "node": wp.empty(2 * cap, dtype=int, device=device),
                "overflow": wp.zeros(1, dtype=int, device=device),
            }
            cls._local.cache = {key: ws}  # keep only the latest shape
        return ws


def geodesic_distance(
    occupancy,
    grid: Grid,
    goal,
    radius_vox: float = 4.0,
    method: str = "auto",
    device: str | None = None,
) -> np.ndarray:
    """Geodesic distance (m) from every voxel centre to ``goal`` avoiding occupied voxels (+inf: none)."""
    from cat.fields.sdf import check_occupancy

    dev = get_device(device)
    free_np = check_occupancy(occupancy, grid) == 0
    T = unpad(geodesic_padded_wp(free_np, grid, goal, dev, radius_vox, method).numpy(), grid)
    return np.where(T >= 0.5 * _INF, np.inf, T).astype(np.float32)
