"""Compose the simulated scene: G1 + floor (+ obstacles) + the sensors the env reads."""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np

from cat.envs.robot import OBSTACLE_BODY, RobotCfg, compile_model, robot_spec

COLLISION_SENSOR = "robot_obstacle_contact"


def query_pos_sensor(name: str) -> str:
    return f"qpos_{name}"


def query_vel_sensor(name: str) -> str:
    return f"qvel_{name}"


def foot_contact_sensor(foot_body: str) -> str:
    return f"floor_contact_{foot_body}"


def foot_obstacle_sensor(foot_body: str) -> str:
    return f"obstacle_contact_{foot_body}"


GHOST_IMPEDANCE = 1.0e-4
"""solimp d of ghost obstacle contacts (MuJoCo's lowest impedance)."""
GHOST_SOLREF = (-1.0e-6, -1.0e-6)
"""Direct (negative) stiffness and damping of ghost contacts: ~0, so nothing pushes the robot out."""


def make_obstacles_ghost(model: mujoco.MjModel) -> int:
    """Obstacle contacts stay in ``mjData.contact`` (the collision sensor counts them) but carry no force worth
    the name: impedance 1e-4 and ~zero direct stiffness / damping, with a higher ``geom_priority`` so the
    obstacle's parameters, not a mix with the robot's, set each contact. Returns the number of geoms changed."""
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBSTACLE_BODY)
    if body < 0:
        return 0
    geoms = np.flatnonzero(model.geom_bodyid == body)
    model.geom_solimp[geoms, 0:2] = GHOST_IMPEDANCE
    model.geom_solref[geoms] = GHOST_SOLREF
    model.geom_priority[geoms] = model.geom_priority.max() + 1
    return len(geoms)


def make_feet_ghost(model: mujoco.MjModel, robot: RobotCfg) -> int:
    """Ghost contacts for the feet only: a foot's obstacle contacts are detected (its ``foot_obstacle_sensor``
    and the collision sensor count them) but exert no force, while the foot still stands on the floor and the
    rest of the body meets physical obstacles. MuJoCo takes a contact's parameters from the geom of higher
    ``geom_priority``: the foot geoms get ghost parameters one level above everything else, the floor one level
    above them, so floor contacts keep the floor's (normal) parameters and obstacle contacts take the feet's.
    Returns the number of foot geoms changed."""
    feet = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f) for f in robot.feet]
    if min(feet) < 0:
        raise ValueError(f"foot bodies {robot.feet} not all in the model")
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    if floor < 0:
        raise ValueError("make_feet_ghost needs the env's 'floor' geom")
    colliding = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    geoms = np.flatnonzero(np.isin(model.geom_bodyid, feet) & colliding)
    top = int(model.geom_priority.max())
    model.geom_solimp[geoms, 0:2] = GHOST_IMPEDANCE
    model.geom_solref[geoms] = GHOST_SOLREF
    model.geom_priority[geoms] = top + 1
    model.geom_priority[floor] = top + 2
    return len(geoms)


def build_env_model(
    robot: RobotCfg, add_obstacles: Callable[[mujoco.MjSpec], None] | None = None, visual_meshes: bool = False
) -> mujoco.MjModel:
    """Compile G1 + floor, optionally obstacles (``add_obstacles(spec)``), plus env sensors.

    The robot's visual meshes (200k vertices, no collision role, inertias are explicit) are dropped unless
    ``visual_meshes``: they make per-world model copies (domain randomisation) 500x slower.

    Sensors added (world frame): position and linear velocity of each query site, floor contact count per
    foot, and (when the spec has an ``obstacles`` body) the number of robot-obstacle contacts, in all and per
    foot.
    """
    return compile_model(env_spec(robot, add_obstacles, visual_meshes))


def env_spec(
    robot: RobotCfg,
    add_obstacles: Callable[[mujoco.MjSpec], None] | None = None,
    visual_meshes: bool = False,
    base: mujoco.MjSpec | None = None,
) -> mujoco.MjSpec:
    """The spec ``build_env_model`` compiles. ``base``: a robot spec (``robot_spec``, visual meshes already
    handled) to start from, copied, so many scene models skip reading the robot again."""
    if base is not None:
        spec = base.copy()
    else:
        spec = robot_spec(robot)
        if not visual_meshes:
            strip_visual_meshes(spec)
    if add_obstacles is not None:
        add_obstacles(spec)
    for site in robot.query_site_names:
        name = site.removeprefix("query_")
        spec.add_sensor(
            name=query_pos_sensor(name),
            type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=site,
        )
        spec.add_sensor(
            name=query_vel_sensor(name),
            type=mujoco.mjtSensor.mjSENS_FRAMELINVEL,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=site,
        )
    body, xbody, geom = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_XBODY, mujoco.mjtObj.mjOBJ_GEOM
    for foot in robot.feet:
        _contact_count_sensor(spec, foot_contact_sensor(foot), (body, foot), (geom, "floor"))
    if spec.body(OBSTACLE_BODY) is not None:
        _contact_count_sensor(spec, COLLISION_SENSOR, (xbody, robot.root_body), (body, OBSTACLE_BODY))
        for foot in robot.feet:  # which part touched (and the feet's share under task.ghost_feet)
            _contact_count_sensor(spec, foot_obstacle_sensor(foot), (body, foot), (body, OBSTACLE_BODY))
    return spec


def _contact_count_sensor(
    spec: mujoco.MjSpec, name: str, obj: tuple[mujoco.mjtObj, str], ref: tuple[mujoco.mjtObj, str]
) -> None:
    """A contact sensor whose one value is the number of contacts between ``obj`` and ``ref``."""
    spec.add_sensor(
        name=name,
        type=mujoco.mjtSensor.mjSENS_CONTACT,
        objtype=obj[0],
        objname=obj[1],
        reftype=ref[0],
        refname=ref[1],
        intprm=[1, 0, 1],  # data = found (contact count), no reduction, one slot
    )


def strip_visual_meshes(spec: mujoco.MjSpec) -> None:
    """Delete the robot's mesh geoms (visual only: contype = conaffinity = 0) and their mesh assets."""
    used = set()
    for geom in list(spec.geoms):
        if geom.type != mujoco.mjtGeom.mjGEOM_MESH:
            continue
        if geom.contype == 0 and geom.conaffinity == 0:
            spec.delete(geom)
        else:
            used.add(geom.meshname)
    for mesh in list(spec.meshes):
        if mesh.name not in used:
            spec.delete(mesh)
