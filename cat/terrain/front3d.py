"""3D-FRONT house loader (scene JSON + 3D-FUTURE model folders) producing a ``House`` for indoor crops.

House JSON (the real format): top-level ``uid``, ``furniture`` [{uid, jid, ...}], ``mesh`` (architecture:
{uid, type, xyz flat, faces flat, ...}) and ``scene.room`` [{type, instanceid, children: [{ref,
instanceid, pos, rot (quaternion x, y, z, w), scale}]}]; a child's ``ref`` names a furniture or mesh uid.
Models are ``<model_dir>/<jid>/raw_model.obj`` (y-up, metres). 3D-FRONT is y-up; we convert to z-up with
(x, y, z) -> (x, −z, y). ``Floor`` meshes give the walkable floor; ceilings, slab tops/bottoms, light
bands, holes and door meshes are skipped (doors stay passable); all other meshes and furniture are
obstacles. Errors name the offending file.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np
import trimesh

from cat.terrain.furniture import House

log = logging.getLogger(__name__)

FLOOR_TYPES = ("Floor",)
SKIP_TYPES = ("Ceiling", "SlabTop", "SlabBottom", "LightBand", "Hole", "Door")
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])


class Front3DError(ValueError):
    """A 3D-FRONT house or 3D-FUTURE model file is missing or malformed (the message names it)."""


def load_front3d(
    house_json: str | os.PathLike,
    model_dir: str | os.PathLike,
    rooms: list[str] | None = None,
    missing_models: str = "error",
) -> House:
    """Read a 3D-FRONT house; ``rooms`` keeps room instance ids or types; ``missing_models`` error|skip."""
    path = Path(house_json)
    if not path.is_file():
        raise Front3DError(f"{path}: 3D-FRONT house file not found")
    try:
        raw = json.loads(path.read_text())
        furniture = {f["uid"]: f for f in raw.get("furniture", [])}
        arch = {m["uid"]: m for m in raw.get("mesh", [])}
        room_list = raw["scene"]["room"]
    except json.JSONDecodeError as err:
        raise Front3DError(f"{path}: invalid JSON ({err})") from err
    except (KeyError, TypeError) as err:
        raise Front3DError(f"{path}: not a 3D-FRONT house (missing {err})") from err
    model_dir = Path(model_dir)
    cache: dict[str, trimesh.Trimesh] = {}
    parts, tags, floors = [], [], []
    for room in room_list:
        if rooms is not None and room.get("instanceid") not in rooms and room.get("type") not in rooms:
            continue
        for child in room.get("children", []):
            try:
                ref = child["ref"]
                tf = _child_transform(child)
            except (KeyError, ValueError, TypeError) as err:
                where = f"child {child.get('instanceid', '?')} in room {room.get('instanceid')}"
                raise Front3DError(f"{path}: bad {where} ({err!r})") from err
            if ref in arch:
                m = arch[ref]
                kind = str(m.get("type", ""))
                if any(s in kind for s in SKIP_TYPES):
                    continue
                mesh = _arch_mesh(m, path).apply_transform(tf)
                if kind in FLOOR_TYPES:
                    floors.append(mesh)
                else:
                    parts.append(mesh)
                    tags.append("arch")
            elif ref in furniture:
                jid = furniture[ref].get("jid")
                model = _model(model_dir, jid, cache, missing_models, path)
                if model is not None:
                    parts.append(model.copy().apply_transform(tf))
                    tags.append("furniture")
            else:
                log.debug("%s: child ref %s matches no furniture or mesh; skipped", path, ref)
    if not floors:
        raise Front3DError(f"{path}: no Floor mesh in the selected rooms")
    to_z = np.eye(4)
    to_z[:3, :3] = Y_UP_TO_Z_UP
    parts = [p.apply_transform(to_z) for p in parts]
    floor = trimesh.util.concatenate(floors).apply_transform(to_z)
    z0 = float(floor.vertices[:, 2].min())  # put the floor at z = 0
    for m in [*parts, floor]:
        m.apply_translation([0, 0, -z0])
    return House(parts=parts, floor=floor, name=str(raw.get("uid", path.stem)), tags=tags)


def _child_transform(child: dict) -> np.ndarray:
    pos = np.asarray(child.get("pos", [0, 0, 0]), dtype=np.float64).reshape(3)
    q = np.asarray(child.get("rot", [0, 0, 0, 1]), dtype=np.float64).reshape(4)
    scale = np.asarray(child.get("scale", [1, 1, 1]), dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(q)) and np.all(np.isfinite(scale))):
        raise ValueError("non-finite pos/rot/scale")
    if np.linalg.norm(q) < 1e-9:
        raise ValueError("zero rotation quaternion")
    tf = trimesh.transformations.quaternion_matrix([q[3], q[0], q[1], q[2]] / np.linalg.norm(q))
    tf[:3, :3] = tf[:3, :3] @ np.diag(scale)
    tf[:3, 3] = pos
    return tf


def _arch_mesh(m: dict, path: Path) -> trimesh.Trimesh:
    try:
        v = np.asarray(m["xyz"], dtype=np.float64).reshape(-1, 3)
        f = np.asarray(m["faces"], dtype=np.int64).reshape(-1, 3)
    except (KeyError, ValueError) as err:
        raise Front3DError(f"{path}: mesh {m.get('uid')} has bad xyz/faces ({err!r})") from err
    if len(f) and (f.min() < 0 or f.max() >= len(v)) or not np.all(np.isfinite(v)):
        raise Front3DError(f"{path}: mesh {m.get('uid')} has out-of-range faces or non-finite vertices")
    return trimesh.Trimesh(v, f, process=True)


def _model(model_dir: Path, jid, cache: dict, missing: str, house: Path) -> trimesh.Trimesh | None:
    obj = model_dir / str(jid) / "raw_model.obj"
    if str(jid) in cache:
        return cache[str(jid)]
    if not obj.is_file():
        if missing == "skip":
            log.warning("3D-FUTURE model missing, skipped: %s", obj)
            cache[str(jid)] = None
            return None
        raise Front3DError(f"{obj}: 3D-FUTURE model not found (furniture jid {jid} of {house})")
    try:
        mesh = trimesh.load(str(obj), force="mesh", process=True)
    except Exception as err:
        raise Front3DError(f"{obj}: could not read model ({type(err).__name__}: {err})") from err
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0 or not np.all(np.isfinite(mesh.vertices)):
        raise Front3DError(f"{obj}: model has no valid triangles")
    cache[str(jid)] = mesh
    return mesh
