"""Convex, watertight building blocks (boxes, prisms) and cropping of part lists.

Primitive-built scenes (typical types, embedded indoor rooms) are a list of convex closed parts. Their
concatenation is the scene mesh: every connected component is closed and convex, components may
interpenetrate (the solid is their union), and the MuJoCo export can use the parts as convex pieces
directly, without coacd.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation


def box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> trimesh.Trimesh:
    """Axis-aligned box between corners ``lo`` and ``hi``."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if np.any(hi - lo <= 0):
        raise ValueError(f"box with non-positive size: lo={lo}, hi={hi}")
    return trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2))


def oriented_box(center, half_extents, yaw: float = 0.0) -> trimesh.Trimesh:
    """Box of ``half_extents`` rotated by ``yaw`` about z around ``center``."""
    tf = trimesh.transformations.rotation_matrix(yaw, [0, 0, 1])
    tf[:3, 3] = center
    return trimesh.creation.box(extents=2 * np.asarray(half_extents, dtype=np.float64), transform=tf)


def bar(axis: str, center, radius: float, length: float, sections: int = 16) -> trimesh.Trimesh:
    """Horizontal cylinder (hurdle bar) along ``axis`` ('x' or 'y')."""
    cyl = trimesh.creation.cylinder(radius=radius, height=length, sections=sections)
    rot = Rotation.from_euler("x" if axis == "y" else "y", 90, degrees=True).as_matrix()
    tf = np.eye(4)
    tf[:3, :3] = rot
    tf[:3, 3] = center
    cyl.apply_transform(tf)
    return cyl


def vcylinder(center_xy, radius: float, z0: float, z1: float, sections: int = 16) -> trimesh.Trimesh:
    """Vertical cylinder (lamp pole, table leg) from ``z0`` to ``z1``."""
    cyl = trimesh.creation.cylinder(radius=radius, height=z1 - z0, sections=sections)
    cyl.apply_translation([center_xy[0], center_xy[1], (z0 + z1) / 2])
    return cyl


def xz_prism(polygon_xz, y0: float, y1: float) -> trimesh.Trimesh:
    """Convex prism: the convex polygon ``polygon_xz`` [(x, z), ...] in the x-z plane, extruded from ``y0`` to
    ``y1`` (a wedge, a sloped slab across the course)."""
    pts = np.asarray(polygon_xz, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not y1 > y0:
        raise ValueError(f"xz_prism needs >= 3 (x, z) points and y1 > y0, got {pts.tolist()}, {y0}, {y1}")
    xyz = np.concatenate([np.column_stack((pts[:, 0], np.full(len(pts), y), pts[:, 1])) for y in (y0, y1)])
    return trimesh.convex.convex_hull(xyz)


def crop_parts(parts: list[trimesh.Trimesh], lo, hi) -> list[trimesh.Trimesh]:
    """Clip every part to the box [lo, hi].

    Convex parts stay closed and convex (hull of the sliced part); other parts are sliced open and need
    re-meshing (``cat.terrain.voxel.occupancy_to_mesh``) to be watertight again.
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    out = []
    for part in parts:
        m = _clip(part, lo, hi)
        if m is None or len(m.faces) == 0 or (m.is_watertight and abs(m.volume) < 1e-9):
            continue
        out.append(m)
    return out


def _clip(part: trimesh.Trimesh, lo: np.ndarray, hi: np.ndarray) -> trimesh.Trimesh | None:
    b = part.bounds
    if np.any(b[1] <= lo) or np.any(b[0] >= hi):
        return None
    convex = part.is_watertight and part.is_convex
    m = part
    for axis in range(3):
        for sign, val in ((1.0, lo[axis]), (-1.0, hi[axis])):
            if (m.bounds[0 if sign > 0 else 1, axis] - val) * sign >= 0:
                continue  # already on the kept side of this plane
            normal, origin = np.zeros(3), np.zeros(3)
            normal[axis], origin[axis] = sign, val
            m = _clip_convex(m, axis, sign, val) if convex else _slice_open(m, origin, normal)
            if m is None or len(m.faces) == 0:
                return None
    return m


def _clip_convex(m: trimesh.Trimesh, axis: int, sign: float, val: float) -> trimesh.Trimesh | None:
    """Convex part ∩ half-space {sign·(x_axis − val) ≥ 0}: hull of kept vertices and edge crossings."""
    v = m.vertices
    s = sign * (v[:, axis] - val)
    keep = v[s >= 0]
    e = m.edges_unique
    cross = (s[e[:, 0]] > 0) != (s[e[:, 1]] > 0)
    a, b = v[e[cross, 0]], v[e[cross, 1]]
    t = (s[e[cross, 0]] / (s[e[cross, 0]] - s[e[cross, 1]]))[:, None]
    pts = np.vstack([keep, a + t * (b - a)])
    if len(pts) < 4 or np.ptp(pts, axis=0).min() < 1e-6:
        return None
    return trimesh.convex.convex_hull(pts)


def _slice_open(m: trimesh.Trimesh, origin: np.ndarray, normal: np.ndarray) -> trimesh.Trimesh | None:
    v, f = trimesh.intersections.slice_faces_plane(m.vertices, m.faces, normal, origin)[:2]
    return trimesh.Trimesh(v, f, process=True) if len(f) else None


def combine(parts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """Concatenate parts without merging vertices across parts (components stay separable)."""
    if not parts:
        return trimesh.Trimesh()
    verts, faces, off = [], [], 0
    for p in parts:
        verts.append(np.asarray(p.vertices, dtype=np.float64))
        faces.append(np.asarray(p.faces, dtype=np.int64) + off)
        off += len(p.vertices)
    return trimesh.Trimesh(np.vstack(verts), np.vstack(faces), process=False)
