"""Live perception: LiDAR scan -> log-odds map -> 128×128×35 window -> HumanoidPF, one cycle at a time, in a
background thread at ``rate_hz`` (paper §III-C: map and field at 10 Hz).

Each cycle takes a snapshot from the robot: the true simulator state (used only to cast the beams: the
simulator plays the world and the sensor) and the robot's estimate of itself (odometry pose + joint encoders).
Returns are placed in the world with the *estimated* sensor pose (forward kinematics of the estimate), as on a
robot. The newest field is published as a one-field ``FieldBank`` (swapped atomically, never written in place),
with the goal it was built for.

Policies that read a voxel grid or an elevation map instead (Table III's students) get them from the same cycle:
the window's occupancy (no geofence) becomes a ``cat.envs.perception.WindowPerception``, whose tables are built by
the code the env's ground-truth terms use, and ``elevation`` / ``voxels`` answer the terms' queries from the
newest one. A result becomes visible ``latency_s`` of robot time after the snapshot it was built from.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from cat.deploy.kinematics import RobotFK
from cat.deploy.lidar import Lidar, LidarCfg
from cat.deploy.voxel_map import MapCfg, VoxelMap, WindowCfg
from cat.envs.config import PerceptionCfg as MapTermsCfg
from cat.envs.perception import ScenePerception, WindowPerception
from cat.fields import FieldBank, FieldCfg, Grid, build_field

log = logging.getLogger(__name__)


@dataclass
class PerceptionCfg:
    lidar: LidarCfg = field(default_factory=LidarCfg)
    map: MapCfg = field(default_factory=MapCfg)
    window: WindowCfg = field(default_factory=WindowCfg)
    rate_hz: float = 10.0
    """Scan / map / field rate (the paper's 10 Hz); the thread runs as fast as it can when it cannot keep up."""
    geofence: bool = True
    """Window voxels outside the map are blocked, so the field never routes the robot out of the mapped area."""
    goal_margin: float = 0.08
    """A goal outside the window is replaced by the closest point this far inside it [m] (a local subgoal)."""
    latency_s: float = 0.0
    """A cycle's field and maps reach the policy this long (robot time) after its snapshot [s]; 0: at once (in real
    time the cycle's own compute time is the latency)."""


@dataclass
class RobotEstimate:
    """What the robot knows about itself (deployable sources only), float64 numpy."""

    root_pos: np.ndarray  # (3,) odometry
    root_quat: np.ndarray  # (4,) wxyz, IMU / odometry
    joint_pos: np.ndarray  # (nj,) encoders, yaml order
    joint_vel: np.ndarray  # (nj,)
    gyro: np.ndarray  # (3,) IMU, pelvis frame
    time: float  # simulated time [s]


@dataclass
class Snapshot:
    """Input of one perception cycle."""

    qpos_true: np.ndarray
    estimate: RobotEstimate
    goal: np.ndarray | None
    goal_version: int


@dataclass
class LiveField:
    """A field built from the map: bank (1 field), its window grid, the goal it serves and the subgoal used."""

    bank: FieldBank
    grid: Grid
    goal: np.ndarray
    subgoal: np.ndarray
    goal_version: int
    stamp: float  # simulated time of the snapshot it was built from
    occupancy: np.ndarray  # (nx, ny, nz) bool window occupancy it was built from


@dataclass
class CycleStats:
    map_ms: float  # scan + map update + window extraction
    field_ms: float  # field build (0 when there is no goal)
    total_ms: float
    wall: float  # time.monotonic() at the end of the cycle


def occupied_in_map(live: LiveField, map_grid: Grid) -> np.ndarray:
    """Centres (m, 3) of the window's occupied voxels that lie in the map (the geofence left out), for display."""
    centres = live.grid.index_to_world(np.argwhere(live.occupancy))
    return centres[map_grid.contains(centres)] if len(centres) else centres


def clamp_into(grid: Grid, point: np.ndarray, margin: float) -> np.ndarray:
    """The point of the grid box shrunk by ``margin`` closest to ``point``."""
    lo = np.asarray(grid.origin) + margin
    hi = grid.upper - margin
    return np.clip(point, lo, hi)


def nearest_free(occ: np.ndarray, grid: Grid, point: np.ndarray, radius: float = 0.6) -> np.ndarray | None:
    """Centre of the free voxel nearest to ``point`` within ``radius`` (None if there is none)."""
    r = int(np.ceil(radius / grid.voxel))
    c = np.clip(grid.world_to_index(point), 0, np.array(grid.shape) - 1)
    lo, hi = np.maximum(c - r, 0), np.minimum(c + r + 1, grid.shape)
    free = ~occ[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
    idx = np.argwhere(free)
    if len(idx) == 0:
        return None
    centres = grid.index_to_world(idx + lo)
    return centres[np.argmin(np.linalg.norm(centres - point, axis=1))]


class Perception:
    """The robot's mapping and field pipeline; ``cycle`` runs one pass, ``start`` runs it in a thread."""

    def __init__(
        self,
        model: mujoco.MjModel,
        fk: RobotFK,
        map_grid: Grid,
        cfg: PerceptionCfg | None = None,
        field_cfg: FieldCfg | None = None,
        seed: int = 0,
        maps: MapTermsCfg | None = None,
        needs_field: bool = True,
    ):
        """``maps``: also publish the window's elevation map / voxel grid tables (a policy reads them);
        ``needs_field``: build HumanoidPF for the goal (off for a policy that reads no field)."""
        self.cfg = cfg or PerceptionCfg()
        self.field_cfg = field_cfg or FieldCfg()
        self.model = model
        self.fk = fk
        self.lidar = Lidar(model, self.cfg.lidar, seed=seed)
        self.map = VoxelMap(map_grid, self.cfg.map)
        self._data = mujoco.MjData(model)  # this thread's own copy: never touches the simulation's data
        self.maps_cfg, self.needs_field = maps, needs_field
        self._free = ScenePerception(maps or MapTermsCfg(), None, "cpu")  # before the first map: free space
        self.latest: LiveField | None = None
        self.latest_map: WindowPerception | None = None
        self._pending: deque[tuple[float, LiveField | None, WindowPerception | None]] = deque()
        self.stats: deque[CycleStats] = deque(maxlen=600)
        self.update_times: list[float] = []  # simulated time of the snapshot behind each field update
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.error: BaseException | None = None

    # --- one cycle ---------------------------------------------------------------------------------------
    def sensor_pose_estimate(self, est: RobotEstimate) -> tuple[np.ndarray, np.ndarray]:
        """Sensor position and rotation from the estimated root pose and encoders (FK of the mount body)."""
        p = self.fk.poses(est.root_pos[None], est.root_quat[None], est.joint_pos[None], [self.lidar.cfg.body])
        return self.lidar.sensor_pose(p.pos[0, 0].numpy(), p.rot[0, 0].numpy())

    def scan_into_map(self, snap: Snapshot) -> None:
        """Cast one scan from the true pose, place it with the estimated pose, insert it into the map."""
        d = self._data
        d.qpos[:] = snap.qpos_true
        mujoco.mj_kinematics(self.model, d)
        scan = self.lidar.scan(d)
        pos, rot = self.sensor_pose_estimate(snap.estimate)
        points = pos + scan.points_sensor() @ rot.T
        self.map.integrate(pos, points)

    def build(self, occ: np.ndarray, grid: Grid, goal: np.ndarray, version: int, stamp: float) -> LiveField | None:
        """HumanoidPF on the window for ``goal`` (or the closest free point inside the window)."""
        sub = clamp_into(grid, np.asarray(goal, dtype=np.float64), self.cfg.goal_margin)
        for attempt in range(2):
            try:
                f = build_field(occ, grid, sub, self.field_cfg)
                return LiveField(FieldBank.from_fields([f]), grid, np.asarray(goal), sub, version, stamp, occ)
            except ValueError as err:  # subgoal in an occupied voxel: move it to free space once
                free = nearest_free(occ, grid, sub) if attempt == 0 else None
                if free is None:
                    log.warning("no field for goal %s: %s", np.round(goal, 2).tolist(), err)
                    return None
                sub = free
        return None

    def cycle(self, snap: Snapshot, scan: bool = True) -> CycleStats:
        """Scan -> map -> window -> field (when a goal is set) and map tables; published after ``latency_s``.
        ``scan=False``: from the map as it is (a map filled otherwise, e.g. a fully observed scene in a test)."""
        t0 = time.perf_counter()
        if scan:
            self.scan_into_map(snap)
        centre, shape = snap.estimate.root_pos[:2], self.cfg.window.shape
        maps = None
        if self.maps_cfg is not None:  # the terms read free space outside the map, as outside a scene's grid
            occ, grid = self.map.window(centre, shape, False)
            maps = WindowPerception(self.maps_cfg, occ, grid)
        building = snap.goal is not None and self.needs_field
        if building:
            occ, grid = self.map.window(centre, shape, self.cfg.geofence)
        t1 = time.perf_counter()
        live = self.build(occ, grid, snap.goal, snap.goal_version, snap.estimate.time) if building else None
        t2 = time.perf_counter()
        self._pending.append((snap.estimate.time + self.cfg.latency_s, live, maps))
        if self.cfg.latency_s <= 0:
            self.publish(snap.estimate.time)
        field_ms = (t2 - t1) * 1e3 if building else 0.0
        st = CycleStats((t1 - t0) * 1e3, field_ms, (t2 - t0) * 1e3, time.monotonic())
        self.stats.append(st)
        return st

    def publish(self, now: float) -> None:
        """Make the results whose latency has passed at robot time ``now`` the latest ones."""
        while self._pending and self._pending[0][0] <= now + 1e-6:  # robot time is a sum of control steps
            _, live, maps = self._pending.popleft()
            if live is not None:
                self.latest = live
                self.update_times.append(live.stamp)
            if maps is not None:
                self.latest_map = maps

    def reset_map(self) -> None:
        """Forget everything mapped and built (a new trial in the same scene)."""
        self.map = VoxelMap(self.map.grid, self.cfg.map)
        self.latest, self.latest_map = None, None
        self._pending.clear()
        self.update_times.clear()

    # --- the map terms' queries (``cat.envs.mdp.observations``: ``env.perception.elevation`` / ``voxels``) ----
    def elevation(self, root_pos, yaw):
        """(ground, overhead) on the robot-centric map grid from the newest live map (free space before one)."""
        return (self.latest_map or self._free).elevation(root_pos, yaw)

    def voxels(self, root_pos, yaw):
        """Robot-centric occupancy from the newest live map (empty before one)."""
        return (self.latest_map or self._free).voxels(root_pos, yaw)

    # --- background thread -------------------------------------------------------------------------------
    def start(self, source: Callable[[], Snapshot]) -> None:
        """Run cycles on snapshots from ``source`` in a daemon thread at up to ``cfg.rate_hz``."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._loop, args=(source,), name="perception", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            self._thread = None

    def _loop(self, source: Callable[[], Snapshot]) -> None:
        period = 1.0 / self.cfg.rate_hz
        next_t = time.monotonic()
        try:
            while not self._stop.is_set():
                self.cycle(source())
                next_t = max(next_t + period, time.monotonic() - period)  # no burst after a slow cycle
                self._stop.wait(max(0.0, next_t - time.monotonic()))
        except BaseException as err:  # surfaced by the runtime; a dead thread must not go unnoticed
            log.exception("perception thread failed")
            self.error = err

    @property
    def field_updates(self) -> int:
        return len(self.update_times)

    def update_rate_hz(self) -> float:
        """Field updates per second of the robot's (simulated) time, first to last (0 before two updates)."""
        t = self.update_times
        return (len(t) - 1) / (t[-1] - t[0]) if len(t) >= 2 and t[-1] > t[0] else 0.0
