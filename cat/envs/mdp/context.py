"""The env contract: what a deployable observation term reads, produced by the env and by the deployed robot.

``TraversalEnv`` (N worlds) and the deploy runtime (``cat.deploy.runtime.Runtime``, one robot) both provide a
``TermContext``; a term declared ``deployable`` (``cat.envs.mdp.observations``) reads nothing else, and of
``state`` only the ``DEPLOY_STATE`` fields (a robot estimates those: IMU, encoders, odometry, forward kinematics;
the runtime fills the others with NaN or zeros). ``tests/test_obs_terms.py`` checks both sides: every deployable
term computes the same from a context holding only these, and the runtime provides them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import torch

if TYPE_CHECKING:
    from cat.envs.config import EnvCfg


@dataclass
class SimState:
    """Per-step robot state in float32 (world frame unless noted)."""

    root_pos: torch.Tensor
    root_quat: torch.Tensor
    root_lin_vel: torch.Tensor
    yaw: torch.Tensor
    gyro: torch.Tensor  # pelvis frame
    gravity: torch.Tensor  # pelvis frame
    joint_pos: torch.Tensor
    joint_vel: torch.Tensor
    link_pos: torch.Tensor  # (N, 13, 3) query links
    link_vel: torch.Tensor
    foot_pos: torch.Tensor  # (N, 2, 3)
    foot_vel: torch.Tensor
    foot_axis: torch.Tensor  # (N, 2, 3) each foot's heel-to-toe (x) axis
    foot_contact: torch.Tensor  # (N, 2) bool
    collision: torch.Tensor  # (N,) bool: any robot-obstacle contact (success rule, metrics, penalty)
    hard_collision: torch.Tensor  # (N,) bool: a contact that exerts force (ends the episode under on_collision)


DEPLOY_STATE = (
    "root_pos",  # odometry position (world) [m]
    "root_quat",  # odometry orientation (wxyz)
    "yaw",  # its heading [rad]
    "gyro",  # IMU angular velocity (pelvis frame) [rad/s]
    "gravity",  # gravity direction in the pelvis frame (IMU orientation)
    "joint_pos",  # encoders [rad]
    "joint_vel",  # [rad/s]
    "link_pos",  # query links by forward kinematics from the odometry pose [m]
    "link_vel",  # their velocity (finite difference on the robot) [m/s]
    "foot_pos",  # the two foot query links
    "foot_vel",
)
"""``SimState`` fields a robot has (the rest, e.g. ``root_lin_vel`` or ``foot_contact``, are privileged)."""


class MapSource(Protocol):
    """Robot-centric maps the map terms read: the env's scene occupancy (``cat.envs.perception.ScenePerception``)
    or, on a robot, its live LiDAR map (``cat.deploy.perception.Perception``), through the same tables."""

    def elevation(self, root_pos: torch.Tensor, yaw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]: ...

    def voxels(self, root_pos: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor: ...


class TermContext(Protocol):
    """What deployable observation terms read (shapes for N worlds; the runtime has N = 1)."""

    cfg: EnvCfg  # the task (gait, perception and field-block settings)
    num_envs: int
    device: torch.device
    dt: float  # control step [s]
    state: SimState  # only its DEPLOY_STATE fields
    default_joint_pos: torch.Tensor  # (N, joints) default pose [rad]
    policy_ids: torch.Tensor  # (actions,) the joints the actions drive
    actions: torch.Tensor  # (N, actions) last action after the clip
    targets: torch.Tensor  # (N, joints) PD targets [rad]
    goals: torch.Tensor  # (N, 3) goal (world) [m]
    phase: torch.Tensor  # (N,) gait clock in [0, 1)
    field_obs_buf: torch.Tensor  # (N, K, 7) HumanoidPF block (cat.envs.mdp.field_obs), refreshed at refresh_hz
    field_obs_odom_buf: torch.Tensor | None  # the block at the odometry-placed links (None: field_obs_buf)
    perception: MapSource  # elevation map / voxel grid source (scene occupancy, or the robot's live map)


CONTEXT_FIELDS = tuple(TermContext.__annotations__)
