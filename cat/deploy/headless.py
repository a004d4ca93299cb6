"""Headless run: one goal, no browser; ends at success, a fall or the time limit and reports one line."""

from __future__ import annotations

import threading
from dataclasses import dataclass

from cat.deploy.runtime import Runtime


@dataclass
class HeadlessResult:
    success: bool  # reached within the success radius, no obstacle contact, no fall
    time_s: float  # from setting the goal to reaching it (or to the end of the run)
    distance_error: float  # closest horizontal root-goal distance [m]
    collisions: int  # robot-obstacle contact onsets
    field_updates_hz: float  # live field rebuilds per second of robot time
    fell: bool

    def line(self) -> str:
        return (
            f"success={int(self.success)} time_s={self.time_s:.2f} distance_error={self.distance_error:.3f} "
            f"collisions={self.collisions} field_updates_hz={self.field_updates_hz:.1f}"
        )


def run_headless(runtime: Runtime, goal_xy, time_limit: float, recorder=None) -> HeadlessResult:
    """Send the robot to ``goal_xy`` (``GoalError`` if it cannot go there) and run until done; scored by the
    evaluation protocol (``cat.envs.trial_metrics``) with ``time_limit`` as the trial window."""
    runtime.deploy.trial_time_s = time_limit
    runtime.set_goal(goal_xy)
    t0 = runtime.outcome.goal_set_time

    def done(rt: Runtime) -> bool:
        o = rt.outcome
        return o.reached or o.fell or rt.sim_time - t0 >= time_limit

    try:
        runtime.run(threading.Event(), done, on_step=None if recorder is None else recorder.log)
    finally:
        runtime.stop()
        if recorder is not None:
            recorder.close()
    o = runtime.outcome
    elapsed = (o.reached_time if o.reached else runtime.sim_time) - t0
    return HeadlessResult(
        success=o.success,
        time_s=elapsed,
        distance_error=o.min_distance,
        collisions=o.collisions,
        field_updates_hz=runtime.perception.update_rate_hz(),
        fell=o.fell,
    )
