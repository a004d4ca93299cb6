"""HumanoidPF (paper §III-A): SDF, geodesic attraction, repulsion, priority weighting, link query, vMF reward.

>>> from cat.fields import Grid, build_field
>>> f = build_field(occupancy_or_mesh, Grid((-0.5, -1, 0), 0.04, (75, 50, 38)), goal=(2.0, 0.0, 0.75))
>>> f.sdf, f.geodesic, f.force  # numpy (nx, ny, nz[, 3])
"""

from cat.fields._wp import init_warp
from cat.fields.bank import QUERY_CHANNELS, FieldBank, FieldSample, SceneLayout, bank_bytes
from cat.fields.config import FieldCfg, StaleFieldError
from cat.fields.contact_sdf import contact_sdf
from cat.fields.field import CHANNELS, Field, build_field, build_fields
from cat.fields.geodesic import geodesic_distance
from cat.fields.grid import Grid
from cat.fields.humanoid_pf import field_reward, humanoid_pf, log_c3, priority_weights, vmf_log_likelihood
from cat.fields.sdf import mesh_sdf_at, occupancy_from_points, sdf_from_mesh, sdf_from_occupancy, sdf_from_points
from cat.fields.store import SceneFields

__all__ = [
    "CHANNELS",
    "Field",
    "FieldBank",
    "FieldCfg",
    "FieldSample",
    "QUERY_CHANNELS",
    "SceneFields",
    "SceneLayout",
    "StaleFieldError",
    "bank_bytes",
    "Grid",
    "build_field",
    "build_fields",
    "contact_sdf",
    "field_reward",
    "geodesic_distance",
    "humanoid_pf",
    "init_warp",
    "log_c3",
    "mesh_sdf_at",
    "occupancy_from_points",
    "priority_weights",
    "sdf_from_mesh",
    "sdf_from_occupancy",
    "sdf_from_points",
    "vmf_log_likelihood",
]
