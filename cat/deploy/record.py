"""rerun recording of a live run: robot, goal, F_H arrows (``cat.viz.record.Recorder``) plus the robot's map:
the occupied voxels of the field window and the window's outline, logged whenever perception publishes."""

from __future__ import annotations

import numpy as np
import rerun as rr

from cat.deploy.perception import occupied_in_map
from cat.viz.record import Recorder


class LiveRecorder(Recorder):
    """Call ``log(runtime)`` after control steps; every ``every``-th step is written (25 Hz by default)."""

    def __init__(self, path: str, runtime, every: int = 2):
        super().__init__(path, runtime.model, runtime.robot.collision_geoms, runtime.scene.mesh)
        self.every = every
        self._steps = 0
        self._last_field = None

    def log(self, runtime) -> None:
        self._steps += 1
        if (self._steps - 1) % self.every:
            return
        view = runtime.view()
        self.set_time(view.time)
        self.log_robot(view.qpos)
        if view.goal is not None:
            self.log_goal(view.goal)
            self.log_scalar("metrics/goal_distance", view.outcome.distance)
        self.log_field(view.link_pos, view.f_h)
        live = runtime.perception.latest
        if live is not None and live is not self._last_field:
            self._last_field = live
            self.log_map(live, runtime.perception.map.grid)

    def log_map(self, live, map_grid) -> None:
        """Occupied window voxels in the map (centres), the window box and the subgoal the field was built for."""
        grid = live.grid
        centres = occupied_in_map(live, map_grid)
        self.rec.log("world/map/occupied", rr.Points3D(centres, radii=grid.voxel / 2, colors=[230, 150, 40]))
        lo, hi = np.asarray(grid.origin), grid.upper
        self.rec.log("world/map/window", rr.Boxes3D(mins=[lo], sizes=[hi - lo], colors=[120, 120, 255]))
        self.rec.log("world/map/subgoal", rr.Points3D([live.subgoal], radii=0.04, colors=[255, 120, 200]))
