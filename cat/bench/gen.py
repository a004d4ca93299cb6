"""``scripts/bench.py gen``: per-scene generation time (mesh, collision geometry, fields) and how far the
MuJoCo collision geometry deviates from the voxel solid the fields are built from.

Deviation probe: a sphere of radius ``PROBE`` is put at voxel centres (below ``z_reach``) and MuJoCo's
collision detection asked whether it touches an obstacle geom. Occupied centres must touch (``missed``
counts those that do not: geometry smaller than the solid); for free centres in contact the distance to
the solid is recorded (``out_max``: how far the geometry reaches into free space).
"""

from __future__ import annotations

import argparse
import logging
import time

import mujoco
import numpy as np
from scipy import ndimage

from cat.terrain.mujoco_export import OBSTACLE_BIT, add_obstacles_to_spec, uses_voxels
from cat.terrain.procedural import make_procedural
from cat.terrain.scene import Scene
from cat.terrain.voxel_collision import VoxelCollisionCfg

PROBE = 0.002  # m


def distance_to_solid(points: np.ndarray, occ: np.ndarray, origin, voxel: float, reach: int = 6) -> np.ndarray:
    """Exact distance (m) from each point to the union of occupied voxel cubes within ``reach`` voxels
    (``inf`` if none); 0 for points inside an occupied voxel."""
    org = np.asarray(origin, dtype=np.float64)
    u = (points - org) / voxel  # continuous index
    base = np.floor(u).astype(int)
    offs = np.stack(np.meshgrid(*[np.arange(-reach, reach + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
    out = np.full(len(points), np.inf)
    for start in range(0, len(points), 256):
        b = base[start : start + 256, None, :] + offs[None]
        ok = np.all((b >= 0) & (b < np.array(occ.shape)), axis=-1)
        bc = np.clip(b, 0, np.array(occ.shape) - 1)
        solid = ok & occ[bc[..., 0], bc[..., 1], bc[..., 2]]
        gap = np.maximum(np.maximum(b - u[start : start + 256, None, :], u[start : start + 256, None, :] - (b + 1)), 0)
        d = np.where(solid, np.linalg.norm(gap, axis=-1), np.inf).min(axis=1)
        out[start : start + 256] = d * voxel
    return out


def probe_model(scene: Scene, method: str = "auto") -> mujoco.MjModel:
    """The scene's obstacles plus a free sphere that collides with them (qpos[:3] places it)."""
    spec = mujoco.MjSpec()
    add_obstacles_to_spec(spec, scene, method=method)
    probe = spec.worldbody.add_body(name="probe")
    probe.add_freejoint()
    probe.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[PROBE, 0, 0], contype=OBSTACLE_BIT, conaffinity=0)
    return spec.compile()


def collision_deviation(scene: Scene, n: int = 2000, seed: int = 0, method: str = "auto") -> dict[str, float]:
    """Probe ``n`` random points inside occupied voxels and ``n`` in free voxels within 0.2 m of the solid,
    all below ``z_reach``; returns ``missed`` (fraction of the inside points not in contact: geometry smaller
    than the solid), ``out_max`` (m: largest distance to the solid of a free point in contact, minus the probe
    radius) and the geom count."""
    occ = scene.occupancy()
    g = scene.grid()
    org = np.asarray(g.origin, dtype=np.float64)
    near_free = ndimage.binary_dilation(occ, iterations=5) & ~occ
    centres_z = org[2] + (np.arange(g.shape[2]) + 0.5) * g.voxel
    low = (centres_z < VoxelCollisionCfg().z_reach)[None, None, :]
    rng = np.random.default_rng(seed)

    def sample(mask: np.ndarray) -> np.ndarray:
        idx = np.argwhere(mask & low)
        idx = idx[rng.choice(len(idx), min(n, len(idx)), replace=False)]
        return org + (idx + rng.uniform(0, 1, idx.shape)) * g.voxel

    inside, near = sample(occ), sample(near_free)
    m = probe_model(scene, method)
    d = mujoco.MjData(m)

    def touches(p: np.ndarray) -> bool:
        d.qpos[:3] = p
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        return d.ncon > 0

    missed = np.mean([not touches(p) for p in inside]) if len(inside) else 0.0
    hit = near[[touches(p) for p in near]]
    out = distance_to_solid(hit, occ, org, g.voxel) - PROBE if len(hit) else np.zeros(1)
    return {"missed": float(missed), "out_max": float(max(out.max(), 0.0)), "geoms": int(m.ngeom - 1)}


def bench_scene(difficulty: float, seed: int, fields: bool = True) -> dict[str, float]:
    """Seconds for each stage of one procedural scene: mesh (layout, morphology, marching cubes), collision
    geometry (+ MuJoCo compile), fields for all its goals; plus the geom count."""
    out = {}
    t = time.perf_counter()
    scene = make_procedural(difficulty, seed)
    out["mesh_s"] = time.perf_counter() - t
    t = time.perf_counter()
    spec = mujoco.MjSpec()
    out["geoms"] = add_obstacles_to_spec(spec, scene)
    spec.compile()
    out["collision_s"] = time.perf_counter() - t
    out["goals"] = len(scene.goals)
    if fields:
        from cat.fields import Grid, SceneFields, build_fields

        t = time.perf_counter()
        gs = scene.grid()
        SceneFields.from_fields(build_fields(scene.occupancy(), Grid(gs.origin, gs.voxel, gs.shape), scene.goals))
        out["fields_s"] = time.perf_counter() - t
    out["total_s"] = sum(v for k, v in out.items() if k.endswith("_s"))
    out["voxel"] = uses_voxels(scene)
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="bench.py gen", description=__doc__)
    p.add_argument("--scenes", type=int, default=4, help="procedural scenes, difficulties spread over [0, 1]")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--deviation", type=int, default=2000, help="probe points per kind (0: skip)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # keep stdout to result lines
    for i, diff in enumerate(np.linspace(0.0, 1.0, args.scenes) if args.scenes > 1 else [0.5]):
        r = bench_scene(float(diff), args.seed * 1000 + i)
        line = (
            f"case=gen kind=procedural difficulty={diff:.2f} goals={r['goals']} geoms={r['geoms']} "
            f"mesh_s={r['mesh_s']:.2f} collision_s={r['collision_s']:.2f} fields_s={r['fields_s']:.2f} "
            f"total_s={r['total_s']:.2f}"
        )
        if args.deviation > 0:
            dev = collision_deviation(make_procedural(float(diff), args.seed * 1000 + i), args.deviation)
            line += f" missed={dev['missed']:.3f} out_max_m={dev['out_max']:.3f}"
        print(line, flush=True)
