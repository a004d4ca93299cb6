"""Robot–obstacle contact judged from the scene SDF (``sim.obstacles=field``), as the authors' release trains.

In ``field`` mode the physics worlds hold the robot and the floor only: one compiled model for every world and
any number of scenes. Obstacles exist as the scene's signed distance d in the field bank (``cat.fields.bank``,
d > 0 free, d < 0 inside). The robot is in contact when one of its collision geoms (capsules, boxes, spheres of
``robots/g1/g1.yaml``'s ``collision_geoms``) comes closer than ``FieldContactCfg.margin`` to an obstacle. With
``FieldContactCfg.cores`` (the default) a capsule is judged by points along its axis (every ``axis_spacing``) and a
sphere by its centre, each at d − radius: a capsule is its axis inflated by its radius, so this is its exact
distance wherever d is exact, edges and corners of obstacles included. Boxes and cylinders, and every geom
without ``cores``, are judged by points on their surface (every ``spacing``) at d. The points are fixed in their
body's frame; each step the body poses come from MuJoCo frame sensors (``add_body_pose_sensors``), so both
backends compute them inside the simulator.

Points outside their scene's field grid count as free (no obstacle is known there). To keep the query cheap,
each collision geom is first tested at the centre of a sphere bounding its points: geoms whose centre lies farther
than the sphere's radius + margin + ``CULL_SLACK`` from every obstacle are not queried point by point.

With ``FieldContactCfg.substeps`` (the default) the judgement is made at every physics substep, from the pose
sensors the backend keeps per substep (``PhysicsBackend.substep_sensordata``): the states the physical contact
sensors are read at, whose max over the substeps is physical contact. Without it, one instant per control step
(the sensor time of its last substep). The margin and spacing, and the agreement measured against physical
contact, are in docs/training.md ("Obstacles as fields").
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np
import torch

from cat.envs.math_utils import quat_to_matrix
from cat.envs.robot import RobotCfg
from cat.envs.scene import build_env_model
from cat.fields.body_points import BodyPoints
from cat.fields.contact_sdf import DEFAULT_BAND, contact_sdf
from cat.terrain.mujoco_export import uses_voxels

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv

log = logging.getLogger(__name__)

OBSTACLE_MODES = ("physical", "field")
"""``sim.obstacles``: obstacle geometry in the physics worlds (``physical``) or only as SDF (``field``)."""
CONTACT_SDFS = ("mesh", "field")
"""``sim.field_contact.sdf``: which SDF the judgement reads (``FieldContactCfg.sdf``)."""
POSE_SENSOR_PREFIX = "field_contact_pose_"
CULL_SLACK = 0.06
"""m: extra distance before a geom's bounding sphere is considered clear (the interpolated SDF of a 4 cm voxel
grid is not exactly 1-Lipschitz; tests check culling never changes the judgement)."""


@dataclass
class FieldContactCfg:
    """How ``sim.obstacles=field`` judges contact (see the module docstring and docs/training.md)."""

    spacing: float = 0.03
    """m: largest gap between neighbouring sample points on a collision geom's surface."""
    margin: float = 0.001
    """m: a judged shape closer than this to an obstacle (SDF below it) is in contact. +1 mm: the fewest
    disagreements with physical contact over random-action rollouts (a calibration sample apart from the test's;
    docs/training.md, "Obstacles as fields"); +4 mm with surface samples only (``cores=False``)."""
    substeps: bool = True
    """Judge at every physics substep (the states physical contact is counted at), not once per control step."""
    sdf: str = "mesh"
    """``mesh``: read each scene's contact SDF, the SDF of what its physics collides with (``fill_contact_sdf``,
    computed when the env is built); ``field``: the fields' d (4 cm occupancy voxels) for every scene."""
    band: float = DEFAULT_BAND
    """m: how far from a surface (by d) the contact SDF is exact (``sdf=mesh``)."""
    cores: bool = True
    """Judge capsules by their axis and spheres by their centre at d − radius (exact between surface samples);
    False: every geom by surface samples (the judgement before 2026-12-05)."""
    axis_spacing: float = 0.01
    """m: largest gap between neighbouring points on a capsule's axis (``cores``)."""


def check_obstacles(mode: str) -> str:
    """``mode`` if it is a known ``sim.obstacles`` value, else a one-line ``ValueError``."""
    if mode not in OBSTACLE_MODES:
        raise ValueError(f"sim.obstacles={mode!r}; valid: {', '.join(OBSTACLE_MODES)}")
    return mode


def substep_pose_sensors(model: mujoco.MjModel, obstacles: str, cfg: FieldContactCfg | None) -> tuple[str, ...]:
    """The pose sensors a backend keeps for every substep: all of them when ``obstacles`` is ``field`` and the
    judgement is per substep (``cfg.substeps``), else none."""
    if obstacles != "field" or not (cfg or FieldContactCfg()).substeps:
        return ()
    names = (model.sensor(i).name for i in range(model.nsensor))
    return tuple(n for n in names if n.startswith(POSE_SENSOR_PREFIX))


def collision_bodies(spec: mujoco.MjSpec, robot: RobotCfg) -> list[str]:
    """Robot bodies carrying at least one of ``robot.collision_geoms``, in spec order."""
    wanted = set(robot.collision_geoms)
    return [b.name for b in spec.bodies if any(g.name in wanted for g in b.geoms)]


def collision_geom_ids(model: mujoco.MjModel, robot: RobotCfg) -> list[int]:
    """Ids of ``robot.collision_geoms`` in ``model``, in the yaml's order."""
    return [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in robot.collision_geoms]


def judged_body_ids(model: mujoco.MjModel, geoms: Sequence[int]) -> list[int]:
    """The bodies carrying ``geoms``, each once, ordered by its first geom: :class:`FieldContact`'s body order."""
    return list(dict.fromkeys(int(model.geom_bodyid[g]) for g in geoms))


def add_body_pose_sensors(spec: mujoco.MjSpec, robot: RobotCfg) -> None:
    """World position and orientation sensors of every robot body with a collision geom (field contact)."""
    xbody = mujoco.mjtObj.mjOBJ_XBODY
    for body in collision_bodies(spec, robot):
        for kind, typ in (("pos", mujoco.mjtSensor.mjSENS_FRAMEPOS), ("quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT)):
            spec.add_sensor(name=f"{POSE_SENSOR_PREFIX}{kind}_{body}", type=typ, objtype=xbody, objname=body)


# --- surface sampling (geom frame) ----------------------------------------------------------------------------
def _ring(radius: float, z: float, spacing: float) -> np.ndarray:
    n = max(3, math.ceil(2 * math.pi * radius / spacing))
    a = 2 * math.pi * np.arange(n) / n
    return np.c_[radius * np.cos(a), radius * np.sin(a), np.full(n, z)]


def _sphere(radius: float, spacing: float, hemisphere: int = 0) -> np.ndarray:
    """Fibonacci points on a sphere (``hemisphere`` +1 / -1: the z >= 0 / z <= 0 half only)."""
    area = (2.0 if hemisphere else 4.0) * math.pi * radius**2
    n = max(6, math.ceil(1.3 * area / spacing**2))
    i = np.arange(n) + 0.5
    z = 1.0 - i / n if hemisphere else 1.0 - 2.0 * i / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    p = np.c_[r * np.cos(phi), r * np.sin(phi), z] * radius
    if hemisphere < 0:
        p[:, 2] *= -1
    return p


def _grid(half: float, spacing: float) -> np.ndarray:
    return np.linspace(-half, half, max(2, math.ceil(2 * half / spacing) + 1))


def geom_surface_points(gtype: int, size: np.ndarray, spacing: float) -> np.ndarray:
    """(P, 3) points covering a sphere, capsule (axis z), cylinder or box surface, neighbours <= ``spacing``."""
    g = mujoco.mjtGeom
    if gtype == g.mjGEOM_SPHERE:
        return _sphere(float(size[0]), spacing)
    if gtype in (g.mjGEOM_CAPSULE, g.mjGEOM_CYLINDER):
        r, h = float(size[0]), float(size[1])
        parts = [_ring(r, z, spacing) for z in _grid(h, spacing)]
        if gtype == g.mjGEOM_CAPSULE:
            parts += [_sphere(r, spacing, +1) + [0, 0, h], _sphere(r, spacing, -1) - [0, 0, h]]
        else:
            for z in (-h, h):
                parts += [_ring(rr, z, spacing) for rr in np.linspace(0, r, max(2, math.ceil(r / spacing) + 1))[1:]]
                parts.append(np.array([[0.0, 0.0, z]]))
        return np.concatenate(parts)
    if gtype == g.mjGEOM_BOX:
        axes = [_grid(float(s), spacing) for s in size[:3]]
        out = []
        for k in range(3):  # the two faces normal to axis k
            u, v = [axes[j] for j in range(3) if j != k]
            uu, vv = np.meshgrid(u, v, indexing="ij")
            for side in (-1.0, 1.0):
                face = np.zeros((uu.size, 3))
                face[:, [j for j in range(3) if j != k]] = np.c_[uu.ravel(), vv.ravel()]
                face[:, k] = side * size[k]
                out.append(face)
        return np.unique(np.round(np.concatenate(out), 9), axis=0)
    raise ValueError(f"field contact: geom type {gtype} is not a sphere, capsule, cylinder or box")


def geom_judged_points(gtype: int, size: np.ndarray, cfg: FieldContactCfg) -> tuple[np.ndarray, float]:
    """(points (P, 3) in the geom's frame, offset): what the judgement reads of a geom, at d − offset. With
    ``cfg.cores`` a capsule is its axis (z, neighbours <= ``axis_spacing``) inflated by its radius and a sphere its
    centre; otherwise, and for boxes and cylinders, the surface samples (:func:`geom_surface_points`) at offset 0."""
    g = mujoco.mjtGeom
    if cfg.cores and gtype == g.mjGEOM_SPHERE:
        return np.zeros((1, 3)), float(size[0])
    if cfg.cores and gtype == g.mjGEOM_CAPSULE:
        h = float(size[1])
        z = np.linspace(-h, h, max(2, math.ceil(2 * h / cfg.axis_spacing) + 1))
        return np.c_[np.zeros_like(z), np.zeros_like(z), z], float(size[0])
    return geom_surface_points(gtype, size, cfg.spacing), 0.0


def _quat_rotate(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate ``v`` (..., 3) by unit quaternions ``q`` (..., 4) (w, x, y, z)."""
    w, xyz = q[..., :1], q[..., 1:]
    t = 2.0 * torch.cross(xyz, v, dim=-1)
    return v + w * t + torch.cross(xyz, t, dim=-1)


def _quat_np(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    return _quat_rotate(torch.tensor(q, dtype=torch.float64), torch.tensor(v, dtype=torch.float64)).numpy()


def body_poses(
    model: mujoco.MjModel, bodies: Sequence[str], qpos: np.ndarray, data: mujoco.MjData | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """(pos (n, B, 3), quat (n, B, 4)) of ``bodies`` for each state row of ``qpos`` (n, nq), by MuJoCo's forward
    kinematics on ``data`` (a scratch ``MjData`` of ``model``; made when not given): poses without pose sensors."""
    data = mujoco.MjData(model) if data is None else data
    ids = [model.body(b).id for b in bodies]
    pos, quat = np.zeros((len(qpos), len(ids), 3)), np.zeros((len(qpos), len(ids), 4))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        pos[i], quat[i] = data.xpos[ids], data.xquat[ids]
    return torch.tensor(pos, dtype=torch.float32), torch.tensor(quat, dtype=torch.float32)


# --- the judgement ---------------------------------------------------------------------------------------------
class FieldContact:
    """Contact of each robot body with the obstacles of each env's scene, judged from the field bank's SDF.

    ``bodies`` are the robot bodies with collision geoms; ``geom_points[g]`` the points judged for collision geom
    ``g`` in its body's frame (body ``geom_body[g]``) at d − ``geom_offset[g]`` (:func:`geom_judged_points`).
    ``ghost_parts`` bodies are judged but do not count as hard contacts; with ``ghost_obstacles`` no contact is
    hard (the physical mode's training aids, same meaning).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        robot: RobotCfg,
        cfg: FieldContactCfg,
        device: str | torch.device = "cpu",
        ghost_parts: Sequence[str] = (),
        ghost_obstacles: bool = False,
    ):
        if cfg.spacing <= 0 or cfg.axis_spacing <= 0:
            raise ValueError(
                f"sim.field_contact.spacing={cfg.spacing}, axis_spacing={cfg.axis_spacing}: both must be > 0"
            )
        if cfg.sdf not in CONTACT_SDFS:
            raise ValueError(f"sim.field_contact.sdf={cfg.sdf!r}; valid: {', '.join(CONTACT_SDFS)}")
        self.cfg, self.device = cfg, torch.device(device)
        geoms = collision_geom_ids(model, robot)
        body_ids = judged_body_ids(model, geoms)
        self.bodies = [model.body(b).name for b in body_ids]
        f32 = dict(dtype=torch.float32, device=self.device)
        pts, offsets, centres, radii = [], [], [], []
        for g in geoms:
            local, off = geom_judged_points(int(model.geom_type[g]), model.geom_size[g], cfg)
            p = model.geom_pos[g] + _quat_np(np.broadcast_to(model.geom_quat[g], (len(local), 4)), local)
            c = 0.5 * (p.min(0) + p.max(0))
            pts.append(torch.tensor(p, **f32))
            offsets.append(off)
            centres.append(c)
            radii.append(float(np.linalg.norm(p - c, axis=1).max()) + off)  # the judged shape's bounding sphere
        self.geom_points = pts  # per geom (K_g, 3), body frame
        self.geom_offset = torch.tensor(offsets, **f32)  # (G,) inflation of each geom's points
        self.geom_body = torch.tensor([body_ids.index(int(model.geom_bodyid[g])) for g in geoms], device=self.device)
        self.geom_centre = torch.tensor(np.array(centres), **f32)  # (G, 3) bounding-sphere centres, body frame
        self.geom_radius = torch.tensor(radii, **f32)  # (G,)
        self.num_points = sum(len(p) for p in pts)
        unknown = sorted(set(ghost_parts) - set(self.bodies))
        if unknown:
            raise ValueError(f"ghost_parts {unknown} have no collision geom; robot bodies that do: {self.bodies}")
        self.hard_bodies = torch.tensor([b not in ghost_parts for b in self.bodies], device=self.device)
        self.ghost_obstacles = ghost_obstacles
        self.cull = True
        self.fused = True
        """Judge with the fused Warp kernel (:meth:`FieldBank.min_sdf_on_bodies`); False: the torch reference."""
        self._cols: torch.Tensor | None = None
        self._sub_cols: torch.Tensor | None = None  # the same columns in substep_sensordata (sensor_columns)
        self._packed: dict[torch.device, BodyPoints] = {}

    def sensor_columns(self, sensors: dict, substep_columns: Sequence[int] = ()) -> None:
        """Find the pose sensors of the bodies in a backend's ``sensors`` (name -> ``SensorSlice``) and, with
        ``substeps``, in its ``substep_columns`` (the sensordata columns of ``substep_sensordata``)."""
        cols = []
        for b in self.bodies:
            p, q = sensors[f"{POSE_SENSOR_PREFIX}pos_{b}"], sensors[f"{POSE_SENSOR_PREFIX}quat_{b}"]
            cols.append(list(range(p.adr, p.adr + 3)) + list(range(q.adr, q.adr + 4)))
        self._cols = torch.tensor(cols, device=self.device)
        self._sub_cols = None
        if self.cfg.substeps:
            where = {c: i for i, c in enumerate(substep_columns)}
            missing = [c for row in cols for c in row if c not in where]
            if missing:
                raise ValueError("field_contact.substeps: the backend keeps no per-substep pose sensors")
            self._sub_cols = torch.tensor([[where[c] for c in row] for row in cols], device=self.device)

    @property
    def pose_columns(self) -> torch.Tensor:
        """(B, 7) sensordata columns of each body's position (3) and orientation (4)."""
        if self._cols is None:
            raise RuntimeError("FieldContact.sensor_columns was never called")
        return self._cols

    def poses(self, sensordata: torch.Tensor, cols: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(pos (n, B, 3), quat (n, B, 4)) of the bodies from sensor rows (n, nsensordata), or from rows of other
        columns (``cols``: (B, 7) indices into them)."""
        if self._cols is None:
            raise RuntimeError("FieldContact.sensor_columns was never called")
        cols = self._cols if cols is None else cols
        x = sensordata[:, cols.to(sensordata.device)].to(self.device, torch.float32)
        q = x[..., 3:]
        return x[..., :3], q / q.norm(dim=-1, keepdim=True).clamp_min(1e-9)

    def body_points(self, device: torch.device) -> BodyPoints:
        """The sample points packed for the fused kernel on ``device`` (cull distance: radius + margin + slack)."""
        if device not in self._packed:
            cull = (self.geom_radius + self.cfg.margin + CULL_SLACK).tolist()
            groups, bodies, off = self.geom_points, self.geom_body.tolist(), self.geom_offset.tolist()
            self._packed[device] = BodyPoints.from_groups(groups, bodies, self.geom_centre, cull, device, off)[0]
        return self._packed[device]

    def body_sdf(self, bank, field_idx: torch.Tensor, pos: torch.Tensor, quat: torch.Tensor) -> torch.Tensor:
        """(n, B) smallest SDF over each body's points (+inf: clear, or culled as clearly free)."""
        contact = self.cfg.sdf == "mesh"
        if not self.fused:
            if contact:
                raise ValueError("FieldContact: the torch reference reads the fields' d (sim.field_contact.sdf=field)")
            return self.body_sdf_torch(bank, field_idx, pos, quat)
        points = self.body_points(bank.device)
        return bank.min_sdf_on_bodies(field_idx, pos, quat, points, cull=self.cull, contact=contact).to(self.device)

    def body_sdf_torch(self, bank, field_idx: torch.Tensor, pos: torch.Tensor, quat: torch.Tensor) -> torch.Tensor:
        """:meth:`body_sdf` in torch through ``bank.query`` (the reference the fused kernel is tested against)."""
        n, nb = pos.shape[:2]
        out = torch.full((n, nb), math.inf, device=self.device)
        if n == 0:
            return out
        idx, gb = field_idx.to(self.device).long(), self.geom_body
        rot = quat_to_matrix(quat)  # (n, B, 3, 3)
        if self.cull:  # geoms whose bounding sphere is clear of every obstacle are not queried point by point
            centre = pos[:, gb] + (rot[:, gb] @ self.geom_centre[:, :, None]).squeeze(-1)
            s = bank.query(idx, centre)
            d = torch.where(s.inside, s.sdf.to(self.device), self._outside_gap(bank, idx, centre))
            near = d < self.geom_radius + self.cfg.margin + CULL_SLACK  # (n, G)
        else:
            near = torch.ones(n, len(gb), dtype=torch.bool, device=self.device)
        points, fields, parts = [], [], []
        for g, local in enumerate(self.geom_points):
            e = near[:, g].nonzero().squeeze(1)
            if len(e) == 0:
                continue
            b = int(gb[g])
            points.append((pos[e, b, None] + local @ rot[e, b].transpose(-1, -2)).reshape(-1, 3))
            fields.append(idx[e].repeat_interleave(len(local)))
            parts.append((b, e, len(local), float(self.geom_offset[g])))
        if not parts:
            return out
        s = bank.query(torch.cat(fields), torch.cat(points)[:, None])
        sdf = torch.where(s.inside, s.sdf, torch.full_like(s.sdf, math.inf)).to(self.device)[:, 0]
        start = 0
        for b, e, k, off in parts:
            m = sdf[start : start + len(e) * k].view(len(e), k).amin(dim=1) - off
            out[e, b] = torch.minimum(out[e, b], m)
            start += len(e) * k
        return out

    @staticmethod
    def _outside_gap(bank, idx: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        """Distance (n, B) of points outside their field's grid box to the box."""
        lo, hi = bank.field_bounds(idx)
        lo, hi = lo.to(p)[:, None], hi.to(p)[:, None]
        return torch.maximum(lo - p, p - hi).clamp_min(0.0).norm(dim=-1)

    def judge(
        self, sensordata: torch.Tensor, bank, field_idx: torch.Tensor, substeps: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(collision (n,), hard_collision (n,)) of the worlds whose sensor rows are ``sensordata`` (n, ...); with
        ``substeps`` (n, S, k: the backend's ``substep_sensordata`` rows) a body touches when it does at any of the
        S substeps."""
        if substeps is None:
            pos, quat = self.poses(sensordata)
            sdf = self.body_sdf(bank, field_idx, pos, quat)
        else:
            if self._sub_cols is None:
                raise RuntimeError("FieldContact.judge: substeps given but sensor_columns found no substep columns")
            n, ns = substeps.shape[:2]
            pos, quat = self.poses(substeps.reshape(n * ns, -1), self._sub_cols)
            sdf = self.body_sdf(bank, field_idx.repeat_interleave(ns), pos, quat).view(n, ns, -1).amin(1)
        touching = sdf < self.cfg.margin
        hard = torch.zeros_like(touching[:, 0]) if self.ghost_obstacles else (touching & self.hard_bodies).any(-1)
        return touching.any(dim=-1), hard


def fill_contact_sdf(scenes, cfg: FieldContactCfg) -> None:
    """Give every scene of ``scenes.bank`` (a ``SceneSet``) its contact SDF, once: the SDF of the geometry its
    physics worlds collide with. Scenes of convex parts (typical, embedded indoor): ``cat.fields.contact_sdf`` of
    the mesh; voxel scenes (procedural, re-meshed crops: ``cat.terrain.mujoco_export.uses_voxels``): d itself."""
    bank = scenes.bank
    if bank.contact_data is not None and bank.contact_band == cfg.band:
        return
    t0, n = time.perf_counter(), len(scenes.scenes)
    for s, scene in enumerate(scenes.scenes):
        d = bank.scene_sdf(s)
        if uses_voxels(scene):  # the physics collides with the voxel solid, whose SDF d is (surface on voxel faces)
            bank.set_contact_sdf(s, d)
        else:  # convex parts of the mesh
            had_mesh = "mesh" in scene.__dict__  # a loaded scene reads its mesh on first use: drop it again after
            mesh = scene.mesh
            bank.set_contact_sdf(s, contact_sdf(mesh, bank.layouts[s].grid, d, cfg.band) if len(mesh.faces) else d)
            if not had_mesh:
                del scene.mesh
        if (s + 1) % 50 == 0 or s + 1 == n:
            log.info("contact SDF: %d / %d scenes (%.0f s)", s + 1, n, time.perf_counter() - t0)
    bank.contact_band = cfg.band


def field_model(robot: RobotCfg) -> mujoco.MjModel:
    """The one model of ``sim.obstacles=field``: robot + floor + the env sensors + the body pose sensors."""
    return build_env_model(robot, lambda spec: add_body_pose_sensors(spec, robot))


def field_contact_for(env: TraversalEnv, model: mujoco.MjModel, cfg: FieldContactCfg | None) -> FieldContact | None:
    """The judgement of a ``field`` env on a scene set (``None``: physical obstacles, or no scenes at all)."""
    if env.obstacles != "field" or env.scenes is None:
        return None
    if env.cfg.ghost_parts_physical:
        raise ValueError("task.ghost_parts_physical draws per-world physical models: not with sim.obstacles=field")
    fc = FieldContact(
        model, env.robot, cfg or FieldContactCfg(), env.device, env.cfg.ghost_parts, env.cfg.ghost_obstacles
    )
    fc.sensor_columns(env.sim.sensors, env.sim.substep_columns)
    if fc.cfg.sdf == "mesh":
        fill_contact_sdf(env.scenes, fc.cfg)
    log.info(
        "sim.obstacles=field: one floor-only model for %d scene(s); contact where the SDF < %.3f m at %d points "
        "on %d bodies (spacing %.3f m) of the %s SDF, judged %s",
        len(env.scenes.scenes),
        fc.cfg.margin,
        fc.num_points,
        len(fc.bodies),
        fc.cfg.spacing,
        "contact (exact near the meshes)" if fc.cfg.sdf == "mesh" else "fields'",
        "at every physics substep" if fc.cfg.substeps else "once per control step",
    )
    return fc
