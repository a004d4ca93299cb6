"""Left/right mirror symmetry of G1 for rsl_rl's ``symmetry_cfg`` (data augmentation and/or mirror loss).

Mirroring is the reflection y -> -y of the world (the x-z plane of the robot's yaw frame). Every observation
term and the 12 leg actions mirror by a column permutation and a sign, so a group mirrors as
``x[:, perm] * sign``, built once from the env's term lists:

- polar vectors (gravity, goal, velocities, positions, field directions): (x, -y, z)
- axial vectors (angular velocity): (-x, y, -z)
- joints: left <-> right; roll and yaw angles change sign, pitch / knee / elbow angles keep it
- the 13 query links: left <-> right; the gait clock shifts half a period (sin, cos) -> (-sin, -cos)
- robot-centric grids (elevation map layers, voxel grid): the lateral axis reverses (cell y -> -y), values keep
  their sign (heights and occupancy are scalars)
- ``field_block_odometry`` mirrors as ``field_block``. A mirrored world keeps its own odometry drift, so its
  block is the mirror image only where the drift is zero (noise off); the mirrored observation is that of the
  mirrored drift (dx, -dy, -dyaw), which the isotropic random walk makes exactly as likely (augmentation-valid)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch
from tensordict import TensorDict

from cat.envs.mdp.registry import OBS_TERMS
from cat.envs.perception import map_shape, voxel_shape

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv

POLAR = ([0, 1, 2], [1.0, -1.0, 1.0])
AXIAL = ([0, 1, 2], [-1.0, 1.0, -1.0])


def mirror_name(name: str) -> str:
    """``left_x`` <-> ``right_x``; other names map to themselves."""
    if name.startswith("left_"):
        return "right_" + name[5:]
    if name.startswith("right_"):
        return "left_" + name[6:]
    return name


def joint_mirror(names: list[str]) -> tuple[list[int], list[float]]:
    """(perm, sign) over joints: mirrored[i] = sign[i] * q[perm[i]]; roll / yaw joints flip sign."""
    perm = [names.index(mirror_name(n)) for n in names]
    sign = [-1.0 if ("roll" in n or "yaw" in n) else 1.0 for n in names]
    return perm, sign


def _links(names: list[str], per_link: tuple[list[int], list[float]]) -> tuple[list[int], list[float]]:
    """Mirror of a (K, d) link block flattened to K*d: links swap sides, each link's d values by ``per_link``."""
    d = len(per_link[0])
    perm, sign = [], []
    for name in names:
        k = names.index(mirror_name(name))
        perm += [k * d + j for j in per_link[0]]
        sign += per_link[1]
    return perm, sign


def grid_mirror(shape: tuple[int, ...], layers: int = 1) -> tuple[list[int], list[float]]:
    """(perm, sign) of ``layers`` row-major grids of ``shape`` (along, across, ...): the across axis reverses."""
    idx = np.arange(layers * int(np.prod(shape))).reshape((layers, *shape))
    return np.flip(idx, axis=2).reshape(-1).tolist(), [1.0] * idx.size


def term_mirror(env: TraversalEnv, term: str) -> tuple[list[int], list[float]]:
    """(perm, sign) of one observation term's columns."""
    joints = env.robot.joint_names
    legs = [joints[i] for i in env.robot.policy_joint_ids]
    links = [q.name for q in env.robot.query_links]
    field = _links(links, ([0, 1, 2, 3, 4, 5, 6], [1.0, -1.0, 1.0, 1.0, -1.0, 1.0, 1.0]))
    table = {
        "gyro": AXIAL,
        "projected_gravity": POLAR,
        "joint_pos": joint_mirror(joints),
        "joint_vel": joint_mirror(joints),
        "last_action": joint_mirror(legs),
        "leg_targets": joint_mirror(legs),
        "goal_command": POLAR,
        "gait_phase": ([0, 1], [-1.0, -1.0]),
        "field_block": field,
        "field_block_odometry": field,  # a mirrored drift (dx, -dy, -dyaw) is as likely: the walk is isotropic
        "base_lin_vel": POLAR,
        "base_height": ([0], [1.0]),
        "link_positions": _links(links, POLAR),
        "foot_contacts": ([1, 0], [1.0, 1.0]),
        "dr_scales": ([0, 1, 2], [1.0, 1.0, 1.0]),
        "scene_group": ([0], [1.0]),
        "elevation_map": grid_mirror(map_shape(env.cfg.perception.height_map), layers=2),
        "ground_map": grid_mirror(map_shape(env.cfg.perception.height_map)),
        "overhead_map": grid_mirror(map_shape(env.cfg.perception.height_map)),
        "voxel_grid": grid_mirror(voxel_shape(env.cfg.perception.voxel_grid)),
    }
    registered = OBS_TERMS.get(term)
    if registered is not None and registered.mirror is not None:
        return registered.mirror
    if term not in table:
        raise ValueError(
            f"observation term {term!r} has no mirror map; add one in cat.envs.symmetry.term_mirror "
            "(or register_observation(..., mirror=...))"
        )
    return table[term]


@dataclass
class MirrorMap:
    """Column permutation and sign per observation group, and for the actions."""

    obs: dict[str, tuple[torch.Tensor, torch.Tensor]]
    actions: tuple[torch.Tensor, torch.Tensor]

    @classmethod
    def of_env(cls, env: TraversalEnv) -> MirrorMap:
        dev = env.device
        groups = {}
        for group, terms in env.obs_groups.items():
            perm, sign, offset = [], [], 0
            for term in terms:
                p, s = term_mirror(env, term)
                perm += [offset + i for i in p]
                sign += s
                offset += len(p)
            h = env.observation_groups.history[group]  # a stacked history mirrors step by step
            perm = [k * offset + i for k in range(h) for i in perm]
            groups[group] = (torch.tensor(perm, device=dev), torch.tensor(sign * h, device=dev))
        legs = [env.robot.joint_names[i] for i in env.robot.policy_joint_ids]
        p, s = joint_mirror(legs)
        return cls(groups, (torch.tensor(p, device=dev), torch.tensor(s, device=dev)))

    def mirror_obs(self, obs: TensorDict) -> TensorDict:
        out = {}
        for group in obs.keys():
            if group not in self.obs:
                raise KeyError(f"no mirror map for observation group {group!r}; known: {sorted(self.obs)}")
            perm, sign = self.obs[group]
            x = obs[group]
            out[group] = x[:, perm.to(x.device)] * sign.to(x.device, x.dtype)
        return TensorDict(out, batch_size=obs.batch_size, device=obs.device)

    def mirror_actions(self, actions: torch.Tensor) -> torch.Tensor:
        perm, sign = self.actions
        return actions[:, perm.to(actions.device)] * sign.to(actions.device, actions.dtype)


def mirror_augment(env: TraversalEnv, obs: TensorDict | None = None, actions: torch.Tensor | None = None):
    """rsl_rl ``data_augmentation_func``: originals stacked with their mirror images along the batch."""
    m = env.mirror_map
    obs_aug = None if obs is None else torch.cat((obs, m.mirror_obs(obs)), dim=0)
    act_aug = None if actions is None else torch.cat((actions, m.mirror_actions(actions)), dim=0)
    return obs_aug, act_aug


def mirror_state(env: TraversalEnv, qpos: torch.Tensor, qvel: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Mirror image of MuJoCo states (k, nq), (k, nv) of the floating-base G1.

    Free joint: position (x, -y, z), quaternion (w, -x, y, -z), world linear velocity (x, -y, z), body angular
    velocity (-x, y, -z); joints by ``joint_mirror``.
    """
    perm, sign = joint_mirror(env.robot.joint_names)
    perm_t = torch.tensor(perm, device=qpos.device)
    sign_t = torch.tensor(sign, device=qpos.device, dtype=qpos.dtype)
    qp, qv = qpos.clone(), qvel.clone()
    qp[:, 1] = -qpos[:, 1]
    qp[:, 4], qp[:, 6] = -qpos[:, 4], -qpos[:, 6]
    qp[:, 7:] = qpos[:, 7:][:, perm_t] * sign_t
    qv[:, 1] = -qvel[:, 1]
    qv[:, 3], qv[:, 5] = -qvel[:, 3], -qvel[:, 5]
    qv[:, 6:] = qvel[:, 6:][:, perm_t] * sign_t
    return qp, qv
