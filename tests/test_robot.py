"""The G1 description and its MuJoCo model."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from cat.envs.robot import (
    FLOOR_BIT,
    OBSTACLE_BIT,
    MenagerieModelError,
    compile_model,
    home_qpos,
    load_robot_cfg,
    robot_spec,
)
from cat.envs.scene import build_env_model


def test_model_has_29_actuators_and_13_query_links(robot_cfg):
    model = compile_model(robot_spec(robot_cfg))
    assert model.nu == 29
    assert [model.actuator(i).name for i in range(model.nu)] == robot_cfg.joint_names
    assert len(robot_cfg.query_links) == 13
    for link in robot_cfg.query_links:
        site = model.site("query_" + link.name)
        assert model.body(int(site.bodyid[0])).name == link.body
        np.testing.assert_allclose(site.pos, link.offset)
    # the documented 13: the released code's 11 sites plus both elbows
    names = {q.name for q in robot_cfg.query_links}
    assert {"head", "pelvis", "torso", "left_elbow", "right_elbow", "left_knee", "right_palm"} <= names


def test_gains_and_torque_limits_follow_yaml(robot_cfg):
    model = compile_model(robot_spec(robot_cfg))
    np.testing.assert_allclose(model.actuator_gainprm[:, 0], robot_cfg.kp)
    np.testing.assert_allclose(-model.actuator_biasprm[:, 2], robot_cfg.kd)
    np.testing.assert_allclose(model.actuator_forcerange[:, 1], robot_cfg.torque_limit)
    assert model.opt.timestep == pytest.approx(robot_cfg.timestep)


def test_pd_servo_holds_a_suspended_joint(robot_cfg):
    """With gravity off, a position servo drives each joint to its target (checks the PD sign convention)."""
    model = compile_model(robot_spec(robot_cfg))
    model.opt.gravity[:] = 0
    data = mujoco.MjData(model)
    data.qpos[:] = home_qpos(robot_cfg)
    target = robot_cfg.default_joint_pos + 0.1
    data.ctrl[:] = target
    for _ in range(400):
        mujoco.mj_step(model, data)
    err = np.abs(data.qpos[7:] - target)
    legs = robot_cfg.policy_joint_ids
    assert err[legs].max() < 0.02


def test_collision_bits(robot_cfg):
    model = compile_model(robot_spec(robot_cfg))
    for name in robot_cfg.collision_geoms:
        g = model.geom(name)
        assert g.contype & OBSTACLE_BIT and g.conaffinity == 0
    assert model.geom("floor").conaffinity == FLOOR_BIT


def test_robot_standing_touches_floor_with_feet_only(robot_cfg):
    model = build_env_model(robot_cfg)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    for _ in range(20):
        mujoco.mj_step(model, data)
    touching = {model.geom(c.geom1).name for c in data.contact[: data.ncon]} | {
        model.geom(c.geom2).name for c in data.contact[: data.ncon]
    }
    assert touching and all("foot" in n or n == "floor" for n in touching)


def test_missing_menagerie_model_says_how_to_fix(tmp_path, monkeypatch):
    monkeypatch.setenv("MENAGERIE_ROOT", str(tmp_path))
    with pytest.raises(MenagerieModelError, match="MENAGERIE_ROOT"):
        robot_spec(load_robot_cfg())


def test_bad_robot_yaml(tmp_path):
    with pytest.raises(FileNotFoundError, match="robot description not found"):
        load_robot_cfg(tmp_path / "nope.yaml")
