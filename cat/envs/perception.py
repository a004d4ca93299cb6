"""Scene-occupancy perception for the baselines: robot-centric elevation maps and voxel grids, per env per step.

At construction every scene of the env's ``SceneSet`` is reduced once to a ground and an overhead height map
and a pooled occupancy grid (``cat.terrain.elevation``), shifted to its tile in the shared world frame and
packed into flat tensors. Each step a fixed grid of sample points in the yaw frame is rotated by each env's
yaw, placed at its root and read by nearest-cell gathers into its own scene's arrays: one batched torch
gather, no per-env Python. Points outside a scene's grid read free space (floor 0, no overhead, empty). With no
scenes (flat task) the maps are constant: the floor and the overhead cap.
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


class _Packed:
    """Per-scene grids concatenated into one flat tensor, with each scene's origin, voxel, shape and offset."""

    def __init__(self, arrays: list[np.ndarray], origins: list[np.ndarray], voxels: list[float], device, dtype):
        self.ndim = arrays[0].ndim
        self.flat = torch.cat([torch.as_tensor(a.reshape(-1), dtype=dtype) for a in arrays]).to(device)
        sizes = [a.size for a in arrays]
        self.base = torch.tensor(np.concatenate(([0], np.cumsum(sizes)[:-1])), dtype=torch.long, device=device)
        self.shape = torch.tensor([a.shape for a in arrays], dtype=torch.long, device=device)
        self.origin = torch.tensor(np.stack(origins)[:, : self.ndim], dtype=torch.float32, device=device)
        self.inv_voxel = torch.tensor([1.0 / v for v in voxels], dtype=torch.float32, device=device)

    def gather(self, scene: torch.Tensor, points: torch.Tensor, default: float) -> torch.Tensor:
        """Values (N, P) at world ``points`` (N, P, ndim) of env scenes ``scene`` (N,); ``default`` outside."""
        idx = torch.floor((points - self.origin[scene][:, None]) * self.inv_voxel[scene][:, None, None]).long()
        shape = self.shape[scene][:, None]
        inside = ((idx >= 0) & (idx < shape)).all(dim=-1)
        flat = self.base[scene][:, None].expand(idx.shape[:2]).clone()
        stride = torch.ones_like(shape[..., 0])
        for d in reversed(range(self.ndim)):
            flat += idx[..., d] * stride
            stride = stride * shape[..., d]
        values = self.flat[flat.clamp(0, self.flat.numel() - 1)].to(torch.float32)
        return torch.where(inside, values, torch.full_like(values, default))


class ScenePerception:
    """Elevation maps and voxel grids of the env's scenes, read at robot-centric points (built on first use)."""

    def __init__(self, cfg: PerceptionCfg, scenes: SceneSet | None, device):
        self.cfg, self.scenes, self.device = cfg, scenes, torch.device(device)
        self._maps: tuple[_Packed, _Packed] | None = None
        self._voxels: _Packed | None = None
        self.map_points = map_points(cfg.height_map).to(self.device)
        self.voxel_points = voxel_points(cfg.voxel_grid).to(self.device)

    # --- precomputation (once per scene) --------------------------------------------------------------------
    def _scene_grids(self):
        for scene, offset in zip(self.scenes.scenes, self.scenes.offsets, strict=True):
            grid = scene.grid()
            yield scene.occupancy(), grid, np.asarray(grid.origin) + offset

    def _build_maps(self) -> tuple[_Packed, _Packed]:
        hm = self.cfg.height_map
        ground, over, origins, voxels = [], [], [], []
        for occ, grid, origin in self._scene_grids():
            pool = pool_voxels(hm.resolution, grid.voxel)
            g, o = elevation_layers(occ, grid, hm.split_height, hm.overhead_cap, pool)
            ground.append(g), over.append(o), origins.append(origin), voxels.append(grid.voxel)
        dev = self.device
        return _Packed(ground, origins, voxels, dev, torch.float32), _Packed(over, origins, voxels, dev, torch.float32)

    def _build_voxels(self) -> _Packed:
        res = self.cfg.voxel_grid.resolution
        occs, origins, voxels = [], [], []
        for occ, grid, origin in self._scene_grids():
            occs.append(pooled_occupancy(occ, pool_voxels(res, grid.voxel)))
            origins.append(origin), voxels.append(grid.voxel)
        return _Packed(occs, origins, voxels, self.device, torch.uint8)

    # --- queries ---------------------------------------------------------------------------------------------
    def _scene_of_env(self, n: int) -> torch.Tensor:
        return self.scenes.scene_of_env[:n].to(self.device)

    def layers_at(self, xy: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(ground, overhead) heights (N, P) at world points ``xy`` (N, P, 2), each env in its own scene."""
        cap = self.cfg.height_map.overhead_cap
        if self.scenes is None:
            shape = xy.shape[:-1]
            return torch.zeros(shape, device=xy.device), torch.full(shape, cap, device=xy.device)
        if self._maps is None:
            self._maps = self._build_maps()
        scene = self._scene_of_env(xy.shape[0])
        ground, over = self._maps
        return ground.gather(scene, xy, 0.0), over.gather(scene, xy, cap)

    def elevation(self, root_pos: torch.Tensor, yaw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(ground, overhead) (N, P) on the robot-centric map grid of each env."""
        return self.layers_at(_to_world(self.map_points, root_pos, yaw))

    def voxels(self, root_pos: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
        """Occupancy (N, P) in {0, 1} at the robot-centric voxel grid cells of each env."""
        pts = self.voxel_points
        if self.scenes is None:
            return torch.zeros(root_pos.shape[0], pts.shape[0], device=root_pos.device)
        if self._voxels is None:
            self._voxels = self._build_voxels()
        xy = _to_world(pts[:, :2], root_pos, yaw)
        xyz = torch.cat((xy, pts[:, 2].expand(xy.shape[:2]).unsqueeze(-1)), dim=-1)
        return self._voxels.gather(self._scene_of_env(root_pos.shape[0]), xyz, 0.0)


def _to_world(local_xy: torch.Tensor, root_pos: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    """Yaw-frame offsets (P, 2) -> world xy (N, P, 2) around each env's root."""
    c, s = torch.cos(yaw)[:, None], torch.sin(yaw)[:, None]
    x, y = local_xy[:, 0], local_xy[:, 1]
    return torch.stack((root_pos[:, :1] + c * x - s * y, root_pos[:, 1:2] + s * x + c * y), dim=-1)
