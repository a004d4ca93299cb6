"""Collision geometry from occupancy (height-field tiles + overhang boxes) matches the voxel solid."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import trimesh

from cat.bench.gen import collision_deviation, distance_to_solid
from cat.terrain import Scene, make_procedural, make_typical
from cat.terrain.mujoco_export import add_obstacles_to_spec, uses_voxels
from cat.terrain.voxel import GridSpec
from cat.terrain.voxel_collision import VoxelCollisionCfg, cover_boxes, fill_gaps, voxel_parts

GRID = GridSpec((0.0, 0.0, 0.0), 0.04, (20, 20, 40))


def _toy() -> np.ndarray:
    """Floor and ceiling blocks, a ledge (overhang) 0.4 m above the floor and a 1-voxel crack."""
    occ = np.zeros(GRID.shape, bool)
    occ[2:6, 2:6, :10] = True  # floor block, 0.4 m
    occ[10:14, 2:6, 30:] = True  # hangs from the top down to 1.2 m
    occ[2:8, 10:16, 10:13] = True  # ledge: free below
    occ[14:18, 10:14, 0:5] = True  # block with a 1-voxel crack above it and a slab on top
    occ[14:18, 10:14, 6:8] = True
    occ[16:20, 16:20, 32:] = True  # fills a whole height-field tile (MuJoCo rescales its data by min/max)
    return occ


def test_runs_tiles_and_boxes_of_a_toy_grid():
    occ = _toy()
    filled = fill_gaps(occ, GRID, VoxelCollisionCfg())
    assert filled[14:18, 10:14, 5].all() and (filled & ~occ).sum() == 16  # only the crack is filled
    parts = voxel_parts(occ, GRID, VoxelCollisionCfg(tile=8))
    assert len(parts.floor) >= 2 and len(parts.ceiling) >= 2  # both hanging blocks end below z_reach
    assert 1 <= len(parts.boxes) <= 4  # the ledge
    lo, hi = parts.boxes[:, 0], parts.boxes[:, 1]
    # the ledge's height, grown by at most one voxel (inflate) into the free space around it
    assert np.all(lo[:, 2] >= 9 * 0.04 - 1e-9) and np.all(hi[:, 2] <= 14 * 0.04 + 1e-9)


def test_cover_boxes_cover_need_within_allowed():
    rng = np.random.default_rng(0)
    allowed = rng.uniform(size=(12, 10, 8)) < 0.7
    need = allowed & (rng.uniform(size=allowed.shape) < 0.5)
    boxes = cover_boxes(allowed, need)
    covered = np.zeros_like(allowed)
    for (i0, j0, k0), (i1, j1, k1) in boxes:
        assert allowed[i0:i1, j0:j1, k0:k1].all()
        covered[i0:i1, j0:j1, k0:k1] = True
    assert covered[need].all()


def _toy_scene() -> Scene:
    occ = _toy()
    scene = Scene(
        mesh=trimesh.Trimesh(),
        bounds=np.array([GRID.origin, np.array(GRID.origin) + np.array(GRID.shape) * GRID.voxel]),
        start=(0.3, 0.3, 0.75),
        goals=[(0.5, 0.5, 0.75)],
        kind="procedural",
    )
    scene.set_occupancy(occ, GRID.voxel)
    return scene


def test_toy_geometry_matches_voxels():
    dev = collision_deviation(_toy_scene(), n=600)
    assert dev["missed"] == 0.0  # never smaller than the voxels
    assert dev["out_max"] <= 0.04 + 1e-3  # one voxel (inflated ledge boxes / filled crack) at most


def test_procedural_geometry_matches_voxels():
    scene = make_procedural(0.6, 4)
    assert uses_voxels(scene) and not uses_voxels(make_typical("side-pass", 0.5, 0))
    dev = collision_deviation(scene, n=400)
    assert dev["missed"] == 0.0
    assert dev["out_max"] < 0.065  # measured ≤ 0.054 (docs/scenes.md)
    assert dev["geoms"] < 800


def test_distance_to_solid_is_exact():
    occ = np.zeros((5, 5, 5), bool)
    occ[2, 2, 2] = True
    pts = np.array([[0.1, 0.1, 0.1], [0.05, 0.1, 0.1], [0.13, 0.13, 0.1], [0.0, 0.0, 0.0]])
    d = distance_to_solid(pts, occ, (0, 0, 0), 0.04)
    np.testing.assert_allclose(d, [0.0, 0.03, np.sqrt(2) * 0.01, np.sqrt(3) * 0.08], atol=1e-9)


def test_voxel_export_offset_moves_every_geom():
    scene = _toy_scene()
    models = []
    for off in ((0.0, 0.0, 0.0), (5.0, -3.0, 0.0)):
        spec = mujoco.MjSpec()
        n = add_obstacles_to_spec(spec, scene, offset=off)
        m = spec.compile()
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)
        models.append((n, d.geom_xpos.copy()))
    assert models[0][0] == models[1][0] > 0
    np.testing.assert_allclose(models[1][1] - models[0][1], np.tile([5.0, -3.0, 0.0], (models[0][0], 1)), atol=1e-9)
    with pytest.raises(ValueError, match="method"):
        add_obstacles_to_spec(mujoco.MjSpec(), scene, method="coacd")


def test_tiles_are_cropped_to_their_solid():
    """A tile's footprint is its solid's samples plus one ring of free ones, never the whole 16-voxel tile."""
    occ = np.zeros(GRID.shape, bool)
    occ[3:5, 9:12, :6] = True  # one small block inside the first 16×16 tile
    (tile,) = voxel_parts(occ, GRID, VoxelCollisionCfg(tile=16)).floor
    h = GRID.voxel
    # solid samples span voxel faces 3..5 (x) and 9..12 (y); one free half-voxel sample on each side
    np.testing.assert_allclose(tile.lower, [3 * h - h / 2, 9 * h - h / 2])
    np.testing.assert_allclose(tile.size, [2 * h + h, 3 * h + h])
    assert tile.heights.shape == (2 * 2 + 1 + 2, 2 * 3 + 1 + 2)
    assert (tile.heights[0] == 0).all() and (tile.heights[-1] == 0).all() and (tile.heights[1:-1, 1:-1] > 0).all()
