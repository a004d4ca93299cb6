"""Procedural obstacle scenes (paper §III-B): noisy rotated boxes, voxel morphology, marching cubes.

Boxes rise from the floor (centred on z = 0, so their visible top depends on their rotation), hang from
the ceiling (centred on the top of the scene) and press in as tall wall slabs forming narrow passages.
Floor and ceiling boxes get a random SO(3) rotation; wall slabs a random yaw and a tilt ≤ ``max_tilt``
so they stay full height. Each face is displaced by 2-D Perlin noise of its in-face coordinates. The
union is rasterised on the 0.04 m grid, closed then opened (3-D morphology removes spikes and slivers),
and turned into a watertight mesh by marching cubes.

Difficulty d ∈ [0, 1] scales counts and sizes. All random draws happen for the maximum counts in a
fixed order, and d only takes prefixes and scales extents about fixed centres; since closing and opening
are increasing operators, the obstacle set grows with d for a fixed seed (free volume falls).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from cat.terrain.noise import Perlin2D
from cat.terrain.scene import GOAL_HEIGHT, Scene, SceneError
from cat.terrain.voxel import VOXEL, GridSpec, ReachCfg, occupancy_to_mesh, reachable, walkable

log = logging.getLogger(__name__)


@dataclass
class ProceduralCfg:
    """Procedural scene parameters; ranges are (easy, hard) for d = 0 → 1."""

    size: float = 5.0  # square block, start at its centre
    height: float = 1.6
    voxel: float = VOXEL
    floor_boxes: tuple[int, int] = (4, 14)
    ceiling_boxes: tuple[int, int] = (2, 8)
    wall_slabs: tuple[int, int] = (2, 10)
    size_scale: tuple[float, float] = (0.75, 1.25)
    noise_amplitude: float = 0.04
    noise_frequency: float = 3.0  # lattice cells per metre
    max_tilt: float = 0.15  # rad, wall slabs
    keep_out: float = 0.5  # obstacle-free radius around the start
    closing_radius: int = 2  # voxels
    opening_radius: int = 1  # voxels
    goal_radius: float = 2.0
    goal_candidates: int = 12
    max_attempts: int = 6


@dataclass
class _Box:
    center: np.ndarray
    half: np.ndarray  # at scale 1
    rot: np.ndarray  # local -> world
    noise: list[Perlin2D]
    scale_axes: np.ndarray  # which half extents scale with difficulty


def _draw_boxes(rng: np.random.Generator, cfg: ProceduralCfg) -> dict[str, list[_Box]]:
    """All candidate boxes at the maximum counts (order fixed, independent of difficulty)."""
    r = cfg.size / 2

    def xy() -> np.ndarray:
        while True:
            p = rng.uniform(-r, r, size=2)
            if np.hypot(*p) > cfg.keep_out + 0.1:
                return p

    def noise() -> list[Perlin2D]:
        return [Perlin2D(rng, cfg.noise_frequency) for _ in range(3)]

    def so3() -> np.ndarray:
        return Rotation.random(random_state=int(rng.integers(2**31))).as_matrix()

    out: dict[str, list[_Box]] = {"floor": [], "ceiling": [], "wall": []}
    for _ in range(cfg.floor_boxes[1]):
        half = rng.uniform([0.15, 0.15, 0.06], [0.45, 0.45, 0.25])
        out["floor"].append(_Box(np.r_[xy(), 0.0], half, so3(), noise(), np.ones(3)))
    for _ in range(cfg.ceiling_boxes[1]):
        half = rng.uniform([0.2, 0.2, 0.12], [0.6, 0.6, 0.3])
        out["ceiling"].append(_Box(np.r_[xy(), cfg.height], half, so3(), noise(), np.ones(3)))
    for _ in range(cfg.wall_slabs[1]):
        half = np.r_[rng.uniform(0.08, 0.12), rng.uniform(0.3, 0.9), cfg.height]
        tilt = Rotation.from_rotvec(np.r_[rng.normal(size=2), 0.0] / np.sqrt(2) * rng.uniform(0, cfg.max_tilt))
        rot = (tilt * Rotation.from_euler("z", rng.uniform(0, 2 * np.pi))).as_matrix()
        out["wall"].append(_Box(np.r_[xy(), cfg.height / 2], half, rot, noise(), np.array([0.0, 1.0, 0.0])))
    return out


def _rasterise(box: _Box, scale: float, grid: GridSpec, occ: np.ndarray, amp: float) -> None:
    half = box.half * np.where(box.scale_axes > 0, scale, 1.0)
    ext = np.abs(box.rot) @ (half + amp)
    sl = grid.box_slice(box.center - ext, box.center + ext)
    if sl is None:
        return
    pts = grid.centers(sl)
    q = (pts - box.center) @ box.rot  # local coordinates
    inside = np.ones(pts.shape[:3], dtype=bool)
    for a in range(3):
        b, c = [i for i in range(3) if i != a]
        sign = np.sign(q[..., a])
        # One Perlin field per axis; opposite faces read it at shifted coordinates.
        bump = amp * box.noise[a](q[..., b] + 17.0 * sign, q[..., c])
        inside &= np.abs(q[..., a]) <= half[a] + bump
    occ[sl] |= inside


def _morphology(occ: np.ndarray, cfg: ProceduralCfg) -> np.ndarray:
    """Closing then opening with voxel balls; edge padding keeps floor/ceiling contacts attached."""
    pad = cfg.closing_radius + cfg.opening_radius + 1
    vol = np.pad(occ, pad, mode="edge")
    vol = ndimage.binary_closing(vol, structure=_ball(cfg.closing_radius))
    vol = ndimage.binary_opening(vol, structure=_ball(cfg.opening_radius))
    return vol[pad:-pad, pad:-pad, pad:-pad]


def _ball(r: int) -> np.ndarray:
    g = np.mgrid[-r : r + 1, -r : r + 1, -r : r + 1]
    return (g**2).sum(0) <= r * r + 1e-9


def procedural_occupancy(
    difficulty: float, rng: np.random.Generator, cfg: ProceduralCfg
) -> tuple[np.ndarray, GridSpec]:
    """Occupancy of one procedural layout on its grid (start at the origin, keep-out carved)."""
    r = cfg.size / 2
    grid = GridSpec.from_bounds(np.array([[-r, -r, 0.0], [r, r, cfg.height]]), cfg.voxel)
    boxes = _draw_boxes(rng, cfg)
    scale = float(np.interp(difficulty, [0, 1], cfg.size_scale))
    occ = np.zeros(grid.shape, dtype=bool)
    for kind, rng_count in (("floor", cfg.floor_boxes), ("ceiling", cfg.ceiling_boxes), ("wall", cfg.wall_slabs)):
        n = int(round(np.interp(difficulty, [0, 1], rng_count)))
        for box in boxes[kind][:n]:
            _rasterise(box, scale, grid, occ, cfg.noise_amplitude)
    occ = _morphology(occ, cfg)
    x, y, _ = grid.axes()
    keep = np.hypot(*np.meshgrid(x, y, indexing="ij")) < cfg.keep_out
    occ[keep] = False
    return occ, grid


def make_procedural(
    difficulty: float = 0.5, seed: int = 0, cfg: ProceduralCfg | None = None, reach: ReachCfg | None = None
) -> Scene:
    """A procedural scene with goals on a circle around the start, kept only when reachable.

    If no candidate goal is reachable the layout is redrawn from the next sub-seed (``meta.attempt``).
    """
    cfg = cfg or ProceduralCfg()
    if not 0.0 <= difficulty <= 1.0:
        raise SceneError(f"difficulty must be in [0, 1], got {difficulty}")
    start = np.array([0.0, 0.0, GOAL_HEIGHT])
    for attempt in range(cfg.max_attempts):
        rng = np.random.default_rng([seed, 7919, attempt])
        occ, grid = procedural_occupancy(difficulty, rng, cfg)
        goals = circle_goals(occ, grid, start, cfg.goal_radius, cfg.goal_candidates, rng, reach)
        if len(goals):
            break
        log.info("procedural seed %d d=%.2f attempt %d: no reachable goal, redrawing", seed, difficulty, attempt)
    else:
        raise SceneError(
            f"procedural seed {seed} difficulty {difficulty}: no reachable goal in {cfg.max_attempts} tries"
        )
    r = cfg.size / 2
    scene = Scene(
        mesh=occupancy_to_mesh(occ, grid),
        bounds=np.array([[-r, -r, 0.0], [r, r, cfg.height]]),
        start=start,
        goals=goals,
        kind="procedural",
        difficulty=float(difficulty),
        seed=int(seed),
        meta={"family": "procedural", "attempt": attempt, "free_volume": float(1 - occ.mean())},
    )
    scene.set_occupancy(occ, grid.voxel)
    return scene


def circle_goals(
    occ: np.ndarray,
    grid: GridSpec,
    start: np.ndarray,
    radius: float,
    n: int,
    rng: np.random.Generator,
    reach: ReachCfg | None = None,
    allowed: np.ndarray | None = None,
) -> np.ndarray:
    """Candidate goals on a circle around ``start`` (random phase), keeping walkable reachable ones."""
    ang = rng.uniform(0, 2 * np.pi) + np.arange(n) * 2 * np.pi / n
    goals = np.c_[start[0] + radius * np.cos(ang), start[1] + radius * np.sin(ang), np.full(n, start[2])]
    ok = reachable(occ, grid, start, goals, reach, allowed)
    walk = walkable(occ, grid, reach)
    idx = grid.index(goals)
    inb = np.all((idx[:, :2] >= 0) & (idx[:, :2] < np.array(grid.shape[:2])), axis=1)
    ok &= inb
    ok[inb] &= walk[idx[inb, 0], idx[inb, 1]]
    return goals[ok]
