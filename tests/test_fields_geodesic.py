"""Geodesic distance (Eikonal) against analytic answers and scikit-fmm."""

from __future__ import annotations

import numpy as np
import pytest

from cat.fields import Grid, geodesic_distance


@pytest.mark.parametrize("goal", [(0.81, 0.6, 0.4), (0.513, 0.377, 0.251)])
def test_empty_space_equals_euclidean(goal):
    g = Grid((0.0, 0.0, 0.0), 0.04, (40, 30, 20))
    T = geodesic_distance(np.zeros(g.shape, bool), g, goal)
    E = np.linalg.norm(g.centers() - np.asarray(goal), axis=-1)
    assert np.all(np.isfinite(T))
    assert (np.abs(T - E) / E).max() <= 0.02


def test_iterative_solver_matches_fast_marching():
    """The CUDA path (parallel relaxation) run on the Warp CPU device gives the fast-march values."""
    g = Grid((0.0, 0.0, 0.0), 0.04, (24, 18, 12))
    occ = np.zeros(g.shape, bool)
    occ[10:12, 3:18, :] = True
    occ[4:8, 2:5, 2:9] = True
    goal = (0.7, 0.3, 0.2)
    a = geodesic_distance(occ, g, goal, method="fmm")
    b = geodesic_distance(occ, g, goal, method="iterative")
    assert np.array_equal(np.isinf(a), np.isinf(b))
    assert np.isinf(a[occ]).all()
    fin = np.isfinite(a)
    diff = np.abs(a[fin] - b[fin])  # both solve the same update; march order differs near corners
    assert diff.max() < 0.15 * g.voxel and np.median(diff) < 1e-3


def test_thin_wall_detour_is_analytic():
    """A one-voxel wall spanning all z forces the path round its edge: length = |s−e| + |e−g|."""
    h = 0.02
    g = Grid((0.0, 0.0, 0.0), h, (100, 100, 3))
    occ = np.zeros(g.shape, bool)
    occ[50, :70, :] = True  # wall in the plane x = 1.0..1.02, from y = 0 up to y = 1.4
    goal = np.array([1.51, 0.51, 0.03])
    T = geodesic_distance(occ, g, goal)
    edge = np.array([1.01, 1.40])  # top of the wall (voxel faces), where paths bend
    idx = [(20, 10), (10, 40), (30, 60), (5, 5)]
    for i, j in idx:
        p = g.index_to_world((i, j, 1))[:2]
        analytic = np.linalg.norm(p - edge) + np.linalg.norm(edge - goal[:2])
        assert abs(T[i, j, 1] - analytic) / analytic <= 0.03, (i, j, T[i, j, 1], analytic)
    # on the goal side the straight line is free
    p = g.index_to_world((80, 20, 1))
    assert abs(T[80, 20, 1] - np.linalg.norm(p - goal)) / np.linalg.norm(p - goal) <= 0.02


def test_agrees_with_scikit_fmm_on_clutter():
    skfmm = pytest.importorskip("skfmm")
    g = Grid((0.0, 0.0, 0.0), 0.04, (50, 40, 24))
    rng = np.random.default_rng(3)
    occ = np.zeros(g.shape, bool)
    for _ in range(45):
        c = rng.integers(0, g.shape)
        s = rng.integers(1, 8, 3)
        occ[c[0] : c[0] + s[0], c[1] : c[1] + s[1], c[2] : c[2] + s[2]] = True
    goal = np.array([1.0, 0.8, 0.5])
    occ[g.world_to_index(goal)[0] - 5 : g.world_to_index(goal)[0] + 5, 15:25, 7:17] = False
    T = geodesic_distance(occ, g, goal)
    r0 = 1.5 * g.voxel
    phi = np.ma.MaskedArray(np.linalg.norm(g.centers() - goal, axis=-1) - r0, occ)
    ref = np.ma.filled(skfmm.distance(phi, dx=g.voxel, order=2), np.inf) + r0
    reach_ref = np.isfinite(ref) & ~occ
    # same reachable set (scikit-fmm leaves pockets unreached as masked/constant: compare where both finite)
    assert np.array_equal(np.isfinite(T), np.isfinite(T) & ~occ)
    both = reach_ref & np.isfinite(T)
    assert both.sum() > 0.8 * (~occ).sum()
    far = both & (np.linalg.norm(g.centers() - goal, axis=-1) > 0.2)
    rel = np.abs(T[far] - ref[far]) / ref[far]
    assert np.median(rel) < 0.01 and np.quantile(rel, 0.99) < 0.04


def test_unreachable_pocket_is_inf():
    g = Grid((0.0, 0.0, 0.0), 0.05, (20, 20, 10))
    occ = np.zeros(g.shape, bool)
    occ[2:8, 2:8, 2:8] = True
    occ[3:7, 3:7, 3:7] = False  # hollow shell: its inside is free but sealed
    T = geodesic_distance(occ, g, (0.8, 0.8, 0.25))
    assert np.isinf(T[3:7, 3:7, 3:7]).all()
    assert np.isinf(T[occ]).all()
    assert np.isfinite(T[~occ]).sum() == (~occ).sum() - 64


def test_bad_goals_raise():
    g = Grid((0.0, 0.0, 0.0), 0.05, (10, 10, 10))
    occ = np.zeros(g.shape, bool)
    occ[5, 5, 5] = True
    with pytest.raises(ValueError, match="outside the grid"):
        geodesic_distance(occ, g, (0.1, 0.1, 0.6))
    with pytest.raises(ValueError, match="inside an obstacle"):
        geodesic_distance(occ, g, g.index_to_world((5, 5, 5)))
    with pytest.raises(ValueError, match="finite"):
        geodesic_distance(occ, g, (np.nan, 0.1, 0.1))
    with pytest.raises(ValueError, match="method"):
        geodesic_distance(occ, g, (0.1, 0.1, 0.1), method="dijkstra")


def test_iterative_solver_converges_on_typical_scene():
    """The CUDA default (parallel relaxation) on a full typical scene, run on the CPU device."""
    from cat.fields.scenes import TYPICAL_GOAL, TYPICAL_GRID, hurdle_crouch

    occ = hurdle_crouch()
    a = geodesic_distance(occ, TYPICAL_GRID, TYPICAL_GOAL, method="fmm")
    b = geodesic_distance(occ, TYPICAL_GRID, TYPICAL_GOAL, method="iterative")
    assert np.array_equal(np.isinf(a), np.isinf(b))
    fin = np.isfinite(a)
    diff = np.abs(a[fin] - b[fin])
    assert diff.max() < 0.25 * TYPICAL_GRID.voxel and np.quantile(diff, 0.99) < 1e-3
