"""Saved fields carry their FieldCfg and format version; stale ones are rebuilt or refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cat.envs.scene_set import SceneSet
from cat.fields import Field, FieldCfg, Grid, SceneFields, StaleFieldError, build_fields
from cat.fields.store import STORE_FILE
from cat.terrain import Scene, make_typical
from cat.terrain.dataset import build_fields as dataset_build_fields
from cat.terrain.dataset import fields_current

STALE = FieldCfg(xi=0.02, d0=0.4)  # other build constants than the defaults


def _grid(scene: Scene) -> Grid:
    g = scene.grid()
    return Grid(g.origin, g.voxel, g.shape)


@pytest.fixture(scope="module")
def scene():
    return make_typical("hurdle-crouch", 0.5, 0)


@pytest.fixture(scope="module")
def stale_fields(scene):
    return SceneFields.from_fields(build_fields(scene.occupancy(), _grid(scene), scene.goals, STALE))


def test_round_trip_keeps_values_cfg_and_version(tmp_path, stale_fields):
    path = stale_fields.save(tmp_path / "a.npz")
    back = SceneFields.load(path)
    assert back.cfg == STALE and back.grid == stale_fields.grid
    np.testing.assert_array_equal(back.force, stale_fields.force)
    np.testing.assert_array_equal(back.sdf_grad, stale_fields.sdf_grad)
    half = SceneFields.load(stale_fields.save(tmp_path / "h.npz", dtype="float16"))
    assert half.force.dtype == np.float16
    np.testing.assert_allclose(half.sdf_grad, stale_fields.sdf_grad, atol=2e-3)
    with np.load(path) as z:
        assert int(z["store_version"]) == 1 and json.loads(str(z["cfg"]))["xi"] == 0.02


def test_other_build_constants_are_stale(tmp_path, stale_fields, scene):
    path = stale_fields.save(tmp_path / STORE_FILE)
    with pytest.raises(StaleFieldError, match=r"d0 saved 0.4 != 0.3; xi saved 0.02 != 0.0068"):
        SceneFields.load(path, FieldCfg())
    SceneFields.load(path, FieldCfg(xi=0.02, d0=0.4, kappa_max=3.0))  # query-time constants do not matter
    with pytest.raises(StaleFieldError, match="other goals"):
        SceneFields.load(path, STALE, goals=scene.goals + 0.1)
    with pytest.raises(StaleFieldError, match="grid"):
        g = _grid(scene)
        SceneFields.load(path, STALE, grid=Grid(g.origin, g.voxel, (10, 10, 10)))


def test_field_load_checks_cfg(tmp_path, scene):
    f = build_fields(scene.occupancy(), _grid(scene), scene.goals[:1], STALE)[0]
    f.save(tmp_path / "goal_00.npz")
    assert Field.load(tmp_path / "goal_00.npz").cfg == STALE
    with pytest.raises(StaleFieldError, match="eta|xi"):
        Field.load(tmp_path / "goal_00.npz", FieldCfg())


def test_scene_set_rebuilds_or_refuses_stale_fields(tmp_path, scene, stale_fields):
    folder = tmp_path / "typical" / "hc"
    scene.save(folder)
    Scene.fields_dir(folder).mkdir()
    stale_fields.save(Scene.fields_dir(folder) / STORE_FILE)
    with pytest.raises(StaleFieldError, match="another field config"):
        SceneSet.from_dir(tmp_path, num_envs=2, on_stale="error")
    ss = SceneSet.from_dir(tmp_path, num_envs=2)  # rebuilt under the default config
    fresh = SceneFields.from_fields(build_fields(scene.occupancy(), _grid(scene), scene.goals, FieldCfg()))
    force = ss.bank.goal_data.view(*fresh.force.shape).numpy()
    np.testing.assert_allclose(force, fresh.force, rtol=1e-5, atol=1e-5)
    assert not np.allclose(force, stale_fields.force, atol=1e-3)
    # under the config they were built with, the saved fields are used as they are
    ss = SceneSet.from_dir(tmp_path, num_envs=2, field_cfg=STALE, on_stale="error")
    np.testing.assert_array_equal(ss.bank.goal_data.view(*fresh.force.shape).numpy(), stale_fields.force)


def test_gen_scenes_rebuilds_stale_fields(tmp_path, scene, stale_fields):
    folder = tmp_path / "hc"
    scene.save(folder)
    assert not fields_current(folder)  # no fields yet
    Scene.fields_dir(folder).mkdir()
    stale_fields.save(Scene.fields_dir(folder) / STORE_FILE)
    assert not fields_current(folder)
    assert dataset_build_fields(scene, folder)
    assert fields_current(folder)
    assert SceneFields.load(Scene.fields_dir(folder) / STORE_FILE, FieldCfg()).cfg == FieldCfg()
