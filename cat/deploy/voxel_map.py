# ruff: noqa: UP018  (Warp kernels need int(0)/float(0.0) to declare mutable locals)
"""Log-odds occupancy map in the world frame (OctoMap-like, dense) and the robot-centred field window.

Each scan updates the map once per voxel (as OctoMap's discrete scan insertion does): voxels a beam passes
through get ``l_miss``, the voxel of its return ``l_hit`` (hit wins over miss within one scan), clamped to
``[l_min, l_max]``. A voxel is occupied when its log-odds exceeds ``l_occupied``; never-observed voxels have
log-odds 0 and count as free, like the field's "outside the grid is free" rule. Returns below ``ground_z``
are the floor: they clear the beam's path but are not obstacles (the floor is never part of a scene's
obstacles, in training or here).

Beams are traversed exactly (Amanatides-Woo voxel walk) in a Warp kernel, one thread per beam.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import warp as wp

from cat.fields import Grid
from cat.fields._wp import get_device


@dataclass
class MapCfg:
    """Log-odds increments and clamps: OctoMap's defaults (hit p = 0.7, miss p = 0.4, clamp 0.12 / 0.97)."""

    voxel: float = 0.04
    """Edge of a map voxel [m] (= the field grid's voxel, so the window is a plain copy)."""
    l_hit: float = 0.85
    """log(0.7 / 0.3): a return makes its voxel more likely occupied."""
    l_miss: float = -0.4
    """log(0.4 / 0.6): a beam passing through makes a voxel more likely free."""
    l_min: float = -2.0
    """Clamp (p = 0.12): a voxel seen free many times still turns occupied after ~3 hits (moving obstacles)."""
    l_max: float = 3.5
    """Clamp (p = 0.97): an occupied voxel turns free after ~10 beams through it."""
    l_occupied: float = 0.0
    """Occupied where log-odds > this (p > 0.5): one hit on an unknown voxel suffices."""
    ground_z: float = 0.06
    """Returns below this height [m] are floor: they clear space but are not obstacles (range noise 2 cm, 3σ)."""
    height: float = 1.4
    """Map height above the floor [m]: the field window's height (DESIGN §4)."""


@dataclass
class WindowCfg:
    """The robot-centred field window (DESIGN §4: 5.12 × 5.12 × 1.4 m at 0.04 m)."""

    shape: tuple[int, int, int] = (128, 128, 35)


@wp.func
def _dda_axis(p: float, d: float, cell: int) -> wp.vec3:
    """Amanatides-Woo set-up along one axis: (step -1/0/+1, t of the first cell boundary, t per cell)."""
    big = float(1.0e30)
    if d > 0.0:
        return wp.vec3(1.0, (float(cell + 1) - p) / d, 1.0 / d)
    if d < 0.0:
        return wp.vec3(-1.0, (float(cell) - p) / d, -1.0 / d)
    return wp.vec3(0.0, big, big)


@wp.kernel
def _trace_kernel(
    origin: wp.vec3,
    points: wp.array(dtype=wp.vec3),
    grid_origin: wp.vec3,
    inv_voxel: float,
    nx: int,
    ny: int,
    nz: int,
    ground_z: float,
    miss: wp.array3d(dtype=wp.uint8),
    hit: wp.array3d(dtype=wp.uint8),
):
    """One beam: mark the voxels it crosses (before its end voxel) as missed, its end voxel as hit."""
    r = wp.tid()
    p0 = (origin - grid_origin) * inv_voxel
    end = points[r]
    p1 = (end - grid_origin) * inv_voxel
    d = p1 - p0
    i = int(wp.floor(p0[0]))
    j = int(wp.floor(p0[1]))
    k = int(wp.floor(p0[2]))
    ie = int(wp.floor(p1[0]))
    je = int(wp.floor(p1[1]))
    ke = int(wp.floor(p1[2]))
    ax = _dda_axis(p0[0], d[0], i)
    ay = _dda_axis(p0[1], d[1], j)
    az = _dda_axis(p0[2], d[2], k)
    si = int(ax[0])
    sj = int(ay[0])
    sk = int(az[0])
    tx = ax[1]
    ty = ay[1]
    tz = az[1]
    dx = ax[2]
    dy = ay[2]
    dz = az[2]
    steps = wp.abs(ie - i) + wp.abs(je - j) + wp.abs(ke - k)
    for _s in range(steps):
        if i >= 0 and i < nx and j >= 0 and j < ny and k >= 0 and k < nz:
            miss[i, j, k] = wp.uint8(1)
        if tx <= ty and tx <= tz:
            i += si
            tx += dx
        elif ty <= tz:
            j += sj
            ty += dy
        else:
            k += sk
            tz += dz
    if end[2] >= ground_z and ie >= 0 and ie < nx and je >= 0 and je < ny and ke >= 0 and ke < nz:
        hit[ie, je, ke] = wp.uint8(1)


@wp.kernel
def _update_kernel(
    logodds: wp.array3d(dtype=float),
    miss: wp.array3d(dtype=wp.uint8),
    hit: wp.array3d(dtype=wp.uint8),
    l_hit: float,
    l_miss: float,
    l_min: float,
    l_max: float,
    i0: int,
    j0: int,
    k0: int,
):
    """Apply one scan's marks (hit wins) with clamping, and clear the marks; the launch covers the scan's box
    starting at voxel ``(i0, j0, k0)``."""
    ii, jj, kk = wp.tid()
    i = ii + i0
    j = jj + j0
    k = kk + k0
    if hit[i, j, k] != wp.uint8(0):
        logodds[i, j, k] = wp.min(logodds[i, j, k] + l_hit, l_max)
    elif miss[i, j, k] != wp.uint8(0):
        logodds[i, j, k] = wp.max(logodds[i, j, k] + l_miss, l_min)
    hit[i, j, k] = wp.uint8(0)
    miss[i, j, k] = wp.uint8(0)


def map_grid(lower_xy, upper_xy, cfg: MapCfg) -> Grid:
    """Map grid covering the xy rectangle, from the floor up to ``cfg.height``, voxel ``cfg.voxel``."""
    lo = np.array([lower_xy[0], lower_xy[1], 0.0])
    hi = np.array([upper_xy[0], upper_xy[1], cfg.height])
    return Grid.from_bounds(lo, hi, cfg.voxel)


class VoxelMap:
    """Dense log-odds grid in the world frame; ``integrate`` one scan at a time, ``window`` for the field.

    Thread-safe: a lock serialises integration and reads (the viewer reads while perception writes)."""

    def __init__(self, grid: Grid, cfg: MapCfg | None = None, device: str | None = "cpu"):
        self.cfg = cfg or MapCfg()
        if not np.isclose(grid.voxel, self.cfg.voxel):
            raise ValueError(f"map grid voxel {grid.voxel} differs from MapCfg.voxel {self.cfg.voxel}")
        self.grid = grid
        self.device = get_device(device)
        self._logodds = wp.zeros(grid.shape, dtype=float, device=self.device)
        self._miss = wp.zeros(grid.shape, dtype=wp.uint8, device=self.device)
        self._hit = wp.zeros(grid.shape, dtype=wp.uint8, device=self.device)
        self._lock = threading.Lock()
        self.scans = 0

    def integrate(self, origin, points: np.ndarray) -> None:
        """Insert one scan: sensor ``origin`` (3,) and its returns ``points`` (m, 3), world frame."""
        cfg, g = self.cfg, self.grid
        pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        origin = np.asarray(origin, dtype=np.float32).reshape(3)
        with self._lock:
            self.scans += 1
            if len(pts) == 0:
                return
            wp.launch(
                _trace_kernel,
                dim=len(pts),
                inputs=[
                    wp.vec3(*origin),
                    wp.array(pts, dtype=wp.vec3, device=self.device),
                    wp.vec3(*g.origin),
                    1.0 / g.voxel,
                    *g.shape,
                    cfg.ground_z,
                    self._miss,
                    self._hit,
                ],
                device=self.device,
            )
            # only voxels in the box spanned by the sensor and its returns can have been marked
            span = np.vstack([pts, origin[None]])
            lo = np.clip(np.floor((span.min(0) - g.origin) / g.voxel).astype(int), 0, np.array(g.shape) - 1)
            hi = np.clip(np.floor((span.max(0) - g.origin) / g.voxel).astype(int) + 1, lo + 1, np.array(g.shape))
            wp.launch(
                _update_kernel,
                dim=tuple(int(v) for v in hi - lo),
                inputs=[
                    self._logodds,
                    self._miss,
                    self._hit,
                    cfg.l_hit,
                    cfg.l_miss,
                    cfg.l_min,
                    cfg.l_max,
                    *(int(v) for v in lo),
                ],
                device=self.device,
            )

    def load_occupancy(self, occ: np.ndarray, grid: Grid) -> None:
        """Set the map where ``grid`` (on the map's voxel lattice) overlaps it: occupied voxels of ``occ`` to
        ``l_max``, the others to ``l_min`` (a prior map, or a fully observed scene)."""
        g = self.grid
        if not np.isclose(grid.voxel, g.voxel):
            raise ValueError(f"grid voxel {grid.voxel} differs from the map's {g.voxel}")
        off_f = (np.asarray(grid.origin) - np.asarray(g.origin)) / g.voxel
        off = np.round(off_f).astype(int)
        if not np.allclose(off_f, off, atol=1e-6):
            raise ValueError("grid is not on the map's voxel lattice")
        lo, hi = np.maximum(off, 0), np.minimum(off + np.array(occ.shape), np.array(g.shape))
        if np.any(hi <= lo):
            return
        src = np.asarray(occ, dtype=bool)[tuple(slice(a - o, b - o) for a, b, o in zip(lo, hi, off, strict=True))]
        with self._lock:
            host = self._logodds.numpy().copy()
            host[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] = np.where(src, self.cfg.l_max, self.cfg.l_min)
            self._logodds.assign(host)

    def logodds(self) -> np.ndarray:
        """Copy of the log-odds grid (nx, ny, nz)."""
        with self._lock:
            return self._logodds.numpy().copy()

    def occupied(self) -> np.ndarray:
        """Boolean occupancy of the whole map."""
        return self.logodds() > self.cfg.l_occupied

    def window_grid(self, center_xy, shape: tuple[int, int, int]) -> Grid:
        """Grid of ``shape`` centred (to the nearest voxel) on ``center_xy``, on the map's voxel lattice, z from
        the map's floor."""
        g = self.grid
        half = np.array(shape[:2]) * g.voxel / 2.0
        corner = np.asarray(center_xy, dtype=np.float64)[:2] - half
        steps = np.round((corner - np.asarray(g.origin[:2])) / g.voxel)
        xy = np.asarray(g.origin[:2]) + steps * g.voxel
        return Grid((float(xy[0]), float(xy[1]), g.origin[2]), g.voxel, shape)

    def window(
        self, center_xy, shape: tuple[int, int, int] = WindowCfg.shape, outside_blocked: bool = False
    ) -> tuple[np.ndarray, Grid]:
        """Occupancy (bool ``shape``) of the window around ``center_xy`` and its grid. Voxels outside the map
        are free, or occupied with ``outside_blocked`` (a geofence around the mapped area)."""
        g = self.grid
        wg = self.window_grid(center_xy, shape)
        off = np.round((np.asarray(wg.origin) - np.asarray(g.origin)) / g.voxel).astype(int)
        out = np.full(shape, outside_blocked, dtype=bool)
        src_lo = np.maximum(off, 0)
        src_hi = np.minimum(off + np.array(shape), np.array(g.shape))
        if np.any(src_hi <= src_lo):
            return out, wg
        with self._lock:
            lo_np = self._logodds.numpy()[
                src_lo[0] : src_hi[0], src_lo[1] : src_hi[1], src_lo[2] : src_hi[2]
            ]  # a view of the host array
            occ = lo_np > self.cfg.l_occupied
        dst_lo = src_lo - off
        dst_hi = dst_lo + (src_hi - src_lo)
        out[dst_lo[0] : dst_hi[0], dst_lo[1] : dst_hi[1], dst_lo[2] : dst_hi[2]] = occ
        return out, wg
