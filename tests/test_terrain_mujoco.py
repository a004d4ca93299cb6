"""MuJoCo export: obstacles as convex parts on one static body that collides with the G1's capsules."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import trimesh

from cat.terrain import Scene, make_indoor, make_typical
from cat.terrain import mujoco_export as mx
from cat.terrain.primitives import box
from cat.terrain.voxel import GridSpec, occupancy_to_mesh


def test_constants_have_one_definition():
    from cat.envs import robot

    assert robot.OBSTACLE_BODY is mx.OBSTACLE_BODY and robot.OBSTACLE_BIT is mx.OBSTACLE_BIT


def _model(robot_cfg, obstacles):
    from cat.envs.robot import compile_model, robot_spec

    spec = robot_spec(robot_cfg)
    n = mx.add_obstacles_to_spec(spec, obstacles)
    return compile_model(spec), n


def _obstacle_contacts(model, robot_cfg, xy, yaw=0.0) -> int:
    from cat.envs.robot import home_qpos

    data = mujoco.MjData(model)
    data.qpos[:] = home_qpos(robot_cfg)
    data.qpos[:2] = xy
    data.qpos[3:7] = [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
    mujoco.mj_forward(model, data)
    body = model.body(mx.OBSTACLE_BODY).id
    return sum(1 for c in data.contact[: data.ncon] if body in (model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]))


def test_typical_contacts(robot_cfg):
    scene = make_typical("hurdle-crouch", 0.5, seed=0)
    model, n = _model(robot_cfg, scene)
    assert n == len(scene.mesh.split(only_watertight=False))  # primitive parts used directly
    body = model.body(mx.OBSTACLE_BODY)
    assert body.parentid[0] == 0 and model.body_dofnum[body.id] == 0  # static child of the world
    geoms = np.flatnonzero(model.geom_bodyid == body.id)
    assert np.all(model.geom_contype[geoms] == 0) and np.all(model.geom_conaffinity[geoms] == mx.OBSTACLE_BIT)
    assert np.all(model.geom_condim[geoms] == 3)
    assert _obstacle_contacts(model, robot_cfg, (0.0, 0.0)) == 0  # standing at the start
    bar_x = scene.mesh.split(only_watertight=False)[0].bounds[:, 0].mean()
    assert _obstacle_contacts(model, robot_cfg, (bar_x, 0.0)) > 0  # legs through the hurdle bar


def test_indoor_contacts(robot_cfg):
    scene = make_indoor(1)
    model, n = _model(robot_cfg, scene)
    assert n > 5
    assert _obstacle_contacts(model, robot_cfg, scene.start[:2]) == 0


def test_pillar_contact_and_clear(robot_cfg):
    model, _ = _model(robot_cfg, [box((0.5, -0.2, 0.0), (0.9, 0.2, 1.5))])
    assert _obstacle_contacts(model, robot_cfg, (0.7, 0.0)) > 0
    assert _obstacle_contacts(model, robot_cfg, (-0.5, 0.0)) == 0


def _l_shape() -> trimesh.Trimesh:
    grid = GridSpec.from_bounds(np.array([[0, -0.6, 0], [1.2, 0.6, 1.2]]), 0.1)
    occ = np.zeros(grid.shape, dtype=bool)
    occ[2:10, 2:5, :10] = True
    occ[2:5, 2:10, :10] = True
    return occupancy_to_mesh(occ, grid)


def test_coacd_cached_and_collides(robot_cfg, tmp_path, monkeypatch):
    monkeypatch.setenv("CAT_CACHE_DIR", str(tmp_path))
    mesh = _l_shape()
    assert mesh.is_watertight and not mesh.is_convex
    parts = mx.convex_parts(mesh)
    assert len(parts) >= 2
    files = list((tmp_path / "coacd").glob("*.npz"))
    assert len(files) == 1 and files[0].stem == mx.mesh_hash(mesh, mx.CoacdCfg())
    again = mx.convex_parts(mesh)  # read back from the cache
    assert len(again) == len(parts)
    for a, b in zip(parts, again, strict=True):
        np.testing.assert_allclose(a.vertices, b.vertices)
    hull_volume = sum(p.convex_hull.volume for p in parts)
    assert hull_volume == pytest.approx(mesh.volume, rel=0.35)
    model, n = _model(robot_cfg, Scene(mesh=mesh, bounds=[[-1, -1, 0], [2, 1, 1.5]], start=[-0.5, 0], goals=[[1.5, 0]]))
    assert n == len(parts)
    assert _obstacle_contacts(model, robot_cfg, (0.5, 0.0)) > 0
    assert _obstacle_contacts(model, robot_cfg, (-0.6, 0.0)) == 0


def test_bad_part_rejected():
    spec = mujoco.MjSpec()
    bad = box((0, 0, 0), (1, 1, 1))
    bad.vertices[0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        mx.add_obstacles_to_spec(spec, [bad])
