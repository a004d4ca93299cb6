"""Scene-occupancy perception for the baselines: robot-centric elevation maps and voxel grids, per env per step.

On first use every scene of the env's ``SceneSet`` is reduced once to a table of columns: per xy voxel of its
grid the ground and overhead heights (``cat.terrain.elevation``), or the pooled occupancy at the voxel grid's
height levels; tables are shifted to their tiles in the shared world frame and packed into one tensor. Each
step a fixed grid of sample points in the yaw frame is rotated by each env's yaw, placed at its root and read
by one nearest-column gather into its own scene's table: batched torch ops, no per-env Python. Points outside
a scene's grid read free space (floor 0, no overhead, empty). With no scenes (flat task) the maps are constant:
the floor and the overhead cap. ``WindowPerception`` reads the same tables built from one live occupancy grid (a
robot's log-odds map window): one definition of each map, whatever the occupancy source.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from cat.envs.config import HeightMapCfg, PerceptionCfg, VoxelGridCfg
from cat.terrain.elevation import elevation_layers, pool_voxels, pooled_occupancy

if TYPE_CHECKING:
    from cat.envs.scene_set import SceneSet


def _axis(extent: float, resolution: float, offset: float = 0.0) -> np.ndarray:
    """Cell centres spanning [-extent/2, extent/2] (+ offset), symmetric, ``round(extent/res) + 1`` of them."""
    n = int(round(extent / resolution)) + 1
    return offset + (np.arange(n) - 0.5 * (n - 1)) * resolution


def map_shape(cfg: HeightMapCfg) -> tuple[int, int]:
    """(cells along the heading, cells across) of the elevation map."""
    return len(_axis(cfg.length, cfg.resolution)), len(_axis(cfg.width, cfg.resolution))


def voxel_shape(cfg: VoxelGridCfg) -> tuple[int, int, int]:
    """(along the heading, across, up) cells of the voxel grid."""
    nz = max(int(round(cfg.height / cfg.resolution)), 1)
    return len(_axis(cfg.length, cfg.resolution)), len(_axis(cfg.width, cfg.resolution)), nz


def map_points(cfg: HeightMapCfg) -> torch.Tensor:
    """(P, 2) sample points in the yaw frame relative to the root, row-major (along, across)."""
    xs, ys = _axis(cfg.length, cfg.resolution, cfg.forward_offset), _axis(cfg.width, cfg.resolution)
    return torch.tensor(np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2), dtype=torch.float32)


def voxel_points(cfg: VoxelGridCfg) -> torch.Tensor:
    """(P, 3) cell centres: x, y in the yaw frame relative to the root, z world height; row-major (x, y, z)."""
    nz = voxel_shape(cfg)[2]
    xs, ys = _axis(cfg.length, cfg.resolution, cfg.forward_offset), _axis(cfg.width, cfg.resolution)
    zs = (np.arange(nz) + 0.5) * cfg.resolution
    return torch.tensor(np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), -1).reshape(-1, 3), dtype=torch.float32)


def elevation_table(occ: np.ndarray, grid, cfg: HeightMapCfg) -> np.ndarray:
    """(X, Y, 2) ground and overhead heights per xy column of occupancy ``occ`` on ``grid``, pooled over a map
    cell: the one definition of the elevation map's columns, for a scene's occupancy and for a live map alike."""
    ground, over = elevation_layers(
        occ, grid, cfg.split_height, cfg.overhead_cap, pool_voxels(cfg.resolution, grid.voxel)
    )
    return np.stack((ground, over), axis=-1)


def voxel_table(occ: np.ndarray, grid, cfg: VoxelGridCfg, zs: np.ndarray) -> np.ndarray:
    """(X, Y, len(zs)) uint8 pooled occupancy of ``occ`` on ``grid`` at heights ``zs`` per xy column: the voxel
    grid's columns (levels outside the grid are empty)."""
    pooled = pooled_occupancy(occ, pool_voxels(cfg.resolution, grid.voxel))
    iz = np.floor((zs - grid.origin[2]) / grid.voxel).astype(int)
    valid = (iz >= 0) & (iz < occ.shape[2])
    table = np.zeros((*occ.shape[:2], len(zs)), dtype=np.uint8)
    table[..., valid] = pooled[..., iz[valid]]
    return table


class _Columns:
    """Per-scene column tables (X, Y, C), each framed by a one-cell border of the free-space ``default`` and packed
    into one (rows, C) tensor. A query is one 2-D index computation per point, clamped into its scene's frame
    (points outside the grid land on the border), and one row gather of all C channels (both map layers, or every
    height level of the voxel grid)."""

    def __init__(self, tables: list[np.ndarray], origins: list[np.ndarray], voxels: list[float], default, device):
        dflt = np.asarray(default, dtype=tables[0].dtype)
        framed = []
        for t in tables:
            f = np.empty((t.shape[0] + 2, t.shape[1] + 2, t.shape[2]), dtype=t.dtype)
            f[:] = dflt
            f[1:-1, 1:-1] = t
            framed.append(f)
        self.table = torch.cat([torch.as_tensor(f.reshape(-1, f.shape[-1])) for f in framed]).to(device)
        sizes = [f.shape[0] * f.shape[1] for f in framed]
        self.base = torch.tensor(np.concatenate(([0], np.cumsum(sizes)[:-1])), dtype=torch.long, device=device)
        self.last = torch.tensor([f.shape[:2] for f in framed], dtype=torch.long, device=device) - 1
        self.origin = torch.tensor(np.stack(origins)[:, :2], dtype=torch.float32, device=device)
        self.inv_voxel = torch.tensor([1.0 / v for v in voxels], dtype=torch.float32, device=device)

    def gather(self, scene: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
        """Rows (N, P, C) at world points ``xy`` (N, P, 2) of env scenes ``scene`` (N,)."""
        u = (xy - self.origin[scene][:, None]) * self.inv_voxel[scene][:, None, None] + 1.0  # index in the frame
        last = self.last[scene][:, None]
        idx = torch.minimum(u.long().clamp_(min=0), last)  # truncation = floor for u >= 0; u < 0 -> border 0
        row = self.base[scene][:, None] + idx[..., 0] * (last[..., 1] + 1) + idx[..., 1]
        return self.table.index_select(0, row.reshape(-1)).reshape(*row.shape, -1)


class ScenePerception:
    """Elevation maps and voxel grids of the env's scenes, read at robot-centric points (built on first use)."""

    def __init__(self, cfg: PerceptionCfg, scenes: SceneSet | None, device):
        self.cfg, self.scenes, self.device = cfg, scenes, torch.device(device)
        self._maps: _Columns | None = None
        self._voxels: _Columns | None = None
        self.map_points = map_points(cfg.height_map).to(self.device)
        self.voxel_points = voxel_points(cfg.voxel_grid).to(self.device)
        n = voxel_shape(cfg.voxel_grid)
        self.voxel_columns = self.voxel_points.reshape(n[0] * n[1], n[2], 3)[:, 0, :2].contiguous()

    # --- precomputation (once per scene) --------------------------------------------------------------------
    def _scene_grids(self):
        for scene, offset in zip(self.scenes.scenes, self.scenes.offsets, strict=True):
            grid = scene.grid()
            yield scene.occupancy(), grid, np.asarray(grid.origin) + offset

    def _build_maps(self) -> _Columns:
        tables, origins, voxels = [], [], []
        for occ, grid, origin in self._scene_grids():
            tables.append(elevation_table(occ, grid, self.cfg.height_map)), origins.append(origin)
            voxels.append(grid.voxel)
        return _Columns(tables, origins, voxels, [0.0, self.cfg.height_map.overhead_cap], self.device)

    def _build_voxels(self) -> _Columns:
        """Per scene, the pooled occupancy at the grid's height levels (X, Y, levels): a column per xy cell."""
        vg = self.cfg.voxel_grid
        zs = self.voxel_points[: voxel_shape(vg)[2], 2].cpu().numpy()
        tables, origins, voxels = [], [], []
        for occ, grid, origin in self._scene_grids():
            tables.append(voxel_table(occ, grid, vg, zs)), origins.append(origin), voxels.append(grid.voxel)
        return _Columns(tables, origins, voxels, np.zeros(len(zs)), self.device)

    def _has_occupancy(self) -> bool:
        return self.scenes is not None

    # --- queries ---------------------------------------------------------------------------------------------
    def _scene_of_env(self, n: int) -> torch.Tensor:
        return self.scenes.scene_of_env[:n].to(self.device)

    def layers_at(self, xy: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(ground, overhead) heights (N, P) at world points ``xy`` (N, P, 2), each env in its own scene."""
        if not self._has_occupancy():
            shape = xy.shape[:-1]
            return torch.zeros(shape, device=xy.device), torch.full(
                shape, self.cfg.height_map.overhead_cap, device=xy.device
            )
        if self._maps is None:
            self._maps = self._build_maps()
        both = self._maps.gather(self._scene_of_env(xy.shape[0]), xy)
        return both[..., 0], both[..., 1]

    def elevation(self, root_pos: torch.Tensor, yaw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(ground, overhead) (N, P) on the robot-centric map grid of each env."""
        return self.layers_at(_to_world(self.map_points, root_pos, yaw))

    def voxels(self, root_pos: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
        """Occupancy (N, P) in {0, 1} at the robot-centric voxel grid cells of each env, row-major (x, y, z)."""
        n = root_pos.shape[0]
        if not self._has_occupancy():
            return torch.zeros(n, self.voxel_points.shape[0], device=root_pos.device)
        if self._voxels is None:
            self._voxels = self._build_voxels()
        xy = _to_world(self.voxel_columns, root_pos, yaw)
        return self._voxels.gather(self._scene_of_env(n), xy).reshape(n, -1).to(torch.float32)


class WindowPerception(ScenePerception):
    """The same maps read from one occupancy grid instead of the env's scenes: a live map's window on a robot
    (``cat.deploy.perception``). Tables, gather and frames are ``ScenePerception``'s; only the occupancy differs.
    Every env (row of ``root_pos``) reads this grid; outside it is free space, as outside a scene's grid."""

    def __init__(self, cfg: PerceptionCfg, occ: np.ndarray, grid, device="cpu"):
        super().__init__(cfg, None, device)
        self._window = (np.asarray(occ, dtype=bool), grid, np.asarray(grid.origin, dtype=np.float64))

    def _has_occupancy(self) -> bool:
        return True

    def _scene_grids(self):
        yield self._window

    def _scene_of_env(self, n: int) -> torch.Tensor:
        return torch.zeros(n, dtype=torch.long, device=self.device)


def _to_world(local_xy: torch.Tensor, root_pos: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    """Yaw-frame offsets (P, 2) -> world xy (N, P, 2) around each env's root."""
    c, s = torch.cos(yaw)[:, None], torch.sin(yaw)[:, None]
    x, y = local_xy[:, 0], local_xy[:, 1]
    return torch.stack((root_pos[:, :1] + c * x - s * y, root_pos[:, 1:2] + s * x + c * y), dim=-1)
