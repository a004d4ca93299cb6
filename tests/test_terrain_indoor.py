"""Indoor crops: embedded procedural houses and the 3D-FRONT loader on small fixtures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cat.terrain import Front3DError, IndoorCfg, check_scene, load_front3d, make_house, make_indoor
from cat.terrain import furniture as fu
from cat.terrain.indoor import walkable_floor

FIX = Path(__file__).parent / "fixtures" / "3dfront"
FUTURE = FIX / "future"


def _check_crop(s):
    assert s.kind == "indoor"
    np.testing.assert_allclose(s.bounds, [[-2.5, -2.5, 0], [2.5, 2.5, 2.0]])
    np.testing.assert_allclose(s.start, [0, 0, 0.75])
    assert s.mesh.is_watertight
    assert 1 <= len(s.goals) <= 12
    np.testing.assert_allclose(np.linalg.norm(s.goals[:, :2], axis=1), 2.0)
    assert 0.0 <= s.difficulty <= 1.0
    check_scene(s)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_embedded_crops(seed):
    s = make_indoor(seed)
    _check_crop(s)
    assert s.meta["primitive_parts"]  # built from closed convex parts, no re-meshing
    assert all(c.is_convex for c in s.mesh.split(only_watertight=False))


def test_deterministic():
    a, b = make_indoor(4), make_indoor(4)
    np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
    np.testing.assert_array_equal(a.goals, b.goals)
    assert a.meta["crop_center"] != make_indoor(5).meta["crop_center"]


def test_start_on_eroded_walkable_floor():
    """The start (crop centre) is on the floor minus furniture footprints eroded by 0.1 m (paper)."""
    house = make_house(np.random.default_rng([0, 4241]))  # the house make_indoor(0) builds
    walk, grid = walkable_floor(house, IndoorCfg())
    s = make_indoor(0)
    i, j = grid.index(np.r_[s.meta["crop_center"], 0.0])[:2]
    assert walk[i, j]
    assert s.clearance(np.array([[0.0, 0.0, 0.05]]))[0] >= 0.1 - 0.04  # up to one voxel of rasterisation


def test_furniture_dimensions():
    rng = np.random.default_rng(0)
    size = lambda parts: np.ptp(np.vstack([p.bounds for p in parts]), axis=0)  # noqa: E731
    np.testing.assert_allclose(size(fu.table()), [1.4, 0.8, 0.75])
    bed = size(fu.bed(rng))
    assert 1.95 <= bed[1] <= 2.1 and bed[2] == pytest.approx(1.0)
    chair = fu.chair(rng)
    seat_top = chair[0].bounds[1, 2]
    assert 0.43 <= seat_top <= 0.47 and 0.85 <= size(chair)[2] <= 0.95
    assert 1.7 <= size(fu.shelf(rng))[2] <= 1.9
    assert 1.5 <= size(fu.floor_lamp(rng))[2] <= 1.7
    for _ in range(20):
        assert size(fu.clutter(rng))[2] <= 0.28  # low enough to step over
    for part in fu.sofa(rng) + fu.dining_set(rng):
        assert part.is_watertight and part.is_convex


def test_front3d_fixture():
    house = load_front3d(FIX / "house.json", FUTURE)
    assert house.name == "fixture-house"
    assert house.tags.count("furniture") == 3 and house.tags.count("arch") == 4  # ceiling skipped
    np.testing.assert_allclose(house.floor.bounds, [[0, -5, 0], [6, 0, 0]])  # y-up -> z-up
    table = house.parts[house.tags.index("furniture")]
    np.testing.assert_allclose(table.bounds, [[3.3, -3.9, 0], [4.7, -3.1, 0.75]], atol=1e-6)
    stool = house.parts[-1]  # rotated 45 degrees about the up axis
    np.testing.assert_allclose(np.ptp(stool.bounds[:, :2], axis=0), 0.35 * np.sqrt(2), atol=1e-6)
    s = make_indoor(0, house=house)
    _check_crop(s)
    assert s.meta["remeshed"]  # open wall quads -> re-meshed from voxels to be watertight


def test_front3d_room_filter():
    with pytest.raises(Front3DError, match="no Floor"):
        load_front3d(FIX / "house.json", FUTURE, rooms=["Bedroom-9"])
    assert len(load_front3d(FIX / "house.json", FUTURE, rooms=["LivingRoom"]).parts) == 7


@pytest.mark.parametrize(
    "name, match",
    [
        ("house_malformed.json", r"house_malformed\.json: invalid JSON"),
        ("house_no_scene.json", r"house_no_scene\.json: not a 3D-FRONT house"),
        ("house_missing_model.json", r"missing-9999/raw_model\.obj: 3D-FUTURE model not found"),
        ("house_broken_model.json", r"broken-0004/raw_model\.obj"),
        ("nope.json", r"nope\.json: 3D-FRONT house file not found"),
    ],
)
def test_front3d_errors(name, match):
    with pytest.raises(Front3DError, match=match):
        load_front3d(FIX / name, FUTURE)


def test_front3d_skip_missing_models():
    house = load_front3d(FIX / "house_missing_model.json", FUTURE, missing_models="skip")
    assert house.tags.count("furniture") == 3
