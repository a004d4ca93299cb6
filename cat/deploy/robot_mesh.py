"""The G1 as it looks: its menagerie visual meshes, one mesh per body, for the viewer.

The simulation drops the visual meshes (``cat.envs.scene.strip_visual_meshes``); drawing collision capsules
makes a stick figure. Here the full model is compiled once, its visual mesh geoms (``contype = conaffinity = 0``)
are put in their body's frame and merged per body, so the viewer moves one mesh per body by the body's pose in the
runtime's (stripped) model, which has the same bodies. The menagerie meshes hold ~390 k triangles; they are
decimated to ``keep`` of them (quadric decimation) so a browser draws them at frame rate, and the result is cached
under ``$XDG_CACHE_HOME/cat`` (keyed by the model files), since compiling and decimating take ~10 s.
"""

from __future__ import annotations

import hashlib
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import trimesh

from cat.envs.robot import RobotCfg, menagerie_model_path, robot_spec

log = logging.getLogger(__name__)


@dataclass
class BodyMesh:
    body: str
    mesh: trimesh.Trimesh  # in the body's frame


def _geom_in_body(model: mujoco.MjModel, g: int) -> trimesh.Trimesh:
    mid = model.geom_dataid[g]
    v0, nv = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
    f0, nf = model.mesh_faceadr[mid], model.mesh_facenum[mid]
    mesh = trimesh.Trimesh(model.mesh_vert[v0 : v0 + nv].copy(), model.mesh_face[f0 : f0 + nf].copy(), process=False)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.geom_quat[g])
    tf = np.eye(4)
    tf[:3, :3], tf[:3, 3] = rot.reshape(3, 3), model.geom_pos[g]
    return mesh.apply_transform(tf)


def visual_meshes(robot: RobotCfg, keep: float = 0.1, cache: bool = True) -> list[BodyMesh]:
    """Per body with visual geoms, their meshes merged in the body's frame and decimated to ``keep`` of their
    triangles (1: as shipped); empty when the model has none."""
    path = _cache_file(robot, keep) if cache else None
    if path is not None and path.is_file():
        with np.load(path) as z:
            names = [str(n) for n in z["bodies"]]
            return [BodyMesh(b, trimesh.Trimesh(z[f"v{i}"], z[f"f{i}"], process=False)) for i, b in enumerate(names)]
    meshes = _build(robot, keep)
    if path is not None and meshes:
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = {"bodies": np.array([m.body for m in meshes])}
        for i, m in enumerate(meshes):
            arrays[f"v{i}"], arrays[f"f{i}"] = m.mesh.vertices.astype(np.float32), m.mesh.faces.astype(np.int32)
        tmp = path.with_suffix(".tmp.npz")
        np.savez_compressed(tmp, **arrays)
        tmp.replace(path)  # a half-written cache is never read
    return meshes


def _cache_file(robot: RobotCfg, keep: float) -> Path:
    model = menagerie_model_path(robot)
    h = hashlib.sha256(f"{keep}".encode())
    for f in sorted([model, *model.parent.joinpath("assets").glob("*")]):
        st = f.stat()
        h.update(f"{f.name}:{st.st_size}:{int(st.st_mtime)}".encode())
    root = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "cat"
    return root / f"g1_visual_{h.hexdigest()[:16]}.npz"


def _build(robot: RobotCfg, keep: float) -> list[BodyMesh]:
    model = robot_spec(robot, floor=False).compile()
    by_body: dict[str, list[trimesh.Trimesh]] = {}
    for g in range(model.ngeom):
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH or model.geom_contype[g] or model.geom_conaffinity[g]:
            continue
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[g]))
        by_body.setdefault(name, []).append(_geom_in_body(model, g))
    out = []
    for body, ms in by_body.items():
        mesh = trimesh.util.concatenate(ms)
        if keep < 1.0 and len(mesh.faces) > 200:
            mesh = mesh.simplify_quadric_decimation(percent=1.0 - keep)
        out.append(BodyMesh(body, mesh))
    log.info("G1 visual meshes: %d bodies, %d triangles", len(out), sum(len(m.mesh.faces) for m in out))
    return out
