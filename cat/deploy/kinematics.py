"""Forward kinematics of the G1 with pytorch-kinematics: the 13 query links (and any body) from the estimated
root pose and the joint encoders, as a robot computes them (no simulator state).

The chain is built from the compiled robot model (``cat.envs.robot.robot_spec``, visual meshes stripped), so
body offsets, joint axes and the 13 ``query_*`` sites are exactly MuJoCo's. pytorch-kinematics' own MJCF
reader is not used: with mujoco 4 its joint-type lookup fails on the new enum type.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import pytorch_kinematics as pk
import torch
from pytorch_kinematics import frame as pk_frame
from pytorch_kinematics import transforms as pk_tf

from cat.envs.math_utils import quat_rotate_inverse, quat_to_matrix
from cat.envs.robot import RobotCfg, compile_model, robot_spec
from cat.envs.scene import strip_visual_meshes

_JOINT_TYPES = {int(mujoco.mjtJoint.mjJNT_HINGE): "revolute", int(mujoco.mjtJoint.mjJNT_SLIDE): "prismatic"}


def robot_model(robot: RobotCfg) -> mujoco.MjModel:
    """The robot alone (no floor, no obstacles, no visual meshes): what FK needs."""
    spec = robot_spec(robot, floor=False)
    strip_visual_meshes(spec)
    return compile_model(spec)


def chain_from_model(model: mujoco.MjModel, root: str) -> pk.Chain:
    """A pytorch-kinematics chain of the bodies below ``root`` (its free joint excluded) plus their sites.

    FK of the chain gives poses in the root body's frame."""

    def offset(pos, quat) -> pk_tf.Transform3d:
        rot = torch.tensor(quat, dtype=torch.float64)
        return pk_tf.Transform3d(rot=rot, pos=torch.tensor(pos, dtype=torch.float64), dtype=torch.float64)

    def build(body_id: int, frame: pk_frame.Frame) -> None:
        children = []
        for child in range(model.nbody):
            if child == body_id or model.body_parentid[child] != body_id:
                continue
            b = model.body(child)
            if model.body_jntnum[child] > 1:
                raise ValueError(f"body {b.name!r}: more than one joint is not supported")
            if model.body_jntnum[child] == 1:
                j = model.joint(int(model.body_jntadr[child]))
                jtype = _JOINT_TYPES.get(int(j.type[0]))
                if jtype is None:
                    raise ValueError(f"joint {j.name!r}: type {int(j.type[0])} is not a hinge or slide")
                joint = pk_frame.Joint(
                    j.name,
                    offset=offset(j.pos, [1.0, 0.0, 0.0, 0.0]),
                    joint_type=jtype,
                    axis=tuple(float(a) for a in j.axis),
                    dtype=torch.float64,
                )
            else:
                joint = pk_frame.Joint(f"{b.name}_fixed", dtype=torch.float64)
            f = pk_frame.Frame(b.name, pk_frame.Link(b.name, offset=offset(b.pos, b.quat)), joint)
            build(child, f)
            children.append(f)
        for s in range(model.nsite):
            if model.site_bodyid[s] == body_id:
                site = model.site(s)
                children.append(pk_frame.Frame(site.name, pk_frame.Link(site.name, offset=offset(site.pos, site.quat))))
        frame.children = children

    root_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, root)
    if root_id < 0:
        raise ValueError(f"root body {root!r} not in the model")
    root_frame = pk_frame.Frame(root, pk_frame.Link(root), pk_frame.Joint(f"{root}_root", dtype=torch.float64))
    build(root_id, root_frame)
    return pk.Chain(root_frame, dtype=torch.float64)


@dataclass
class FramePoses:
    """World poses of named frames: positions (B, F, 3), rotation matrices (B, F, 3, 3)."""

    pos: torch.Tensor
    rot: torch.Tensor


class RobotFK:
    """FK of named frames (bodies or sites) of the robot from a root pose and the joint angles.

    Joint angles are given in the robot yaml's joint order (= MuJoCo's actuator and qpos order)."""

    def __init__(self, robot: RobotCfg, model: mujoco.MjModel | None = None):
        model = model or robot_model(robot)
        self.robot = robot
        self.chain = chain_from_model(model, robot.root_body)
        names = self.chain.get_joint_parameter_names()
        missing = set(names) - set(robot.joint_names)
        if missing:
            raise ValueError(f"chain joints not in the robot description: {sorted(missing)}")
        # chain parameter order <- yaml order
        self._perm = torch.tensor([robot.joint_names.index(n) for n in names])
        self._indices: dict[tuple[str, ...], torch.Tensor] = {}

    def poses(self, root_pos, root_quat, joint_pos, frames: list[str]) -> FramePoses:
        """World poses of ``frames`` for a batch: root_pos (B, 3), root_quat (B, 4) wxyz, joint_pos (B, nj)."""
        root_pos = torch.as_tensor(root_pos, dtype=torch.float64).reshape(-1, 3)
        root_quat = torch.as_tensor(root_quat, dtype=torch.float64).reshape(-1, 4)
        q = torch.as_tensor(joint_pos, dtype=torch.float64).reshape(len(root_pos), -1)[:, self._perm]
        key = tuple(frames)
        if key not in self._indices:
            self._indices[key] = self.chain.get_frame_indices(*frames)
        mats = self.chain.forward_kinematics(q, frame_indices=self._indices[key])
        local = torch.stack([mats[f].get_matrix() for f in frames], dim=1)  # (B, F, 4, 4) in the root frame
        r_root = quat_to_matrix(root_quat)[:, None]  # (B, 1, 3, 3)
        pos = (r_root @ local[..., :3, 3:4]).squeeze(-1) + root_pos[:, None]
        return FramePoses(pos=pos, rot=r_root @ local[..., :3, :3])

    def link_positions(self, root_pos, root_quat, joint_pos) -> torch.Tensor:
        """(B, 13, 3) world positions of the HumanoidPF query links (robots/g1/g1.yaml order)."""
        return self.poses(root_pos, root_quat, joint_pos, self.robot.query_site_names).pos


def gravity_in_body(root_quat: torch.Tensor) -> torch.Tensor:
    """Projected gravity (unit, pelvis frame) from an IMU orientation estimate (B, 4) wxyz."""
    down = torch.tensor([0.0, 0.0, -1.0], dtype=root_quat.dtype).expand(len(root_quat), 3)
    return quat_rotate_inverse(root_quat, down)


__all__ = ["FramePoses", "RobotFK", "chain_from_model", "gravity_in_body", "quat_to_matrix", "robot_model"]
