# ruff: noqa: UP018  (Warp kernels need int(0)/float(0.0) to declare mutable locals)
"""HumanoidPF potential and force on a grid: U = η·geo + U_rep(d), F = −∇U (paper §III-A, eqs. 1–3).

``build_field`` runs the whole pipeline — SDF, geodesic distance, potential and force — as Warp kernels.
On the CPU the exact EDT (one core) and the fast march (one core) run concurrently in two threads.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field

import numpy as np
import trimesh
import warp as wp

from cat.fields import geodesic as geo_mod
from cat.fields import sdf as sdf_mod
from cat.fields._wp import get_device, run_concurrently, to_wp
from cat.fields.config import FieldCfg, cfg_from_dict, read_saved_header
from cat.fields.grid import Grid

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
CHANNELS = ("fx", "fy", "fz", "sdf", "gx", "gy", "gz", "geo")
"""Per-voxel channels of a field (and of a :class:`FieldBank`): F, d, ∇d, geodesic (extended)."""
NUM_CHANNELS = len(CHANNELS)
GEO_FILL = 1.0e3
"""Geodesic channel value (m) for blocked/unreachable voxels not adjacent to a reachable one."""


@wp.func
def _geo_grad(g0: float, gm: float, gp: float, h: float) -> float:
    """Derivative of the geodesic along one axis: central where both neighbours are reachable,
    one-sided where only one is (never across an obstacle), 0 where neither is."""
    lim = float(1.0e19)
    if g0 >= lim:
        return 0.0
    if gm < lim and gp < lim:
        return (gp - gm) / (2.0 * h)
    if gp < lim:
        return (gp - g0) / h
    if gm < lim:
        return (g0 - gm) / h
    return 0.0


@wp.func
def _sdf_grad(sdf: wp.array3d(dtype=float), i: int, j: int, k: int, h: float) -> wp.vec3:
    """Central differences of d (one-sided at the grid boundary)."""
    nx = sdf.shape[0]
    ny = sdf.shape[1]
    nz = sdf.shape[2]
    i0 = wp.max(i - 1, 0)
    i1 = wp.min(i + 1, nx - 1)
    j0 = wp.max(j - 1, 0)
    j1 = wp.min(j + 1, ny - 1)
    k0 = wp.max(k - 1, 0)
    k1 = wp.min(k + 1, nz - 1)
    gx = float(0.0)
    gy = float(0.0)
    gz = float(0.0)
    if i1 > i0:
        gx = (sdf[i1, j, k] - sdf[i0, j, k]) / (float(i1 - i0) * h)
    if j1 > j0:
        gy = (sdf[i, j1, k] - sdf[i, j0, k]) / (float(j1 - j0) * h)
    if k1 > k0:
        gz = (sdf[i, j, k1] - sdf[i, j, k0]) / (float(k1 - k0) * h)
    return wp.vec3(gx, gy, gz)


@wp.kernel
def _field_kernel(
    sdf: wp.array3d(dtype=float),
    geo: wp.array(dtype=float),
    i_start: int,
    h: float,
    eta: float,
    xi: float,
    d0: float,
    d_min: float,
    geo_fill: float,
    out: wp.array4d(dtype=float),
    potential: wp.array3d(dtype=float),
):
    """One thread per (i, j) row (i from ``i_start``): U, F = −η∇geo − U_rep'(d)∇d, ∇d, extended geodesic."""
    ii, j = wp.tid()
    i = ii + i_start
    ny = sdf.shape[1]
    nz = sdf.shape[2]
    pz = nz + 4
    sx = (ny + 4) * pz
    lim = float(1.0e19)
    for k in range(nz):
        p = ((i + 2) * (ny + 4) + (j + 2)) * pz + (k + 2)
        g0 = geo[p]
        gxm = geo[p - sx]
        gxp = geo[p + sx]
        gym = geo[p - pz]
        gyp = geo[p + pz]
        gzm = geo[p - 1]
        gzp = geo[p + 1]
        d = sdf[i, j, k]
        gd = _sdf_grad(sdf, i, j, k, h)
        grad_geo = wp.vec3(_geo_grad(g0, gxm, gxp, h), _geo_grad(g0, gym, gyp, h), _geo_grad(g0, gzm, gzp, h))
        f = -eta * grad_geo
        u_rep = float(0.0)
        if d < d0:
            dc = wp.max(d, d_min)
            s = 1.0 / dc - 1.0 / d0
            u_rep = 0.5 * xi * s * s
            f = f + (xi * s / (dc * dc)) * gd
        if g0 < lim:
            potential[i, j, k] = eta * g0 + u_rep
        else:
            potential[i, j, k] = wp.inf
            # extend the geodesic one voxel into blocked space so interpolation at surfaces stays sane
            gn = wp.min(wp.min(wp.min(gxm, gxp), wp.min(gym, gyp)), wp.min(gzm, gzp))
            if gn < lim:
                g0 = gn + h
            else:
                g0 = geo_fill
        out[i, j, k, 0] = f[0]
        out[i, j, k, 1] = f[1]
        out[i, j, k, 2] = f[2]
        out[i, j, k, 3] = d
        out[i, j, k, 4] = gd[0]
        out[i, j, k, 5] = gd[1]
        out[i, j, k, 6] = gd[2]
        out[i, j, k, 7] = g0


@dataclass
class Field:
    """A built HumanoidPF on one grid for one goal (numpy float32 arrays, C-ordered (nx, ny, nz, ...))."""

    grid: Grid
    goal: np.ndarray
    data: np.ndarray
    """(nx, ny, nz, 8) channels :data:`CHANNELS`: F (3), d, ∇d (3), geodesic extended by one voxel."""
    geodesic: np.ndarray
    """(nx, ny, nz) geodesic distance to the goal (m); +inf where blocked or unreachable."""
    potential: np.ndarray
    """(nx, ny, nz) U = η·geo + U_rep(d); +inf where the geodesic is."""
    cfg: FieldCfg = field(default_factory=FieldCfg)

    @property
    def force(self) -> np.ndarray:
        """F = −∇U, (nx, ny, nz, 3); finite everywhere."""
        return self.data[..., 0:3]

    @property
    def sdf(self) -> np.ndarray:
        """Signed distance d (m), (nx, ny, nz); positive in free space."""
        return self.data[..., 3]

    @property
    def grad_sdf(self) -> np.ndarray:
        """∇d by central differences, (nx, ny, nz, 3)."""
        return self.data[..., 4:7]

    @property
    def reachable(self) -> np.ndarray:
        return np.isfinite(self.geodesic)

    def save(self, path) -> None:
        """Write an ``.npz`` with the arrays, grid metadata, goal, constants and a format version."""
        np.savez_compressed(
            path,
            format_version=np.int64(FORMAT_VERSION),
            origin=np.asarray(self.grid.origin, dtype=np.float64),
            voxel=np.float64(self.grid.voxel),
            shape=np.asarray(self.grid.shape, dtype=np.int64),
            goal=np.asarray(self.goal, dtype=np.float64),
            data=self.data,
            geodesic=self.geodesic,
            potential=self.potential,
            cfg=np.asarray(json.dumps(self.cfg.to_dict())),
            channels=np.asarray(",".join(CHANNELS)),
        )

    @classmethod
    def load(cls, path, cfg: FieldCfg | None = None) -> Field:
        """Read a field written by :meth:`save`. With ``cfg``, a field built under other build constants
        (:data:`cat.fields.config.BUILD_KEYS`) raises :class:`cat.fields.config.StaleFieldError`."""
        with np.load(path, allow_pickle=False) as z:
            saved, grid = read_saved_header(z, path, "format_version", FORMAT_VERSION, cfg)
            grid = Grid(*grid)
            data = (z["goal"].copy(), z["data"].copy(), z["geodesic"].copy(), z["potential"].copy())
            return cls(grid, *data, cfg_from_dict(saved))


def mesh_free_mask(sdf: np.ndarray, grid: Grid) -> np.ndarray:
    """Free voxels for the geodesic of a mesh scene: centre farther than half a voxel from the surface
    (and outside). Any surface crossing the segment between two face-adjacent centres lies within
    h/2 of one of them, so even a zero-thickness wall blocks the 6-neighbour fast march."""
    return sdf > 0.5 * grid.voxel


_LOADED: set[str] = set()


def _load_modules(dev) -> None:
    """Compile/load the kernel modules once before two threads launch from them."""
    if str(dev) not in _LOADED:
        wp.load_module(sdf_mod, device=dev)
        wp.load_module(geo_mod, device=dev)
        _LOADED.add(str(dev))


def _check_goal(goal) -> np.ndarray:
    g = np.asarray(goal, dtype=np.float64)
    if g.shape != (3,):
        raise ValueError(f"goal must be a 3-vector, got shape {g.shape}")
    if not np.all(np.isfinite(g)):
        raise ValueError(f"goal must be finite, got {g.tolist()}")
    return g


def _sdf_and_free(obstacles, grid: Grid, dev) -> tuple[wp.array, np.ndarray, wp.array | None]:
    """SDF (Warp) and free mask (numpy) of a mesh or occupancy; the occupancy SDF is left to the caller
    (returned as the uint8 occupancy array to transform) so it can overlap with a fast march."""
    if isinstance(obstacles, trimesh.Trimesh):
        sdf_wp = sdf_mod.sdf_from_mesh_wp(obstacles, grid, dev)
        return sdf_wp, mesh_free_mask(sdf_wp.numpy(), grid), None
    arr = np.asarray(obstacles)
    if arr.ndim == 2 and arr.shape[1] == 3 and np.issubdtype(arr.dtype, np.floating):
        obstacles = sdf_mod.occupancy_from_points(arr, grid)  # point cloud (live perception)
    occ = sdf_mod.check_occupancy(obstacles, grid)
    return wp.empty(grid.shape, dtype=float, device=dev), occ == 0, to_wp(occ, wp.uint8, dev)


def _assemble(sdf_wp: wp.array, geo_wp: wp.array, grid: Grid, goal, cfg: FieldCfg, dev, parts: int) -> Field:
    """Potential, force and channels from SDF and geodesic (``parts`` concurrent launches on the CPU)."""
    out = wp.empty((*grid.shape, NUM_CHANNELS), dtype=float, device=dev)
    pot = wp.empty(grid.shape, dtype=float, device=dev)
    nx = grid.shape[0]
    parts = parts if dev.is_cpu and nx >= 16 else 1

    def launch(p: int) -> None:
        i0, i1 = nx * p // parts, nx * (p + 1) // parts
        wp.launch(
            _field_kernel,
            dim=(i1 - i0, grid.shape[1]),
            inputs=[sdf_wp, geo_wp, i0, grid.voxel, cfg.eta, cfg.xi, cfg.d0, cfg.d_min, GEO_FILL, out, pot],
            device=dev,
        )

    run_concurrently(*[lambda p=p: launch(p) for p in range(parts)])
    geo = geo_mod.unpad(geo_wp.numpy(), grid)
    geo = np.where(geo >= 1.0e19, np.inf, geo).astype(np.float32)
    return Field(grid, np.asarray(goal, dtype=np.float64), out.numpy(), geo, pot.numpy(), cfg)


def build_field(
    obstacles,
    grid: Grid,
    goal,
    cfg: FieldCfg | None = None,
    device: str | None = None,
    method: str = "auto",
) -> Field:
    """Build HumanoidPF for ``goal`` from a ``trimesh.Trimesh``, a boolean occupancy of ``grid.shape``
    or an (M, 3) float point cloud (voxelised: a voxel containing a point is occupied).

    Raises ValueError for a goal outside the grid or inside an obstacle, a mismatched occupancy shape,
    an empty mesh or NaN input."""
    cfg = cfg or FieldCfg()
    goal = _check_goal(goal)
    dev = get_device(device)
    sdf_wp, free_np, occ_wp = _sdf_and_free(obstacles, grid, dev)

    def march() -> wp.array:
        return geo_mod.geodesic_padded_wp(free_np, grid, goal, dev, cfg.goal_init_radius, method)

    if occ_wp is None:
        geo_wp = march()
    elif dev.is_cpu:
        # both solvers are single-core Warp launches that release the GIL: overlap them
        _load_modules(dev)
        geo_wp = run_concurrently(march, lambda: sdf_mod.sdf_from_occupancy_wp(occ_wp, grid, sdf_wp))[0]
    else:
        sdf_mod.sdf_from_occupancy_wp(occ_wp, grid, sdf_wp)
        geo_wp = march()
    return _assemble(sdf_wp, geo_wp, grid, goal, cfg, dev, parts=2)


def build_fields(
    obstacles,
    grid: Grid,
    goals,
    cfg: FieldCfg | None = None,
    device: str | None = None,
    method: str = "auto",
) -> list[Field]:
    """Fields of one scene for several goals (a training bank): the SDF is computed once, and on the
    CPU two goals are marched concurrently. Same errors as :func:`build_field` (for any goal)."""
    cfg = cfg or FieldCfg()
    goals = [_check_goal(g) for g in goals]
    dev = get_device(device)
    sdf_wp, free_np, occ_wp = _sdf_and_free(obstacles, grid, dev)
    if occ_wp is not None:
        sdf_mod.sdf_from_occupancy_wp(occ_wp, grid, sdf_wp)
    for g in goals:  # fail fast, before any march
        geo_mod.goal_seeds(free_np, grid, g, cfg.goal_init_radius)
    _load_modules(dev)

    def one(g: np.ndarray) -> Field:
        geo_wp = geo_mod.geodesic_padded_wp(free_np, grid, g, dev, cfg.goal_init_radius, method)
        return _assemble(sdf_wp, geo_wp, grid, g, cfg, dev, parts=1)

    step = 2 if dev.is_cpu else 1
    fields: list[Field] = []
    for i in range(0, len(goals), step):
        fields += run_concurrently(*[lambda g=g: one(g) for g in goals[i : i + step]])
    return fields
