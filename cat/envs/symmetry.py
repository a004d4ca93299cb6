"""Left/right mirror symmetry of G1 for rsl_rl's ``symmetry_cfg`` (data augmentation and/or mirror loss).

Mirroring is the reflection y -> -y of the world (the x-z plane of the robot's yaw frame). Every observation
term and the 12 leg actions mirror by a column permutation and a sign, so a group mirrors as
``x[:, perm] * sign``, built once from the env's term lists and each term's declared ``mirror``
(``cat.envs.mdp.observations``, built from ``cat.envs.mdp.mirror``):

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

import torch
from tensordict import TensorDict

from cat.envs.mdp.mirror import AXIAL, POLAR, Mirror, grid_mirror, joint_mirror, mirror_name
from cat.envs.mdp.registry import obs_term

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv

__all__ = [
    "AXIAL",
    "POLAR",
    "MirrorMap",
    "grid_mirror",
    "joint_mirror",
    "mirror_augment",
    "mirror_name",
    "mirror_state",
    "term_mirror",
]


def term_mirror(env: TraversalEnv, term: str) -> Mirror:
    """(perm, sign) of one observation term's columns: its declaration's ``mirror`` (``cat.envs.mdp.terms``)."""
    mirror = obs_term(term).mirror
    if mirror is None:
        raise ValueError(
            f"observation term {term!r} has no mirror map; declare one (observation_term / register_observation "
            "mirror=...)"
        )
    return mirror(env.cfg, env.robot)


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
