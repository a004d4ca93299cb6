"""The deployed robot in one MuJoCo world: estimate -> FK -> live field -> observation -> policy -> PD targets.

The simulator (MuJoCo C, one ``MjData``) plays the world and the sensors. The controller sees only what a G1 has:
IMU (gyro, orientation), joint encoders, an odometry pose (here the simulator's pelvis pose plus optional noise and
drift: the stand-in for the paper's LiDAR-inertial odometry) and its own LiDAR map (``cat.deploy.perception``): the
live HumanoidPF built on it, or, for a policy reading a voxel grid or an elevation map, those maps from it through
the env's own tables (only the block the policy reads is built). The observation groups the policy reads
(``PolicySpec.obs_groups``: the actor, or a distilled student) are built by the env's own ``ObservationGroups``
(noise off: same terms, same history stacking) on a one-robot context, the field block by the same ``field_obs``,
and actions go through the same ``apply_actions``. Only terms declared ``deployable``
(``cat.envs.mdp.observations``) are computed; they read the env contract (``cat.envs.mdp.context.TermContext``),
which this class provides. The policy is a checkpoint or an exported ONNX file (``cat.deploy.policy``); an ONNX file
whose metadata differs from this runtime's layout is refused.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field

import mujoco
import numpy as np
import torch
from tensordict import TensorDict

from cat.deploy.kinematics import RobotFK, gravity_in_body
from cat.deploy.metadata import PolicyMetadata, free_space_sdf, layout_metadata
from cat.deploy.perception import LiveField, Perception, PerceptionCfg, RobotEstimate, Snapshot
from cat.deploy.policy import PolicySpec, load_policy
from cat.deploy.scenes import GoalChecker
from cat.deploy.voxel_map import map_grid
from cat.envs.config import EnvCfg
from cat.envs.math_utils import yaw_from_quat, yaw_quat
from cat.envs.mdp import terminations as term_terms
from cat.envs.mdp.actions import apply_actions, soft_joint_limits
from cat.envs.mdp.context import SimState
from cat.envs.mdp.field_obs import field_obs
from cat.envs.mdp.registry import OBS_TERMS
from cat.envs.obs_groups import ObservationGroups, resolve_groups
from cat.envs.robot import RobotCfg, home_qpos, load_robot_cfg
from cat.envs.scene import COLLISION_SENSOR, build_env_model
from cat.envs.trial_metrics import TrialMetrics, horizontal_distance
from cat.fields import FieldCfg, humanoid_pf
from cat.terrain import Scene
from cat.terrain.mujoco_export import add_obstacles_to_spec

log = logging.getLogger(__name__)

MAP_TERMS = ("elevation_map", "ground_map", "overhead_map", "voxel_grid")  # read ``perception``'s live map tables
FIELD_TERMS = ("field_block", "field_block_odometry")  # read the live HumanoidPF


@dataclass
class DeployCfg:
    perception: PerceptionCfg = field(default_factory=PerceptionCfg)
    realtime: bool = True
    """Pace the simulation at wall-clock speed with perception in its own thread (a robot); False: lockstep,
    one perception cycle every 1/rate_hz of simulated time, as fast as the CPU allows (reproducible)."""
    map_margin: float = 0.5
    """The map covers the scene's bounds plus this margin [m]."""
    odom_pos_noise: float = 0.0
    """Std of the odometry position error [m] (0: the pelvis pose as a perfect odometry would give it)."""
    odom_yaw_noise: float = 0.0
    """Std of the odometry yaw error [rad]."""
    odom_drift_xy: float = 0.0
    """Odometry drift: a random walk of the position error, std sigma * sqrt(t) per axis [m / sqrt(s)] (the
    model of ``cat.envs.odometry``), from zero at each reset."""
    odom_drift_yaw: float = 0.0
    """Random walk of the heading error [rad / sqrt(s)]."""
    start_yaw: float = 0.0
    trial_time_s: float = 1.0e6
    """Window of a goal's trial [s]: reaching the goal later does not count (headless: its ``time_limit``)."""
    """Heading at the start [rad] (typical scenes run along +x)."""
    seed: int = 0


@dataclass
class Outcome:
    """The current goal's trial, scored by the evaluation protocol's rules (``cat.envs.trial_metrics``) on the true
    root position, plus the number of contact onsets."""

    goal_set_time: float = 0.0
    reached_time: float = float("inf")  # simulated time of the first reading within the success radius
    min_distance: float = float("inf")  # DE: closest horizontal root-goal distance
    distance: float = float("inf")  # horizontal root-goal distance now
    collided: bool = False  # robot-obstacle contact at any physics step of the trial
    collisions: int = 0  # contact onsets, checked after every physics step
    fell: bool = False
    success: bool = False  # reached, never collided, never fell

    @property
    def reached(self) -> bool:
        return bool(np.isfinite(self.reached_time))


@dataclass
class RobotView:
    """What the viewer and recorder draw, copied under the runtime's lock."""

    time: float
    qpos: np.ndarray
    geom_pos: np.ndarray  # (G, 3) robot collision geoms
    geom_quat: np.ndarray  # (G, 4) wxyz
    body_pos: np.ndarray  # (B, 3) every body of the model (for the visual meshes)
    body_quat: np.ndarray  # (B, 4) wxyz
    goal: np.ndarray | None
    link_pos: np.ndarray  # (13, 3) FK
    f_h: np.ndarray  # (13, 3) HumanoidPF at the links (zeros without a field)
    walking: bool
    outcome: Outcome


class Runtime:
    """One G1 in ``scene`` driven by ``spec`` (a checkpoint or hold) with live perception."""

    def __init__(
        self,
        scene: Scene,
        spec: PolicySpec,
        cfg: DeployCfg | None = None,
        robot: RobotCfg | None = None,
        field_cfg: FieldCfg | None = None,
    ):
        self.deploy = cfg or DeployCfg()
        self.scene, self.spec = scene, spec
        self.cfg: EnvCfg = spec.task  # named as in the env: the shared term functions read ``env.cfg``
        self.task = self.cfg
        _check_deployable(self.task, spec.obs_groups)
        self.observation_groups = ObservationGroups(self.task, list(spec.obs_groups), noise=False)
        self.robot = robot or load_robot_cfg()
        self.field_cfg = field_cfg or FieldCfg()
        has_obstacles = len(scene.mesh.faces) > 0
        self.model = build_env_model(self.robot, (lambda s: add_obstacles_to_spec(s, scene)) if has_obstacles else None)
        trained = spec.run.sim.obstacles if spec.run is not None else "physical"
        if trained != "physical":  # the demo's world always holds the obstacle geometry and counts real contacts
            log.info("the policy trained with sim.obstacles=%s: the demo simulates physical obstacles", trained)
        self.data = mujoco.MjData(self.model)
        self.fk = RobotFK(self.robot)
        lo, hi = scene.bounds[0, :2] - self.deploy.map_margin, scene.bounds[1, :2] + self.deploy.map_margin
        reads = {t for g in spec.obs_groups for t in resolve_groups(self.task.observations)[g]}
        self.reads_maps = bool(reads & set(MAP_TERMS))  # a voxel / elevation student: map tables from the live map
        self.reads_field = bool(reads & set(FIELD_TERMS)) or not self.reads_maps
        self.perception = Perception(
            self.model,
            self.fk,
            map_grid(lo, hi, self.deploy.perception.map),
            self.deploy.perception,
            self.field_cfg,
            maps=self.task.perception if self.reads_maps else None,
            needs_field=self.reads_field,
        )
        self.checker = GoalChecker(scene)
        self.rng = np.random.default_rng(self.deploy.seed)
        self._lock = threading.RLock()
        self._coll_adr = self.model.sensor(COLLISION_SENSOR).adr[0] if has_obstacles else None
        self._gyro_adr = int(self.model.sensor("gyro_pelvis").adr[0])
        names = set(self.robot.collision_geoms)
        self.geom_ids = np.array([i for i in range(self.model.ngeom) if self.model.geom(i).name in names])
        self._init_controller()
        self.goal_version = 0
        self.reset()
        obs = self.observation()
        self.layout = self._layout()
        self.policy = load_policy(spec, obs, len(self.robot.policy_joints), self.layout)

    # --- controller state (one robot, shaped like the env's batch of one) ----------------------------------
    def _init_controller(self) -> None:
        r, f32 = self.robot, torch.float32
        self.num_envs, self.device, self.dt = 1, torch.device("cpu"), r.control_dt
        self.default_joint_pos = torch.tensor(r.default_joint_pos, dtype=f32)[None]
        self.policy_ids = torch.tensor(r.policy_joint_ids)
        rng = torch.tensor(self.model.jnt_range[1:], dtype=f32)  # skip the free joint
        self.soft_lower, self.soft_upper = soft_joint_limits(rng, r.soft_limit_factor)
        self.gait_freq = torch.tensor([float(np.mean(self.task.gait_freq))])
        k = len(r.query_links)
        self.w0 = torch.full((k,), self.field_cfg.w_other, dtype=f32)
        self.w0[0] = self.field_cfg.w_root  # the root (pelvis) has priority, as in the env
        # A policy trained on flat ground saw the analytic empty-space field: d = sdf_clip, grad d = 0 wherever
        # nothing is near. Report free space that way to it; scene-trained policies get the field as built.
        self._free_space_sdf = free_space_sdf(self.task)
        self.field_refresh = max(1, round(1.0 / (self.task.field_obs.refresh_hz * self.dt)))
        self.perception_every = max(1, round(1.0 / (self.deploy.perception.rate_hz * self.dt)))

    def reset(self, start_xy=None, yaw: float | None = None) -> None:
        """Stand at the scene's start (or ``start_xy`` facing ``yaw``), no goal, empty bookkeeping (the map is
        kept: ``perception.reset_map`` forgets it)."""
        with self._lock:
            d = self.data
            mujoco.mj_resetData(self.model, d)
            d.qpos[:] = home_qpos(self.robot)
            d.qpos[:2] = self.scene.start[:2] if start_xy is None else np.asarray(start_xy, dtype=np.float64)[:2]
            yaw = self.deploy.start_yaw if yaw is None else float(yaw)
            d.qpos[3:7] = yaw_quat(torch.tensor([yaw], dtype=torch.float64))[0].numpy()
            self._drift = np.zeros(3)  # odometry starts at the true pose
            d.ctrl[:] = self.robot.default_joint_pos
            mujoco.mj_forward(self.model, d)
            f32 = torch.float32
            self.targets = self.default_joint_pos.clone()
            self.actions = torch.zeros(1, len(self.robot.policy_joints), dtype=f32)
            self.phase = torch.zeros(1, dtype=f32)
            self.goals = torch.zeros(1, 3, dtype=f32)
            self.goal: np.ndarray | None = None  # goal_version keeps counting: a field of an old goal never matches
            self.field_obs_buf = torch.zeros(1, len(self.robot.query_links), 7, dtype=f32)
            self.field_obs_odom_buf = None  # field_block_odometry reads field_block: the links are placed by odometry
            self.f_h = torch.zeros(1, len(self.robot.query_links), 3, dtype=f32)
            self.used_field: LiveField | None = None
            self.step_count = 0
            self.sim_time = 0.0
            self.outcome = Outcome()
            self.trial: TrialMetrics | None = None
            self._trial_steps = 0
            self._step_contact = False
            self._prev_link_pos: torch.Tensor | None = None
            self._links_step = -1
            self._released = False
            self.observation_groups.reset()  # stacked groups restart, filled with their next value (as at an env reset)
            self._in_contact = False
            self._update_state(self.estimate())
            if hasattr(self, "policy"):
                self.policy.reset()

    def _layout(self) -> PolicyMetadata:
        """This runtime's observation / action / field layout, with term sizes as it computes them."""
        sizes = {t: int(fn(self).shape[-1]) for t, fn in self.observation_groups.fns.items()}
        limits = torch.stack((self.soft_lower, self.soft_upper), dim=-1).numpy()
        return layout_metadata(
            self.robot, self.field_cfg, self.task, list(self.observation_groups.groups), limits, sizes
        )

    # --- what the robot knows -------------------------------------------------------------------------------
    def estimate(self) -> RobotEstimate:
        """IMU, encoders and odometry now (odometry = pelvis pose + configured noise)."""
        d, c = self.data, self.deploy
        pos = d.qpos[:3].copy()
        pos[:2] += self._drift[:2]
        quat = d.qpos[3:7].copy()
        if c.odom_pos_noise > 0:
            pos += self.rng.normal(0.0, c.odom_pos_noise, 3)
        dyaw = self._drift[2] + (self.rng.normal(0.0, c.odom_yaw_noise) if c.odom_yaw_noise > 0 else 0.0)
        if dyaw != 0.0:
            dq = yaw_quat(torch.tensor([dyaw], dtype=torch.float64))[0].numpy()
            quat = np.empty(4)
            mujoco.mju_mulQuat(quat, dq, d.qpos[3:7])
        return RobotEstimate(
            root_pos=pos,
            root_quat=quat,
            joint_pos=d.qpos[7:].copy(),
            joint_vel=d.qvel[6:].copy(),
            gyro=d.sensordata[self._gyro_adr : self._gyro_adr + 3].copy(),
            time=self.sim_time,
        )

    def _update_state(self, est: RobotEstimate) -> None:
        """The env's ``SimState`` from the estimate; terms a robot cannot observe are NaN (never read).

        The 13 links (FK) are only needed where the field block refreshes: they are computed on the step before
        a refresh and on the refresh step, and their velocity is the difference of the two (one control step)."""
        f32 = torch.float32
        root_pos = torch.tensor(est.root_pos, dtype=f32)[None]
        quat64 = torch.tensor(est.root_quat)[None]
        r = self.field_refresh
        if self.step_count % r in (0, r - 1) or self._prev_link_pos is None:
            link_pos = self.fk.link_positions(est.root_pos[None], est.root_quat[None], est.joint_pos[None]).to(f32)
            prev = self._prev_link_pos
            fresh = prev is not None and self._links_step == self.step_count - 1
            link_vel = (link_pos - prev) / self.dt if fresh else torch.zeros_like(link_pos)
            self._prev_link_pos, self._links_step = link_pos, self.step_count
        else:
            link_pos, link_vel = self.state.link_pos, self.state.link_vel
        nan3 = torch.full((1, 3), float("nan"))
        feet = [self.robot.query_site_names.index(f"query_{s}_foot") for s in ("left", "right")]
        self.state = SimState(
            root_pos=root_pos,
            root_quat=quat64.to(f32),
            root_lin_vel=nan3,
            yaw=yaw_from_quat(quat64).to(f32),
            gyro=torch.tensor(est.gyro, dtype=f32)[None],
            gravity=gravity_in_body(quat64).to(f32),
            joint_pos=torch.tensor(est.joint_pos, dtype=f32)[None],
            joint_vel=torch.tensor(est.joint_vel, dtype=f32)[None],
            link_pos=link_pos,
            link_vel=link_vel,
            foot_pos=link_pos[:, feet],
            foot_vel=link_vel[:, feet],
            foot_axis=torch.full((1, 2, 3), float("nan")),  # read by a reward term only
            foot_contact=torch.zeros(1, 2, dtype=torch.bool),
            collision=torch.zeros(1, dtype=torch.bool),
            hard_collision=torch.zeros(1, dtype=torch.bool),
        )

    def _refresh_field_obs(self) -> None:
        """F_H, grad d, d at the FK links from the newest live field (the env's 10 Hz field block)."""
        live = self.perception.latest
        if live is None or live.goal_version != self.goal_version:
            return
        st = self.state
        s = live.bank.query(torch.zeros(1, dtype=torch.long), st.link_pos)
        sdf, grad = s.sdf, s.grad_sdf
        if self._free_space_sdf is not None:  # the flat task's field convention (``field_source.GoalField``)
            free = sdf >= self._free_space_sdf
            sdf = torch.where(free, torch.full_like(sdf, self._free_space_sdf), sdf)
            grad = torch.where(free[..., None], torch.zeros_like(grad), grad)
        f_h = humanoid_pf(s.force, grad, sdf, st.link_vel, self.w0, self.field_cfg.lam)
        self.f_h = f_h
        self.used_field = live
        if self.task.field_obs.enabled:
            self.field_obs_buf = field_obs(st.yaw, f_h, grad, sdf, self.task.field_obs)

    def observation(self, commit: bool = False) -> TensorDict:
        """The groups the policy reads exactly as the env builds them (without training noise).

        A group with ``history`` H > 1 is its last H vectors, oldest first, the older ones those the policy read
        at its previous steps (all the current one after a reset or at release). ``commit``: this observation is
        the one the policy reads at this control step (the history moves on); otherwise nothing changes."""
        return self.observation_groups.compute(self, commit=commit)

    # --- goals ----------------------------------------------------------------------------------------------
    def set_goal(self, xy, check: bool = True) -> np.ndarray:
        """Check and set a new goal (raises ``GoalError``); the robot walks once a field for it exists.
        ``check=False``: ``xy`` is a full (x, y, z) goal taken as it is (an evaluation trial's, fixed by the
        protocol)."""
        with self._lock:
            goal = self.checker.check(xy, self.data.qpos[:2]) if check else np.asarray(xy, dtype=np.float64)[:3]
            self.goal = goal
            self.goals[0] = torch.tensor(goal, dtype=torch.float32)
            self.goal_version += 1
            self.outcome = Outcome(goal_set_time=self.sim_time)
            self.trial = TrialMetrics(1, self.dt, self.task.success.radius, self.deploy.trial_time_s)
            self._trial_steps = 0
            self.trial.start(torch.zeros(1, dtype=torch.long), *self._readings(contact=False))
            self._sync_outcome()
            log.info("goal set to (%.2f, %.2f)", goal[0], goal[1])
            return goal

    @property
    def on_gantry(self) -> bool:
        """Until the policy first acts (a goal and its field) the robot hangs still in its standing pose: physics
        paused, sensors and mapping on. The default pose alone does not balance a G1 (it tips over in ~1.5 s),
        and the demo should start standing whatever the policy."""
        return not self._released

    @property
    def walking(self) -> bool:
        """The policy acts once its block is there: the field for the current goal has reached the observation,
        or (a policy reading no field) a live map has."""
        ready = self.used_field is not None if self.reads_field else self.perception.latest_map is not None
        return self.goal is not None and ready and not self.outcome.fell

    # --- one control step -------------------------------------------------------------------------------------
    def step(self) -> None:
        with self._lock:
            self.perception.publish(self.sim_time)  # results whose latency has passed
            if self.step_count % self.field_refresh == 0:
                self._refresh_field_obs()
            if self.walking:
                if not self._released:  # the policy's first step: fresh recurrent state and history, as at a reset
                    self.policy.reset()
                    self.observation_groups.reset()
                    self._released = True
                with torch.inference_mode():
                    act = self.policy(self.observation(commit=True))
                self.actions = act.to(torch.float32).clamp(-self.task.action_clip, self.task.action_clip)
            else:
                self.actions = torch.zeros_like(self.actions)
            scale = self.robot.action_scale
            apply_actions(self.targets, self.actions, self.policy_ids, scale, self.soft_lower, self.soft_upper)
            self.data.ctrl[:] = self.targets[0].numpy()
            self._step_contact = False
            if not self.on_gantry:
                for _ in range(self.robot.decimation):
                    mujoco.mj_step(self.model, self.data)
                    self._count_contact()
            self.step_count += 1
            self.sim_time += self.dt
            if self.deploy.odom_drift_xy > 0 or self.deploy.odom_drift_yaw > 0:
                sigma = np.array([self.deploy.odom_drift_xy] * 2 + [self.deploy.odom_drift_yaw])
                self._drift += self.rng.normal(0.0, 1.0, 3) * sigma * np.sqrt(self.dt)
            self.phase = torch.remainder(self.phase + self.gait_freq * self.dt, 1.0)
            self._update_state(self.estimate())
            self._score()

    def _count_contact(self) -> None:
        if self._coll_adr is None:
            return
        touching = bool(self.data.sensordata[self._coll_adr] > 0)
        if touching and not self._in_contact:
            self.outcome.collisions += 1
        self._in_contact = touching
        self._step_contact |= touching

    def _readings(self, contact: bool) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(distance, collision, fall) of this step for the trial metrics, on the true root position."""
        root = torch.tensor(self.data.qpos[:2], dtype=torch.float32)
        dist = horizontal_distance(root, torch.tensor(self.goal[:2], dtype=torch.float32)).reshape(1)
        fall = term_terms.fallen(self) | ~torch.isfinite(self.state.root_pos).all(dim=-1)
        return dist, torch.tensor([contact]), fall

    def _score(self) -> None:
        if self.trial is None:
            if term_terms.fallen(self)[0]:
                self.outcome.fell = True
            return
        self._trial_steps += 1
        self.trial.update(torch.tensor([self._trial_steps]), *self._readings(self._step_contact))
        self._sync_outcome()

    def _sync_outcome(self) -> None:
        o, t = self.outcome, self.trial
        o.distance = float(horizontal_distance(torch.tensor(self.data.qpos[:2]), torch.tensor(self.goal[:2])))
        o.min_distance = float(t.min_dist[0])
        o.reached_time = o.goal_set_time + float(t.reach_time[0])
        o.collided, o.fell, o.success = bool(t.collided[0]), bool(t.fell[0]), bool(t.success()[0])

    # --- perception hook, views ---------------------------------------------------------------------------
    def snapshot(self) -> Snapshot:
        with self._lock:
            goal = None if self.goal is None else self.goal.copy()
            return Snapshot(self.data.qpos.copy(), self.estimate(), goal, self.goal_version)

    def view(self) -> RobotView:
        with self._lock:
            d = self.data
            quats = np.zeros((len(self.geom_ids), 4))
            for k, g in enumerate(self.geom_ids):
                mujoco.mju_mat2Quat(quats[k], d.geom_xmat[g])
            goal = None if self.goal is None else self.goal.copy()
            return RobotView(
                self.sim_time,
                d.qpos.copy(),
                d.geom_xpos[self.geom_ids].copy(),
                quats,
                d.xpos.copy(),
                d.xquat.copy(),
                goal,
                self.state.link_pos[0].numpy().copy(),
                self.f_h[0].numpy().copy(),
                self.walking,
                Outcome(**vars(self.outcome)),
            )

    # --- loops ----------------------------------------------------------------------------------------------
    def start_perception(self) -> None:
        """Real time: one perception cycle now, then the thread. The first cycle compiles Warp's kernels on a cold
        cache (seconds), which must not run on the robot's clock before its first map and field."""
        if self.deploy.realtime:
            self.perception.cycle(self.snapshot())
            self.perception.start(self.snapshot)

    def stop(self) -> None:
        self.perception.stop()

    def run(self, stop: threading.Event, done=lambda rt: False, on_step=None) -> None:
        """Step until ``stop`` is set or ``done(self)``; real time (perception threaded) or lockstep.
        ``on_step(self)`` runs after every control step (recording)."""
        self.start_perception()
        period, next_t = self.dt, time.monotonic()
        while not stop.is_set() and not done(self):
            if not self.deploy.realtime and self.step_count % self.perception_every == 0:
                self.perception.cycle(self.snapshot())
            self.step()
            if on_step is not None:
                on_step(self)
            if self.perception.error is not None:
                raise RuntimeError(f"perception failed: {self.perception.error}") from self.perception.error
            if self.deploy.realtime:
                next_t += period
                lag = time.monotonic() - next_t
                if lag < 0:
                    stop.wait(-lag)
                elif lag > 0.25:  # fell behind (a loaded CPU): drop the backlog instead of racing to catch up
                    next_t = time.monotonic()


def _check_deployable(task: EnvCfg, obs_groups: list[str]) -> None:
    """``ValueError`` for a group the task lacks, a term a robot cannot compute (not declared ``deployable``) or a
    history below 1."""
    groups = resolve_groups(task.observations)
    for g in obs_groups:
        if g not in groups:
            raise ValueError(f"the policy reads observation group {g!r}, its task has {', '.join(groups)}")
        if int(task.observations[g].history) < 1:
            raise ValueError(f"observation group {g!r} has history={task.observations[g].history}; must be >= 1")
        bad = [t for t in groups[g] if t not in OBS_TERMS or not OBS_TERMS[t].deployable]
        if bad:
            raise ValueError(f"the policy observes {bad}, which this deployed robot does not compute")
    if not obs_groups:
        raise ValueError("the policy reads no observation group")
