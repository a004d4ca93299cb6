# ruff: noqa: UP018  (Warp kernels need int(0)/float(0.0) to declare mutable locals)
"""Signed distance fields on a :class:`Grid` (Warp kernels).

Sign convention: d > 0 in free space, d < 0 inside obstacles, |d| in metres.

* Occupancy grid → SDF: exact Euclidean distance transform between voxel centres (Felzenszwalb &
  Huttenlocher's separable lower-envelope EDT, one Warp thread per grid row, 3 launches). Voxels are
  cubes, so the surface lies on the faces between free and occupied voxels, half a voxel from either
  centre: ``d = edt(free → nearest occupied centre) − voxel/2`` for a free voxel and
  ``d = −(edt(occupied → nearest free centre) − voxel/2)`` for an occupied one. Space outside the grid
  counts as free; with no obstacle at all every voxel gets ``+FAR``.
* Triangle mesh → SDF: exact point–triangle distance (``wp.Mesh`` BVH query) with the generalised
  winding-number sign: a point is inside where the winding number is ≥ 0.5, which also gives a sensible
  sign for non-watertight or self-intersecting meshes (open boxes, floors as single quads).
"""

from __future__ import annotations

import logging
import threading

import numpy as np
import trimesh
import warp as wp

from cat.fields._wp import get_device, to_wp
from cat.fields.grid import Grid

log = logging.getLogger(__name__)

FAR = 1.0e4
"""Distance (m) reported when no surface of the relevant kind exists in the grid."""
_INF = 1.0e20


@wp.kernel
def _edt_scan_kernel(
    occ: wp.array3d(dtype=wp.uint8),
    out_sq: wp.array3d(dtype=float),
    in_sq: wp.array3d(dtype=float),
):
    """1-D squared distance along z (the contiguous axis) to the nearest occupied / free voxel."""
    i, j = wp.tid()
    nz = occ.shape[2]
    last_occ = float(-_INF)
    last_free = float(-_INF)
    for k in range(nz):
        kf = float(k)
        if occ[i, j, k] != wp.uint8(0):
            last_occ = kf
        else:
            last_free = kf
        out_sq[i, j, k] = (kf - last_occ) * (kf - last_occ)
        in_sq[i, j, k] = (kf - last_free) * (kf - last_free)
    last_occ = float(_INF)
    last_free = float(_INF)
    for kk in range(nz):
        k = nz - 1 - kk
        kf = float(k)
        if occ[i, j, k] != wp.uint8(0):
            last_occ = kf
        else:
            last_free = kf
        out_sq[i, j, k] = wp.min(out_sq[i, j, k], (last_occ - kf) * (last_occ - kf))
        in_sq[i, j, k] = wp.min(in_sq[i, j, k], (last_free - kf) * (last_free - kf))


@wp.func
def _envelope(
    f: wp.array(dtype=float),
    g: wp.array(dtype=float),
    base: int,
    stride: int,
    n: int,
    v: wp.array(dtype=int),
    z: wp.array(dtype=float),
    w: int,
):
    """Felzenszwalb–Huttenlocher lower envelope of parabolas: g(t) = min_q (t − q)² + f(q).

    Row samples are ``f[base + t * stride]``; ``v[w:]``, ``z[w:]`` are this row's scratch."""
    kk = _hull(f, base, stride, n, v, z, w)
    if kk < 0:
        for t in range(n):
            g[base + t * stride] = float(_INF)
        return
    c = int(0)
    for t in range(n):
        tf = float(t)
        while z[w + c + 1] < tf:
            c += 1
        p = v[w + c]
        g[base + t * stride] = (tf - float(p)) * (tf - float(p)) + f[base + p * stride]


@wp.func
def _hull(
    f: wp.array(dtype=float),
    base: int,
    stride: int,
    n: int,
    v: wp.array(dtype=int),
    z: wp.array(dtype=float),
    w: int,
) -> int:
    """Lower envelope of the finite parabolas of a row; returns the index of the last one (−1: none)."""
    kk = int(-1)
    for q in range(n):
        fq = f[base + q * stride]
        if fq >= float(0.5 * _INF):
            continue
        qf = float(q)
        hq = fq + qf * qf
        while kk >= 0:
            p = v[w + kk]
            pf = float(p)
            sp = (hq - (f[base + p * stride] + pf * pf)) / (2.0 * (qf - pf))
            if sp <= z[w + kk]:
                kk -= 1
            else:
                break
        kk += 1
        v[w + kk] = q
        if kk == 0:
            z[w] = float(-_INF)
        else:
            p = v[w + kk - 1]
            pf = float(p)
            z[w + kk] = (hq - (f[base + p * stride] + pf * pf)) / (2.0 * (qf - pf))
        z[w + kk + 1] = float(_INF)
    return kk


@wp.func
def _envelope_signed(
    f: wp.array(dtype=float),
    base: int,
    stride: int,
    n: int,
    v: wp.array(dtype=int),
    z: wp.array(dtype=float),
    w: int,
    occ: wp.array(dtype=wp.uint8),
    want: wp.uint8,
    sign: float,
    voxel: float,
    sdf: wp.array(dtype=float),
):
    """Last pass: envelope, then write ``sign·(√g − ½)·voxel`` at the voxels whose occupancy is ``want``."""
    kk = _hull(f, base, stride, n, v, z, w)
    c = int(0)
    for t in range(n):
        i = base + t * stride
        if occ[i] == want:
            if kk < 0:
                sdf[i] = sign * FAR
            else:
                tf = float(t)
                while z[w + c + 1] < tf:
                    c += 1
                p = v[w + c]
                sdf[i] = sign * (wp.sqrt((tf - float(p)) * (tf - float(p)) + f[base + p * stride]) - 0.5) * voxel


@wp.kernel
def _edt_pass_kernel(
    axis: int,
    ny: int,
    nz: int,
    n: int,
    f_out: wp.array(dtype=float),
    f_in: wp.array(dtype=float),
    g_out: wp.array(dtype=float),
    g_in: wp.array(dtype=float),
    v: wp.array(dtype=int),
    z: wp.array(dtype=float),
    occ: wp.array(dtype=wp.uint8),
    voxel: float,
    sdf: wp.array(dtype=float),
):
    """One separable EDT pass along ``axis`` for the outside and inside transforms.

    Axis 1 (y) writes squared distances to ``g_*``; axis 0 (x) is the last pass and writes the SDF."""
    r, s = wp.tid()
    base = int(0)
    stride = int(0)
    if axis == 1:
        base = r * ny * nz + s
        stride = nz
    else:
        base = r * nz + s
        stride = ny * nz
    w = (r * nz + s) * (n + 2)
    # the inside transform is positive only at occupied voxels: rows without any are all zero
    has_inside = int(0)
    for t in range(n):
        if f_in[base + t * stride] > 0.0:
            has_inside = 1
            break
    if axis == 1:
        _envelope(f_out, g_out, base, stride, n, v, z, w)
        if has_inside != 0:
            _envelope(f_in, g_in, base, stride, n, v, z, w)
        else:
            for t in range(n):
                g_in[base + t * stride] = 0.0
    else:
        _envelope_signed(f_out, base, stride, n, v, z, w, occ, wp.uint8(0), 1.0, voxel, sdf)
        if has_inside != 0:
            _envelope_signed(f_in, base, stride, n, v, z, w, occ, wp.uint8(1), -1.0, voxel, sdf)


class _EdtWorkspace:
    """Scratch arrays for the EDT, cached per (shape, device) so rebuilds do not reallocate."""

    _local = threading.local()  # per thread: concurrent builds must not share scratch arrays

    @classmethod
    def get(cls, shape: tuple[int, int, int], device) -> dict:
        key = (shape, str(device))
        cache = getattr(cls._local, "cache", {})
        ws = cache.get(key)
        if ws is None:
            nx, ny, nz = shape
            rows = max(nx, ny) * nz
            ws = {name: wp.empty(shape, dtype=float, device=device) for name in ("a_out", "a_in", "b_out", "b_in")}
            ws["v"] = wp.empty(rows * (max(nx, ny) + 2), dtype=int, device=device)
            ws["z"] = wp.empty(rows * (max(nx, ny) + 2), dtype=float, device=device)
            cls._local.cache = {key: ws}  # keep only the latest shape
        return ws


def sdf_from_occupancy_wp(occ: wp.array, grid: Grid, sdf: wp.array | None = None) -> wp.array:
    """Exact signed EDT of a uint8 occupancy Warp array (1 = occupied); returns a float32 Warp array."""
    device = occ.device
    nx, ny, nz = grid.shape
    ws = _EdtWorkspace.get(grid.shape, device)
    flat = {k: ws[k].flatten() for k in ("a_out", "a_in", "b_out", "b_in")}
    if sdf is None:
        sdf = wp.empty(grid.shape, dtype=float, device=device)
    scratch = (ws["v"], ws["z"])
    occ_f, sdf_f, h = occ.flatten(), sdf.flatten(), grid.voxel
    wp.launch(_edt_scan_kernel, dim=(nx, ny), inputs=[occ, ws["a_out"], ws["a_in"]], device=device)
    # along y: rows indexed by (x, z); along x: rows indexed by (y, z)
    wp.launch(
        _edt_pass_kernel,
        dim=(nx, nz),
        inputs=[1, ny, nz, ny, flat["a_out"], flat["a_in"], flat["b_out"], flat["b_in"], *scratch, occ_f, h, sdf_f],
        device=device,
    )
    wp.launch(
        _edt_pass_kernel,
        dim=(ny, nz),
        inputs=[0, ny, nz, nx, flat["b_out"], flat["b_in"], flat["a_out"], flat["a_in"], *scratch, occ_f, h, sdf_f],
        device=device,
    )
    return sdf


def check_occupancy(occ, grid: Grid) -> np.ndarray:
    """Validate an occupancy array against ``grid`` and return it as a C-contiguous uint8 array."""
    occ = np.asarray(occ)
    if occ.shape != grid.shape:
        raise ValueError(f"occupancy shape {occ.shape} does not match grid shape {grid.shape}")
    if occ.dtype != np.bool_:
        if not np.issubdtype(occ.dtype, np.number):
            raise TypeError(f"occupancy must be boolean or numeric, got {occ.dtype}")
        if np.issubdtype(occ.dtype, np.floating) and not np.all(np.isfinite(occ)):
            raise ValueError("occupancy contains NaN or inf")
    return np.ascontiguousarray(occ != 0, dtype=np.uint8)


def sdf_from_occupancy(occ, grid: Grid, device: str | None = None) -> np.ndarray:
    """Signed distance (m) at voxel centres of a boolean occupancy grid (True = obstacle)."""
    dev = get_device(device)
    occ_wp = to_wp(check_occupancy(occ, grid), wp.uint8, dev)
    return sdf_from_occupancy_wp(occ_wp, grid).numpy()


def occupancy_from_points(points, grid: Grid) -> np.ndarray:
    """Boolean occupancy marking every voxel that contains at least one point (others ignored)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(pts)):
        raise ValueError("point cloud contains NaN or inf")
    idx = grid.world_to_index(pts)
    keep = np.all((idx >= 0) & (idx < np.asarray(grid.shape)), axis=1)
    occ = np.zeros(grid.shape, dtype=bool)
    occ[tuple(idx[keep].T)] = True
    return occ


def sdf_from_points(points, grid: Grid, device: str | None = None) -> np.ndarray:
    """SDF of a point cloud voxelised on ``grid`` (live perception: point cloud → occupancy → EDT)."""
    return sdf_from_occupancy(occupancy_from_points(points, grid), grid, device)


@wp.kernel
def _mesh_sdf_kernel(
    mesh: wp.uint64,
    origin: wp.vec3,
    voxel: float,
    max_dist: float,
    sdf: wp.array3d(dtype=float),
):
    i, j, k = wp.tid()
    p = origin + voxel * wp.vec3(float(i) + 0.5, float(j) + 0.5, float(k) + 0.5)
    q = wp.mesh_query_point_sign_winding_number(mesh, p, max_dist, 2.0, 0.5)
    if q.result:
        c = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
        sdf[i, j, k] = q.sign * wp.length(p - c)
    else:
        sdf[i, j, k] = FAR


@wp.kernel
def _mesh_points_kernel(
    mesh: wp.uint64,
    pts: wp.array(dtype=wp.vec3),
    max_dist: float,
    out: wp.array(dtype=float),
):
    t = wp.tid()
    p = pts[t]
    q = wp.mesh_query_point_sign_winding_number(mesh, p, max_dist, 2.0, 0.5)
    if q.result:
        out[t] = q.sign * wp.length(p - wp.mesh_eval_position(mesh, q.face, q.u, q.v))
    else:
        out[t] = FAR


def _wp_mesh(mesh: trimesh.Trimesh, device) -> wp.Mesh:
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"expected a trimesh.Trimesh, got {type(mesh).__name__}")
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise ValueError("obstacle mesh is empty (no faces)")
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    if not np.all(np.isfinite(verts)):
        raise ValueError("obstacle mesh has NaN or inf vertices")
    return wp.Mesh(
        points=wp.array(verts.astype(np.float32), dtype=wp.vec3, device=device),
        indices=wp.array(np.asarray(mesh.faces, dtype=np.int32).reshape(-1), dtype=int, device=device),
        support_winding_number=True,
    )


def sdf_from_mesh_wp(mesh: trimesh.Trimesh, grid: Grid, device) -> wp.array:
    """Exact signed distance of a triangle mesh at the voxel centres (winding number ≥ 0.5 = inside)."""
    wmesh = _wp_mesh(mesh, device)
    sdf = wp.empty(grid.shape, dtype=float, device=device)
    wp.launch(
        _mesh_sdf_kernel,
        dim=grid.shape,
        inputs=[wmesh.id, wp.vec3(*grid.origin), grid.voxel, float(FAR), sdf],
        device=device,
    )
    return sdf


def sdf_from_mesh(mesh: trimesh.Trimesh, grid: Grid, device: str | None = None) -> np.ndarray:
    """Signed distance (m) of a triangle mesh at the voxel centres of ``grid``."""
    return sdf_from_mesh_wp(mesh, grid, get_device(device)).numpy()


def mesh_sdf_at(mesh: trimesh.Trimesh, points, device: str | None = None, max_dist: float = FAR) -> np.ndarray:
    """Signed distance (m) of a triangle mesh at arbitrary points (M, 3); ``FAR`` where no surface lies within
    ``max_dist`` (a smaller bound makes the search cheaper)."""
    dev = get_device(device)
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    wmesh = _wp_mesh(mesh, dev)
    out = wp.empty(len(pts), dtype=float, device=dev)
    wp.launch(
        _mesh_points_kernel,
        dim=len(pts),
        inputs=[wmesh.id, wp.array(pts, dtype=wp.vec3, device=dev), float(max_dist), out],
        device=dev,
    )
    return out.numpy()
