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


def test_the_viewer_draws_the_g1_visual_meshes(tmp_path, monkeypatch, robot_cfg):
    """One decimated mesh per body of the simulated model, cached: a second call reads the same meshes back."""
    import mujoco

    from cat.deploy.robot_mesh import visual_meshes
    from cat.envs.scene import build_env_model

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    meshes = visual_meshes(robot_cfg, keep=0.1)
    model = build_env_model(robot_cfg)  # the runtime's model: visual meshes stripped, same bodies
    assert len(meshes) >= 20
    assert all(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, m.body) >= 0 for m in meshes)
    tris = sum(len(m.mesh.faces) for m in meshes)
    assert 10_000 < tris < 80_000  # ~390 k as shipped
    again = visual_meshes(robot_cfg, keep=0.1)
    assert len(list((tmp_path / "cat").glob("g1_visual_*.npz"))) == 1
    for a, b in zip(meshes, again, strict=True):
        assert a.body == b.body
        np.testing.assert_allclose(a.mesh.vertices, b.mesh.vertices, atol=1e-6)
    # the pelvis mesh sits around the pelvis (its frame), not at the world origin of another body
    pelvis = next(m for m in meshes if m.body == "pelvis").mesh
    assert np.linalg.norm(pelvis.bounds.mean(axis=0)) < 0.2
