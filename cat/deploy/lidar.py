"""Simulated head LiDAR (Livox Mid-360-like) by MuJoCo ray casting.

The simulator plays the sensor only: rays leave the *true* sensor pose and hit floor and obstacles
(``mj_multiRay`` restricted to geom groups 0-2, so the robot's own collision geoms, group 3-4, are never hit —
the self-filter every legged-robot LiDAR driver applies). What comes out is what the real sensor gives: ranges
along known beam directions in the sensor frame, with range noise and dropouts. Placing the returns in the
world is the perception side's job, with the *estimated* pose (``cat.deploy.perception``).

Pattern: the Mid-360 scans non-repetitively over 360° × [-7°, +52°]; here every scan takes the next
``rays_per_scan`` points of a 2-D low-discrepancy (R2) sequence over that band (uniform in azimuth and in
sin(elevation), i.e. uniform over the band's solid angle), so consecutive scans fill each other's gaps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

# R2 sequence constants: 1/g and 1/g^2 for the plastic number g (g^3 = g + 1)
_G = 1.32471795724474602596
_A1, _A2 = 1.0 / _G, 1.0 / (_G * _G)


@dataclass
class LidarCfg:
    """Mount, pattern and error model. Defaults: a Mid-360 mounted upside down in the G1's head."""

    body: str = "torso_link"
    """Body the sensor is fixed to (the G1's head is part of ``torso_link``)."""
    offset: tuple[float, float, float] = (0.05, 0.0, 0.44)
    """Sensor origin in the body frame [m]: front of the head, ~1.25 m above the floor when standing."""
    inverted: bool = True
    """Mounted upside down (as on the G1): the [-7°, +52°] band then looks down, at the floor and obstacles."""
    pitch_deg: float = 10.0
    """Extra forward tilt of the mount [deg]: the floor ahead is seen from ~0.6 m, head height up to ~3 m away."""
    elevation_deg: tuple[float, float] = (-7.0, 52.0)
    """Vertical field of view in the sensor frame [deg] (Mid-360 spec)."""
    rays_per_scan: int = 12000
    """Beams per scan (the Mid-360 gives 20k points per 0.1 s; 12k keeps ray casting ~3 ms)."""
    min_range: float = 0.1
    """Blind zone [m] (Mid-360 spec)."""
    max_range: float = 6.0
    """Returns beyond this are dropped [m]: the 5.12 m window's corners are < 3.7 m from its centre."""
    range_noise: float = 0.02
    """Range noise std [m] (Mid-360 spec: 2 cm, 1σ)."""
    dropout: float = 0.05
    """Probability that a beam returns nothing (dark or grazing surfaces)."""
    geom_groups: tuple[int, ...] = (0, 1, 2)
    """MuJoCo geom groups the beams can hit: floor (0) and obstacles (1); robot geoms (3, 4) excluded."""


@dataclass
class Scan:
    """One scan: beam directions in the sensor frame (n, 3) and ranges (n,), NaN where nothing returned."""

    directions: np.ndarray
    ranges: np.ndarray

    def points_sensor(self) -> np.ndarray:
        """(m, 3) returns in the sensor frame."""
        ok = np.isfinite(self.ranges)
        return self.directions[ok] * self.ranges[ok, None]


def mount_rotation(cfg: LidarCfg) -> np.ndarray:
    """Rotation body <- sensor: upside down (180° about x) then pitched forward about the body's y axis."""
    flip = np.diag([1.0, -1.0, -1.0]) if cfg.inverted else np.eye(3)
    p = math.radians(cfg.pitch_deg)
    pitch = np.array([[math.cos(p), 0.0, math.sin(p)], [0.0, 1.0, 0.0], [-math.sin(p), 0.0, math.cos(p)]])
    return pitch @ flip


def pattern(cfg: LidarCfg, scan_index: int) -> np.ndarray:
    """Beam directions (n, 3) of scan ``scan_index`` in the sensor frame (continues the R2 sequence)."""
    k = np.arange(cfg.rays_per_scan, dtype=np.float64) + float(scan_index) * cfg.rays_per_scan
    u = np.mod(0.5 + _A1 * k, 1.0)
    v = np.mod(0.5 + _A2 * k, 1.0)
    lo, hi = (math.sin(math.radians(e)) for e in cfg.elevation_deg)
    sin_el = lo + (hi - lo) * v
    cos_el = np.sqrt(1.0 - sin_el * sin_el)
    az = 2.0 * math.pi * u
    return np.stack((cos_el * np.cos(az), cos_el * np.sin(az), sin_el), axis=-1)


class Lidar:
    """Casts scans in a MuJoCo model; keeps its own scan counter and noise generator."""

    def __init__(self, model: mujoco.MjModel, cfg: LidarCfg | None = None, seed: int = 0):
        self.cfg = cfg or LidarCfg()
        self.model = model
        self.body_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, self.cfg.body)
        if self.body_id < 0:
            raise ValueError(f"LiDAR body {self.cfg.body!r} not in the model")
        self.mount_rot = mount_rotation(self.cfg)
        self.offset = np.asarray(self.cfg.offset, dtype=np.float64)
        self.groups = np.zeros(mujoco.mjNGROUP, dtype=np.uint8)
        self.groups[list(self.cfg.geom_groups)] = 1
        self.rng = np.random.default_rng(seed)
        self.scan_index = 0
        n = self.cfg.rays_per_scan
        self._geomid = np.zeros(n, dtype=np.int32)
        self._dist = np.zeros(n, dtype=np.float64)

    def sensor_pose(self, body_pos: np.ndarray, body_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) and rotation world <- sensor (3, 3) from the mount body's world pose."""
        return body_pos + body_rot @ self.offset, body_rot @ self.mount_rot

    def scan(self, data: mujoco.MjData) -> Scan:
        """Cast one scan from the sensor pose in ``data`` (its kinematics must be current)."""
        cfg = self.cfg
        dirs = pattern(cfg, self.scan_index)
        self.scan_index += 1
        pos, rot = self.sensor_pose(data.xpos[self.body_id], data.xmat[self.body_id].reshape(3, 3))
        world_dirs = np.ascontiguousarray(dirs @ rot.T)
        mujoco.mj_multiRay(
            self.model,
            data,
            pos,
            world_dirs.reshape(-1),
            self.groups,
            1,
            -1,
            self._geomid,
            self._dist,
            None,
            len(dirs),
            cfg.max_range,
        )
        ranges = self._dist + self.rng.normal(0.0, cfg.range_noise, len(dirs))
        lost = (self._geomid < 0) | (self.rng.random(len(dirs)) < cfg.dropout)
        lost |= (self._dist < cfg.min_range) | (ranges > cfg.max_range)
        return Scan(directions=dirs, ranges=np.where(lost, np.nan, ranges))
