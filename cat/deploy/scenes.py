"""The demo's world: a scene from a name, folder or mesh file, and the check of a goal the user asks for.

Goal checks use the scene itself (what the user sees in the viewer), not the robot's map: a goal inside a
table is a wrong request whether or not the robot has looked at the table yet. They are input validation,
never part of the robot's observation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from cat.envs.scene_source import typical_kind_or_none
from cat.terrain import GOAL_HEIGHT, TYPICAL_KINDS, Scene, SceneError, make_typical
from cat.terrain.scene import MESH_SUFFIXES, SCENE_FILE
from cat.terrain.voxel import reachable_mask

FLAT = "flat"
FLAT_BOUNDS = np.array([[-4.0, -4.0, 0.0], [8.0, 4.0, 1.5]])  # the window stays clear of the fence near the start
MESH_REACH = 2.56  # a mesh scene's map spans at least the robot's 5.12 m field window around its start [m]


class GoalError(ValueError):
    """A requested goal the robot cannot be sent to; the message says why in one line."""


def load_scene(spec: str, start_xy: tuple[float, float] | None = None, seed: int = 0) -> Scene:
    """``flat``, a typical type (``hurdle-crouch``, ...), a scene folder (``scene.json``) or a mesh file.

    Typical types may be spelt as tasks are (``hurdle_crouch``). A mesh file becomes a scene whose map spans the
    mesh and the robot's 5.12 m field window around the start ``start_xy`` (default the origin), so a goal
    beside a small mesh (a pillar) is on the map."""
    path = Path(spec)
    if spec == FLAT:
        scene = Scene(trimesh.Trimesh(), FLAT_BOUNDS, start=(0.0, 0.0), goals=[(2.0, 0.0)], kind=FLAT)
    elif (kind := typical_kind_or_none(spec)) is not None and not path.exists():
        scene = make_typical(kind, difficulty=0.5, seed=seed)
    elif path.is_dir():
        if not (path / SCENE_FILE).is_file():
            raise SceneError(f"{path}: not a scene folder (no {SCENE_FILE})")
        scene = Scene.load(path)
    elif path.suffix.lower() in MESH_SUFFIXES:
        start = (0.0, 0.0) if start_xy is None else start_xy
        scene = Scene.from_mesh(path, start=start, goal=start)  # goals come from the user
        window = np.array(
            [[start[0] - MESH_REACH, start[1] - MESH_REACH], [start[0] + MESH_REACH, start[1] + MESH_REACH]]
        )
        scene.bounds[0, :2] = np.minimum(scene.bounds[0, :2], window[0])
        scene.bounds[1, :2] = np.maximum(scene.bounds[1, :2], window[1])
    else:
        kinds = ", ".join((FLAT, *TYPICAL_KINDS))
        raise SceneError(f"scene {spec!r} is not a typical type ({kinds}), a scene folder or a mesh file")
    if start_xy is not None:
        scene.start = np.array([start_xy[0], start_xy[1], GOAL_HEIGHT])
    return scene


class GoalChecker:
    """Accepts a floor point as a goal only inside the scene, outside obstacles and reachable on foot."""

    def __init__(self, scene: Scene, margin: float = 0.1, min_clearance: float = 0.1):
        self.scene = scene
        self.margin = margin
        self.min_clearance = min_clearance
        self.grid = scene.grid()
        self.occ = scene.occupancy()
        self._reach_from: tuple[int, int] | None = None
        self._reach: np.ndarray | None = None

    def _reachable(self, robot_xy: np.ndarray) -> np.ndarray:
        """(nx, ny) columns a humanoid can walk to from the robot's column (cached per column)."""
        key = tuple(int(v) for v in self.grid.index(np.r_[robot_xy, GOAL_HEIGHT])[:2])
        if key != self._reach_from:
            self._reach = reachable_mask(self.occ, self.grid, np.r_[robot_xy, GOAL_HEIGHT])
            self._reach_from = key
        return self._reach

    def check(self, xy, robot_xy) -> np.ndarray:
        """The goal (3,) at pelvis height above floor point ``xy``, or GoalError with the reason."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1)[:2]
        if xy.shape != (2,) or not np.all(np.isfinite(xy)):
            raise GoalError(f"goal must be a finite x,y point, got {xy.tolist()}")
        goal = np.r_[xy, GOAL_HEIGHT]
        lo, hi = self.scene.bounds[0, :2] + self.margin, self.scene.bounds[1, :2] - self.margin
        if np.any(xy < lo) or np.any(xy > hi):
            raise GoalError(
                f"goal ({xy[0]:.2f}, {xy[1]:.2f}) is outside the map "
                f"(x {lo[0]:.2f}..{hi[0]:.2f}, y {lo[1]:.2f}..{hi[1]:.2f})"
            )
        if self.scene.clearance(goal[None])[0] < self.min_clearance:
            raise GoalError(f"goal ({xy[0]:.2f}, {xy[1]:.2f}) is inside an obstacle")
        i, j = self.grid.index(goal)[:2]
        if not self._reachable(np.asarray(robot_xy, dtype=np.float64)[:2])[i, j]:
            raise GoalError(f"goal ({xy[0]:.2f}, {xy[1]:.2f}) is unreachable from the robot's position")
        return goal


def floor_hit(ray_origin, ray_direction, floor_z: float = 0.0) -> np.ndarray | None:
    """Where a view ray meets the floor plane (xy), or None when it points away from it."""
    o = np.asarray(ray_origin, dtype=np.float64)
    d = np.asarray(ray_direction, dtype=np.float64)
    if abs(d[2]) < 1e-9:
        return None
    t = (floor_z - o[2]) / d[2]
    if t <= 0:
        return None
    return (o + t * d)[:2]
