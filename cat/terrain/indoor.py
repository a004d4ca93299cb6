"""Indoor crops (paper §III-B): 5 × 5 m blocks cut from furnished houses around sampled starts.

As in the paper, all furniture is projected onto the ground and the floor minus these footprints is
eroded by 0.1 m; the start is sampled there, a ``crop`` × ``crop`` block is cut around it (the scene is
re-centred so the start is at the origin), and goals are candidates on a 2 m circle around the start,
kept only when reachable through the crop (and on the house floor). An indoor crop's difficulty is
measured, not chosen: the fraction of its floor a humanoid cannot stand on (clutter density). Houses
come from the embedded procedural generator (``cat.terrain.furniture``) or from 3D-FRONT (``cat.terrain.front3d``).

Crops made only of closed convex parts keep them (exact MuJoCo parts, no coacd); crops that cut open
non-closed meshes (3D-FRONT) are re-meshed from their occupancy by marching cubes to be watertight.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from cat.terrain.furniture import House, make_house
from cat.terrain.primitives import combine, crop_parts
from cat.terrain.procedural import circle_goals
from cat.terrain.scene import GOAL_HEIGHT, Scene, SceneError
from cat.terrain.voxel import VOXEL, GridSpec, ReachCfg, erode_xy, occupancy, occupancy_to_mesh, rasterize_xy, walkable

log = logging.getLogger(__name__)


@dataclass
class IndoorCfg:
    crop: float = 5.0  # block side (m)
    height: float = 2.0  # crop height (m); ceilings are above and not part of the scene
    erode: float = 0.1  # clearance erosion of the walkable floor (paper: 0.1 m)
    goal_radius: float = 2.0
    goal_candidates: int = 12
    min_goals: int = 1
    max_attempts: int = 30
    voxel: float = VOXEL


def walkable_floor(house: House, cfg: IndoorCfg) -> tuple[np.ndarray, GridSpec]:
    """Floor minus the ground projection of everything below ``cfg.height``, eroded by ``cfg.erode``."""
    pts = np.vstack([p.bounds for p in house.parts] + [house.floor.bounds])
    lo, hi = pts.min(0), pts.max(0)
    grid = GridSpec.from_bounds(np.array([[lo[0], lo[1], 0.0], [hi[0], hi[1], cfg.height]]), cfg.voxel)
    footprint = occupancy(combine(house.parts), grid).any(axis=2)
    floor = rasterize_xy(house.floor.triangles, grid)
    return erode_xy(floor & ~footprint, cfg.erode, cfg.voxel), grid


def crop_house(house: House, center_xy: np.ndarray, cfg: IndoorCfg) -> tuple[Scene, np.ndarray]:
    """Cut the block around ``center_xy`` and re-centre it; returns the scene (no goals yet) and its floor mask."""
    h = cfg.crop / 2
    lo = np.array([center_xy[0] - h, center_xy[1] - h, 0.0])
    hi = np.array([center_xy[0] + h, center_xy[1] + h, cfg.height])
    shift = -np.array([center_xy[0], center_xy[1], 0.0])
    parts = [p.apply_translation(shift) for p in crop_parts(house.parts, lo, hi)]
    bounds = np.array([lo + shift, hi + shift])
    grid = GridSpec.from_bounds(bounds, cfg.voxel)
    mesh = combine(parts)
    occ = occupancy(mesh, grid)
    closed = all(p.is_watertight for p in parts)
    if not closed:  # open 3D-FRONT surfaces: re-mesh so the scene mesh is watertight
        mesh = occupancy_to_mesh(occ, grid)
    floor = rasterize_xy(house.floor.triangles + shift, grid)
    scene = Scene(
        mesh=mesh,
        bounds=bounds,
        start=np.array([0.0, 0.0, GOAL_HEIGHT]),
        goals=np.zeros((0, 3)),
        kind="indoor",
        meta={
            "family": "indoor",
            "source": house.name,
            "crop_center": [float(center_xy[0]), float(center_xy[1])],
            "primitive_parts": closed,
            "remeshed": not closed,
        },
    )
    scene.set_occupancy(occ, cfg.voxel)
    return scene, floor


def make_indoor(
    seed: int = 0,
    house: House | None = None,
    cfg: IndoorCfg | None = None,
    reach: ReachCfg | None = None,
    stream: int = 0,
) -> Scene:
    """One indoor crop: a procedural house (or ``house``), a sampled start, reachable goals on a circle.

    ``stream`` > 0 selects a separate family of random streams (``[seed, 4241, stream]``): the held-out test
    set (``cat.eval.test_set``) uses stream 1, so no training seed (stream 0) can ever produce its scenes.
    """
    cfg = cfg or IndoorCfg()
    rng = np.random.default_rng([seed, 4241, stream] if stream else [seed, 4241])
    house = house if house is not None else make_house(rng)
    walk, wgrid = walkable_floor(house, cfg)
    cells = np.argwhere(walk)
    if len(cells) == 0:
        raise SceneError(f"{house.name}: no walkable floor left after erosion by {cfg.erode} m")
    x, y, _ = wgrid.axes()
    for attempt in range(cfg.max_attempts):
        i, j = cells[rng.integers(len(cells))]
        center = np.array([x[i], y[j]])
        scene, floor = crop_house(house, center, cfg)
        goals = circle_goals(
            scene.occupancy(cfg.voxel), scene.grid(cfg.voxel), scene.start, cfg.goal_radius,
            cfg.goal_candidates, rng, reach, allowed=floor,
        )  # fmt: skip
        if len(goals) >= cfg.min_goals:
            scene.goals, scene.seed = goals, int(seed)
            walk_crop = walkable(scene.occupancy(cfg.voxel), scene.grid(cfg.voxel), reach) & floor
            scene.difficulty = float(np.clip(1.0 - walk_crop.sum() / max(floor.sum(), 1), 0.0, 1.0))
            scene.meta["attempt"] = attempt
            return scene
    raise SceneError(f"{house.name}: no start with {cfg.min_goals} reachable goal(s) in {cfg.max_attempts} tries")
