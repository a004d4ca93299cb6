"""Per-scene field storage: the channels a bank reads, d and ∇d once per scene and F once per goal.

``SceneFields`` is what a :class:`cat.fields.FieldBank` loads for one scene, and the format of
``<scene>/fields/humanoid_pf.npz`` (uncompressed ``.npz``: read at disk speed, no decompression). The
geodesic and the potential are not stored: nothing downstream of the bank reads them.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cat.fields.config import FieldCfg, StaleFieldError, cfg_from_dict, read_saved_header
from cat.fields.field import Field
from cat.fields.grid import Grid

STORE_VERSION = 1
STORE_FILE = "humanoid_pf.npz"
STORAGE_DTYPES = {"float32": np.float32, "float16": np.float16}


def check_scene_fields(fields: list[Field]) -> Field:
    """The first of one scene's goal fields, after checking they share a grid and a config."""
    if not fields:
        raise ValueError("SceneFields needs at least one field")
    f0 = fields[0]
    for f in fields[1:]:
        if f.grid != f0.grid:
            raise ValueError(f"fields of one scene must share a grid: {f.grid} != {f0.grid}")
        if f.cfg != f0.cfg:
            raise ValueError("fields of one scene must share a FieldCfg")
    return f0


@dataclass
class SceneFields:
    """HumanoidPF of one scene for several goals, reduced to what the bank queries."""

    grid: Grid
    goals: np.ndarray
    """(G, 3) goal positions."""
    sdf_grad: np.ndarray
    """(nx, ny, nz, 4): d, ∇d (goal independent)."""
    force: np.ndarray
    """(G, nx, ny, nz, 3): F = −∇U per goal."""
    cfg: FieldCfg

    def __post_init__(self) -> None:
        shape = self.grid.shape
        self.goals = np.asarray(self.goals, dtype=np.float64).reshape(-1, 3)
        if self.sdf_grad.shape != (*shape, 4):
            raise ValueError(f"sdf_grad must be {(*shape, 4)}, got {self.sdf_grad.shape}")
        if self.force.shape != (len(self.goals), *shape, 3):
            raise ValueError(f"force must be {(len(self.goals), *shape, 3)}, got {self.force.shape}")

    @property
    def num_goals(self) -> int:
        return len(self.goals)

    @classmethod
    def from_fields(cls, fields: list[Field]) -> SceneFields:
        """Fields of one scene (same grid and config, one per goal; d, ∇d taken from the first)."""
        f0 = check_scene_fields(fields)
        force = np.empty((len(fields), *f0.grid.shape, 3), dtype=np.float32)
        for i, f in enumerate(fields):
            force[i] = f.force
        sdf_grad = np.ascontiguousarray(f0.data[..., 3:7])
        return cls(f0.grid, np.stack([f.goal for f in fields]), sdf_grad, force, f0.cfg)

    def save(self, path: str | os.PathLike, dtype: str = "float32") -> Path:
        """Write an uncompressed ``.npz`` (atomically: temp file, then rename) in ``dtype`` storage."""
        if dtype not in STORAGE_DTYPES:
            raise ValueError(f"dtype must be one of {sorted(STORAGE_DTYPES)}, got {dtype!r}")
        path = Path(path)
        np_dtype = STORAGE_DTYPES[dtype]
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(
            tmp,
            store_version=np.int64(STORE_VERSION),
            origin=np.asarray(self.grid.origin, dtype=np.float64),
            voxel=np.float64(self.grid.voxel),
            shape=np.asarray(self.grid.shape, dtype=np.int64),
            goals=self.goals,
            sdf_grad=self.sdf_grad.astype(np_dtype, copy=False),
            force=self.force.astype(np_dtype, copy=False),
            cfg=np.asarray(json.dumps(self.cfg.to_dict(), sort_keys=True)),
        )
        tmp.replace(path)
        return path

    @classmethod
    def load(
        cls, path: str | os.PathLike, cfg: FieldCfg | None = None, grid: Grid | None = None, goals=None
    ) -> SceneFields:
        """Read a file written by :meth:`save` (arrays keep their storage dtype).

        Given ``cfg``, ``grid`` or ``goals``, a file built under other build constants, on another grid or for
        other goals raises :class:`StaleFieldError` before the arrays are read; another format version too."""
        with np.load(path, allow_pickle=False) as z:
            saved_grid, saved_goals, saved_cfg = _check(z, path, cfg, grid, goals)
            return cls(saved_grid, saved_goals, z["sdf_grad"], z["force"], saved_cfg)

    @staticmethod
    def check(path: str | os.PathLike, cfg: FieldCfg | None = None, grid: Grid | None = None, goals=None) -> None:
        """The checks of :meth:`load` without reading the arrays (raises :class:`StaleFieldError`)."""
        with np.load(path, allow_pickle=False) as z:
            _check(z, path, cfg, grid, goals)


def _check(z, path, cfg: FieldCfg | None, grid: Grid | None, goals) -> tuple[Grid, np.ndarray, FieldCfg]:
    saved, header_grid = read_saved_header(z, path, "store_version", STORE_VERSION, cfg)
    saved_grid = Grid(*header_grid)
    if grid is not None and not _same_grid(saved_grid, grid):
        raise StaleFieldError(f"{path}: built on grid {saved_grid}, expected {grid}")
    saved_goals = z["goals"]
    if goals is not None:
        want = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
        if saved_goals.shape != want.shape or not np.allclose(saved_goals, want, atol=1e-6):
            raise StaleFieldError(f"{path}: built for other goals ({len(saved_goals)} saved, {len(want)} asked)")
    return saved_grid, saved_goals, cfg_from_dict(saved)


def _same_grid(a: Grid, b: Grid) -> bool:
    return a.shape == b.shape and np.isclose(a.voxel, b.voxel) and np.allclose(a.origin, b.origin, atol=1e-6)
