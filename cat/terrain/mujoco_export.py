"""Scene obstacles in MuJoCo: convex parts (or voxel height fields and boxes) attached to an ``MjSpec``.

Collision convention (shared with ``cat.envs.robot``, duplicated here so terrain does not import envs; a
test checks they agree): obstacles have ``contype = 0``, ``conaffinity = OBSTACLE_BIT``, ``condim = 3``
and all hang on one static body ``OBSTACLE_BODY``, a child of the world body.

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
from cat.terrain.voxel_collision import VoxelCollisionCfg, add_voxel_parts_to_spec, voxel_parts

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
) -> int:
    """Add the obstacles, moved by ``offset``, as geoms of a static world child ``body_name``; returns the
    geom count.

    ``scene_or_parts`` is a scene (voxel height fields and boxes when :func:`uses_voxels`, else convex parts),
    a mesh (decomposed by ``convex_parts``) or a list of convex parts. ``method="convex"`` forces convex
    parts for a voxel scene, ``"voxel"`` voxel geometry for any scene.
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
        prefix = f"{body_name}_{len(spec.geoms)}_"
        return add_voxel_parts_to_spec(spec, vparts, body, prefix, conaffinity, rgba, voxel_cfg)
    if isinstance(scene_or_parts, Scene):
        parts = convex_parts(scene_or_parts.mesh, cfg, cache)
    elif isinstance(scene_or_parts, trimesh.Trimesh):
        parts = convex_parts(scene_or_parts, cfg, cache)
    else:
        parts = list(scene_or_parts)
    if np.any(off != 0.0):
        parts = [p.copy().apply_translation(off) for p in parts]
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
        body.add_geom(
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
