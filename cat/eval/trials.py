"""Trials: (scene, goal, start pose), enumerated deterministically (paper §IV-A).

Every scene × each of its goals × K start poses. Start pose ``k`` of (scene ``s``, goal ``g``) is drawn from
``numpy.random.default_rng([seed, s, g, k])``: the position uniformly in the scene's start region, the yaw
uniformly within ``±yaw_range`` of the heading to the goal (the training distribution). A pose depends only on
(seed, s, g, k), never on K, batch size or order, so a longer list extends a shorter one.

The list is start-major (all scenes and goals for k = 0, then k = 1, ...), so its first n trials spread over
scenes and goals (``scripts/play.py episodes=n``).

Flat ground has no scene: its "goals" are ``num_goals`` points on a circle of ``radius`` around the origin at
headings 2π g / num_goals, the start is the origin.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cat.terrain.scene import Scene


@dataclass(frozen=True)
class Trial:
    """One trial, coordinates in the scene's own frame."""

    scene: int  # index into the evaluated scene list (0 on flat ground)
    goal: int  # goal index within the scene
    start: int  # start-pose index k
    start_xy: tuple[float, float]
    yaw: float  # initial heading of the robot [rad]
    goal_xyz: tuple[float, float, float]


def _start_pose(seed: int, s: int, g: int, k: int, lo, hi, goal_xy, yaw_range: float) -> tuple[tuple, float]:
    u = np.random.default_rng([seed, s, g, k]).random(3)
    xy = np.asarray(lo) + u[:2] * (np.asarray(hi) - np.asarray(lo))
    heading = math.atan2(goal_xy[1] - xy[1], goal_xy[0] - xy[0])
    return (float(xy[0]), float(xy[1])), float(heading + (2 * u[2] - 1) * yaw_range)


def scene_trials(scenes: Sequence[Scene], starts: int, seed: int, yaw_range: float) -> list[Trial]:
    """Every scene × each goal × ``starts`` start poses (start-major order)."""
    if starts < 1:
        raise ValueError(f"need at least one start pose per goal, got {starts}")
    out = []
    for k in range(starts):
        for s, scene in enumerate(scenes):
            lo, hi = scene.start_region
            for g, goal in enumerate(scene.goals):
                xy, yaw = _start_pose(seed, s, g, k, lo, hi, goal[:2], yaw_range)
                out.append(Trial(s, g, k, xy, yaw, tuple(float(v) for v in goal)))
    return out


def flat_trials(
    starts: int, seed: int, yaw_range: float, num_goals: int = 8, radius: float = 2.0, height: float = 0.75
) -> list[Trial]:
    """Flat ground: goals ``radius`` away at ``num_goals`` evenly spaced headings × ``starts`` start yaws."""
    if starts < 1:
        raise ValueError(f"need at least one start pose per goal, got {starts}")
    out = []
    for k in range(starts):
        for g in range(num_goals):
            a = 2 * math.pi * g / num_goals
            goal = (radius * math.cos(a), radius * math.sin(a), height)
            xy, yaw = _start_pose(seed, 0, g, k, (0.0, 0.0), (0.0, 0.0), goal[:2], yaw_range)
            out.append(Trial(0, g, k, xy, yaw, goal))
    return out


def first_trials(make, n: int, per_round: int) -> list[Trial]:
    """The first ``n`` trials of ``make(starts)`` (start-major), with just enough start poses."""
    return make(max(1, math.ceil(n / max(per_round, 1))))[:n]
