"""Regular voxel grid shared by every HumanoidPF quantity.

One convention everywhere: voxel ``(i, j, k)`` covers ``origin + [i, i+1) * voxel`` (per axis) and its
sample point (the *voxel centre*) is ``origin + (i + 1/2) * voxel``. Arrays are C-ordered ``(nx, ny, nz)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Grid:
    """Axis-aligned voxel grid: ``origin`` (lower corner, m), cubic ``voxel`` size (m), ``shape``."""

    origin: tuple[float, float, float]
    voxel: float
    shape: tuple[int, int, int]

    def __post_init__(self) -> None:
        origin = tuple(float(v) for v in np.asarray(self.origin, dtype=np.float64).reshape(3))
        shape = tuple(int(v) for v in np.asarray(self.shape).reshape(3))
        if not np.all(np.isfinite(origin)):
            raise ValueError(f"Grid origin must be finite, got {origin}")
        if not (np.isfinite(self.voxel) and self.voxel > 0):
            raise ValueError(f"Grid voxel must be a positive size, got {self.voxel}")
        if min(shape) < 1:
            raise ValueError(f"Grid shape must be positive, got {shape}")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "shape", shape)
        object.__setattr__(self, "voxel", float(self.voxel))

    @classmethod
    def from_bounds(cls, lower, upper, voxel: float) -> Grid:
        """Smallest grid with lower corner ``lower`` that covers ``upper`` (shape rounded up)."""
        lower = np.asarray(lower, dtype=np.float64)
        extent = np.asarray(upper, dtype=np.float64) - lower
        shape = np.maximum(np.ceil(extent / voxel - 1e-9), 1).astype(int)
        return cls(tuple(lower), voxel, tuple(shape))

    @property
    def size(self) -> np.ndarray:
        """Physical extent (m) per axis."""
        return np.asarray(self.shape, dtype=np.float64) * self.voxel

    @property
    def upper(self) -> np.ndarray:
        """Upper corner of the grid box (m)."""
        return np.asarray(self.origin) + self.size

    @property
    def num_voxels(self) -> int:
        return int(np.prod(self.shape))

    def index_to_world(self, ijk) -> np.ndarray:
        """Voxel centre(s) of (possibly fractional) indices ``ijk`` (..., 3)."""
        return np.asarray(self.origin) + (np.asarray(ijk, dtype=np.float64) + 0.5) * self.voxel

    def world_to_continuous(self, xyz) -> np.ndarray:
        """Continuous index coordinate of world points: voxel centres map to integers."""
        return (np.asarray(xyz, dtype=np.float64) - np.asarray(self.origin)) / self.voxel - 0.5

    def world_to_index(self, xyz) -> np.ndarray:
        """Index of the voxel containing each point (may lie outside ``[0, shape)``)."""
        return np.floor((np.asarray(xyz, dtype=np.float64) - np.asarray(self.origin)) / self.voxel).astype(np.int64)

    def contains(self, xyz) -> np.ndarray:
        """True where a point lies inside the grid box ``[origin, upper]``."""
        p = np.asarray(xyz, dtype=np.float64)
        return np.all((p >= np.asarray(self.origin)) & (p <= self.upper), axis=-1)

    def centers(self) -> np.ndarray:
        """All voxel centres, shape (nx, ny, nz, 3)."""
        axes = [self.origin[a] + (np.arange(self.shape[a]) + 0.5) * self.voxel for a in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def axis_centers(self, axis: int) -> np.ndarray:
        """Voxel-centre coordinates along one axis."""
        return self.origin[axis] + (np.arange(self.shape[axis]) + 0.5) * self.voxel

    def to_dict(self) -> dict:
        return {"origin": list(self.origin), "voxel": self.voxel, "shape": list(self.shape)}
