"""Observation terms. Each takes the env and returns (N, dim); the env concatenates them per group."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

from cat.envs.math_utils import rotate_yaw_inverse

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv


def gyro(env: TraversalEnv) -> torch.Tensor:
    """Pelvis angular velocity in the pelvis frame (IMU gyro)."""
    return env.state.gyro


def projected_gravity(env: TraversalEnv) -> torch.Tensor:
    return env.state.gravity


def joint_pos(env: TraversalEnv) -> torch.Tensor:
    """Joint angles relative to the default pose."""
    return env.state.joint_pos - env.default_joint_pos


def joint_vel(env: TraversalEnv) -> torch.Tensor:
    return env.state.joint_vel


def last_action(env: TraversalEnv) -> torch.Tensor:
    return env.actions


def leg_targets(env: TraversalEnv) -> torch.Tensor:
    """Current incremental PD targets of the policy joints, relative to the default pose."""
    return env.targets[:, env.policy_ids] - env.default_joint_pos[:, env.policy_ids]


def goal_command(env: TraversalEnv) -> torch.Tensor:
    """Goal relative to the root in the yaw frame (x, y, z), horizontal distance clipped to 5 m."""
    rel = rotate_yaw_inverse(env.state.yaw, env.goals - env.state.root_pos)
    dist = rel[:, :2].norm(dim=-1, keepdim=True)
    scale = torch.clamp(5.0 / dist.clamp_min(1e-6), max=1.0)
    return torch.cat((rel[:, :2] * scale, rel[:, 2:]), dim=-1)


def gait_phase(env: TraversalEnv) -> torch.Tensor:
    angle = 2 * torch.pi * env.phase
    return torch.stack((torch.sin(angle), torch.cos(angle)), dim=-1)


def field_block(env: TraversalEnv) -> torch.Tensor:
    """HumanoidPF at the 13 links (F_H, grad d, clipped d) in the yaw frame, refreshed at ``refresh_hz``."""
    return env.field_obs_buf.reshape(env.num_envs, -1)


def field_block_odometry(env: TraversalEnv) -> torch.Tensor:
    """``field_block`` as the robot's odometry sees it: the field queried at the links displaced by a drifting
    pose error and turned into the drifted yaw frame (``cat.envs.odometry``; on with ``noise.enabled``). Without
    drift (noise off, or a robot whose field block already comes from its own odometry pose) it is ``field_block``.
    """
    if env.field_obs_odom_buf is None:
        return field_block(env)
    return env.field_obs_odom_buf.reshape(env.num_envs, -1)


def elevation_map(env: TraversalEnv) -> torch.Tensor:
    """Two-layer elevation map around the robot (ground then overhead layer, each row-major along x, across y).

    World heights [m] of the obstacle tops below / undersides above each cell of a yaw-aligned grid
    (``perception.height_map``); the ASTraversal observation and the paper's w/o OBS_field replacement.
    """
    ground, overhead = env.perception.elevation(env.state.root_pos, env.state.yaw)
    return torch.cat((ground, overhead), dim=-1)


def ground_map(env: TraversalEnv) -> torch.Tensor:
    """The ground layer alone: terrain below the feet (Humanoid Parkour's height map)."""
    return env.perception.elevation(env.state.root_pos, env.state.yaw)[0]


def overhead_map(env: TraversalEnv) -> torch.Tensor:
    """The overhead layer alone (the overhead perception the paper adds to Humanoid Parkour)."""
    return env.perception.elevation(env.state.root_pos, env.state.yaw)[1]


def voxel_grid(env: TraversalEnv) -> torch.Tensor:
    """Robot-centric occupancy in {0, 1} (``perception.voxel_grid``), row-major (x, y, z): Table III's voxel input."""
    return env.perception.voxels(env.state.root_pos, env.state.yaw)


# --- privileged (critic) terms --------------------------------------------------------------------------
def base_lin_vel(env: TraversalEnv) -> torch.Tensor:
    return rotate_yaw_inverse(env.state.yaw, env.state.root_lin_vel)


def base_height(env: TraversalEnv) -> torch.Tensor:
    return env.state.root_pos[:, 2:3]


def link_positions(env: TraversalEnv) -> torch.Tensor:
    rel = env.state.link_pos - env.state.root_pos[:, None, :]
    return rotate_yaw_inverse(env.state.yaw, rel).reshape(env.num_envs, -1)


def foot_contacts(env: TraversalEnv) -> torch.Tensor:
    return env.state.foot_contact.float()


def dr_scales(env: TraversalEnv) -> torch.Tensor:
    return env.dr_scales


def scene_group(env: TraversalEnv) -> torch.Tensor:
    """(N, 1) index of each env's scene group (its scene's kind in ``env.scene_group_names``; 0 on flat ground):
    routes distillation labels to each group's specialist, never a network input."""
    if env.scenes is None:
        return torch.zeros(env.num_envs, 1, device=env.device)
    return env.scenes.groups_of_envs().to(env.device, torch.float32)[:, None]
