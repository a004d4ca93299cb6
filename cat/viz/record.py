"""Record env rollouts to a rerun ``.rrd`` for replay: robot collision shapes, goal, obstacles, F_H arrows."""

from __future__ import annotations

import logging

import mujoco
import numpy as np
import rerun as rr

log = logging.getLogger(__name__)


def _mat_to_quat_xyzw(mats: np.ndarray) -> np.ndarray:
    quats = np.zeros((len(mats), 4))
    for i, m in enumerate(mats):
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, m)
        quats[i] = (q[1], q[2], q[3], q[0])
    return quats


class Recorder:
    """A rerun stream of one G1: its collision shapes, the goal, obstacles and the F_H arrows at the 13 links.

    Callers set the time (``set_time``) and log what they have; ``RolloutRecorder`` does it for an env world,
    the click demo (``cat.deploy``) for its live robot."""

    def __init__(self, path: str, model, robot_geoms, obstacles=None, arrow_scale: float = 0.3):
        self.model, self.arrow_scale = model, arrow_scale
        self.data = mujoco.MjData(model)
        self.rec = rr.RecordingStream("cat_rollout")
        self.rec.save(path)
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        m = model
        robot = set(robot_geoms)
        ids = [i for i in range(m.ngeom) if m.geom(i).name in robot]
        self.caps = [i for i in ids if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_CAPSULE]
        self.spheres = [i for i in ids if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_SPHERE]
        self.boxes = [i for i in ids if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_BOX]
        if obstacles is not None:
            self.log_mesh(obstacles)

    def log_mesh(self, obstacles) -> None:
        """(Re-)log the obstacle mesh (static)."""
        if len(obstacles.faces) == 0:
            return
        self.rec.log(
            "world/obstacles",
            rr.Mesh3D(
                vertex_positions=obstacles.vertices, triangle_indices=obstacles.faces, albedo_factor=[0.6, 0.6, 0.65]
            ),
            static=True,
        )

    def set_time(self, seconds: float) -> None:
        self.rec.set_time("sim_time", duration=seconds)

    def log_robot(self, qpos: np.ndarray) -> None:
        """Collision capsules, spheres and boxes of the robot at ``qpos``."""
        m, d = self.model, self.data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        if self.caps:
            c = np.array(self.caps)
            half = m.geom_size[c, 1]
            axis = d.geom_xmat[c].reshape(-1, 3, 3)[:, :, 2]
            self.rec.log(
                "world/robot/capsules",
                rr.Capsules3D(
                    lengths=2 * half,
                    radii=m.geom_size[c, 0],
                    translations=d.geom_xpos[c] - axis * half[:, None],
                    quaternions=_mat_to_quat_xyzw(d.geom_xmat[c]),
                    colors=[80, 140, 220],
                ),
            )
        if self.spheres:
            s = np.array(self.spheres)
            self.rec.log(
                "world/robot/spheres",
                rr.Ellipsoids3D(centers=d.geom_xpos[s], half_sizes=np.repeat(m.geom_size[s, :1], 3, 1)),
            )
        if self.boxes:
            b = np.array(self.boxes)
            self.rec.log(
                "world/robot/boxes",
                rr.Boxes3D(
                    centers=d.geom_xpos[b], half_sizes=m.geom_size[b], quaternions=_mat_to_quat_xyzw(d.geom_xmat[b])
                ),
            )

    def log_goal(self, goal: np.ndarray) -> None:
        self.rec.log("world/goal", rr.Points3D([goal], radii=0.05, colors=[240, 60, 60]))

    def log_field(self, links: np.ndarray, f_h: np.ndarray) -> None:
        """F_H arrows (13, 3) at the query links (13, 3)."""
        self.rec.log(
            "world/field/F_H", rr.Arrows3D(origins=links, vectors=f_h * self.arrow_scale, colors=[40, 200, 90])
        )

    def log_scalar(self, name: str, value: float) -> None:
        self.rec.log(name, rr.Scalars(float(value)))

    def close(self) -> None:
        self.rec.flush()


class RolloutRecorder(Recorder):
    """Logs world ``env_id`` of a ``TraversalEnv`` each control step on the ``sim_time`` timeline."""

    def __init__(self, path: str, env, env_id: int = 0, arrow_scale: float = 0.3):
        super().__init__(path, env.sim.model, env.robot.collision_geoms, None, arrow_scale)
        self.env, self.env_id = env, env_id
        self.step_count = 0
        self.log_obstacles()

    def log_obstacles(self) -> None:
        """(Re-)log the obstacles of the recorded world's current scene (static)."""
        scenes = getattr(self.env, "scenes", None)
        if scenes is not None:
            self.log_mesh(scenes.mesh_for_env(self.env_id))

    def log_step(self, env) -> None:
        """Log the current state of the recorded world."""
        i = self.env_id
        self.set_time(self.step_count * env.dt)
        self.step_count += 1
        self.log_robot(env.sim.qpos[i].detach().cpu().numpy())
        self.log_goal(env.goals[i].detach().cpu().numpy())
        self.log_field(env.state.link_pos[i].detach().cpu().numpy(), env.humanoid_pf[i].detach().cpu().numpy())
        self.log_scalar("metrics/goal_distance", float(env.goal_distance[i]))
