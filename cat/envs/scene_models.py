"""Per-world scenes (``sim.per_world_scenes``): one compiled model per scene, each world steps its scene's model.

``mujoco.rollout`` steps world i on ``models[i]`` but with one ``MjData`` per *thread*, shared by the worlds that
thread runs, so every model a thread meets must give ``MjData`` the same layout: the same count of everything
``MjData`` holds (:func:`data_layout`: bodies, geoms, bounding-volume nodes, sensors, arena, ...). Scene models
differ in their obstacle geoms (3 convex parts in a typical scene, 500 height-field tiles and boxes in a
procedural one) and in their bounding-volume nodes (2F-1 per mesh of F faces, 2n-1 per body of n colliding
geoms). Hence:

* scenes fall into *layout classes* by geom count (a class spans counts within ``group_ratio`` of its
  smallest); the MuJoCo backend runs one rollout per class present, each with that class's ``MjData``;
* within a class every model is padded to one layout with inert geoms on the static body ``PAD_BODY``
  (contype = conaffinity = 0, far below the floor: they collide with nothing): spheres for the geom
  count, closed meshes of chosen face counts for the node count. A pad geom costs one pose transform per
  physics step; classes keep the padding within ``group_ratio`` of the scene's own geoms.

Everything the env reads (qpos, qvel, controls, sensors) is the robot's and identical in every scene model:
checked here, naming the scene that differs.

Domain randomisation (:class:`WorldModels`): per scene a pool of ``DomainRandCfg.pool_size`` copies, each with
(kp, kd, mass) scales drawn once; an env draws a member at reset and observes that member's scales. Memory is
scenes x pool x one small model (the robot without visual meshes is ~80 kB), whatever the number of envs.
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Callable, Sequence

import mujoco
import numpy as np
import torch
import trimesh

from cat.envs.config import DomainRandCfg
from cat.envs.field_contact import add_body_pose_sensors
from cat.envs.mdp.events import scaled_gains
from cat.envs.robot import RobotCfg, robot_spec
from cat.envs.scene import env_spec, model_composer, strip_visual_meshes
from cat.envs.sim.layout import PAD_BODY, SceneModelError, check_compatible, data_layout
from cat.envs.sim.mujoco_backend import set_model_gains, set_model_mass_scale
from cat.terrain import Scene
from cat.terrain.mujoco_export import add_obstacles_to_spec

log = logging.getLogger(__name__)

PAD_Z = -50.0  # m: pad geoms sit far below the floor
_PAD_MIN_GEOMS = 4  # pad geoms per padded model: room for up to 4 pad meshes
_PAD_NODE_SLACK = 32  # extra bounding-volume nodes a padded model carries (>= 28: see _pad_meshes)
OBSTACLE_CELLS = (4, 4)
"""Each scene's obstacle geoms hang on 4 × 4 static cell bodies over its floor plan (0.75-1.25 m cells): MuJoCo
then tests a limb against a cell's box before the cell's geoms, which cut obstacle collision time by 1.3-2.2×
on procedural and indoor scenes (docs/benchmarks.md). The count is fixed so every scene has the same bodies."""


def scene_name(scene: Scene, i: int) -> str:
    return f"scene {i} ({scene.kind!r}, seed {scene.seed})"


def build_scene_models(
    robot: RobotCfg, scenes: Sequence[Scene], group_ratio: float = 1.25, pose_sensors: bool = False
) -> list[mujoco.MjModel]:
    """One model per scene (robot + that scene's obstacles in its own frame), padded so that models of one layout
    class share ``MjData`` (see the module docstring). Raises :class:`SceneModelError` naming a scene whose
    state, controls or sensors differ from the first scene's."""
    base = robot_spec(robot)
    strip_visual_meshes(base)
    specs, models = [], []
    for scene in scenes:

        def add(spec: mujoco.MjSpec, scene: Scene = scene) -> None:
            add_obstacles_to_spec(spec, scene, cells=OBSTACLE_CELLS)
            spec.worldbody.add_body(name=PAD_BODY)
            if pose_sensors:  # body_clearance's body poses (cat.envs.body_clearance)
                add_body_pose_sensors(spec, robot)

        spec = env_spec(robot, add, base=base)
        specs.append(spec)
        models.append(_compile(spec, scene))
    names = [scene_name(s, i) for i, s in enumerate(scenes)]
    check_compatible(models, names)
    for members in layout_classes([m.ngeom for m in models], group_ratio):
        layouts = {data_layout(models[i]) for i in members}
        if len(layouts) == 1:
            continue
        target_geoms = max(models[i].ngeom for i in members) + _PAD_MIN_GEOMS
        target_nodes = max(models[i].nbvh for i in members) + _PAD_NODE_SLACK
        for i in members:
            _add_padding(specs[i], target_geoms - models[i].ngeom, target_nodes - models[i].nbvh)
            models[i] = _compile(specs[i], scenes[i])
        if len({data_layout(models[i]) for i in members}) != 1:  # a MuJoCo change in how it counts nodes
            raise SceneModelError(f"padding did not equalise the layouts of {[names[i] for i in members]}")
    return models


def layout_classes(ngeom: Sequence[int], group_ratio: float) -> list[list[int]]:
    """Indices grouped by geom count: a class holds the counts within ``group_ratio`` of its smallest."""
    order = sorted(range(len(ngeom)), key=lambda i: ngeom[i])
    classes: list[list[int]] = []
    limit = -1
    for i in order:
        if ngeom[i] > limit:
            classes.append([])
            limit = math.ceil(ngeom[i] * group_ratio)
        classes[-1].append(i)
    return classes


def _compile(spec: mujoco.MjSpec, scene: Scene) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as err:
        raise SceneModelError(f"MuJoCo could not compile the {scene.kind!r} scene: {err}") from err


def _add_padding(spec: mujoco.MjSpec, geoms: int, nodes: int) -> None:
    """``geoms`` inert geoms on ``PAD_BODY`` adding exactly ``nodes`` bounding-volume nodes.

    MuJoCo builds a binary tree with one leaf per element: a body of n colliding geoms has 2n-1 nodes (geoms
    that collide with nothing are left out) and a mesh of F faces 2F-1. Pad meshes carry the nodes; the rest
    of the pad geoms are spheres."""
    faces = _pad_meshes(nodes)
    if len(faces) > geoms:
        raise AssertionError("not enough pad geoms for the pad meshes")
    body = spec.body(PAD_BODY)
    inert = dict(contype=0, conaffinity=0, group=5, pos=[0.0, 0.0, PAD_Z])
    for k, f in enumerate(faces):
        mesh = _closed_mesh(f)
        name = f"{PAD_BODY}_mesh_{k}"
        spec.add_mesh(name=name, uservert=mesh.vertices.ravel().tolist(), userface=mesh.faces.ravel().tolist())
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, **inert)
    for _ in range(geoms - len(faces)):
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0.0, 0.0], **inert)


def _pad_meshes(extra: int) -> list[int]:
    """Face counts of closed meshes (even, >= 4) whose nodes (2F-1 each) sum to ``extra`` (>= 28)."""
    if extra == 0:
        return []
    m = {3: 1, 2: 2, 1: 3, 0: 4}[extra % 4]  # sum(2F-1) = 2*sum(F) - m with sum(F) even
    total = (extra + m) // 2
    if extra < 28 or total % 2 or total < 4 * m:
        raise ValueError(f"cannot pad {extra} bounding-volume nodes with closed meshes")
    return [4] * (m - 1) + [total - 4 * (m - 1)]


def _closed_mesh(faces: int) -> trimesh.Trimesh:
    """A small convex closed mesh with exactly ``faces`` triangles (even, >= 4): a tetrahedron or a bipyramid."""
    r = 0.01
    if faces == 4:
        pts = np.array([[r, 0, 0], [0, r, 0], [0, 0, r], [-r, -r, -r]], dtype=float)
    else:
        k = faces // 2
        a = 2 * np.pi * np.arange(k) / k
        pts = np.r_[np.c_[r * np.cos(a), r * np.sin(a), np.zeros(k)], [[0, 0, r], [0, 0, -r]]]
    hull = trimesh.convex.convex_hull(pts)
    if len(hull.faces) != faces:
        raise AssertionError(f"pad mesh has {len(hull.faces)} faces, wanted {faces}")
    return hull


class WorldModels:
    """The per-world model table of a scene set: per scene ``pool`` models (scene-major: model id =
    ``scene * pool + member``), each with its (kp, kd, mass) scale factors ``scales[scene, member]``.

    Without domain randomisation the pool is the scene model itself (``pool = 1``, scales 1)."""

    def __init__(self, scene_models: list[mujoco.MjModel], robot: RobotCfg, pool: int = 1):
        if pool < 1:
            raise ValueError(f"pool size must be >= 1, got {pool}")
        self.robot, self.pool, self.num_scenes = robot, pool, len(scene_models)
        self._mass0 = [m.body_mass.copy() for m in scene_models]
        self._inertia0 = [m.body_inertia.copy() for m in scene_models]
        self.models = [m if k == 0 else copy.deepcopy(m) for m in scene_models for k in range(pool)]
        self.scales = torch.ones(self.num_scenes, pool, 3)

    @classmethod
    def build(
        cls,
        robot: RobotCfg,
        scenes: Sequence[Scene],
        dr: DomainRandCfg,
        seed: int = 0,
        group_ratio: float = 1.25,
        pose_sensors: bool = False,
    ) -> WorldModels:
        """Scene models of ``scenes``; with ``dr.enabled`` a pool of ``dr.pool_size`` randomised copies each,
        their scales drawn from ``dr``'s ranges with a generator of its own (seeded by ``seed``); ``pose_sensors``:
        every model carries the body pose sensors (``body_clearance``)."""
        wm = cls(build_scene_models(robot, scenes, group_ratio, pose_sensors), robot, dr.pool_size if dr.enabled else 1)
        if dr.enabled:
            g = torch.Generator().manual_seed(seed + 0x5CE7E)
            shape = (wm.num_scenes, wm.pool)

            def u(rng: tuple[float, float]) -> torch.Tensor:
                return rng[0] + (rng[1] - rng[0]) * torch.rand(*shape, generator=g)

            wm.set_scales(torch.stack((u(dr.kp_scale), u(dr.kd_scale), u(dr.mass_scale)), dim=-1))
        log.info(
            "per-world scene models: %d scenes in %d MjData layout classes, pool %d, %d models, %.1f MB",
            wm.num_scenes,
            wm.num_layouts,
            wm.pool,
            len(wm.models),
            wm.nbytes / 2**20,
        )
        return wm

    def compose(self, add_obstacles: Callable[[mujoco.MjSpec], None]) -> mujoco.MjModel:
        """The env model of this table's robot with the obstacles ``add_obstacles`` adds (``model_composer``):
        how the physics layer builds a slot model over the table (``cat.envs.sim.warp_slots``)."""
        return model_composer(self.robot)(add_obstacles)

    def ids(self, scene_ids: torch.Tensor, members: torch.Tensor) -> torch.Tensor:
        """Model ids of (scene, pool member) pairs."""
        return scene_ids.long() * self.pool + members.long()

    def set_scales(self, scales: torch.Tensor) -> None:
        """Set every pool member's gains and masses from ``scales`` (scenes, pool, 3) = (kp, kd, mass) factors
        (the env's ``dr_scales`` convention: kp = robot kp x factor, masses = the scene model's x factor)."""
        scales = scales.to("cpu", torch.float32)
        if scales.shape != self.scales.shape:
            raise ValueError(f"pool scales of shape {tuple(scales.shape)} do not fit {tuple(self.scales.shape)}")
        for s in range(self.num_scenes):
            kp, kd = scaled_gains(self.robot, scales[s])
            for k in range(self.pool):
                m = self.models[s * self.pool + k]
                set_model_gains(m, kp[k].double().numpy(), kd[k].double().numpy())
                set_model_mass_scale(m, float(scales[s, k, 2]), self._mass0[s], self._inertia0[s])
        self.scales = scales.clone()

    @property
    def nbytes(self) -> int:
        """Bytes of the compiled models of the table (``MjModel`` buffers)."""
        return sum(int(m.nbuffer) for m in self.models)

    @property
    def num_layouts(self) -> int:
        return len({data_layout(m) for m in self.models})
