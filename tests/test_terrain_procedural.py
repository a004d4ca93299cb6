"""Procedural obstacle scenes: watertight meshes, reachable goals, determinism, difficulty monotonicity."""

from __future__ import annotations

import numpy as np
import pytest

from cat.terrain import ProceduralCfg, SceneError, check_scene, make_procedural
from cat.terrain.procedural import _morphology
from cat.terrain.voxel import free_volume_fraction, occupancy


@pytest.mark.parametrize("difficulty", [0.0, 0.5, 1.0])
def test_valid(difficulty):
    s = make_procedural(difficulty, seed=2)
    assert s.kind == "procedural" and s.difficulty == difficulty
    assert s.mesh.is_watertight and s.mesh.is_volume
    np.testing.assert_allclose(s.bounds, [[-2.5, -2.5, 0], [2.5, 2.5, 1.6]])
    assert 1 <= len(s.goals) <= 12
    np.testing.assert_allclose(np.linalg.norm(s.goals[:, :2] - s.start[:2], axis=1), 2.0)
    check_scene(s)


def test_mesh_matches_occupancy(tmp_path):
    s = make_procedural(0.5, seed=1)
    s.save(tmp_path / "p")
    from cat.terrain import Scene

    loaded = Scene.load(tmp_path / "p")
    np.testing.assert_array_equal(occupancy(loaded.mesh, loaded.grid()), s.occupancy())
    assert loaded.reachable_goals().all()


def test_deterministic():
    a, b = make_procedural(0.6, seed=5), make_procedural(0.6, seed=5)
    np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
    np.testing.assert_array_equal(a.goals, b.goals)
    assert not np.array_equal(make_procedural(0.6, seed=6).occupancy(), a.occupancy())


@pytest.mark.parametrize("seed", [0, 3])
def test_difficulty_monotone(seed):
    scenes = [make_procedural(d, seed=seed) for d in np.linspace(0, 1, 5)]
    assert all(s.meta["attempt"] == 0 for s in scenes)
    free = [free_volume_fraction(s.occupancy()) for s in scenes]
    assert np.all(np.diff(free) < 0), free
    occ = [s.occupancy() for s in scenes]
    for lo, hi in zip(occ, occ[1:], strict=False):
        assert not (lo & ~hi).any()  # obstacles only grow with difficulty


def test_morphology_removes_spikes_and_holes():
    cfg = ProceduralCfg()
    occ = np.zeros((30, 30, 30), dtype=bool)
    occ[5:20, 5:20, 0:15] = True
    occ[10, 10, 5] = False  # pinhole: closed
    occ[25, 25, 25] = True  # isolated speck: opened away
    occ[20:27, 12, 8] = True  # 1-voxel spike: opened away
    out = _morphology(occ, cfg)
    assert out[10, 10, 5] and not out[25, 25, 25] and not out[23:27, 12, 8].any()
    assert out[6:19, 6:19, 0].all()  # still attached to the floor (opening only rounds edges)


def test_bad_difficulty():
    with pytest.raises(SceneError, match="difficulty"):
        make_procedural(-0.1, 0)
