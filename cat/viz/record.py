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


class RolloutRecorder:
    """Logs world ``env_id`` of a ``TraversalEnv`` each control step on the ``sim_time`` timeline."""

    def __init__(self, path: str, env, env_id: int = 0, arrow_scale: float = 0.3):
        self.env, self.env_id, self.arrow_scale = env, env_id, arrow_scale
        self.model = env.sim.model
        self.data = mujoco.MjData(self.model)
        self.rec = rr.RecordingStream("cat_rollout")
        self.rec.save(path)
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        m = self.model
        robot = set(env.robot.collision_geoms)
        ids = [i for i in range(m.ngeom) if m.geom(i).name in robot]
        self.caps = [i for i in ids if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_CAPSULE]
        self.spheres = [i for i in ids if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_SPHERE]
        self.boxes = [i for i in ids if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_BOX]
        self.step_count = 0
        self.log_obstacles()

    def log_obstacles(self) -> None:
        """(Re-)log the obstacles of the recorded world's current scene (static)."""
        scenes = getattr(self.env, "scenes", None)
        if scenes is None:
            return
        mesh = scenes.mesh_for_env(self.env_id)
        self.rec.log(
            "world/obstacles",
            rr.Mesh3D(vertex_positions=mesh.vertices, triangle_indices=mesh.faces, albedo_factor=[0.6, 0.6, 0.65]),
            static=True,
        )

    def log_step(self, env) -> None:
        """Log the current state of the recorded world."""
        i, m, d = self.env_id, self.model, self.data
        d.qpos[:] = env.sim.qpos[i].detach().cpu().numpy()
        mujoco.mj_kinematics(m, d)
        self.rec.set_time("sim_time", duration=self.step_count * env.dt)
        self.step_count += 1
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
        goal = env.goals[i].detach().cpu().numpy()
        self.rec.log("world/goal", rr.Points3D([goal], radii=0.05, colors=[240, 60, 60]))
        links = env.state.link_pos[i].detach().cpu().numpy()
        fh = env.humanoid_pf[i].detach().cpu().numpy()
        self.rec.log("world/field/F_H", rr.Arrows3D(origins=links, vectors=fh * self.arrow_scale, colors=[40, 200, 90]))
        self.rec.log("metrics/goal_distance", rr.Scalars(float(env.goal_distance[i])))

    def close(self) -> None:
        self.rec.flush()
