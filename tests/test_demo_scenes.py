"""The click demo's scene loading: task spellings of the typical types, and a small mesh's map spans the robot's
field window (a goal beside a pillar is on the map)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from cat.deploy.scenes import MESH_REACH, GoalChecker, GoalError, load_scene
from cat.terrain import SceneError


def test_task_spelling_of_a_typical_type_is_accepted():
    a, b = load_scene("hurdle_crouch"), load_scene("hurdle-crouch")
    assert a.kind == b.kind == "hurdle-crouch"
    np.testing.assert_allclose(a.mesh.bounds, b.mesh.bounds)
    with pytest.raises(SceneError, match="not a typical type"):
        load_scene("hurdle_crouchh")


def test_a_small_mesh_maps_the_robots_window(tmp_path):
    pillar = tmp_path / "pillar.obj"
    trimesh.creation.box(bounds=[[0.6, -0.2, 0.0], [1.0, 0.2, 1.8]]).export(pillar)
    scene = load_scene(str(pillar))
    assert np.all(scene.bounds[0, :2] <= -MESH_REACH + 1e-9) and np.all(scene.bounds[1, :2] >= MESH_REACH - 1e-9)
    checker = GoalChecker(scene)
    np.testing.assert_allclose(checker.check((2.0, 0.0), (0.0, 0.0))[:2], (2.0, 0.0))  # behind the pillar
    with pytest.raises(GoalError, match="inside an obstacle"):
        checker.check((0.8, 0.0), (0.0, 0.0))
    with pytest.raises(GoalError, match="outside the map"):
        checker.check((4.0, 0.0), (0.0, 0.0))
