"""Observation terms: each a function ``fn(env) -> (N, dim)`` with its declaration (``cat.envs.mdp.terms``).

The declaration on each function is everything the code knows about the term: its size, noise, mirror map,
whether a deployed robot computes it, its clip and meaning (ONNX metadata) and the config fixing its width. The
env concatenates terms per group (``cat.envs.obs_groups``); symmetry, export and the deploy runtime read the
same declarations. A new term is a function here with its ``@observation_term(...)`` (and a config that lists it
in a group; docs/extending.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from cat.envs.body_clearance import CLEARANCE_CLIP, clearance_bodies
from cat.envs.math_utils import rotate_yaw_inverse
from cat.envs.mdp.mirror import AXIAL, FIELD_LINK, POLAR, grid_mirror, joint_mirror, link_mirror
from cat.envs.mdp.terms import TermNoise, observation_term
from cat.envs.perception import map_shape, voxel_shape

if TYPE_CHECKING:
    from cat.envs.config import EnvCfg
    from cat.envs.robot import RobotCfg
    from cat.envs.traversal_env import TraversalEnv

GOAL_COMMAND_CLIP = 5.0  # goal_command: horizontal goal distance scaled to at most this [m]
NOISY = TermNoise()  # U(-s, s) added, s = NoiseCfg.<term>


# --- declaration helpers: sizes and mirror maps from (task, robot) ---------------------------------------
def _joints(task: EnvCfg, robot: RobotCfg):
    return joint_mirror(list(robot.joint_names))


def _legs(task: EnvCfg, robot: RobotCfg):
    return joint_mirror([robot.joint_names[i] for i in robot.policy_joint_ids])


def _links(per_link):
    return lambda task, robot: link_mirror([q.name for q in robot.query_links], per_link)


def _map_cells(task: EnvCfg) -> int:
    return int(np.prod(map_shape(task.perception.height_map)))


def _map_mirror(layers: int):
    return lambda task, robot: grid_mirror(map_shape(task.perception.height_map), layers=layers)


def _height_map_layout(task: EnvCfg) -> tuple:
    hm = task.perception.height_map
    return ("height_map", hm.length, hm.width, hm.resolution, hm.forward_offset)


def _voxel_layout(task: EnvCfg) -> tuple:
    vg = task.perception.voxel_grid
    return ("voxel_grid", vg.length, vg.width, vg.height, vg.resolution, vg.forward_offset)


def _field_layout(task: EnvCfg) -> tuple:
    return ("field_obs", bool(task.field_obs.enabled))  # off: the block reads zeros (w/o OBS_field)


def _field_clip(task: EnvCfg) -> float:
    return task.field_obs.sdf_clip


def _overhead_cap(task: EnvCfg) -> float:
    return task.perception.height_map.overhead_cap


def _field_size(task: EnvCfg, robot: RobotCfg) -> int:
    return 7 * len(robot.query_links)


def _num_joints(task: EnvCfg, robot: RobotCfg) -> int:
    return robot.num_joints


def _num_legs(task: EnvCfg, robot: RobotCfg) -> int:
    return len(robot.policy_joints)


# --- deployable (actor) terms ----------------------------------------------------------------------------
@observation_term(
    3, noise=NOISY, mirror=AXIAL, deployable=True, note="pelvis angular velocity in the pelvis frame [rad/s] (IMU gyro)"
)
def gyro(env: TraversalEnv) -> torch.Tensor:
    """Pelvis angular velocity in the pelvis frame (IMU gyro)."""
    return env.state.gyro


@observation_term(3, noise=NOISY, mirror=POLAR, deployable=True, note="unit gravity vector in the pelvis frame")
def projected_gravity(env: TraversalEnv) -> torch.Tensor:
    return env.state.gravity


@observation_term(
    _num_joints,
    noise=NOISY,
    mirror=_joints,
    deployable=True,
    note="joint angles minus default_joint_pos, joint_names order [rad]",
)
def joint_pos(env: TraversalEnv) -> torch.Tensor:
    """Joint angles relative to the default pose."""
    return env.state.joint_pos - env.default_joint_pos


@observation_term(
    _num_joints, noise=NOISY, mirror=_joints, deployable=True, note="joint velocities, joint_names order [rad/s]"
)
def joint_vel(env: TraversalEnv) -> torch.Tensor:
    return env.state.joint_vel


@observation_term(_num_legs, mirror=_legs, deployable=True, note="previous action after the action clip")
def last_action(env: TraversalEnv) -> torch.Tensor:
    return env.actions


@observation_term(
    _num_legs, mirror=_legs, deployable=True, note="PD targets of policy_joints minus their defaults [rad]"
)
def leg_targets(env: TraversalEnv) -> torch.Tensor:
    """Current incremental PD targets of the policy joints, relative to the default pose."""
    return env.targets[:, env.policy_ids] - env.default_joint_pos[:, env.policy_ids]


@observation_term(
    3,
    mirror=POLAR,
    deployable=True,
    clip=lambda task: GOAL_COMMAND_CLIP,
    note="goal minus root in the yaw frame (x, y, z) [m]; x, y scaled so their norm is at most clip",
)
def goal_command(env: TraversalEnv) -> torch.Tensor:
    """Goal relative to the root in the yaw frame (x, y, z), horizontal distance clipped to 5 m."""
    rel = rotate_yaw_inverse(env.state.yaw, env.goals - env.state.root_pos)
    dist = rel[:, :2].norm(dim=-1, keepdim=True)
    scale = torch.clamp(GOAL_COMMAND_CLIP / dist.clamp_min(1e-6), max=1.0)
    return torch.cat((rel[:, :2] * scale, rel[:, 2:]), dim=-1)


@observation_term(
    2,
    mirror=([0, 1], [-1.0, -1.0]),  # half a period: (sin, cos) -> (-sin, -cos)
    deployable=True,
    note="sin, cos of 2 pi phase; phase += gait freq * control_dt per step",
)
def gait_phase(env: TraversalEnv) -> torch.Tensor:
    angle = 2 * torch.pi * env.phase
    return torch.stack((torch.sin(angle), torch.cos(angle)), dim=-1)


@observation_term(
    _field_size,
    noise=NOISY,
    mirror=_links(FIELD_LINK),
    deployable=True,
    clip=_field_clip,
    layout=_field_layout,
    note="per query link: F_H (3), grad d (3) in the yaw frame, d clipped to +-clip [m]; refreshed at refresh_hz",
)
def field_block(env: TraversalEnv) -> torch.Tensor:
    """HumanoidPF at the 13 links (F_H, grad d, clipped d) in the yaw frame, refreshed at ``refresh_hz``."""
    return env.field_obs_buf.reshape(env.num_envs, -1)


@observation_term(
    _field_size,
    noise=TermNoise(shares="field_block"),  # one reading placed two ways: a teacher labels with the student's error
    mirror=_links(FIELD_LINK),  # a mirrored drift (dx, -dy, -dyaw) is as likely: the walk is isotropic
    deployable=True,  # on a robot the block comes from its odometry pose already: its field_block
    clip=_field_clip,
    layout=_field_layout,
    note="field_block at the links placed by the odometry pose (trained with a drifting pose error); on a robot, "
    "its field_block",
)
def field_block_odometry(env: TraversalEnv) -> torch.Tensor:
    """``field_block`` as the robot's odometry sees it: the field queried at the links displaced by a drifting
    pose error and turned into the drifted yaw frame (``cat.envs.odometry``; on with ``noise.enabled``). Without
    drift (noise off, or a robot whose field block already comes from its own odometry pose) it is ``field_block``.
    """
    if env.field_obs_odom_buf is None:
        return field_block(env)
    return env.field_obs_odom_buf.reshape(env.num_envs, -1)


# --- perception maps (baselines; a deployed robot reads them from its live map: cat.deploy.perception) ----
@observation_term(
    lambda task, robot: 2 * _map_cells(task),
    deployable=True,
    noise=NOISY,
    mirror=_map_mirror(2),
    clip=_overhead_cap,
    layout=_height_map_layout,
    note="ground then overhead layer of the yaw-frame height map [m], overhead capped at clip",
)
def elevation_map(env: TraversalEnv) -> torch.Tensor:
    """Two-layer elevation map around the robot (ground then overhead layer, each row-major along x, across y).

    World heights [m] of the obstacle tops below / undersides above each cell of a yaw-aligned grid
    (``perception.height_map``); the ASTraversal observation and the paper's w/o OBS_field replacement.
    """
    ground, overhead = env.perception.elevation(env.state.root_pos, env.state.yaw)
    return torch.cat((ground, overhead), dim=-1)


@observation_term(
    lambda task, robot: _map_cells(task),
    deployable=True,
    noise=NOISY,
    mirror=_map_mirror(1),
    layout=_height_map_layout,
    note="ground layer [m]",
)
def ground_map(env: TraversalEnv) -> torch.Tensor:
    """The ground layer alone: terrain below the feet (Humanoid Parkour's height map)."""
    return env.perception.elevation(env.state.root_pos, env.state.yaw)[0]


@observation_term(
    lambda task, robot: _map_cells(task),
    deployable=True,
    noise=NOISY,
    mirror=_map_mirror(1),
    clip=_overhead_cap,
    layout=_height_map_layout,
    note="overhead layer [m], capped at clip",
)
def overhead_map(env: TraversalEnv) -> torch.Tensor:
    """The overhead layer alone (the overhead perception the paper adds to Humanoid Parkour)."""
    return env.perception.elevation(env.state.root_pos, env.state.yaw)[1]


@observation_term(
    lambda task, robot: int(np.prod(voxel_shape(task.perception.voxel_grid))),
    deployable=True,
    noise=TermNoise(kind="flip"),  # occupancy in {0, 1}: noise flips cells instead of adding to them
    mirror=lambda task, robot: grid_mirror(voxel_shape(task.perception.voxel_grid)),
    layout=_voxel_layout,
    note="occupancy in {0, 1}",
)
def voxel_grid(env: TraversalEnv) -> torch.Tensor:
    """Robot-centric occupancy in {0, 1} (``perception.voxel_grid``), row-major (x, y, z): Table III's voxel input."""
    return env.perception.voxels(env.state.root_pos, env.state.yaw)


# --- privileged (critic) terms --------------------------------------------------------------------------


@observation_term(
    lambda task, robot: len(clearance_bodies(robot)),
    mirror=lambda task, robot: link_mirror(clearance_bodies(robot), ([0], [1.0])),
    clip=lambda task: CLEARANCE_CLIP,
    note="per collision body: smallest SDF of its collision shapes [m], clipped to +-clip (privileged: a teacher's "
    "or critic's input)",
)
def body_clearance(env: TraversalEnv) -> torch.Tensor:
    """How far each collision body is from the nearest obstacle (``cat.envs.body_clearance``): what the 13-link
    field block does not see (a toe ahead of its ankle, a hand's edge)."""
    return env.body_clearance.read(env)


@observation_term(3, mirror=POLAR, note="root velocity in the yaw frame [m/s] (privileged)")
def base_lin_vel(env: TraversalEnv) -> torch.Tensor:
    return rotate_yaw_inverse(env.state.yaw, env.state.root_lin_vel)


@observation_term(1, mirror=([0], [1.0]), note="root height [m] (privileged)")
def base_height(env: TraversalEnv) -> torch.Tensor:
    return env.state.root_pos[:, 2:3]


@observation_term(
    lambda task, robot: 3 * len(robot.query_links),
    mirror=_links(POLAR),
    note="query links minus root, yaw frame (privileged)",
)
def link_positions(env: TraversalEnv) -> torch.Tensor:
    rel = env.state.link_pos - env.state.root_pos[:, None, :]
    return rotate_yaw_inverse(env.state.yaw, rel).reshape(env.num_envs, -1)


@observation_term(2, mirror=([1, 0], [1.0, 1.0]), note="left, right foot contact in {0, 1} (privileged)")
def foot_contacts(env: TraversalEnv) -> torch.Tensor:
    return env.state.foot_contact.float()


@observation_term(3, mirror=([0, 1, 2], [1.0, 1.0, 1.0]), note="domain-randomisation scales kp, kd, mass (privileged)")
def dr_scales(env: TraversalEnv) -> torch.Tensor:
    return env.dr_scales


@observation_term(
    1, mirror=([0], [1.0]), note="index of the env's scene group (distillation routing, not a network input)"
)
def scene_group(env: TraversalEnv) -> torch.Tensor:
    """(N, 1) index of each env's scene group (its scene's kind in ``env.scene_group_names``; 0 on flat ground):
    routes distillation labels to each group's specialist, never a network input."""
    if env.scenes is None:
        return torch.zeros(env.num_envs, 1, device=env.device)
    return env.scenes.groups_of_envs().to(env.device, torch.float32)[:, None]
