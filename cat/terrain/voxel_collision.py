"""Collision geometry straight from an occupancy grid: height-field tiles plus boxes, in milliseconds.

For scenes that *are* voxels (procedural obstacles, re-meshed crops) the occupancy is the ground truth the
SDF and the fields are built from, so the physics should match it rather than a convex decomposition of
the marching-cubes mesh (coacd: 45–55 s per procedural scene and centimetres of deviation). Each column of
the grid holds runs of occupied voxels:

* the run touching the floor becomes a **floor height field** and the run touching the grid top a
  **ceiling height field** (hung upside down; left out where it ends above ``z_reach``): exact per column,
  whatever the Perlin noise on the tops and sides. MuJoCo interpolates between samples, so samples are
  taken every half voxel and each takes the maximum of the voxels it touches: the solid is never smaller
  than the voxels and at most half a voxel larger (at the foot of a step). Fields are cut into tiles
  (``tile`` voxels) so that MuJoCo's bounding boxes stay tight; tiles with nothing in them are left out.
* runs in between (**overhangs**: tilted boxes, ledges) are covered by axis-aligned boxes grown greedily
  over the occupied voxels plus at most ``inflate`` voxels of the free space next to them, which keeps the
  box count in the tens to hundreds.

Two fills keep that count down where no robot can tell the difference: a free gap of at most ``crack``
voxels between an overhang and the floor or ceiling run is filled, and so is a gap that lies entirely
above ``z_reach`` (no G1 link gets there). The deviations are therefore: ≤ ½ voxel outward on floor and
ceiling runs, ≤ ``inflate`` voxels outward on overhangs, ≤ ``crack`` voxels in the filled cracks, never
inward.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from cat.terrain.voxel import GridSpec


@dataclass
class VoxelCollisionCfg:
    """How occupancy becomes MuJoCo geoms (see the module docstring for the error each setting allows)."""

    tile: int = 16  # height-field tile edge (voxels): tight bounding boxes, empty tiles dropped
    inflate: int = 1  # overhang boxes may cover free voxels this close (6-neighbour steps) to the solid
    crack: int = 2  # free gaps of at most this many voxels between an overhang and a floor/ceiling run are filled
    z_reach: float = 1.45  # m; gaps entirely above this height are filled (G1 standing: head ≤ 1.34 m)
    floor_gap: float = 0.01  # m; free height-field samples sit this far below the floor (no contact with feet)
    base: float = 0.05  # m; height-field base thickness (MuJoCo needs one; outside the scene)


@dataclass
class HeightTile:
    """One height-field tile: ``heights`` (2·ni+1, 2·nj+1) metres above the floor (or below the grid top)."""

    lower: np.ndarray  # (2,) world xy of the tile's lower corner
    size: np.ndarray  # (2,) world xy extent
    heights: np.ndarray


@dataclass
class VoxelParts:
    """Collision geometry of an occupancy grid: floor and ceiling height-field tiles and boxes (lo, hi)."""

    floor: list[HeightTile]
    ceiling: list[HeightTile]
    boxes: np.ndarray  # (B, 2, 3) world lower / upper corners
    floor_z: float  # world z of the floor (grid bottom)
    top_z: float  # world z of the grid top

    @property
    def num_geoms(self) -> int:
        return len(self.floor) + len(self.ceiling) + len(self.boxes)


def _end_runs(occ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column: length of the occupied run from the bottom and from the top (voxels)."""
    nz = occ.shape[2]
    full = occ.all(axis=2)
    bottom = np.where(occ[..., 0], np.argmax(~occ, axis=2), 0)
    top = np.where(occ[..., -1], np.argmax(~occ[..., ::-1], axis=2), 0)
    bottom[full] = nz
    top[full] = nz
    return bottom, top


def _middle(occ: np.ndarray, bottom: np.ndarray, top: np.ndarray) -> np.ndarray:
    k = np.arange(occ.shape[2])
    return occ & (k >= bottom[..., None]) & (k < (occ.shape[2] - top)[..., None])


def fill_gaps(occ: np.ndarray, grid: GridSpec, cfg: VoxelCollisionCfg) -> np.ndarray:
    """``occ`` with the cracks (≤ ``crack`` voxels) and the gaps above ``z_reach`` between overhangs and the
    floor or ceiling runs filled, repeated until nothing changes."""
    o = occ.copy()
    nz = o.shape[2]
    k = np.arange(nz)
    k_reach = int(np.ceil((cfg.z_reach - grid.origin[2]) / grid.voxel - 1e-9))
    for _ in range(nz):
        bottom, top = _end_runs(o)
        mid = _middle(o, bottom, top)
        has = mid.any(axis=2)
        low = np.where(has, np.argmax(mid, axis=2), nz)  # lowest overhang voxel
        high = np.where(has, nz - 1 - np.argmax(mid[..., ::-1], axis=2), -1)  # highest
        gap_lo, gap_hi = low - bottom, (nz - top) - 1 - high
        fill_lo = has & (gap_lo > 0) & (gap_lo <= cfg.crack)
        fill_hi = has & (gap_hi > 0) & ((gap_hi <= cfg.crack) | (high + 1 >= k_reach))
        if not (fill_lo.any() or fill_hi.any()):
            break
        o |= fill_lo[..., None] & (k >= bottom[..., None]) & (k < low[..., None])
        o |= fill_hi[..., None] & (k > high[..., None]) & (k < (nz - top)[..., None])
    return o


def cover_boxes(allowed: np.ndarray, need: np.ndarray) -> np.ndarray:
    """Greedy boxes (B, 2, 3) of voxel index bounds [lo, hi) inside ``allowed`` covering every ``need`` voxel:
    from each uncovered voxel (in index order) grow along z as far as allowed, then +y, then +x."""
    need = need.copy()
    nx, ny, nz = allowed.shape
    out = []
    for i, j, k in np.argwhere(need):
        if not need[i, j, k]:
            continue
        k0, k1 = k, k + 1
        while k0 > 0 and allowed[i, j, k0 - 1]:
            k0 -= 1
        while k1 < nz and allowed[i, j, k1]:
            k1 += 1
        j1 = j + 1
        while j1 < ny and allowed[i, j1, k0:k1].all():
            j1 += 1
        i1 = i + 1
        while i1 < nx and allowed[i1, j:j1, k0:k1].all():
            i1 += 1
        need[i:i1, j:j1, k0:k1] = False
        out.append(((i, j, k0), (i1, j1, k1)))
    return np.asarray(out, dtype=np.int64).reshape(-1, 2, 3)


def _samples(h: np.ndarray) -> np.ndarray:
    """Column heights (ni, nj) → samples every half voxel (2ni+1, 2nj+1), each the max of the voxels it
    touches (so MuJoCo's interpolation never cuts into a voxel)."""
    u = np.repeat(np.repeat(h, 2, axis=0), 2, axis=1)
    p = np.pad(u, 1, constant_values=0.0)
    return np.maximum(np.maximum(p[:-1, :-1], p[:-1, 1:]), np.maximum(p[1:, :-1], p[1:, 1:]))


def _tiles(heights: np.ndarray, grid: GridSpec, tile: int) -> list[HeightTile]:
    s = _samples(heights)
    nx, ny = heights.shape
    org, h = np.asarray(grid.origin[:2], dtype=np.float64), grid.voxel
    out = []
    for i0 in range(0, nx, tile):
        for j0 in range(0, ny, tile):
            i1, j1 = min(i0 + tile, nx), min(j0 + tile, ny)
            block = s[2 * i0 : 2 * i1 + 1, 2 * j0 : 2 * j1 + 1]
            solid = np.argwhere(block > 0.0)
            if not len(solid):
                continue
            # crop to the solid and one ring of zero samples (the foot of its slope): the same surface, and a
            # bounding box that hugs it, so limbs over the free floor of the tile are not tested against it
            lo = np.maximum(solid.min(axis=0) - 1, 0)
            hi = np.minimum(solid.max(axis=0) + 2, block.shape)
            lower = org + (2 * np.array([i0, j0]) + lo) * (h / 2)
            out.append(HeightTile(lower, (hi - lo - 1) * (h / 2), block[lo[0] : hi[0], lo[1] : hi[1]].copy()))
    return out


def voxel_parts(occ: np.ndarray, grid: GridSpec, cfg: VoxelCollisionCfg | None = None) -> VoxelParts:
    """Height-field tiles and overhang boxes for a boolean occupancy on ``grid`` (see the module docstring)."""
    cfg = cfg or VoxelCollisionCfg()
    occ = np.asarray(occ, dtype=bool)
    if occ.shape != tuple(grid.shape):
        raise ValueError(f"occupancy shape {occ.shape} does not match the grid {tuple(grid.shape)}")
    h = grid.voxel
    filled = fill_gaps(occ, grid, cfg)
    bottom, top = _end_runs(filled)
    overhang = _middle(filled, bottom, top)
    allowed = filled.copy()
    for _ in range(cfg.inflate):  # free voxels within `inflate` face steps of the solid
        grown = allowed.copy()
        grown[1:] |= allowed[:-1]
        grown[:-1] |= allowed[1:]
        grown[:, 1:] |= allowed[:, :-1]
        grown[:, :-1] |= allowed[:, 1:]
        grown[..., 1:] |= allowed[..., :-1]
        grown[..., :-1] |= allowed[..., 1:]
        allowed = grown
    idx = cover_boxes(allowed, overhang)
    org = np.asarray(grid.origin, dtype=np.float64)
    boxes = org + idx.astype(np.float64) * h
    floor_z, top_z = float(org[2]), float(org[2] + grid.shape[2] * h)
    depth = np.where(bottom == grid.shape[2], 0, top) * h  # full columns: in the floor field only
    depth[top_z - depth >= cfg.z_reach] = 0.0  # ceiling runs that end above z_reach cannot be touched
    return VoxelParts(_tiles(bottom * h, grid, cfg.tile), _tiles(depth, grid, cfg.tile), boxes, floor_z, top_z)


def add_voxel_parts_to_spec(
    spec: mujoco.MjSpec,
    parts: VoxelParts,
    body: mujoco.MjsBody,
    prefix: str,
    conaffinity: int,
    rgba: tuple[float, float, float, float],
    cfg: VoxelCollisionCfg | None = None,
) -> int:
    """Add the tiles (as ``mjGEOM_HFIELD``) and boxes to ``body``; returns the geom count."""
    cfg = cfg or VoxelCollisionCfg()
    common = dict(contype=0, conaffinity=conaffinity, condim=3, group=1, rgba=list(rgba))
    n = 0
    for kind, tiles in (("floor", parts.floor), ("ceiling", parts.ceiling)):
        for t in tiles:
            elev = np.where(t.heights > 0.0, t.heights + cfg.floor_gap, 0.0)
            # MuJoCo rescales height-field data to [0, 1] by its min and max: lift the geom by the minimum
            # and deepen the base by as much, so the surface stays where it is and the solid reaches down.
            low, high = float(elev.min()), float(elev.max())
            span = max(high - low, 1e-6)
            if kind == "ceiling":  # hung upside down: a half turn about x flips local y
                elev = elev[:, ::-1]
                z, quat = parts.top_z + cfg.floor_gap - low, [0.0, 1.0, 0.0, 0.0]
            else:
                z, quat = parts.floor_z - cfg.floor_gap + low, [1.0, 0.0, 0.0, 0.0]
            rows = (elev.T - low) / span  # MuJoCo: rows along y, columns along x
            name = f"{prefix}{kind}_{n}"
            half = t.size / 2
            spec.add_hfield(
                name=name,
                nrow=rows.shape[0],
                ncol=rows.shape[1],
                size=[float(half[0]), float(half[1]), span, low + cfg.base],
                userdata=rows.ravel().tolist(),
            )
            pos = [float(t.lower[0] + half[0]), float(t.lower[1] + half[1]), z]
            body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=name, pos=pos, quat=quat, **common)
            n += 1
    for lo, hi in parts.boxes:
        body.add_geom(
            name=f"{prefix}box_{n}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=((hi - lo) / 2).tolist(),
            pos=((hi + lo) / 2).tolist(),
            **common,
        )
        n += 1
    return n
