"""Grid conventions and signed distance fields (mesh: exact; occupancy / points: exact EDT)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from cat.fields import Grid, mesh_sdf_at, occupancy_from_points, sdf_from_mesh, sdf_from_occupancy, sdf_from_points

RNG = np.random.default_rng(0)


def box_sdf(p, centre, half):
    q = np.abs(p - centre) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(-1), 0.0)


def test_grid_voxel_centre_convention():
    g = Grid((-0.5, -1.0, 0.0), 0.04, (75, 50, 38))
    assert np.allclose(g.index_to_world((0, 0, 0)), [-0.48, -0.98, 0.02])
    assert np.allclose(g.upper, [2.5, 1.0, 1.52])
    ijk = RNG.integers(0, g.shape, size=(100, 3))
    c = g.index_to_world(ijk)
    assert np.array_equal(g.world_to_index(c), ijk)
    assert np.allclose(g.world_to_continuous(c), ijk)
    assert np.allclose(g.centers()[3, 4, 5], g.index_to_world((3, 4, 5)))
    assert g.contains(g.origin) and not g.contains(g.upper + 1e-6)
    with pytest.raises(ValueError):
        Grid((0, 0, 0), -1.0, (2, 2, 2))
    gb = Grid.from_bounds((0, 0, 0), (1.0, 0.5, 0.3), 0.04)
    assert gb.shape == (25, 13, 8)


def test_mesh_sdf_box_exact():
    centre, half = np.array([0.8, 0.6, 0.4]), np.array([0.25, 0.2, 0.15])
    box = trimesh.creation.box(2 * half)
    box.apply_translation(centre)
    p = RNG.uniform(0.0, 1.3, (2000, 3))
    assert np.abs(mesh_sdf_at(box, p) - box_sdf(p, centre, half)).max() <= 1e-4
    g = Grid((0.0, 0.0, 0.0), 0.05, (26, 24, 16))
    d = sdf_from_mesh(box, g)
    assert np.abs(d - box_sdf(g.centers(), centre, half)).max() <= 1e-4


def test_mesh_sdf_sphere_exact():
    centre, r = np.array([0.1, -0.2, 0.5]), 0.3
    sphere = trimesh.creation.icosphere(subdivisions=6, radius=r)  # facet sagitta ~1e-5 m
    sphere.apply_translation(centre)
    p = centre + RNG.uniform(-0.6, 0.6, (2000, 3))
    exact = np.linalg.norm(p - centre, axis=1) - r
    assert np.abs(mesh_sdf_at(sphere, p) - exact).max() <= 1e-4


def test_mesh_sdf_non_watertight_rule():
    """Winding number ≥ 0.5 = inside: an open-topped box still has an inside; a lone quad has none."""
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    top = box.face_normals[:, 2] > 0.9
    open_box = trimesh.Trimesh(box.vertices, box.faces[~top], process=False)
    assert not open_box.is_watertight
    d = mesh_sdf_at(open_box, [[0.0, 0.0, -0.2], [0.0, 0.0, 0.45], [0.0, 0.0, 0.8], [2.0, 0.0, 0.0]])
    assert d[0] < 0 and np.isclose(d[0], -0.3, atol=1e-5)
    assert d[2] > 0 and d[3] > 0
    quad = trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]])
    d = mesh_sdf_at(quad, [[0, 0, 0.3], [0, 0, -0.3]])
    assert np.allclose(d, [0.3, 0.3], atol=1e-6)


def test_occupancy_sdf_is_exact_edt_with_half_voxel_faces():
    g = Grid((0.0, 0.0, 0.0), 0.04, (23, 17, 11))
    occ = RNG.random(g.shape) < 0.03
    d = sdf_from_occupancy(occ, g)
    ref = np.where(occ, -(ndimage.distance_transform_edt(occ) - 0.5), ndimage.distance_transform_edt(~occ) - 0.5)
    assert np.abs(d - ref * g.voxel).max() < 1e-5


def test_occupancy_sdf_of_sphere_within_one_voxel():
    g = Grid((-0.6, -0.6, -0.6), 0.04, (30, 30, 30))
    r = 0.33
    exact = np.linalg.norm(g.centers(), axis=-1) - r
    d = sdf_from_occupancy(exact < 0, g)
    assert np.abs(d - exact).max() <= g.voxel
    assert np.all(np.sign(d) == np.sign(exact))


def test_point_cloud_sdf_within_one_voxel():
    g = Grid((-0.6, -0.6, -0.6), 0.04, (30, 30, 30))
    centre, half = np.zeros(3), np.array([0.21, 0.15, 0.11])
    box = trimesh.creation.box(2 * half)
    pts = box.sample(40000, seed=1)
    occ = occupancy_from_points(pts, g)
    assert occ.sum() > 0 and occ.dtype == bool
    d = sdf_from_points(pts, g)
    exact = box_sdf(g.centers(), centre, half)
    outside = exact > 0.05
    assert np.abs(d[outside] - exact[outside]).max() <= g.voxel + 1e-6


def test_sdf_bad_inputs():
    g = Grid((0, 0, 0), 0.1, (4, 4, 4))
    with pytest.raises(ValueError, match="shape"):
        sdf_from_occupancy(np.zeros((4, 4, 3), bool), g)
    bad = np.zeros(g.shape)
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        sdf_from_occupancy(bad, g)
    with pytest.raises(ValueError, match="empty"):
        sdf_from_mesh(trimesh.Trimesh(), g)
    with pytest.raises(ValueError, match="NaN"):
        sdf_from_points([[0.1, np.nan, 0.2]], g)
    assert np.all(sdf_from_occupancy(np.zeros(g.shape, bool), g) > 1e3)  # no obstacle: +FAR
