"""The paper's trial metrics (§IV-A), defined once; the env's training log and every evaluation use them.

A trial runs from an env's reset for ``SuccessCfg.time_s`` (5 s) of simulated time, one reading per control
step, the reset state included (step 0). Within that window:

* **reached**: the horizontal root-goal distance is ``<= radius`` (0.1 m) at some step; ``reach_time`` is the
  first such step's time (steps since reset x dt);
* **collided**: the robot touched obstacle geometry at any physics substep (the backends' contact sensor is
  the max over substeps);
* **fell**: the fall rule (``cat.envs.mdp.terminations.fallen`` or a non-finite state) fired;
* **success** = reached and not collided and not fell. Contact or a fall after reaching is still a failure;
  reaching after the window is not a success;
* **DE** (distance error) = the closest horizontal root-goal distance of the trial.

Readings after a fall are ignored (the trial is over: a robot sliding on the floor neither reaches nor
collides), and so are readings after the window (training episodes run longer than a trial).
See docs/evaluation.md for the paper's sentence beside each rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch


def horizontal_distance(root_pos: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """(...,) distance between root and goal in the xy plane (z ignored)."""
    return (goal[..., :2] - root_pos[..., :2]).norm(dim=-1)


def window_steps(time_s: float, dt: float) -> int:
    """Control steps in a trial of ``time_s`` seconds (5 s at 50 Hz: 250)."""
    return int(round(time_s / dt))


class TrialMetrics:
    """Running per-env trial statistics: call ``start`` at reset and ``update`` after every control step.

    Args:
        num_envs: number of envs N.
        dt: control period [s].
        radius: success radius on the horizontal root-goal distance [m] (paper: 0.1).
        time_s: trial length [s] (paper: 5).
    """

    def __init__(self, num_envs: int, dt: float, radius: float, time_s: float, device: torch.device | str = "cpu"):
        self.dt, self.radius, self.time_s = dt, radius, time_s
        self.window = window_steps(time_s, dt)
        f32 = dict(device=device, dtype=torch.float32)
        self.min_dist = torch.full((num_envs,), math.inf, **f32)
        self.reach_time = torch.full((num_envs,), math.inf, **f32)
        self.collided = torch.zeros(num_envs, dtype=torch.bool, device=device)
        self.fell = torch.zeros(num_envs, dtype=torch.bool, device=device)

    def start(self, env_ids: torch.Tensor, dist: torch.Tensor, collision: torch.Tensor, fall: torch.Tensor) -> None:
        """New trials for ``env_ids`` whose reset state (step 0) has these readings (each (k,))."""
        self.min_dist[env_ids] = math.inf
        self.reach_time[env_ids] = math.inf
        self.collided[env_ids] = False
        self.fell[env_ids] = False
        steps = torch.zeros(len(env_ids), dtype=torch.long, device=self.min_dist.device)
        self._record(env_ids, steps, dist, collision, fall)

    def update(self, steps: torch.Tensor, dist: torch.Tensor, collision: torch.Tensor, fall: torch.Tensor) -> None:
        """Readings of all envs after a control step; ``steps`` (N,) counts control steps since each reset."""
        self._record(slice(None), steps, dist, collision, fall)

    def _record(self, ids, steps, dist, collision, fall) -> None:
        active = (steps <= self.window) & ~self.fell[ids]
        self.min_dist[ids] = torch.where(active, torch.minimum(self.min_dist[ids], dist), self.min_dist[ids])
        first = active & (dist <= self.radius) & torch.isinf(self.reach_time[ids])
        self.reach_time[ids] = torch.where(first, steps.to(torch.float32) * self.dt, self.reach_time[ids])
        self.collided[ids] = self.collided[ids] | (active & collision)
        self.fell[ids] = self.fell[ids] | (active & fall)

    def success(self, env_ids: torch.Tensor | slice = slice(None)) -> torch.Tensor:
        """Reached within the window, never touched an obstacle, never fell."""
        return torch.isfinite(self.reach_time[env_ids]) & ~self.collided[env_ids] & ~self.fell[env_ids]

    def distance_error(self, env_ids: torch.Tensor | slice = slice(None)) -> torch.Tensor:
        """Closest horizontal root-goal distance of the trial so far."""
        return self.min_dist[env_ids]

    def state_dict(self) -> dict[str, torch.Tensor]:
        """Copies of the running statistics (for an exact training resume)."""
        return {k: getattr(self, k).clone() for k in ("min_dist", "reach_time", "collided", "fell")}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        for k, v in state.items():
            getattr(self, k).copy_(v)

    def results(self, env_ids: torch.Tensor) -> list[TrialResult]:
        """Per-env results (host values) of ``env_ids``."""
        ok = self.success(env_ids).tolist()
        de, reach = self.min_dist[env_ids].tolist(), self.reach_time[env_ids].tolist()
        coll, fell = self.collided[env_ids].tolist(), self.fell[env_ids].tolist()
        return [TrialResult(*row) for row in zip(ok, de, coll, fell, reach, strict=True)]


@dataclass(frozen=True)
class TrialResult:
    """One trial's outcome; ``reach_time`` is ``inf`` when the goal was not reached within the window."""

    success: bool
    de: float
    collided: bool
    fell: bool
    reach_time: float


def score_trajectory(
    root_xy: torch.Tensor,
    goal_xy: torch.Tensor,
    collision: torch.Tensor,
    fall: torch.Tensor,
    dt: float,
    radius: float = 0.1,
    time_s: float = 5.0,
) -> TrialResult:
    """Score one recorded trajectory: readings at steps 0..T (root (T+1, 2), flags (T+1,)), goal (2,)."""
    m = TrialMetrics(1, dt, radius, time_s)
    dist = horizontal_distance(root_xy.float(), goal_xy.float().expand_as(root_xy))
    ids = torch.zeros(1, dtype=torch.long)
    m.start(ids, dist[:1], collision[:1].bool(), fall[:1].bool())
    for k in range(1, len(dist)):
        m.update(torch.tensor([k]), dist[k : k + 1], collision[k : k + 1].bool(), fall[k : k + 1].bool())
    return m.results(ids)[0]


@dataclass(frozen=True)
class Summary:
    """Rates and mean DE over a list of trials."""

    trials: int
    success_rate: float
    distance_error: float
    collision_rate: float
    fall_rate: float

    def line(self) -> str:
        """The one-line result that ``scripts/play.py`` prints."""
        return (
            f"episodes={self.trials} success_rate={self.success_rate:.3f} distance_error={self.distance_error:.3f} "
            f"collision_rate={self.collision_rate:.3f} fall_rate={self.fall_rate:.3f}"
        )


def summarize(results: list[TrialResult]) -> Summary:
    """SR, mean DE, collision and fall rates (fractions) over ``results``."""
    n = len(results)
    if n == 0:
        raise ValueError("no trials to summarise")
    return Summary(
        trials=n,
        success_rate=sum(r.success for r in results) / n,
        distance_error=sum(r.de for r in results) / n,
        collision_rate=sum(r.collided for r in results) / n,
        fall_rate=sum(r.fell for r in results) / n,
    )
