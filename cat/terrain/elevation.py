"""2.5-D views of a scene's occupancy for perception baselines: a two-layer elevation map and a coarse voxel grid.

Per (x, y) column of the occupancy grid the obstacles form vertical runs of occupied voxels. A run whose
underside is below ``split_height`` stands on (or near) the floor and is *ground*: the ground layer is the top of
the highest such run (0, the floor, where there is none). A run whose underside is at or above ``split_height``
hangs overhead: the overhead layer is the underside of the lowest such run (``cap`` where there is none). Runs are
disjoint and ordered in z, so ground < overhead in every column.

Both layers and the occupancy can be pooled over a square of ``pool`` voxels either side of each column, so a
map cell reports the highest ground / lowest overhead / any occupancy within its own footprint rather than at
one point.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from cat.terrain.voxel import GridSpec


def elevation_layers(
    occ: np.ndarray, grid: GridSpec, split_height: float, cap: float, pool: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """(ground, overhead) float32 (X, Y) height maps [m, world z] of boolean occupancy ``occ`` (X, Y, Z)."""
    occ = np.asarray(occ, dtype=bool)
    nz = occ.shape[2]
    z0, v = grid.origin[2], grid.voxel
    k = np.arange(nz)
    starts = occ & ~np.concatenate((np.zeros_like(occ[..., :1]), occ[..., :-1]), axis=-1)
    run_start = np.maximum.accumulate(np.where(starts, k, -1), axis=-1)  # index of the run each voxel belongs to
    bottom = z0 + run_start * v  # underside of that run
    is_ground = occ & (bottom < split_height)
    is_over = occ & (bottom >= split_height)
    top = z0 + (k + 1) * v
    ground = np.where(is_ground, top, 0.0).max(axis=-1)
    ground = np.maximum(ground, 0.0)
    overhead = np.where(is_over, z0 + k * v, np.inf).min(axis=-1)
    overhead = np.minimum(overhead, cap)
    if pool > 0:
        size = 2 * pool + 1
        ground = ndimage.maximum_filter(ground, size=size, mode="nearest")
        overhead = ndimage.minimum_filter(overhead, size=size, mode="nearest")
    return ground.astype(np.float32), overhead.astype(np.float32)


def pooled_occupancy(occ: np.ndarray, pool: int = 0) -> np.ndarray:
    """Occupancy dilated by ``pool`` voxels in every direction (a coarse cell is occupied if any voxel of its
    footprint is)."""
    occ = np.asarray(occ, dtype=bool)
    if pool <= 0:
        return occ.copy()
    return ndimage.binary_dilation(occ, structure=np.ones((2 * pool + 1,) * 3, dtype=bool))


def pool_voxels(resolution: float, voxel: float) -> int:
    """Voxels either side of a column that fall inside a cell of ``resolution`` centred on it."""
    return max(int(np.floor(0.5 * resolution / voxel)), 0)
