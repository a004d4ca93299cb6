"""Compose the simulated scene: G1 + floor (+ obstacles) + the sensors the env reads."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from cat.envs.robot import OBSTACLE_BODY, RobotCfg, compile_model, robot_spec
from cat.envs.sim.base import COLLISION_SENSOR, PART_SENSOR_PREFIX
from cat.terrain.mujoco_export import obstacle_geom_ids

if TYPE_CHECKING:
    from cat.envs.config import EnvCfg


def query_pos_sensor(name: str) -> str:
    return f"qpos_{name}"


def query_vel_sensor(name: str) -> str:
    return f"qvel_{name}"


def foot_contact_sensor(foot_body: str) -> str:
    return f"floor_contact_{foot_body}"


def foot_axis_sensor(foot_body: str) -> str:
    """The foot body's x axis in the world frame (heel-to-toe direction)."""
    return f"xaxis_{foot_body}"


def part_obstacle_sensor(body: str) -> str:
    """Contacts between one robot body's geoms and the obstacles (which part touched; the feet's share under
    ``task.ghost_parts``)."""
    return f"{PART_SENSOR_PREFIX}{body}"


GHOST_IMPEDANCE = 1.0e-4
"""solimp d of ghost obstacle contacts (MuJoCo's lowest impedance)."""
GHOST_SOLREF = (-1.0e-6, -1.0e-6)
"""Direct (negative) stiffness and damping of ghost contacts: ~0, so nothing pushes the robot out."""


def make_obstacles_ghost(model: mujoco.MjModel) -> int:
    """Obstacle contacts stay in ``mjData.contact`` (the collision sensor counts them) but carry no force worth
    the name: impedance 1e-4 and ~zero direct stiffness / damping, with a higher ``geom_priority`` so the
    obstacle's parameters, not a mix with the robot's, set each contact. Returns the number of geoms changed."""
    return _make_geoms_ghost(model, obstacle_geom_ids(model))


def make_parts_ghost(model: mujoco.MjModel, bodies: Sequence[str]) -> int:
    """Ghost contacts for some robot bodies only (``task.ghost_parts``, e.g. feet and shanks): their obstacle
    contacts are detected (their ``part_obstacle_sensor`` and the collision sensor count them) but exert no
    force, while they still stand on the floor and the other bodies meet physical obstacles. MuJoCo takes a
    contact's parameters from the geom of higher ``geom_priority``: these bodies' geoms get ghost parameters
    one level above everything else, the floor one level above them, so floor contacts keep the floor's
    (normal) parameters and obstacle contacts take the ghost ones. Returns the number of geoms changed."""
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in bodies]
    unknown = [b for b, i in zip(bodies, ids, strict=True) if i < 0]
    if unknown:
        raise ValueError(f"ghost_parts: no body {unknown} in the robot model")
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    if floor < 0:
        raise ValueError("ghost parts need the env's 'floor' geom")
    colliding = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    n = _make_geoms_ghost(model, np.flatnonzero(np.isin(model.geom_bodyid, ids) & colliding))
    model.geom_priority[floor] = model.geom_priority.max() + 1
    return n


def make_training_ghosts(models: Sequence[mujoco.MjModel], cfg: EnvCfg, pool: int = 0) -> int:
    """Apply ``cfg.ghost_obstacles`` / ``cfg.ghost_parts`` to the env's models (one model, or the per-world table
    of ``pool`` members per scene, scene-major). Returns the pool members per scene whose parts stay physical."""
    physical = physical_pool_members(cfg, pool)
    for i, m in enumerate(models):
        if cfg.ghost_obstacles:
            make_obstacles_ghost(m)
        elif cfg.ghost_parts and not (physical and i % pool < physical):
            make_parts_ghost(m, cfg.ghost_parts)
    return physical


def physical_pool_members(cfg: EnvCfg, pool: int) -> int:
    """How many of each scene's ``pool`` per-world models (domain-randomisation members; 0: no per-world models)
    keep ``cfg.ghost_parts`` physical under ``cfg.ghost_parts_physical``; clear errors for what it needs."""
    frac = cfg.ghost_parts_physical
    if not 0.0 <= frac <= 1.0:
        raise ValueError(f"task.ghost_parts_physical={frac}: must be in [0, 1]")
    if frac == 0.0:
        return 0
    if not cfg.ghost_parts:
        raise ValueError("task.ghost_parts_physical needs task.ghost_parts (the parts it makes physical)")
    if pool < 1 or not cfg.domain_rand.enabled:
        raise ValueError(
            "task.ghost_parts_physical draws per episode among domain-randomisation pool members: it needs "
            "sim.per_world_scenes=true and task.domain_rand.enabled=true"
        )
    return round(frac * pool)


def _make_geoms_ghost(model: mujoco.MjModel, geoms: np.ndarray) -> int:
    """Ghost solver parameters on ``geoms``, one ``geom_priority`` level above every other geom so that theirs
    set each of their contacts. Returns the number of geoms changed."""
    top = model.geom_priority.max()
    model.geom_solimp[geoms, 0:2] = GHOST_IMPEDANCE
    model.geom_solref[geoms] = GHOST_SOLREF
    model.geom_priority[geoms] = top + 1
    return len(geoms)


def build_env_model(
    robot: RobotCfg, add_obstacles: Callable[[mujoco.MjSpec], None] | None = None, visual_meshes: bool = False
) -> mujoco.MjModel:
    """Compile G1 + floor, optionally obstacles (``add_obstacles(spec)``), plus env sensors.

    The robot's visual meshes (200k vertices, no collision role, inertias are explicit) are dropped unless
    ``visual_meshes``: they make per-world model copies (domain randomisation) 500x slower.

    Sensors added (world frame): position and linear velocity of each query site, floor contact count and x
    axis per foot, and (when the spec has an ``obstacles`` body) the number of robot-obstacle contacts, in all and per
    robot body with a collision geom.
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
        spec.add_sensor(
            name=foot_axis_sensor(foot), type=mujoco.mjtSensor.mjSENS_FRAMEXAXIS, objtype=xbody, objname=foot
        )
    if spec.body(OBSTACLE_BODY) is not None:
        _contact_count_sensor(spec, COLLISION_SENSOR, (xbody, robot.root_body), (xbody, OBSTACLE_BODY))
        wanted = set(robot.collision_geoms)
        for part in spec.bodies:  # every robot body with a collision geom
            if any(g.name in wanted for g in part.geoms):
                _contact_count_sensor(spec, part_obstacle_sensor(part.name), (body, part.name), (xbody, OBSTACLE_BODY))
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


def model_composer(robot: RobotCfg) -> Callable[[Callable[[mujoco.MjSpec], None]], mujoco.MjModel]:
    """``compose(add_obstacles)``: the env model of ``robot`` (visual meshes stripped, the robot read once) with
    the obstacles ``add_obstacles`` puts on the spec. Handed to the physics layer (``SlotTable.build``), which
    composes its slot model this way without importing the env."""
    base = robot_spec(robot)
    strip_visual_meshes(base)
    return lambda add_obstacles: env_spec(robot, add_obstacles, base=base).compile()
