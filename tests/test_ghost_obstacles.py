"""Ghost obstacles (``task.ghost_obstacles``): contacts are detected and counted, but exert no force; evaluation
always meets physical obstacles."""

from __future__ import annotations

import mujoco
import numpy as np

from cat.envs.config import EnvCfg
from cat.envs.robot import OBSTACLE_BODY, load_robot_cfg
from cat.envs.scene import COLLISION_SENSOR, build_env_model, make_obstacles_ghost
from cat.eval.runner import EvalCfg, eval_task
from cat.terrain import typical_variants
from cat.terrain.mujoco_export import add_obstacles_to_spec


def _robot_on_the_bar(ghost: bool):
    robot = load_robot_cfg()
    scene = typical_variants("hurdle-crouch", 1, 0)[0]
    model = build_env_model(robot, lambda spec: add_obstacles_to_spec(spec, scene))
    if ghost:
        assert make_obstacles_ghost(model) > 0
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0) if model.nkey else mujoco.mj_resetData(model, data)
    bar = scene.mesh.split(only_watertight=False)[0].bounds
    data.qpos[0] = 0.5 * (bar[0, 0] + bar[1, 0])  # pelvis over the bar: the feet are inside it
    data.qpos[2] = 0.78
    mujoco.mj_forward(model, data)
    return model, data


def _obstacle_normal_force(model, data) -> tuple[int, float]:
    """(number of robot-obstacle contacts, their summed normal force [N])."""
    body = model.body(OBSTACLE_BODY).id
    force, total, count = np.zeros(6), 0.0, 0
    for k, c in enumerate(data.contact[: data.ncon]):
        if body in (model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]):
            mujoco.mj_contactForce(model, data, k, force)
            total += abs(force[0])
            count += 1
    return count, total


def test_ghost_contacts_are_counted_but_exert_no_force():
    for ghost in (False, True):
        model, data = _robot_on_the_bar(ghost)
        robot_weight = 9.81 * model.body_subtreemass[model.body(load_robot_cfg().root_body).id]
        sensor = data.sensordata[model.sensor_adr[model.sensor(COLLISION_SENSOR).id]]
        count, normal = _obstacle_normal_force(model, data)
        assert sensor > 0 and count > 0  # the collision rule sees the touch either way
        for _ in range(100):  # 0.2 s
            mujoco.mj_step(model, data)
        if ghost:
            assert normal < 1e-3 * robot_weight  # nothing pushes the feet out of the bar
            assert data.qpos[2] > 0.7  # standing on the floor through the bar
        else:
            assert normal > robot_weight  # the bar shoves the feet out
            assert data.qpos[2] < 0.5  # and the robot falls over it


def test_evaluation_is_always_physical():
    task = EnvCfg(ghost_obstacles=True)
    assert eval_task(task, 4, EvalCfg()).ghost_obstacles is False
