"""A scene's contact SDF: its field d, made exact near the obstacle surfaces (``sim.field_contact.sdf=mesh``).

HumanoidPF's d comes from the scene's 4 cm occupancy voxels (as live perception builds it), so it places an
obstacle's surface within about ±2 cm of the mesh: enough for an observation, too coarse for judging contact at a
5 mm margin (a thin bar can be missed by a whole voxel). Field-judged contact can read this grid instead: the same
grid and interpolation, with every voxel centre within ``band`` of a surface (by d) re-measured as the exact signed
distance to the mesh (winding-number sign, ``cat.fields.sdf.mesh_sdf_at``). Farther voxels keep d: the judgement
only compares values near its margin, and its culling values at a bounding sphere's centre against the sphere's
radius, where ±2 cm does not change the outcome. Agreement with physical contact: docs/training.md.
"""

from __future__ import annotations

import numpy as np
import trimesh

from cat.fields.grid import Grid
from cat.fields.sdf import FAR, mesh_sdf_at

DEFAULT_BAND = 0.1
"""m: voxels whose d is below this in magnitude are re-measured (d's surface error, ±2 cm, plus the reach of the
trilinear interpolation at the margin, 4 cm, with room)."""


def contact_sdf(mesh: trimesh.Trimesh, grid: Grid, d: np.ndarray, band: float = DEFAULT_BAND) -> np.ndarray:
    """(nx, ny, nz) float32: ``d`` (the scene's field SDF on ``grid``) with the voxels where ``|d| < band`` replaced
    by the exact signed distance of ``mesh`` at their centres (those with no surface within ``band`` plus a voxel
    keep d)."""
    if d.shape != tuple(grid.shape):
        raise ValueError(f"contact_sdf: d of shape {d.shape} does not match the grid {tuple(grid.shape)}")
    if band <= 0:
        raise ValueError(f"sim.field_contact.band={band}: must be > 0")
    out = np.array(d, dtype=np.float32)
    near = np.nonzero(np.abs(out) < band)
    if len(near[0]) == 0:
        return out
    centres = np.asarray(grid.origin) + grid.voxel * (np.stack(near, axis=1) + 0.5)
    exact = mesh_sdf_at(mesh, centres, max_dist=band + grid.voxel)
    found = exact < 0.5 * FAR
    out[tuple(ix[found] for ix in near)] = exact[found]
    return out


__all__ = ["DEFAULT_BAND", "contact_sdf"]
