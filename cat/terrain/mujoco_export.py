"""Scene obstacles in MuJoCo: convex parts (or voxel height fields and boxes) attached to an ``MjSpec``.

Collision convention (shared with ``cat.envs.robot``, duplicated here so terrain does not import envs; a
test checks they agree): obstacles have ``contype = 0``, ``conaffinity = OBSTACLE_BIT``, ``condim = 3``
and all hang on one static body ``OBSTACLE_BODY``, a child of the world body, or on static children of it
(``cells``: one per cell of a grid over the scene's floor plan). MuJoCo's collision broad phase prunes by body
before it walks a body's tree of geom boxes, so cells keep limbs away from most of a scene's geoms at the price
of one cheap box test per cell (docs/benchmarks.md, "Physics with obstacles"). :func:`obstacle_geom_ids` finds
the obstacle geoms either way.

Scenes made of voxels (procedural obstacles, re-meshed crops: :func:`uses_voxels`) get their collision
geometry from the occupancy grid the fields are built from (``cat.terrain.voxel_collision``: height-field
tiles plus boxes, milliseconds, within half a voxel to a voxel of the solid). Other scenes use convex parts:
the mesh is split into connected components; closed convex components (every part of a typical or
embedded-indoor scene: boxes, prisms) are used as they are, others go through coacd with modest settings
(``CoacdCfg``). coacd results are cached in ``$CAT_CACHE_DIR/coacd`` (default ``~/.cache/cat/coacd``) under
a hash of the component's vertices, faces and the settings.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import mujoco
import numpy as np
import trimesh

from cat.terrain.scene import Scene, SceneError
from cat.terrain.voxel import GridSpec
from cat.terrain.voxel_collision import VoxelCollisionCfg, VoxelParts, add_voxel_parts_to_spec, voxel_parts

log = logging.getLogger(__name__)

OBSTACLE_BODY = "obstacles"
OBSTACLE_BIT = 1
MIN_PART_VOLUME = 1e-7  # m^3; thinner hulls are dropped (MuJoCo rejects degenerate meshes)


@dataclass
class CoacdCfg:
    """coacd settings: coarse enough for ~10-30 s on a 25k-face component on one CPU core."""

    threshold: float = 0.08  # concavity tolerance
    max_convex_hull: int = 16  # per component
    resolution: int = 1000  # sampling resolution of the manifold preprocessing
    preprocess_mode: str = "auto"
    mcts_iterations: int = 60
    mcts_max_depth: int = 2
    mcts_nodes: int = 10
    max_ch_vertex: int = 64
    seed: int = 0


def cache_dir() -> Path:
    """``$CAT_CACHE_DIR/coacd`` or ``~/.cache/cat/coacd``."""
    root = os.environ.get("CAT_CACHE_DIR")
    return (Path(root) if root else Path.home() / ".cache" / "cat") / "coacd"


def mesh_hash(mesh: trimesh.Trimesh, cfg: CoacdCfg) -> str:
    h = hashlib.sha1()
    h.update(np.ascontiguousarray(np.round(mesh.vertices, 7), dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    h.update(json.dumps(asdict(cfg), sort_keys=True).encode())
    return h.hexdigest()


def coacd_parts(mesh: trimesh.Trimesh, cfg: CoacdCfg | None = None, cache: Path | None = None) -> list[trimesh.Trimesh]:
    """coacd convex decomposition of one mesh, read from / written to the cache."""
    import coacd

    cfg = cfg or CoacdCfg()
    cache = cache or cache_dir()
    path = cache / f"{mesh_hash(mesh, cfg)}.npz"
    if path.is_file():
        data = np.load(path)
        n = len([k for k in data.files if k.startswith("v")])
        return [trimesh.Trimesh(data[f"v{i}"], data[f"f{i}"], process=False) for i in range(n)]
    coacd.set_log_level("error")
    params = asdict(cfg)
    result = coacd.run_coacd(coacd.Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)), **params)
    parts = [trimesh.Trimesh(np.asarray(v), np.asarray(f), process=False) for v, f in result]
    cache.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    arrays = {f"v{i}": p.vertices for i, p in enumerate(parts)} | {f"f{i}": p.faces for i, p in enumerate(parts)}
    np.savez_compressed(tmp, **arrays)
    tmp.replace(path)
    return parts


def convex_parts(
    mesh: trimesh.Trimesh, cfg: CoacdCfg | None = None, cache: Path | None = None
) -> list[trimesh.Trimesh]:
    """Convex pieces covering ``mesh``: convex closed components as is, the rest through coacd."""
    parts: list[trimesh.Trimesh] = []
    if len(mesh.faces) == 0:
        return parts
    n_coacd = 0
    for comp in mesh.split(only_watertight=False):
        if comp.is_watertight and comp.is_convex:
            parts.append(comp)
        else:
            n_coacd += 1
            parts += coacd_parts(comp, cfg, cache)
    log.debug("convex parts: %d (%d components through coacd)", len(parts), n_coacd)
    return parts


def uses_voxels(scene: Scene) -> bool:
    """Whether a scene's obstacles are voxels (procedural, or re-meshed from a rasterisation)."""
    return scene.kind == "procedural" or bool(scene.meta.get("remeshed"))


def add_obstacles_to_spec(
    spec: mujoco.MjSpec,
    scene_or_parts: Scene | trimesh.Trimesh | list[trimesh.Trimesh],
    cfg: CoacdCfg | None = None,
    cache: Path | None = None,
    body_name: str = OBSTACLE_BODY,
    conaffinity: int = OBSTACLE_BIT,
    rgba: tuple[float, float, float, float] = (0.75, 0.55, 0.35, 1.0),
    offset=(0.0, 0.0, 0.0),
    voxel_cfg: VoxelCollisionCfg | None = None,
    method: str = "auto",
    cells: tuple[int, int] | None = None,
) -> int:
    """Add the obstacles, moved by ``offset``, as geoms of a static world child ``body_name``; returns the
    geom count.

    ``scene_or_parts`` is a scene (voxel height fields and boxes when :func:`uses_voxels`, else convex parts),
    a mesh (decomposed by ``convex_parts``) or a list of convex parts. ``method="convex"`` forces convex
    parts for a voxel scene, ``"voxel"`` voxel geometry for any scene. ``cells=(nx, ny)``: the geoms go to
    ``nx * ny`` static children of ``body_name`` (``<body_name>_cell_<k>``, all of them made, empty or not, so
    every scene gets the same bodies), each holding the geoms whose centre lies in its cell of the scene's
    floor plan (its bounds; the parts' bounds for meshes and part lists).
    """
    if method not in ("auto", "voxel", "convex"):
        raise ValueError(f"method must be 'auto', 'voxel' or 'convex', got {method!r}")
    body = spec.body(body_name)
    if body is None:
        body = spec.worldbody.add_body(name=body_name)
    off = np.asarray(offset, dtype=np.float64).reshape(3)
    is_scene = isinstance(scene_or_parts, Scene)
    if is_scene and (method == "voxel" or (method == "auto" and uses_voxels(scene_or_parts))):
        g = scene_or_parts.grid()
        grid = GridSpec(tuple(float(v) for v in np.asarray(g.origin) + off), g.voxel, g.shape)
        vparts = voxel_parts(scene_or_parts.occupancy(), grid, voxel_cfg)
        plan = _CellBodies(spec, body, cells, scene_or_parts.bounds[:, :2] + off[:2])
        prefix = f"{body_name}_{len(spec.geoms)}_"
        n = 0
        for k, cell in plan.split_voxel_parts(vparts):
            n += add_voxel_parts_to_spec(spec, cell, plan.bodies[k], f"{prefix}{k}_", conaffinity, rgba, voxel_cfg)
        return n
    if isinstance(scene_or_parts, Scene):
        parts = convex_parts(scene_or_parts.mesh, cfg, cache)
    elif isinstance(scene_or_parts, trimesh.Trimesh):
        parts = convex_parts(scene_or_parts, cfg, cache)
    else:
        parts = list(scene_or_parts)
    if np.any(off != 0.0):
        parts = [p.copy().apply_translation(off) for p in parts]
    if is_scene:
        plan_xy = scene_or_parts.bounds[:, :2] + off[:2]
    elif parts:
        corners = np.array([p.bounds[:, :2] for p in parts])
        plan_xy = np.array([corners[:, 0].min(axis=0), corners[:, 1].max(axis=0)])
    else:
        plan_xy = np.zeros((2, 2))
    plan = _CellBodies(spec, body, cells, plan_xy)
    prefix = f"{body_name}_{len(spec.meshes)}_"
    n = 0
    for part in parts:
        if not np.all(np.isfinite(part.vertices)):
            raise SceneError("obstacle part has non-finite vertices")
        hull = part if part.is_convex and part.is_watertight else part.convex_hull
        if hull.volume < MIN_PART_VOLUME:
            continue
        name = f"{prefix}{n}"
        spec.add_mesh(name=name, uservert=hull.vertices.ravel().tolist(), userface=hull.faces.ravel().tolist())
        plan.body_at(hull.bounds.mean(axis=0)).add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=name,
            contype=0,
            conaffinity=conaffinity,
            condim=3,
            group=1,
            rgba=list(rgba),
        )
        n += 1
    return n


class _CellBodies:
    """The static bodies obstacle geoms go to: ``body`` itself, or one child per cell of an ``nx × ny`` grid over
    the floor plan ``plan_xy`` ((2, 2) lower / upper corner; centres outside go to the nearest cell)."""

    def __init__(self, spec: mujoco.MjSpec, body: mujoco.MjsBody, cells: tuple[int, int] | None, plan_xy: np.ndarray):
        self.cells = None if cells is None else (int(cells[0]), int(cells[1]))
        if self.cells is not None and min(self.cells) < 1:
            raise ValueError(f"cells must be two positive counts, got {cells}")
        self.lo = np.asarray(plan_xy[0], dtype=np.float64)
        self.span = np.maximum(np.asarray(plan_xy[1], dtype=np.float64) - self.lo, 1e-9)
        if self.cells is None:
            self.bodies = [body]
        else:
            self.bodies = [body.add_body(name=f"{body.name}_cell_{k}") for k in range(self.cells[0] * self.cells[1])]

    def index(self, centre) -> int:
        if self.cells is None:
            return 0
        ij = np.floor((np.asarray(centre, dtype=np.float64)[:2] - self.lo) / self.span * self.cells).astype(int)
        i, j = np.clip(ij, 0, np.array(self.cells) - 1)
        return int(i) * self.cells[1] + int(j)

    def body_at(self, centre) -> mujoco.MjsBody:
        return self.bodies[self.index(centre)]

    def split_voxel_parts(self, parts: VoxelParts) -> list[tuple[int, VoxelParts]]:
        """``parts`` split by cell (tiles by their centre, boxes by theirs); cells with nothing are left out."""
        groups: dict[int, tuple[list, list, list]] = {}
        for t in parts.floor:
            groups.setdefault(self.index(t.lower + t.size / 2), ([], [], []))[0].append(t)
        for t in parts.ceiling:
            groups.setdefault(self.index(t.lower + t.size / 2), ([], [], []))[1].append(t)
        for b in parts.boxes:
            groups.setdefault(self.index(b.mean(axis=0)), ([], [], []))[2].append(b)
        z = (parts.floor_z, parts.top_z)
        return [
            (k, VoxelParts(floor, ceiling, np.asarray(boxes, dtype=np.float64).reshape(-1, 2, 3), *z))
            for k, (floor, ceiling, boxes) in sorted(groups.items())
        ]


def obstacle_geom_ids(model: mujoco.MjModel, body_name: str = OBSTACLE_BODY) -> np.ndarray:
    """Geom ids on ``body_name`` and its descendants (its cell bodies); empty when there is no such body."""
    root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name)
    if root < 0:
        return np.zeros(0, dtype=np.int64)
    inside = np.zeros(model.nbody, dtype=bool)
    inside[root] = True
    for b in range(root + 1, model.nbody):  # MuJoCo numbers a body after its parent
        inside[b] = inside[model.body_parentid[b]]
    return np.flatnonzero(inside[model.geom_bodyid])
