"""Ghost obstacles (``task.ghost_obstacles``) and ghost parts (``task.ghost_parts``): contacts are detected and
counted, but exert no force (for the named robot bodies only: the rest meets physical obstacles); evaluation always
meets physical obstacles."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch

from cat.envs.config import DomainRandCfg, EnvCfg
from cat.envs.mdp.terminations import collided
from cat.envs.robot import OBSTACLE_BODY, load_robot_cfg
from cat.envs.scene import (
    COLLISION_SENSOR,
    PART_SENSOR_PREFIX,
    build_env_model,
    foot_contact_sensor,
    make_obstacles_ghost,
    make_parts_ghost,
    part_obstacle_sensor,
)
from cat.envs.scene_set import SceneSet
from cat.envs.traversal_env import TraversalEnv
from cat.eval.runner import EvalCfg, eval_task
from cat.terrain import typical_variants
from cat.terrain.mujoco_export import add_obstacles_to_spec
from cat.terrain.typical import warmup_variants


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


FEET = ["left_ankle_roll_link", "right_ankle_roll_link"]
LOWER_LEGS = [*FEET, "left_knee_link", "right_knee_link"]


def _feet_in_the_warmup_bar(ghost_feet: bool):
    """The G1 standing with both feet inside the easiest hurdle-pass warm-up bar (4.5 cm high)."""
    robot = load_robot_cfg()
    scene = warmup_variants("hurdle-pass", 1, 0)[0]
    model = build_env_model(robot, lambda spec: add_obstacles_to_spec(spec, scene))
    if ghost_feet:
        assert make_parts_ghost(model, FEET) == 8  # a box and three capsules per foot
    data = mujoco.MjData(model)
    bar = min(scene.mesh.split(only_watertight=False), key=lambda p: p.bounds[1, 2]).bounds
    data.qpos[0] = 0.5 * (bar[0, 0] + bar[1, 0]) - 0.04  # the foot centre (4 cm ahead of the ankle) on the bar
    data.qpos[2] = 0.79
    mujoco.mj_forward(model, data)
    return robot, model, data


def test_ghost_feet_pass_through_the_bar_and_stand_on_the_floor():
    for ghost in (False, True):
        robot, model, data = _feet_in_the_warmup_bar(ghost)
        sensor = {n: data.sensordata[model.sensor_adr[model.sensor(n).id]] for n in (COLLISION_SENSOR,)}
        feet = [data.sensordata[model.sensor_adr[model.sensor(part_obstacle_sensor(f)).id]] for f in robot.feet]
        assert min(feet) > 0 and sensor[COLLISION_SENSOR] == sum(feet)  # both feet, nothing else, touch
        weight = 9.81 * model.body_subtreemass[model.body(robot.root_body).id]
        normal = 0.0
        for _ in range(100):  # 0.2 s
            mujoco.mj_step(model, data)
            normal = max(normal, _obstacle_normal_force(model, data)[1])
        floor = [data.sensordata[model.sensor_adr[model.sensor(foot_contact_sensor(f)).id]] for f in robot.feet]
        if ghost:
            assert normal < 1e-3 * weight  # the bar does not push the feet
            assert min(floor) > 0 and data.qpos[2] > 0.75  # both feet still stand on the floor
        else:
            assert normal > 0.5 * weight  # the bar shoves the feet out


def test_ghost_feet_leave_the_rest_of_the_body_physical():
    """Feet and shins inside the paper's first hurdle-crouch bar: only the feet's contacts go soft."""
    robot = load_robot_cfg()
    scene = typical_variants("hurdle-crouch", 1, 0)[0]
    model = build_env_model(robot, lambda spec: add_obstacles_to_spec(spec, scene))
    make_parts_ghost(model, FEET)
    data = mujoco.MjData(model)
    bar = scene.mesh.split(only_watertight=False)[0].bounds
    data.qpos[0] = 0.5 * (bar[0, 0] + bar[1, 0])
    data.qpos[2] = 0.78
    mujoco.mj_forward(model, data)
    mujoco.mj_step(model, data)
    feet = {model.body(f).id for f in robot.feet}
    body = model.body(OBSTACLE_BODY).id
    force, by_part = np.zeros(6), {"foot": [], "other": []}
    for k, c in enumerate(data.contact[: data.ncon]):
        parts = {model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]}
        if body in parts:
            mujoco.mj_contactForce(model, data, k, force)
            by_part["foot" if parts & feet else "other"].append(abs(force[0]))
    assert by_part["foot"] and by_part["other"]
    assert max(by_part["foot"]) < 1.0 and max(by_part["other"]) > 10.0


def test_env_ghost_parts_are_a_collision_that_does_not_end_the_episode():
    scenes = SceneSet.typical("hurdle-pass", 3, variants=1, warmup=1, per_world=True)
    cfg = EnvCfg(num_envs=3, ghost_parts=LOWER_LEGS, domain_rand=DomainRandCfg(enabled=False))
    cfg.terminations.on_collision = True
    env = TraversalEnv(cfg, scenes=scenes, seed=0)
    assert env.scenes.scene_of_env[0] == 0 and env.scenes.scenes[0].difficulty == -1.0  # the 4.5 cm bar
    env.scenes.assign_scenes(torch.tensor([2]), torch.tensor([0]))
    qpos, qvel = env.sim.qpos[[0, 2]].clone(), env.sim.qvel[[0, 2]].clone()
    qpos[:, 3:7] = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=qpos.dtype)
    qpos[0, :3] = torch.tensor([0.47 - 0.04, 0.0, 0.79], dtype=qpos.dtype)  # env 0: feet in the bar
    qpos[1, :3] = torch.tensor([0.47, 0.0, 0.50], dtype=qpos.dtype)  # env 2: crouched into it, pelvis touches
    env.sim.reset(torch.tensor([0, 2]), qpos, qvel)
    env._update_state()
    s = env.state
    assert s.collision[0] and not s.hard_collision[0] and not collided(env)[0]
    assert s.collision[2] and s.hard_collision[2] and collided(env)[2]
    for _ in range(5):  # 0.1 s standing in the bar: every substep's feet contacts, never a hard one
        _, _, dones, _ = env.step(torch.zeros(3, 12))
        assert env.state.collision[0] and not env.state.hard_collision[0] and not dones[0]
    assert env.trial.collided[0]  # counted against success, the episode goes on
    with pytest.raises(ValueError, match=r"ghost_parts: no body \['torso'\] in the robot model"):
        TraversalEnv(EnvCfg(num_envs=1, ghost_parts=["torso"]), scenes=scenes, seed=0)
    with pytest.raises(ValueError, match=r"ghost_parts \['left_hip_pitch_link'\] have no collision geom"):
        TraversalEnv(EnvCfg(num_envs=1, ghost_parts=["left_hip_pitch_link"]), scenes=scenes, seed=0)


def test_every_collision_body_has_an_obstacle_contact_sensor_reduced_over_substeps():
    """The parts' counts are maxima over a control step's substeps, like the total: a last-substep count would
    miss feet contacts of earlier substeps, and total minus feet would read them as a hard collision."""
    scenes = SceneSet.typical("hurdle-pass", 2, variants=1, warmup=1, per_world=True)
    env = TraversalEnv(EnvCfg(num_envs=2), scenes=scenes, seed=0)
    model = env.sim.model
    bodies = {model.body(model.geom_bodyid[model.geom(g).id]).name for g in env.robot.collision_geoms}
    parts = {n.removeprefix(PART_SENSOR_PREFIX) for n in env.sim.sensors if n.startswith(PART_SENSOR_PREFIX)}
    assert parts == bodies and set(env.robot.feet) <= parts
    maxed = set(env.sim.max_columns)
    for name in [COLLISION_SENSOR] + [part_obstacle_sensor(p) for p in parts]:
        assert env.sim.sensors[name].adr in maxed


def test_evaluation_is_physical_for_ghost_parts_too():
    evaluated = eval_task(EnvCfg(ghost_parts=FEET, ghost_parts_physical=0.5), 4, EvalCfg())
    assert evaluated.ghost_parts == [] and evaluated.ghost_parts_physical == 0.0


def test_a_share_of_pool_members_keeps_the_ghost_parts_physical():
    """``ghost_parts_physical=0.5`` with a pool of 2: member 0 of each scene keeps the feet and shanks physical
    (feet in the bar are a hard collision), member 1 has them ghost (the same contact is not)."""
    scenes = SceneSet.typical("hurdle-pass", 2, variants=1, warmup=1, per_world=True)
    dr = DomainRandCfg(enabled=True, pool_size=2)
    cfg = EnvCfg(num_envs=2, ghost_parts=LOWER_LEGS, ghost_parts_physical=0.5, domain_rand=dr)
    env = TraversalEnv(cfg, scenes=scenes, seed=0)
    wm = env.world_models
    foot = env.sim.model.geom("left_foot1_collision").id
    ghost_ref = [float(wm.models[wm.ids(torch.tensor([0]), torch.tensor([k]))].geom_solref[foot, 0]) for k in (0, 1)]
    assert ghost_ref[0] > 0 and ghost_ref[1] < 0  # member 0: the robot's own contact, member 1: ghost
    ids = torch.tensor([0, 1])
    env.scenes.assign_scenes(ids, torch.tensor([0, 0]))  # both on the 4.5 cm warm-up bar
    env.sim.assign_models(ids, wm.ids(torch.tensor([0, 0]), torch.tensor([0, 1])))
    qpos, qvel = env.sim.qpos.clone(), env.sim.qvel.clone()
    qpos[:, 3:7] = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=qpos.dtype)
    qpos[:, :3] = torch.tensor([0.47 - 0.04, 0.0, 0.79], dtype=qpos.dtype)  # feet in the bar
    env.sim.reset(ids, qpos, qvel)
    env._update_state()
    assert env.state.collision.all()
    assert env.state.hard_collision.tolist() == [True, False]
    bad = [
        (dict(ghost_parts_physical=1.5), r"ghost_parts_physical=1.5: must be in \[0, 1\]"),
        (dict(ghost_parts=[], ghost_parts_physical=0.5), "needs task.ghost_parts"),
        (dict(ghost_parts_physical=0.5, domain_rand=DomainRandCfg(enabled=False)), "needs sim.per_world_scenes"),
    ]
    for kw, message in bad:
        with pytest.raises(ValueError, match=message):
            TraversalEnv(EnvCfg(num_envs=2, **{"ghost_parts": LOWER_LEGS, "domain_rand": dr, **kw}), scenes=scenes)
