"""Scene format: save/load, user meshes, bad input, voxel conventions, Perlin noise."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from cat.terrain import GOAL_HEIGHT, Scene, SceneError, check_scene
from cat.terrain.noise import Perlin2D
from cat.terrain.primitives import box, combine, crop_parts
from cat.terrain.voxel import GridSpec, occupancy, occupancy_to_mesh, reachable


def _pillar_scene() -> Scene:
    mesh = box((0.81, -0.31, 0.0), (1.21, 0.31, 1.5))  # faces off voxel centres: occupancy is unambiguous
    return Scene(mesh=mesh, bounds=[[-0.5, -1, 0], [2.5, 1, 1.5]], start=[0, 0], goals=[[2, 0]], kind="test")


def test_save_load_roundtrip(tmp_path):
    scene = _pillar_scene()
    scene.save(tmp_path / "s")
    loaded = Scene.load(tmp_path / "s")
    assert loaded.kind == "test" and loaded.difficulty == 0.0
    np.testing.assert_allclose(loaded.start, [0, 0, GOAL_HEIGHT])
    np.testing.assert_allclose(loaded.goals, [[2, 0, GOAL_HEIGHT]])
    np.testing.assert_allclose(loaded.mesh.vertices, scene.mesh.vertices)
    assert loaded.mesh.is_watertight
    raw = json.loads((tmp_path / "s" / "scene.json").read_text())
    assert raw["grid"] == {"origin": [-0.5, -1.0, 0.0], "voxel": 0.04, "shape": [75, 50, 38]}
    # the occupancy cache round-trips and equals re-voxelising the mesh
    assert 0.04 in loaded._occ
    np.testing.assert_array_equal(loaded.occupancy(), occupancy(loaded.mesh, loaded.grid()))
    (tmp_path / "s" / "occupancy.npz").write_bytes(b"garbage")
    again = Scene.load(tmp_path / "s")
    assert 0.04 not in again._occ and again.occupancy().sum() == loaded.occupancy().sum()


def test_grid_convention_and_occupancy():
    grid = GridSpec.from_bounds(np.array([[0, 0, 0], [0.4, 0.4, 0.4]]), 0.04)
    assert grid.shape == (10, 10, 10)
    np.testing.assert_allclose(grid.axes()[0][:2], [0.02, 0.06])
    occ = occupancy(box((0.0, 0.0, 0.0), (0.2, 0.4, 0.4)), grid)
    assert occ[:5].all() and not occ[5:].any()  # centres 0.02..0.18 inside, 0.22.. outside


def test_occupancy_to_mesh_watertight_and_consistent():
    grid = GridSpec.from_bounds(np.array([[0, 0, 0], [1, 1, 1]]), 0.04)
    occ = np.zeros(grid.shape, dtype=bool)
    occ[5:15, 5:20, 0:10] = True  # touches the floor: padding closes it
    occ[12:20, 12:14, 5:20] = True
    mesh = occupancy_to_mesh(occ, grid)
    assert mesh.is_watertight and mesh.is_volume
    np.testing.assert_array_equal(occupancy(mesh, grid), occ)


def test_from_mesh_formats(tmp_path):
    m = box((0.8, -0.3, 0.0), (1.2, 0.3, 1.5))
    for ext in ("obj", "ply", "stl"):
        path = tmp_path / f"pillar.{ext}"
        m.export(path)
        scene = Scene.from_mesh(path, start=(0, 0), goal=(2, 0), check=True)
        assert len(scene.mesh.faces) == 12
        assert scene.bounds[0, 2] == 0.0 and scene.bounds[1, 2] >= 1.5
        assert scene.reachable_goals().all()


@pytest.mark.parametrize(
    "content, match",
    [
        ("", "no triangles"),
        ("hello, I am not a mesh\n", "no triangles|could not read"),
        ("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "NaN"),
    ],
)
def test_bad_user_mesh(tmp_path, content, match):
    path = tmp_path / "bad.obj"
    path.write_text(content)
    out = tmp_path / "out"
    with pytest.raises(SceneError, match=match) as err:
        Scene.from_mesh(path, start=(0, 0), goal=(2, 0)).save(out)
    assert "bad.obj" in str(err.value)
    assert not out.exists()


def test_bad_user_mesh_other_cases(tmp_path):
    with pytest.raises(SceneError, match="not found"):
        Scene.from_mesh(tmp_path / "missing.ply", (0, 0), (1, 0))
    (tmp_path / "a.txt").write_text("1 2 3")
    with pytest.raises(SceneError, match="unsupported mesh format"):
        Scene.from_mesh(tmp_path / "a.txt", (0, 0), (1, 0))
    (tmp_path / "b.ply").write_bytes(b"\x00\x01garbage")
    with pytest.raises(SceneError, match="b.ply"):
        Scene.from_mesh(tmp_path / "b.ply", (0, 0), (1, 0))
    good = tmp_path / "c.obj"
    box((0, 0, 0), (1, 1, 1)).export(good)
    with pytest.raises(SceneError, match="start"):
        Scene.from_mesh(good, (np.nan, 0), (3, 0))


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(SceneError, match="scene.json"):
        Scene.load(tmp_path)
    (tmp_path / "scene.json").write_text("{not json")
    with pytest.raises(SceneError, match="invalid JSON"):
        Scene.load(tmp_path)
    _pillar_scene().save(tmp_path / "s")
    (tmp_path / "s" / "mesh.ply").unlink()
    with pytest.raises(SceneError, match="mesh.ply"):
        Scene.load(tmp_path / "s")


def test_check_scene_rejects_blocked_goal():
    wall = box((0.9, -1.0, 0.0), (1.0, 1.0, 1.5))
    scene = Scene(mesh=wall, bounds=[[-0.5, -1, 0], [2.5, 1, 1.5]], start=[0, 0], goals=[[2, 0]])
    assert not scene.reachable_goals().any()
    with pytest.raises(SceneError, match="not reachable"):
        check_scene(scene)
    inside = Scene(mesh=wall, bounds=scene.bounds, start=[0, 0], goals=[[0.95, 0]])
    with pytest.raises(SceneError, match="too close"):
        check_scene(inside)


def test_parts_thinner_than_the_grid_are_reported(caplog):
    """A 1 cm floor strip holds no voxel centre of the 4 cm grid (centres at 2, 6, ... cm): the scene reports it
    and check_scene warns; a 6 cm strip is seen."""
    thin = box((0.9, -1.0, 0.0), (1.1, 1.0, 0.01))
    scene = Scene(
        mesh=combine([thin]),
        bounds=np.array([[-0.5, -1.0, 0.0], [2.5, 1.0, 1.5]]),
        start=np.array([0.0, 0.0, GOAL_HEIGHT]),
        goals=np.array([[2.0, 0.0, GOAL_HEIGHT]]),
    )
    (bounds,) = scene.unseen_parts()
    np.testing.assert_allclose(bounds, [[0.9, -1.0, 0.0], [1.1, 1.0, 0.01]], atol=1e-9)
    assert not scene.occupancy().any()
    with caplog.at_level("WARNING"):
        check_scene(scene)
    assert "hold no voxel centre" in caplog.text
    thick = Scene(
        mesh=combine([box((0.9, -1.0, 0.0), (1.1, 1.0, 0.06))]),
        bounds=scene.bounds,
        start=scene.start,
        goals=scene.goals,
    )
    assert thick.unseen_parts() == [] and thick.occupancy().any()


def test_mirrored_scene_is_the_reflection():
    """Scene.mirrored reflects y: the occupancy is the flipped occupancy (the typical grid is symmetric about
    y = 0), the mesh stays closed with the same volume, start region / start / goals follow, and twice is the
    original."""
    from cat.terrain import typical_variants

    scene = typical_variants("side-pass", 10, seed=0)[4]
    m = scene.mirrored()
    assert m.mesh.is_watertight and m.mesh.volume == pytest.approx(scene.mesh.volume)
    np.testing.assert_array_equal(m.occupancy(), scene.occupancy()[:, ::-1])
    np.testing.assert_allclose(m.bounds, scene.bounds)  # symmetric bounds stay put
    np.testing.assert_allclose(m.goals, scene.goals * [1, -1, 1])
    np.testing.assert_allclose(m.start_region, [[-0.3, -0.3], [0.1, 0.3]])
    check_scene(m)
    back = m.mirrored()
    np.testing.assert_allclose(back.mesh.vertices, scene.mesh.vertices)
    assert back.meta.get("mirrored") is False and m.meta["mirrored"] is True
    lopsided = Scene(mesh=scene.mesh, bounds=[[-0.5, -1.0, 0], [2.5, 1.5, 1.5]], start=[0, 0.2], goals=[[2, 0.4]])
    lm = lopsided.mirrored()
    np.testing.assert_allclose(lm.bounds, [[-0.5, -1.5, 0], [2.5, 1.0, 1.5]])
    np.testing.assert_allclose(lm.start_region, [[-0.1, -0.3], [0.1, -0.1]])


def test_reachability_model():
    """A humanoid steps over low bars and crouches under 1 m ceilings, but not under a table."""
    grid = GridSpec.from_bounds(np.array([[-0.5, -1, 0], [2.5, 1, 1.5]]))
    start, goal = np.array([0, 0, 0.75]), np.array([[2, 0, 0.75]])
    cases = {
        "bar top 0.25": (box((1, -1, 0), (1.2, 1, 0.25)), True),
        "bar top 0.45": (box((1, -1, 0), (1.2, 1, 0.45)), False),
        "low box 0.6 deep": (box((1, -1, 0), (1.6, 1, 0.2)), False),
        "low box 0.36 deep": (box((1, -1, 0), (1.36, 1, 0.2)), True),
        "ceiling at 1.0": (box((1, -1, 1.0), (1.6, 1, 1.5)), True),
        "table at 0.75": (box((1, -1, 0.71), (1.6, 1, 0.75)), False),
        "slit 0.32": (combine([box((1, -1, 0), (1.12, -0.16, 1.5)), box((1, 0.16, 0), (1.12, 1, 1.5))]), True),
        "slit 0.16": (combine([box((1, -1, 0), (1.12, -0.08, 1.5)), box((1, 0.08, 0), (1.12, 1, 1.5))]), False),
    }
    for name, (mesh, expect) in cases.items():
        assert reachable(occupancy(mesh, grid), grid, start, goal)[0] == expect, name


def test_crop_parts_keeps_convex_parts_closed():
    parts = crop_parts([box((-1, -1, 0), (1, 1, 3)), trimesh.creation.icosphere(radius=0.5)], (0, 0, 0), (2, 2, 2))
    assert len(parts) == 2
    for p in parts:
        assert p.is_watertight and p.is_convex
        assert np.all(p.bounds[0] >= -1e-9) and np.all(p.bounds[1] <= 2 + 1e-9)
    np.testing.assert_allclose(parts[0].volume, 2.0)


def test_perlin_noise():
    rng = np.random.default_rng(0)
    p = Perlin2D(rng, frequency=4.0)
    x, y = np.meshgrid(np.linspace(0, 2, 200), np.linspace(0, 2, 200))
    v = p(x, y)
    assert v.shape == x.shape and np.all(np.abs(v) <= 1.0 + 1e-9)
    assert 0.1 < v.std() < 0.5
    np.testing.assert_allclose(p(np.array([0.25]), np.array([0.5])), p(np.array([0.25]), np.array([0.5])))
    # continuous: neighbouring samples 1 cm apart differ little
    assert np.abs(np.diff(v, axis=1)).max() < 0.2
    q = Perlin2D(np.random.default_rng(0), frequency=4.0)
    np.testing.assert_array_equal(q(x, y), v)


def test_loaded_scene_reads_its_mesh_on_first_use(tmp_path):
    """A training set of hundreds of scenes keeps no meshes it never uses; a bad file still names itself."""
    scene = _pillar_scene()
    scene.save(tmp_path / "s")
    loaded = Scene.load(tmp_path / "s")
    assert "mesh" not in loaded.__dict__  # not read yet: the occupancy came from its cache
    np.testing.assert_array_equal(loaded.occupancy(), scene.occupancy())
    assert "mesh" not in loaded.__dict__
    assert len(loaded.mesh.faces) == len(scene.mesh.faces) and "mesh" in loaded.__dict__
    # the cache is bit-packed; each call hands out its own array
    bits, shape = loaded._occ[0.04]
    assert bits.dtype == np.uint8 and bits.size == (np.prod(shape) + 7) // 8
    a = loaded.occupancy()
    a[:] = True
    assert not loaded.occupancy().all()
    with pytest.raises(SceneError, match="does not match the scene grid"):
        loaded.set_occupancy(np.zeros((3, 3, 3), dtype=bool))
    # a corrupt mesh is found when it is read, and the error names the file
    (tmp_path / "s" / "mesh.ply").write_bytes(b"\x00\x01garbage")
    lazy = Scene.load(tmp_path / "s")
    with pytest.raises(SceneError, match="mesh.ply"):
        _ = lazy.mesh
    (tmp_path / "s" / "mesh.ply").unlink()
    with pytest.raises(SceneError, match="mesh file not found"):
        Scene.load(tmp_path / "s")
