"""Where an episode on a scene set starts and which goal it heads for (paper §III-B: "start and goal locations
randomly sampled for each episode").

Two modes (``EpisodeCfg.mode``):

* ``scene``: the scene's own start region and one of its goals (the typical types, whose layout puts the obstacle
  between the two; and every evaluation trial, which the protocol places itself);
* ``free``: for scenes of ``EpisodeCfg.free_kinds`` (indoor crops, procedural scenes, user meshes), any standing
  pose from which one of the scene's precomputed goals (one HumanoidPF field each) is reachable at a geodesic
  distance within ``goal_distance``. The upper bound of that range grows with the env's curriculum level, so the
  distance is part of the curriculum as the scene difficulty is.

Feasibility is computed once per scene from its occupancy: a *standing* column is free from the floor up to
``stand_height`` within ``stand_radius`` of its centre (the robot, arms out, fits upright); the geodesic distance
to a goal is the 8-connected shortest path (``skimage.graph.MCP_Geometric``) over the *walkable* columns of
``cat.terrain.voxel.walkable`` (the humanoid may step over low obstacles and crouch under high ones, as the
scene generators' reachability test assumes). A start is a standing column at a finite geodesic distance in
range, jittered within its voxel. With ``goal_stand_radius`` > 0 a goal is served only if its own column stands at
that radius (the test set's ``goal_stand_radius``, ``cat.eval.test_set``): a trial there can end without contact.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import torch
from scipy import ndimage
from skimage.graph import MCP_Geometric

from cat.terrain import Scene
from cat.terrain.voxel import ReachCfg, standing_mask, walkable

log = logging.getLogger(__name__)

EPISODE_MODES = ("scene", "free")


@dataclass
class EpisodeCfg:
    """Start and goal sampling on scene sets (``task.episodes``)."""

    mode: str = "scene"  # scene | free (module docstring)
    free_kinds: list[str] = field(default_factory=lambda: ["indoor", "procedural", "user"])
    goal_distance: tuple[float, float] = (1.0, 3.5)  # geodesic start-goal distance [m]; 5 s at ~0.9 m/s
    distance_curriculum: bool = True  # the range's upper bound grows with the env's curriculum level
    stand_height: float = 1.35  # free height above a start [m] (G1 upright: ~1.32 m)
    stand_radius: float = 0.40  # free radius around a start [m] (G1 at its default pose: wrists ~0.35-0.4 m out)
    # > 0: only goals whose column stands at this radius (free to stand_height) are served; a goal 0.1 m from a
    # wardrobe (the scene generators' reachability allows it) cannot be reached without touching. 0: every goal
    goal_stand_radius: float = 0.0


GOAL_RADII = tuple(round(0.04 * k, 2) for k in range(11))  # 0 .. 0.40 m, the steps of goal_stand_radii


def goal_stand_radii(scene: Scene, height: float = EpisodeCfg.stand_height, radii=GOAL_RADII) -> np.ndarray:
    """Per goal of ``scene``, the largest of ``radii`` at which the goal's column is a standing column
    (``standing_mask``: free to ``height`` within that radius); -1 where it is not free even at the smallest, or
    outside the grid. A trial ends only with the robot within 0.1 m of its goal touching nothing; at a goal 0.1 m
    from a wardrobe the G1's arms (0.35-0.4 m out at the default pose) cannot. Shared by the episode sampler
    (``goal_stand_radius``) and the unseen test set (``cat.eval.test_set``)."""
    occ, grid = scene.occupancy(), scene.grid()
    ij = grid.index(np.asarray(scene.goals, dtype=np.float64).reshape(-1, 3))[:, :2]
    inside = (ij >= 0).all(axis=1) & (ij[:, 0] < occ.shape[0]) & (ij[:, 1] < occ.shape[1])
    i, j = np.where(inside, ij[:, 0], 0), np.where(inside, ij[:, 1], 0)
    best = np.full(len(ij), -1.0)
    for r in sorted(radii):
        best[inside & standing_mask(occ, grid.voxel, height, r)[i, j]] = r
    return best


class EpisodeError(ValueError):
    """Episode sampling that no scene can serve (the message names the setting)."""


def check_episode_cfg(cfg: EpisodeCfg) -> None:
    """Refuse values that would silently do something else."""
    if cfg.mode not in EPISODE_MODES:
        raise EpisodeError(f"task.episodes.mode={cfg.mode!r}; valid: {', '.join(EPISODE_MODES)}")
    lo, hi = cfg.goal_distance
    if not 0.0 < lo <= hi:
        raise EpisodeError(f"task.episodes.goal_distance must satisfy 0 < min <= max, got {[lo, hi]}")
    if cfg.stand_height <= 0 or cfg.stand_radius < 0:
        raise EpisodeError("task.episodes.stand_height must be > 0 and stand_radius >= 0")
    if cfg.goal_stand_radius < 0:
        raise EpisodeError(f"task.episodes.goal_stand_radius must be >= 0, got {cfg.goal_stand_radius}")


@dataclass
class SceneStarts:
    """Feasible starts of one scene: per goal, the standing points (m, 2) in the scene frame sorted by their
    geodesic distance (m,) to that goal. float32 (voxel centres and path lengths of a few metres: 1e-7 m of
    rounding), a third of float64's 24 bytes per cell: ~60 MiB for a 355-scene set instead of ~180."""

    points: list[np.ndarray]
    distance: list[np.ndarray]

    @property
    def goals_served(self) -> np.ndarray:
        return np.array([len(p) > 0 for p in self.points], dtype=bool)


def geodesic_to(walk: np.ndarray, goal_ij: tuple[int, int], voxel: float) -> np.ndarray:
    """(nx, ny) 8-connected shortest-path length [m] over ``walk`` from the goal column (inf: unreachable)."""
    if not walk[goal_ij]:
        return np.full(walk.shape, np.inf)
    cost = np.where(walk, 1.0, np.inf)
    dist, _ = MCP_Geometric(cost, fully_connected=True).find_costs([goal_ij])
    return np.where(np.isfinite(dist), dist * voxel, np.inf)


def scene_starts(scene: Scene, cfg: EpisodeCfg, reach: ReachCfg | None = None) -> SceneStarts:
    """The feasible starts of every goal of ``scene`` (module docstring)."""
    occ, grid = scene.occupancy(), scene.grid()
    stand = standing_mask(occ, grid.voxel, cfg.stand_height, cfg.stand_radius)
    walk = walkable(occ, grid, reach)
    # a goal column that the body radius just misses still seeds its walkable neighbourhood
    walk_seed = walk | ndimage.binary_dilation(walk) & ~occ[:, :, 0]
    r = cfg.goal_stand_radius
    goal_ok = goal_stand_radii(scene, cfg.stand_height, (r,)) >= r if r else np.ones(len(scene.goals), dtype=bool)
    lo, hi = cfg.goal_distance
    centres = np.stack(np.meshgrid(*[grid.axes()[a] for a in (0, 1)], indexing="ij"), axis=-1)
    points, distance = [], []
    for goal, ok in zip(scene.goals, goal_ok, strict=True):
        i, j = grid.index(goal[None])[0, :2]
        if not (0 <= i < occ.shape[0] and 0 <= j < occ.shape[1]) or not ok:
            points.append(np.zeros((0, 2), dtype=np.float32))
            distance.append(np.zeros(0, dtype=np.float32))
            continue
        w = walk.copy()
        w[i, j] = walk_seed[i, j]
        d = geodesic_to(w, (int(i), int(j)), grid.voxel)
        ok = stand & np.isfinite(d) & (d >= lo) & (d <= hi)
        order = np.argsort(d[ok], kind="stable")
        points.append(centres[ok][order].astype(np.float32))
        distance.append(d[ok][order].astype(np.float32))
    return SceneStarts(points, distance)


class EpisodeSampler:
    """Per-episode start and goal for the scenes of a ``SceneSet`` (``free`` mode; ``scene`` mode is the set's
    own start regions)."""

    def __init__(self, scenes: list[Scene], cfg: EpisodeCfg, voxel: float):
        check_episode_cfg(cfg)
        self.cfg, self.voxel = cfg, voxel
        self.starts: list[SceneStarts | None] = []
        for s in scenes:
            self.starts.append(scene_starts(s, cfg) if cfg.mode == "free" and s.kind in cfg.free_kinds else None)
        free = [i for i, s in enumerate(self.starts) if s is not None]
        served = [i for i in free if self.starts[i].goals_served.any()]
        if free and not served:
            raise EpisodeError(
                f"task.episodes.goal_distance={list(cfg.goal_distance)}"
                + (f" with goal_stand_radius={cfg.goal_stand_radius}" if cfg.goal_stand_radius else "")
                + f": no goal of the {len(free)} scene(s) of kinds {sorted({scenes[i].kind for i in free})} is "
                "reachable from a standing start in that range"
            )
        for i in sorted(set(free) - set(served)):
            log.warning("scene %d (%s): no start in goal_distance; it keeps its own start region", i, scenes[i].kind)
            self.starts[i] = None
        if free:
            n = [int(sum(len(p) for p in self.starts[i].points)) for i in served]
            log.info("free episodes: %d scenes, %d-%d feasible (start, goal) cells each", len(served), min(n), max(n))

    def is_free(self, scene_idx: int) -> bool:
        return self.starts[scene_idx] is not None

    def sample(self, scene_idx: int, progress: float, gen: torch.Generator) -> tuple[np.ndarray, int]:
        """(start xy in the scene frame, goal index) for one episode; ``progress`` in (0, 1] scales the
        range's upper bound when ``distance_curriculum`` is on."""
        st = self.starts[scene_idx]
        goals = np.flatnonzero(st.goals_served)
        g = int(goals[int(torch.randint(len(goals), (1,), generator=gen))])
        lo, hi = self.cfg.goal_distance
        cap = lo + (hi - lo) * (progress if self.cfg.distance_curriculum else 1.0)
        n = max(int(np.searchsorted(st.distance[g], cap, side="right")), 1)
        k = int(torch.randint(n, (1,), generator=gen))
        jitter = (torch.rand(2, generator=gen).numpy() - 0.5) * self.voxel
        return st.points[g][k] + jitter, g
