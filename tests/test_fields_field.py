"""build_field: potential, force, API, persistence and errors."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from cat.fields import Field, FieldCfg, Grid, build_field, build_fields

GRID = Grid((-0.5, -1.0, 0.0), 0.04, (75, 50, 38))
GOAL = (2.0, 0.0, 0.75)


def _box_occ(grid: Grid) -> np.ndarray:
    c = grid.centers()
    return np.all(np.abs(c - [1.0, 0.0, 0.75]) < [0.1, 0.15, 0.2], axis=-1)


@pytest.fixture(scope="module")
def field() -> Field:
    return build_field(_box_occ(GRID), GRID, GOAL)


def test_api_shapes_and_types(field):
    assert field.sdf.shape == GRID.shape and field.geodesic.shape == GRID.shape
    assert field.force.shape == (*GRID.shape, 3) and field.grad_sdf.shape == (*GRID.shape, 3)
    assert field.force.dtype == np.float32
    occ = _box_occ(GRID)
    assert np.isinf(field.geodesic[occ]).all() and np.isfinite(field.geodesic[~occ]).all()
    assert np.all(field.sdf[occ] < 0) and np.all(field.sdf[~occ] > 0)
    assert np.isfinite(field.potential[~occ]).all()


def test_force_finite_everywhere(field):
    assert np.isfinite(field.data).all()


def test_force_points_away_inside_d0_and_to_goal_far(field):
    cfg = field.cfg
    d, F, gd = field.sdf, field.force, field.grad_sdf
    free = d > 0
    near = free & (d < cfg.d0 / 3)  # repulsion dominates attraction here (crossover at d0/2)
    assert near.sum() > 100
    assert np.all((F[near] * gd[near]).sum(-1) > 0)
    # repulsion adds an outward push everywhere within d0: F·∇d ≥ attraction's component
    within = free & (d < cfg.d0) & np.isfinite(field.geodesic)
    h = field.grid.voxel
    gg = np.stack(np.gradient(np.where(np.isfinite(field.geodesic), field.geodesic, 0.0), h), -1)
    interior = within & (d > 2 * h)
    assert np.all((F[interior] * gd[interior]).sum(-1) >= (-cfg.eta * gg[interior] * gd[interior]).sum(-1) - 1e-3)
    # far from obstacles F is the unit attraction toward the goal
    c = field.grid.centers()
    to_goal = np.asarray(GOAL) - c
    dist = np.linalg.norm(to_goal, axis=-1)
    far = (d > cfg.d0) & (dist > 0.2)
    cos = (F[far] * to_goal[far]).sum(-1) / (np.linalg.norm(F[far], axis=-1) * dist[far])
    assert np.all(cos > 0)
    norm = np.linalg.norm(F[far], axis=-1)  # |∇geo| = 1, except on the ridge behind the box (< 0.1 %)
    assert np.mean(np.abs(norm - cfg.eta) < 0.05) > 0.99 and norm.min() > 0.8 * cfg.eta
    goal_side = far & (c[..., 0] > 1.3)
    assert np.all(cos[goal_side[far]] > 0.98)


def test_mesh_obstacles_match_occupancy_field():
    box = trimesh.creation.box((0.2, 0.3, 0.4))
    box.apply_translation((1.0, 0.0, 0.75))
    fm = build_field(box, GRID, GOAL)
    fo = build_field(_box_occ(GRID), GRID, GOAL)
    assert np.isfinite(fm.data).all()
    # occupancy SDF within one voxel of the exact mesh SDF
    assert np.abs(fm.sdf - fo.sdf).max() <= GRID.voxel
    # the mesh blocks voxels within h/2 of its surface (see mesh_free_mask): paths hug a 2 cm larger box
    both = np.isfinite(fm.geodesic) & np.isfinite(fo.geodesic)
    rel = np.abs(fm.geodesic[both] - fo.geodesic[both]) / np.maximum(fo.geodesic[both], 0.1)
    assert np.median(rel) < 1e-3 and rel.max() < 0.1


def test_save_load_roundtrip(field, tmp_path):
    p = tmp_path / "f.npz"
    field.save(p)
    g = Field.load(p)
    assert g.grid == field.grid and np.allclose(g.goal, field.goal)
    assert np.array_equal(g.data, field.data) and np.array_equal(g.geodesic, field.geodesic)
    assert g.cfg == field.cfg
    z = dict(np.load(p))
    z["format_version"] = np.int64(99)
    np.savez(tmp_path / "bad.npz", **z)
    with pytest.raises(ValueError, match="format version"):
        Field.load(tmp_path / "bad.npz")


def test_custom_constants_change_repulsion():
    occ = _box_occ(GRID)
    strong = build_field(occ, GRID, GOAL, FieldCfg(xi=0.05))
    weak = build_field(occ, GRID, GOAL, FieldCfg(xi=0.001))
    near = (weak.sdf > 0) & (weak.sdf < 0.1)
    assert np.all(np.linalg.norm(strong.force[near], axis=-1) > np.linalg.norm(weak.force[near], axis=-1))


def test_bad_inputs_raise():
    occ = _box_occ(GRID)
    with pytest.raises(ValueError, match="outside the grid"):
        build_field(occ, GRID, (5.0, 0.0, 0.5))
    with pytest.raises(ValueError, match="inside an obstacle"):
        build_field(occ, GRID, (1.0, 0.0, 0.75))
    with pytest.raises(ValueError, match="shape"):
        build_field(occ[:-1], GRID, GOAL)
    with pytest.raises(ValueError, match="finite"):
        build_field(occ, GRID, (np.nan, 0.0, 0.5))
    with pytest.raises(ValueError, match="empty"):
        build_field(trimesh.Trimesh(), GRID, GOAL)


def test_concurrent_builds_do_not_interfere():
    """Scratch buffers are per thread: builds from two threads give the single-threaded results."""
    import threading

    occ = _box_occ(GRID)
    goals = [(2.0, -0.5, 0.75), (2.0, 0.5, 0.75)]
    ref = [build_field(occ, GRID, g).data for g in goals]
    got: dict = {}

    def job(i: int) -> None:
        for r in range(3):
            got[(i, r)] = build_field(occ, GRID, goals[i]).data

    threads = [threading.Thread(target=job, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(got) == 6 and all(np.array_equal(v, ref[i]) for (i, _), v in got.items())


def test_build_fields_many_goals_equals_single_builds():
    occ = _box_occ(GRID)
    goals = [(2.0, y, 0.75) for y in (-0.6, -0.2, 0.2)]
    many = build_fields(occ, GRID, goals)
    assert len(many) == 3
    for g, f in zip(goals, many, strict=True):
        ref = build_field(occ, GRID, g)
        assert np.allclose(f.goal, g) and np.array_equal(f.data, ref.data)
    with pytest.raises(ValueError, match="inside an obstacle"):
        build_fields(occ, GRID, [GOAL, (1.0, 0.0, 0.75)])


def test_point_cloud_obstacles():
    box = trimesh.creation.box((0.2, 0.3, 0.4))
    box.apply_translation((1.0, 0.0, 0.75))
    f = build_field(box.sample(20000, seed=0), GRID, GOAL)
    assert np.isfinite(f.data).all()
    c = GRID.world_to_index([1.0, 0.35, 0.75])
    assert f.sdf[tuple(c)] > 0 and np.isinf(f.geodesic).sum() > 0
