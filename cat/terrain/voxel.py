"""Voxel grids for scenes: occupancy from meshes, humanoid traversability, reachability, re-meshing.

One convention everywhere: voxel ``(i, j, k)`` has its centre at
``origin + (idx + 0.5) * voxel``. Reachability is a 2.5-D model of a humanoid: a floor column is
*passable* when, above some free voxel no higher than ``step_height`` (a hurdle it can step over), there
is a free vertical run of at least ``headroom`` (room for a crouched G1), and, if the floor itself is
covered, the low obstacle is at most ``hurdle_depth`` deep (within half of it of usable floor).
Impassable columns are dilated by ``body_radius`` and the rest is flood-filled in 2-D from the start
(``scipy.ndimage``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import ndimage

log = logging.getLogger(__name__)

VOXEL = 0.04


@dataclass(frozen=True)
class GridSpec:
    """Axis-aligned voxel grid: ``origin`` is the min corner, voxel centres at origin + (i+½)·voxel."""

    origin: tuple[float, float, float]
    voxel: float
    shape: tuple[int, int, int]

    @staticmethod
    def from_bounds(bounds: np.ndarray, voxel: float = VOXEL) -> GridSpec:
        """Grid covering ``bounds`` ((2, 3) min/max corners) with ``voxel`` spacing (size rounded)."""
        b = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
        shape = tuple(int(n) for n in np.maximum(np.round((b[1] - b[0]) / voxel), 1).astype(int))
        return GridSpec(tuple(float(v) for v in b[0]), float(voxel), shape)

    def axes(self) -> list[np.ndarray]:
        """Voxel-centre coordinates along x, y, z."""
        return [self.origin[a] + (np.arange(self.shape[a]) + 0.5) * self.voxel for a in range(3)]

    def centers(self, sl: tuple[slice, slice, slice] | None = None) -> np.ndarray:
        """Voxel centres (..., 3) of the whole grid or of the index box ``sl``."""
        ax = self.axes()
        if sl is not None:
            ax = [a[s] for a, s in zip(ax, sl, strict=True)]
        return np.stack(np.meshgrid(*ax, indexing="ij"), axis=-1)

    def index(self, points: np.ndarray) -> np.ndarray:
        """Integer voxel index of each point (unclipped)."""
        p = np.asarray(points, dtype=np.float64)
        return np.floor((p - np.asarray(self.origin)) / self.voxel).astype(int)

    def box_slice(self, lo: np.ndarray, hi: np.ndarray) -> tuple[slice, slice, slice] | None:
        """Index box of voxels whose centres may lie in [lo, hi]; None when it misses the grid."""
        i0 = np.maximum(np.floor((np.asarray(lo) - self.origin) / self.voxel - 0.5).astype(int), 0)
        i1 = np.minimum(np.ceil((np.asarray(hi) - self.origin) / self.voxel + 0.5).astype(int), self.shape)
        if np.any(i1 <= i0):
            return None
        return tuple(slice(int(a), int(b)) for a, b in zip(i0, i1, strict=True))

    def to_dict(self) -> dict:
        return {"origin": list(self.origin), "voxel": self.voxel, "shape": list(self.shape)}


# ----------------------------------------------------------------------------------------- occupancy
def occupancy(mesh: trimesh.Trimesh, grid: GridSpec, unseen: list[np.ndarray] | None = None) -> np.ndarray:
    """Boolean occupancy of ``grid`` (voxel centre inside any mesh component).

    Each connected component is handled on its own bounding box: convex ones by half-space tests,
    closed non-convex ones by ray-parity ``contains``, open surfaces by marking the voxels they cross and
    filling enclosed holes. Overlapping components are therefore a union (a winding number > 0.5).
    ``unseen`` (a list) receives the bounds of components inside the grid that hold no voxel centre: thinner
    than the grid resolves, they are missing from the occupancy and everything built on it (fields, maps) while
    the physics still collides with them. (A thin feature of a larger component is not detected.)
    """
    occ = np.zeros(grid.shape, dtype=bool)
    if len(mesh.faces) == 0:
        return occ
    for comp in mesh.split(only_watertight=False):
        sl = grid.box_slice(*comp.bounds)
        if sl is None:
            continue
        pts = grid.centers(sl)
        flat = pts.reshape(-1, 3)
        if comp.is_watertight and comp.is_convex:
            inside = _inside_convex(comp, flat)
        elif comp.is_watertight and comp.is_volume:
            inside = comp.contains(flat)
        else:
            inside = _surface_voxels(comp, grid, sl)
            occ[sl] |= inside
            continue
        occ[sl] |= inside.reshape(pts.shape[:3])
        if unseen is not None and not inside.any():
            unseen.append(comp.bounds.copy())
    return occ


def _inside_convex(comp: trimesh.Trimesh, pts: np.ndarray) -> np.ndarray:
    normals = comp.face_normals
    offsets = np.einsum("ij,ij->i", normals, comp.triangles[:, 0])
    # Unique planes keep the test cheap for triangulated boxes and prisms.
    planes = np.unique(np.round(np.c_[normals, offsets], 9), axis=0)
    return np.all(pts @ planes[:, :3].T <= planes[:, 3] + 1e-9, axis=1)


def _surface_voxels(comp: trimesh.Trimesh, grid: GridSpec, sl: tuple[slice, ...]) -> np.ndarray:
    """Voxels crossed by an open surface, plus the cavities they enclose."""
    shape = tuple(s.stop - s.start for s in sl)
    mask = np.zeros(shape, dtype=bool)
    count = max(int(comp.area / (0.25 * grid.voxel) ** 2), 1000)
    pts, _ = trimesh.sample.sample_surface(comp, count, seed=0)
    pts = np.vstack([pts, comp.vertices])
    idx = grid.index(pts) - np.array([s.start for s in sl])
    ok = np.all((idx >= 0) & (idx < shape), axis=1)
    mask[tuple(idx[ok].T)] = True
    return ndimage.binary_fill_holes(mask)


# ------------------------------------------------------------------------------------ traversability
@dataclass
class ReachCfg:
    """Humanoid size used by the reachability test (G1: pelvis ~0.8 m, torso depth ~0.2 m)."""

    step_height: float = 0.30  # highest obstacle top the robot can hurdle (hurdle tops ≤ 0.25 m)
    headroom: float = 0.90  # free height a crouched G1 needs (ceiling bottoms ≥ 1.0 m)
    body_radius: float = 0.10  # lateral clearance (side-stepping through a slit: half torso depth)
    hurdle_depth: float = 0.40  # deepest low obstacle one stride clears without touching it


def passable_columns(occ: np.ndarray, grid: GridSpec, cfg: ReachCfg | None = None) -> np.ndarray:
    """(nx, ny) mask of floor columns a humanoid could stand in or step through (before dilation)."""
    cfg = cfg or ReachCfg()
    free = ~occ
    nz = occ.shape[2]
    run = np.zeros(occ.shape, dtype=np.int32)  # free voxels stacked upward from each voxel
    acc = np.zeros(occ.shape[:2], dtype=np.int32)
    for k in range(nz - 1, -1, -1):
        acc = np.where(free[:, :, k], acc + 1, 0)
        run[:, :, k] = acc
    k_step = min(max(int(np.floor(cfg.step_height / grid.voxel)), 0), nz - 1)
    need = min(int(np.ceil(cfg.headroom / grid.voxel - 1e-6)), nz)
    stand = run[:, :, 0] >= need  # a foot can go down here
    step = np.any(run[:, :, : k_step + 1] >= need, axis=2)  # a leg can swing over a low obstacle here
    if not stand.any():
        return stand
    # a low obstacle is only stepped over if it is at most hurdle_depth deep: every column of it lies
    # within half that depth of ground the feet can use
    depth = ndimage.distance_transform_edt(~stand) * grid.voxel
    return step & (stand | (depth <= cfg.hurdle_depth / 2 + 0.5 * grid.voxel))


def walkable(occ: np.ndarray, grid: GridSpec, cfg: ReachCfg | None = None) -> np.ndarray:
    """Passable columns eroded by the body radius (the centre of the robot may be there)."""
    cfg = cfg or ReachCfg()
    blocked = ~passable_columns(occ, grid, cfg)
    r = cfg.body_radius / grid.voxel
    n = int(np.ceil(r))
    yy, xx = np.mgrid[-n : n + 1, -n : n + 1]
    disk = (xx**2 + yy**2) <= r**2 + 1e-9
    return ~ndimage.binary_dilation(blocked, structure=disk)


def reachable_mask(
    occ: np.ndarray,
    grid: GridSpec,
    start: np.ndarray,
    cfg: ReachCfg | None = None,
    allowed: np.ndarray | None = None,
) -> np.ndarray:
    """(nx, ny) columns connected (8-neighbour flood fill) to the start's column through walkable space.

    ``allowed`` optionally restricts the walkable columns (e.g. to the floor of a house).
    """
    walk = walkable(occ, grid, cfg)
    if allowed is not None:
        walk &= allowed
    i, j = grid.index(np.asarray(start, dtype=np.float64))[:2]
    if not (0 <= i < grid.shape[0] and 0 <= j < grid.shape[1]) or not walk[i, j]:
        return np.zeros_like(walk)
    labels, _ = ndimage.label(walk, structure=np.ones((3, 3), dtype=bool))
    return labels == labels[i, j]


def reachable(
    occ: np.ndarray,
    grid: GridSpec,
    start: np.ndarray,
    goals: np.ndarray,
    cfg: ReachCfg | None = None,
    allowed: np.ndarray | None = None,
) -> np.ndarray:
    """Boolean per goal: reachable from ``start`` through walkable space."""
    mask = reachable_mask(occ, grid, start, cfg, allowed)
    goals = np.atleast_2d(np.asarray(goals, dtype=np.float64))
    idx = grid.index(goals)[:, :2]
    ok = np.all((idx >= 0) & (idx < np.array(grid.shape[:2])), axis=1)
    out = np.zeros(len(goals), dtype=bool)
    out[ok] = mask[idx[ok, 0], idx[ok, 1]]
    return out


def free_volume_fraction(occ: np.ndarray) -> float:
    """Fraction of voxels not occupied (difficulty proxy: falls as scenes get harder)."""
    return float(1.0 - occ.mean())


# ------------------------------------------------------------------------------------- re-meshing
def occupancy_to_mesh(occ: np.ndarray, grid: GridSpec, smooth: float = 0.0) -> trimesh.Trimesh:
    """Closed surface of an occupancy by marching cubes (scikit-image) on a zero-padded volume.

    Padding closes the surface where obstacles touch the grid boundary (e.g. the floor), so the result is
    watertight. ``smooth`` (voxels) applies a Gaussian blur before the 0.5 iso-level to soften stairs.
    """
    from skimage.measure import marching_cubes

    if not occ.any():
        return trimesh.Trimesh()
    vol = np.pad(occ.astype(np.float32), 1)
    if smooth > 0:
        vol = ndimage.gaussian_filter(vol, smooth)
        vol[0, :, :] = vol[-1, :, :] = vol[:, 0, :] = vol[:, -1, :] = vol[:, :, 0] = vol[:, :, -1] = 0
    verts, faces, _, _ = marching_cubes(vol, level=0.5, spacing=(grid.voxel,) * 3)
    # padded index p has centre origin + (p - 1 + 0.5) * voxel
    verts = verts + np.asarray(grid.origin) - 0.5 * grid.voxel
    mesh = trimesh.Trimesh(verts, faces[:, ::-1], process=True)
    mesh.fix_normals()
    return mesh


def rasterize_xy(triangles: np.ndarray, grid: GridSpec) -> np.ndarray:
    """(nx, ny) mask of columns whose centre lies in the xy projection of any triangle (T, 3, 3)."""
    mask = np.zeros(grid.shape[:2], dtype=bool)
    x, y, _ = grid.axes()
    for tri in np.asarray(triangles, dtype=np.float64)[:, :, :2]:
        lo, hi = tri.min(0), tri.max(0)
        i0, i1 = np.searchsorted(x, lo[0]), np.searchsorted(x, hi[0], side="right")
        j0, j1 = np.searchsorted(y, lo[1]), np.searchsorted(y, hi[1], side="right")
        if i1 <= i0 or j1 <= j0:
            continue
        px, py = np.meshgrid(x[i0:i1], y[j0:j1], indexing="ij")
        a, b, c = tri
        den = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1])
        if abs(den) < 1e-12:
            continue
        l1 = ((b[1] - c[1]) * (px - c[0]) + (c[0] - b[0]) * (py - c[1])) / den
        l2 = ((c[1] - a[1]) * (px - c[0]) + (a[0] - c[0]) * (py - c[1])) / den
        mask[i0:i1, j0:j1] |= (l1 >= -1e-9) & (l2 >= -1e-9) & (1 - l1 - l2 >= -1e-9)
    return mask


def erode_xy(mask: np.ndarray, radius: float, voxel: float) -> np.ndarray:
    """Erode a 2-D mask by a disk of ``radius`` metres (outside the grid counts as not in the mask)."""
    r = radius / voxel
    n = int(np.ceil(r))
    yy, xx = np.mgrid[-n : n + 1, -n : n + 1]
    return ndimage.binary_erosion(mask, structure=(xx**2 + yy**2) <= r**2 + 1e-9, border_value=0)


def standing_mask(occ: np.ndarray, voxel: float, height: float, radius: float) -> np.ndarray:
    """(nx, ny) columns free from the floor to ``height`` with ``radius`` of free columns around them: where a
    humanoid stands upright, arms out (training starts, ``cat.envs.episodes``; test-set starts, ``cat.eval``)."""
    need = min(int(np.ceil(height / voxel - 1e-6)), occ.shape[2])
    free_col = ~occ[:, :, :need].any(axis=2)
    return erode_xy(free_col, radius, voxel) if radius > 0 else free_col
