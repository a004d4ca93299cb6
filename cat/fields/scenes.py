"""Small deterministic occupancy scenes for the benchmark, docs figure and tests."""

from __future__ import annotations

import numpy as np

from cat.fields.grid import Grid

TYPICAL_GRID = Grid((-0.5, -1.0, 0.0), 0.04, (75, 50, 38))
"""Paper-type scene: 3.0 × 2.0 × 1.5 m, course along +x from (0, 0) to the goal (2, 0, 0.75)."""
TYPICAL_GOAL = (2.0, 0.0, 0.75)
WINDOW_GRID = Grid((-2.56, -2.56, 0.0), 0.04, (128, 128, 35))
"""Deployment window: 5.12 × 5.12 × 1.4 m around the robot."""


def hurdle_crouch(grid: Grid = TYPICAL_GRID) -> np.ndarray:
    """Hurdle bar (r 0.1 m, top 0.2 m) at x = 0.5, ceiling slab (bottom 1.05 m) over x ∈ [1.0, 1.4],
    and a side box at x ∈ [0.2, 0.6], y > 0.55: a typical 'hurdle-crouch' layout."""
    c = grid.centers()
    x, y, z = c[..., 0], c[..., 1], c[..., 2]
    bar = (x - 0.5) ** 2 + (z - 0.1) ** 2 <= 0.1**2
    ceiling = (x >= 1.0) & (x <= 1.4) & (z >= 1.05)
    side = (x >= 0.2) & (x <= 0.6) & (y >= 0.55) & (z <= 0.9)
    return bar | ceiling | side


def cluttered_window(grid: Grid = WINDOW_GRID, n_boxes: int = 40, seed: int = 0) -> np.ndarray:
    """Indoor-like clutter: random furniture-sized boxes on the floor and hanging from the ceiling,
    two walls with doorways; the 0.6 m around the window centre (the robot) is kept free."""
    rng = np.random.default_rng(seed)
    c = grid.centers()
    occ = np.zeros(grid.shape, bool)
    lo, hi = np.asarray(grid.origin), grid.upper
    for _ in range(n_boxes):
        size = rng.uniform([0.2, 0.2, 0.3], [1.2, 0.9, 1.0])
        centre = rng.uniform(lo[:2], hi[:2])
        z0, z1 = (0.0, size[2]) if rng.random() < 0.75 else (hi[2] - size[2] / 2, hi[2])
        occ |= np.all(np.abs(c[..., :2] - centre) <= size[:2] / 2, axis=-1) & (c[..., 2] >= z0) & (c[..., 2] <= z1)
    wall_x = (np.abs(c[..., 0] - 1.5) < 0.06) & (np.abs(c[..., 1] + 0.3) > 0.45)
    wall_y = (np.abs(c[..., 1] + 1.8) < 0.06) & (np.abs(c[..., 0] - 0.2) > 0.4)
    occ |= wall_x | wall_y
    occ &= np.linalg.norm(c[..., :2], axis=-1) > 0.6
    return occ
