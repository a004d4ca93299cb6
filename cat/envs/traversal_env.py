"""G1 goal-reaching / traversal env implementing rsl_rl's VecEnv (auto-reset inside ``step``).

Observation groups are named in ``EnvCfg.observations`` (by default ``actor``: deployable IMU, joints, actions,
goal, gait clock, HumanoidPF block; ``critic``: the actor terms without noise + privileged state) and built by
``cat.envs.obs_groups``. Terms are the plain functions of ``cat.envs.mdp``, selected by name in
``EnvCfg.observations`` / ``.rewards`` (weights) / ``.terminations``.
"""

from __future__ import annotations

import math
from dataclasses import fields

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from cat.envs import field_source as fsrc
from cat.envs import snapshot
from cat.envs.body_clearance import TERM as CLEARANCE_TERM
from cat.envs.body_clearance import BodyClearance
from cat.envs.config import EnvCfg
from cat.envs.curriculum import DifficultyCurriculum
from cat.envs.episode_log import episode_log
from cat.envs.field_contact import (
    FieldContactCfg,
    add_body_pose_sensors,
    check_obstacles,
    field_contact_for,
    field_model,
    substep_pose_sensors,
)
from cat.envs.field_source import FieldSample
from cat.envs.math_utils import quat_rotate_inverse, yaw_from_quat, yaw_quat
from cat.envs.mdp import events
from cat.envs.mdp import rewards as rew_terms
from cat.envs.mdp import terminations as term_terms
from cat.envs.mdp.actions import apply_actions, soft_joint_limits
from cat.envs.mdp.commands import command_source, velocity_command
from cat.envs.mdp.context import SimState
from cat.envs.mdp.field_obs import field_obs
from cat.envs.mdp.registry import reward_fn, reward_terms
from cat.envs.obs_groups import ObservationGroups, lookup_term
from cat.envs.odometry import OdometryDrift
from cat.envs.perception import ScenePerception
from cat.envs.robot import RobotCfg, home_qpos, load_robot_cfg
from cat.envs.scene import (
    COLLISION_SENSOR,
    PART_SENSOR_PREFIX,
    build_env_model,
    foot_axis_sensor,
    foot_contact_sensor,
    make_training_ghosts,
    part_obstacle_sensor,
    query_pos_sensor,
    query_vel_sensor,
)
from cat.envs.sim import check_backend, make_backend
from cat.envs.trial_metrics import TrialMetrics, horizontal_distance
from cat.fields import FieldCfg, humanoid_pf


class TraversalEnv(VecEnv):
    """N G1 robots walking to goals through (optionally) obstacle scenes, guided by HumanoidPF."""

    def __init__(
        self,
        cfg: EnvCfg,
        sim: str = "mujoco",
        device: str = "cpu",
        robot: RobotCfg | None = None,
        field_cfg: FieldCfg | None = None,
        scenes=None,
        seed: int = 0,
        obstacles: str = "physical",
        field_contact: FieldContactCfg | None = None,
    ):
        """``obstacles`` (``sim.obstacles``): ``physical`` obstacle geometry in the worlds, or ``field``: the floor
        only, contact judged from the scenes' SDF (``cat.envs.field_contact``, configured by ``field_contact``)."""
        self.cfg = cfg
        self.obstacles = check_obstacles(obstacles)
        self.robot = robot or load_robot_cfg()
        self.field_cfg = field_cfg or FieldCfg()
        self.num_envs = cfg.num_envs
        self.num_actions = len(self.robot.policy_joints)
        self.dt = self.robot.control_dt
        self.max_episode_length = int(math.ceil(cfg.episode_length_s / self.dt))
        self.generator = torch.Generator(device="cpu").manual_seed(seed)
        self.scenes = scenes
        self.observation_groups = ObservationGroups(cfg)  # checks group and term names before anything is built
        self._command_direction = command_source(cfg.command.source)
        rew_terms.heading_gate(cfg.rewards.params.heading_gate)

        self.world_models = None  # per-world scene models (scenes.per_world), cat.envs.scene_models
        poses = self.observation_groups.uses(CLEARANCE_TERM)  # body_clearance reads the body pose sensors
        if self.obstacles == "field":  # one floor-only model for every world and scene
            models = [field_model(self.robot)]
        elif scenes is not None and scenes.per_world:
            from cat.envs.scene_models import WorldModels

            check_backend(sim)  # before the scene models are built
            self.world_models = WorldModels.build(self.robot, scenes.scenes, cfg.domain_rand, seed, pose_sensors=poses)
            models = self.world_models.models
        else:
            models = [build_env_model(self.robot, _with_pose_sensors(scenes, self.robot, poses))]
        # pool members (per scene) whose ghost parts stay physical
        pool = self.world_models.pool if self.world_models else 0
        self._physical_members = 0 if self.obstacles == "field" else make_training_ghosts(models, cfg, pool)
        model = models[0]
        judged = self.obstacles if scenes is not None else "physical"  # field contact needs scenes
        self.sim = make_backend(
            sim,
            model,
            self.num_envs,
            self.robot.decimation,
            device=device,
            world_models=self.world_models,
            substep_sensors=substep_pose_sensors(model, judged, field_contact),
        )
        self.device = self.sim.device
        self.field = None
        self.curriculum = None
        if cfg.curriculum.group_weights and not (scenes is not None and cfg.curriculum.enabled):
            raise ValueError("task.curriculum.group_weights needs a scene task with the curriculum enabled")
        if scenes is not None and cfg.curriculum.enabled:
            kinds = [scenes.group_names[int(g)] for g in scenes.group_of_scene]
            self.curriculum = DifficultyCurriculum(scenes.difficulties, self.num_envs, cfg.curriculum, kinds)
        if scenes is not None:
            scenes.set_episodes(cfg.episodes)
        self.field_source = (
            scenes.field_source(self.device)
            if scenes is not None
            else fsrc.GoalField(eta=self.field_cfg.eta, free_sdf=cfg.field_obs.sdf_clip)
        )
        self.perception = ScenePerception(cfg.perception, scenes, self.device)
        self.field_contact = field_contact_for(self, model, field_contact)  # None: physical contact sensors
        self.body_clearance = BodyClearance(self, model) if poses else None
        self._init_buffers(model)
        self.reset_idx(torch.arange(self.num_envs, device=self.device))
        self._compute_obs()

    # --- setup -------------------------------------------------------------------------------------------
    def _init_buffers(self, model) -> None:
        n, dev, r = self.num_envs, self.device, self.robot
        f32 = dict(device=dev, dtype=torch.float32)
        self.default_joint_pos = torch.tensor(r.default_joint_pos, **f32).repeat(n, 1)
        self.policy_ids = torch.tensor(r.policy_joint_ids, device=dev)
        self.knee_ids = torch.tensor([r.joint_names.index(j) for j in r.joint_names if "knee" in j], device=dev)
        rng = torch.tensor(model.jnt_range[1:], **f32)  # skip the free joint
        self.soft_lower, self.soft_upper = soft_joint_limits(rng, r.soft_limit_factor)
        self.kp = torch.tensor(r.kp, **f32).repeat(n, 1)
        self.kd = torch.tensor(r.kd, **f32).repeat(n, 1)
        self.dr_scales = torch.ones(n, 3, **f32)
        self.targets = self.default_joint_pos.clone()
        self.actions = torch.zeros(n, self.num_actions, **f32)
        self.prev_actions = torch.zeros_like(self.actions)
        # this step's flag of each termination term, kept until the next step (resets do not clear it)
        self.termination_flags: dict[str, torch.Tensor] = {}
        self.goals = torch.zeros(n, 3, **f32)
        self.phase = torch.zeros(n, **f32)
        self.gait_freq = torch.ones(n, **f32)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long, device=dev)  # the runner may randomise it
        self.step_count = torch.zeros(n, dtype=torch.long, device=dev)  # control steps since this env's reset
        self.common_step = 0
        self.push_timer = torch.zeros(n, **f32)
        self.failed = torch.zeros(n, dtype=torch.bool, device=dev)
        self.auto_reset = True  # False: done envs are not reset inside step (evaluation drives resets)
        self.trial = TrialMetrics(n, self.dt, self.cfg.success.radius, self.cfg.success.time_s, dev)
        k = len(r.query_links)
        self.w0 = torch.full((k,), self.field_cfg.w_other, **f32)
        self.w0[0] = self.field_cfg.w_root  # the root (pelvis) has priority (paper eq. w0); query_links[0]
        self.field_obs_buf = torch.zeros(n, k, 7, **f32)
        self.field_refresh = max(1, round(1.0 / (self.cfg.field_obs.refresh_hz * self.dt)))
        # field_block_odometry: the block at the links as a drifting odometry places them (off: reads field_block)
        self.odometry, self.field_obs_odom_buf = None, None
        noise = self.cfg.noise
        if noise.enabled and self.cfg.field_obs.enabled and self.observation_groups.uses("field_block_odometry"):
            self.odometry = OdometryDrift(n, noise.odometry_xy, noise.odometry_yaw, dev)
            self.field_obs_odom_buf = torch.zeros(n, k, 7, **f32)
        self.reward_terms = reward_terms(self.cfg.rewards)  # name -> (weight, params); registered terms last
        self.reward_names = list(self.reward_terms)
        self.obs_groups = self.observation_groups.groups  # group name -> terms, in order (symmetry, layouts)
        self._mirror_map = None
        for t in self.cfg.terminations.terms:
            lookup_term(term_terms, t, "termination")
        self.episode_sums = {name: torch.zeros(n, **f32) for name in self.reward_names}
        names = r.query_site_names
        self._foot_link = [names.index("query_left_foot"), names.index("query_right_foot")]
        self._sensor_index()
        self._update_state()

    # --- state -------------------------------------------------------------------------------------------
    def _sensor_index(self) -> None:
        """Column indices of the sensors the env reads, so one gather per step extracts them all."""
        s, r = self.sim, self.robot

        def cols(name: str) -> list[int]:
            sl = s.sensors[name]
            return list(range(sl.adr, sl.adr + sl.dim))

        names = [q.name for q in r.query_links]
        self._i_link_pos = torch.tensor([cols(query_pos_sensor(nm)) for nm in names], device=self.device)
        self._i_link_vel = torch.tensor([cols(query_vel_sensor(nm)) for nm in names], device=self.device)
        self._i_gyro = torch.tensor(cols("gyro_pelvis"), device=self.device)
        self._i_feet = torch.tensor([cols(foot_contact_sensor(f))[0] for f in r.feet], device=self.device)
        self._i_foot_axis = torch.tensor([cols(foot_axis_sensor(f)) for f in r.feet], device=self.device)
        self._i_collision = cols(COLLISION_SENSOR)[0] if COLLISION_SENSOR in s.sensors else None
        self._i_hard_collision = None  # with ghost parts: the other bodies' contacts (max over the substeps)
        if self._i_collision is not None and self.cfg.ghost_parts:
            parts = [n.removeprefix(PART_SENSOR_PREFIX) for n in s.sensors if n.startswith(PART_SENSOR_PREFIX)]
            missing = sorted(set(self.cfg.ghost_parts) - set(parts))
            if missing:
                raise ValueError(f"ghost_parts {missing} have no collision geom; robot bodies that do: {parts}")
            hard = [p for p in parts if p not in self.cfg.ghost_parts]
            self._i_hard_collision = torch.tensor([cols(part_obstacle_sensor(p))[0] for p in hard], device=self.device)
        self._down = torch.tensor([0.0, 0.0, -1.0], device=self.device)

    def _read_state(self, ids: torch.Tensor | slice) -> SimState:
        """Robot state of worlds ``ids`` from the backend's qpos / qvel / sensordata."""
        s = self.sim
        qpos, qvel = s.qpos[ids].to(torch.float32), s.qvel[ids].to(torch.float32)
        sens = s.sensordata[ids].to(torch.float32)
        quat = qpos[:, 3:7]
        link_pos, link_vel = sens[:, self._i_link_pos], sens[:, self._i_link_vel]
        if (fc := self.field_contact) is not None:
            sub = s.substep_sensordata[ids] if fc.cfg.substeps else None
            collision, hard = fc.judge(sens, self.field_source.bank, self.field_source.field_idx[ids], sub)
        else:
            collision, hard = self._physical_contact(sens, ids)
        return SimState(
            root_pos=qpos[:, :3],
            root_quat=quat,
            root_lin_vel=qvel[:, :3],
            yaw=yaw_from_quat(quat),
            gyro=sens[:, self._i_gyro],
            gravity=quat_rotate_inverse(quat, self._down.expand(len(quat), 3)),
            joint_pos=qpos[:, 7:],
            joint_vel=qvel[:, 6:],
            link_pos=link_pos,
            link_vel=link_vel,
            foot_pos=link_pos[:, self._foot_link],
            foot_vel=link_vel[:, self._foot_link],
            foot_axis=sens[:, self._i_foot_axis],
            foot_contact=sens[:, self._i_feet] > 0,
            collision=collision,
            hard_collision=hard,
        )

    def _physical_contact(self, sens: torch.Tensor, ids: torch.Tensor | slice) -> tuple[torch.Tensor, torch.Tensor]:
        """(collision, hard_collision) from the model's robot-obstacle contact sensors (``sim.obstacles=physical``)."""
        if self._i_collision is None:
            collision = torch.zeros(len(sens), dtype=torch.bool, device=self.device)
        else:
            collision = sens[:, self._i_collision] > 0
        # ghost contacts (all of them, or some parts') are counted but push nothing
        if self.cfg.ghost_obstacles:
            hard = torch.zeros_like(collision)
        elif self._i_hard_collision is not None:
            hard = (sens[:, self._i_hard_collision] > 0).any(dim=-1)
            if self._physical_members:  # worlds on a physical pool member: every contact pushes
                physical = (self.sim.model_ids[ids] % self.world_models.pool < self._physical_members).to(self.device)
                hard = torch.where(physical, collision, hard)
        else:
            hard = collision
        return collision, hard

    def _update_state(self, env_ids: torch.Tensor | None = None) -> None:
        """Read the state of all worlds, or refresh only ``env_ids`` (after their reset)."""
        if env_ids is None:
            self.state = self._read_state(slice(None))
            return
        new = self._read_state(env_ids)
        for f in fields(SimState):
            getattr(self.state, f.name)[env_ids] = getattr(new, f.name)

    def _update_field(self, env_ids: torch.Tensor | None = None) -> None:
        """Field at the links now (for rewards) and the velocity command (its direction from ``command.source``).

        With ``env_ids`` only those envs are re-queried (after their reset); the others keep this step's values.
        """
        ids = slice(None) if env_ids is None else env_ids
        st, goals = self.state, self.goals[ids]
        link_pos, link_vel, root_xy = st.link_pos[ids], st.link_vel[ids], st.root_pos[ids, :2]
        field = self.field_source.sample(link_pos, goals, env_ids)
        hpf = humanoid_pf(field.force, field.grad_sdf, field.sdf, link_vel, self.w0, self.field_cfg.lam)
        dist = horizontal_distance(root_xy, goals)
        cmd = velocity_command(self._command_direction(hpf, root_xy, goals), dist, self.cfg.command)
        if env_ids is None:
            self.field, self.humanoid_pf, self.goal_distance, self.command_vel = field, hpf, dist, cmd
            return
        for f in fields(FieldSample):
            getattr(self.field, f.name)[env_ids] = getattr(field, f.name)
        self.humanoid_pf[env_ids] = hpf
        self.goal_distance[env_ids] = dist
        self.command_vel[env_ids] = cmd

    def _refresh_field_obs(self, env_ids: torch.Tensor | None = None) -> None:
        if not self.cfg.field_obs.enabled:
            return
        ids = slice(None) if env_ids is None else env_ids
        self.field_obs_buf[ids] = field_obs(
            self.state.yaw[ids],
            self.humanoid_pf[ids],
            self.field.grad_sdf[ids],
            self.field.sdf[ids],
            self.cfg.field_obs,
        )
        if self.odometry is not None:
            self.field_obs_odom_buf[ids] = self._odometry_field_obs(env_ids)

    def _odometry_field_obs(self, env_ids: torch.Tensor | None) -> torch.Tensor:
        """``field_obs`` of the field queried where the odometry places the links (``cat.envs.odometry``)."""
        ids = slice(None) if env_ids is None else env_ids
        st, odom = self.state, self.odometry
        points, yaw = odom.displace(st.root_pos[ids], st.yaw[ids], st.link_pos[ids], env_ids)
        field = self.field_source.sample(points, self.goals[ids], env_ids)
        vel = odom.rotate(st.link_vel[ids], env_ids)  # link velocities in the odometry's frame
        hpf = humanoid_pf(field.force, field.grad_sdf, field.sdf, vel, self.w0, self.field_cfg.lam)
        return field_obs(yaw, hpf, field.grad_sdf, field.sdf, self.cfg.field_obs)

    # --- VecEnv ------------------------------------------------------------------------------------------
    def get_observations(self) -> TensorDict:
        return self.obs_buf

    def step(self, actions: torch.Tensor):
        cfg = self.cfg
        self.prev_actions = self.actions
        self.actions = actions.to(self.device, torch.float32).clamp(-cfg.action_clip, cfg.action_clip)
        scale = self.robot.action_scale
        apply_actions(self.targets, self.actions, self.policy_ids, scale, self.soft_lower, self.soft_upper)
        self.sim.step(self.targets)

        self.episode_length_buf += 1
        self.step_count += 1
        self.phase = torch.remainder(self.phase + self.gait_freq * self.dt, 1.0)
        self._update_state()
        self._update_field()
        self.common_step += 1
        if self.common_step % self.field_refresh == 0:
            if self.odometry is not None:  # drift since the last refresh, or since the reset if more recent
                self.odometry.advance(self.step_count.clamp(max=self.field_refresh) * self.dt, self.generator)
            self._refresh_field_obs()

        # terminations
        self.failed = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        self.termination_flags = {name: getattr(term_terms, name)(self) for name in cfg.terminations.terms}
        for flags in self.termination_flags.values():
            self.failed |= flags
        time_outs = self.episode_length_buf >= self.max_episode_length
        dones = self.failed | time_outs

        # rewards
        reward = torch.zeros(self.num_envs, device=self.device)
        for name, (weight, params) in self.reward_terms.items():
            value = reward_fn(name)(self, **params) * weight
            value = torch.nan_to_num(value, nan=0.0, posinf=0.0, neginf=0.0)
            self.episode_sums[name] += value
            reward += value
        self._track_success()

        extras = {"time_outs": time_outs, "log": {}}
        done_ids = dones.nonzero(as_tuple=False).flatten()
        if len(done_ids) > 0 and self.auto_reset:
            extras["log"] = episode_log(self, done_ids)
            if self.curriculum is not None:
                self.curriculum.update(done_ids, self.episode_success(done_ids))
                extras["log"].update(self.curriculum.log())
            extras["episode_end"] = {
                "env_ids": done_ids,
                "success": self.episode_success(done_ids),
                "distance_error": self.trial.distance_error(done_ids).clone(),
                "collided": self.trial.collided[done_ids].clone(),
                "fell": self.trial.fell[done_ids].clone(),
            }
            self.reset_idx(done_ids)
        events.push_robots(self)
        self._compute_obs()
        return self.obs_buf, reward, dones.to(torch.long), extras

    # --- episode bookkeeping -----------------------------------------------------------------------------
    def _track_success(self) -> None:
        """The trial metrics (``cat.envs.trial_metrics``) over the first ``success.time_s`` of each episode."""
        self.trial.update(self.step_count, self.goal_distance, self.state.collision, self._fell())

    def _fell(self) -> torch.Tensor:
        """The metric's fall rule: the ``fallen`` termination's thresholds, or a diverged state."""
        return term_terms.fallen(self) | term_terms.non_finite(self)

    def episode_success(self, env_ids: torch.Tensor) -> torch.Tensor:
        """Paper's success (``TrialMetrics.success``): reached within the trial window, no contact, no fall."""
        return self.trial.success(env_ids)

    @property
    def reached_time(self) -> torch.Tensor:
        """(N,) time of the first arrival within the success radius since reset (inf: not yet)."""
        return self.trial.reach_time

    @property
    def scene_group_names(self) -> list[str]:
        """Scene groups (kinds) of the env's scene set, in ``scene_group`` index order; ``["flat"]`` without one."""
        return ["flat"] if self.scenes is None else list(self.scenes.group_names)

    @property
    def mirror_map(self):
        """Left/right mirror of every observation group and the actions (``cat.envs.symmetry``), built once."""
        if self._mirror_map is None:
            from cat.envs.symmetry import MirrorMap

            self._mirror_map = MirrorMap.of_env(self)
        return self._mirror_map

    # --- state a resumed training needs ---------------------------------------------------------------------
    def training_state(self) -> dict:
        """Env state that must survive a stop/resume of training (the difficulty curriculum, when on)."""
        return {} if self.curriculum is None else {"curriculum": self.curriculum.state_dict()}

    def load_training_state(self, state: dict) -> None:
        """Restore what ``training_state`` returned."""
        if self.curriculum is not None and "curriculum" in state:
            self.curriculum.load_state_dict(state["curriculum"])

    def get_state(self) -> dict:
        """Everything that makes the next step of every env what it would have been (``cat.envs.snapshot``)."""
        return snapshot.get_state(self)

    def set_state(self, snap: dict) -> None:
        """Restore ``get_state``'s snapshot (same task and number of envs); checked before anything changes."""
        snapshot.set_state(self, snap)

    # --- resets ------------------------------------------------------------------------------------------
    def reset_idx(self, env_ids: torch.Tensor) -> None:
        """Start new episodes for ``env_ids`` from the task's start / goal distribution."""
        k = len(env_ids)
        if k == 0:
            return
        g, dev = self.generator, self.device
        c = self.cfg.command
        uniform = self._uniform

        if self.scenes is not None:
            if self.curriculum is not None:
                self.scenes.assign_scenes(env_ids, self.curriculum.pick_scenes(env_ids, g))
            progress = self.curriculum.progress(env_ids) if self.curriculum is not None else None
            start, goal, heading = self.scenes.sample_episode(env_ids, g, progress)
            start, goal, heading = start.to(dev), goal.to(dev), heading.to(dev)
        else:
            start = torch.zeros(k, 3, device=dev)
            start[:, :2] = uniform(-c.start_xy_range, c.start_xy_range, k, 2)
            heading = uniform(-math.pi, math.pi, k)
            radius = uniform(c.goal_radius[0], c.goal_radius[1], k)
            goal = start + torch.stack((radius * heading.cos(), radius * heading.sin(), torch.zeros_like(radius)), -1)
            goal[:, 2] = c.goal_height
        yaw = heading + uniform(-c.start_yaw_range, c.start_yaw_range, k)
        self._reset_envs(env_ids, start, yaw, goal)

    def reset_to(
        self,
        env_ids: torch.Tensor,
        start_xy: torch.Tensor,
        yaw: torch.Tensor,
        goal: torch.Tensor,
        scene_ids: torch.Tensor | None = None,
        goal_ids: torch.Tensor | None = None,
    ) -> None:
        """Reset ``env_ids`` to given trials and refresh the observations (evaluation; no sampling of poses).

        ``start_xy`` (k, 2), ``yaw`` (k,) and ``goal`` (k, 3) are in world coordinates; with a scene set,
        ``scene_ids`` / ``goal_ids`` (k,) name the scene tile and goal whose field each env reads.
        """
        ids = torch.as_tensor(env_ids, device=self.device, dtype=torch.long).reshape(-1)
        if self.scenes is not None:
            if scene_ids is None or goal_ids is None:
                raise ValueError("reset_to on a scene set needs scene_ids and goal_ids")
            self.scenes.place(ids, scene_ids, goal_ids)
        start = torch.zeros(len(ids), 3, device=self.device)
        start[:, :2] = start_xy.to(self.device, torch.float32)
        self._reset_envs(ids, start, yaw.to(self.device, torch.float32), goal.to(self.device, torch.float32))
        self._compute_obs()

    def _uniform(self, lo: float, hi: float, *shape: int) -> torch.Tensor:
        return (lo + (hi - lo) * torch.rand(*shape, generator=self.generator)).to(self.device)

    def _reset_envs(self, env_ids: torch.Tensor, start: torch.Tensor, yaw: torch.Tensor, goal: torch.Tensor) -> None:
        """Put the robots of ``env_ids`` at ``start`` xy facing ``yaw`` with ``goal``; reset their episode state."""
        k, dev, uniform = len(env_ids), self.device, self._uniform
        qpos = torch.tensor(home_qpos(self.robot), device=dev, dtype=torch.float64).repeat(k, 1)
        qpos[:, :2] = start[:, :2].double()
        qpos[:, 3:7] = yaw_quat(yaw).double()
        qpos[:, 7:] += uniform(-0.05, 0.05, k, self.robot.num_joints).double()
        qvel = torch.zeros(k, self.sim.model.nv, device=dev, dtype=torch.float64)
        if self.world_models is not None:  # the scene's model (a randomised pool member with domain_rand)
            events.assign_world_models(self, env_ids)
        elif self.cfg.domain_rand.enabled:
            events.randomise_physics(self, env_ids)
        self.sim.reset(env_ids, qpos, qvel)

        self.goals[env_ids] = goal.to(torch.float32)
        self.targets[env_ids] = self.default_joint_pos[env_ids]
        self.actions[env_ids] = 0.0
        self.prev_actions[env_ids] = 0.0
        self.phase[env_ids] = uniform(0.0, 1.0, k)
        self.gait_freq[env_ids] = uniform(*self.cfg.gait_freq, k)
        self.episode_length_buf[env_ids] = 0
        self.step_count[env_ids] = 0
        self.push_timer[env_ids] = uniform(*self.cfg.push.interval_s, k)
        for v in self.episode_sums.values():
            v[env_ids] = 0.0
        self.observation_groups.reset(env_ids)
        if self.odometry is not None:
            self.odometry.reset(env_ids)
        if self.scenes is not None:
            self.field_source.assign(env_ids, self.scenes.field_ids(env_ids))
        if self.field is not None:
            self._update_state(env_ids)
            self._update_field(env_ids)
        else:  # construction: first read of every world
            self._update_state()
            self._update_field()
        self.trial.start(env_ids, self.goal_distance[env_ids], self.state.collision[env_ids], self._fell()[env_ids])
        self._refresh_field_obs(env_ids)

    # --- observations ------------------------------------------------------------------------------------
    def _compute_obs(self) -> None:
        self.obs_buf = self.observation_groups.compute(self)


def _with_pose_sensors(scenes, robot: RobotCfg, poses: bool):
    """The spec hook of a single env model: the scenes' obstacles, and the body pose sensors when ``poses``."""
    add = scenes.add_to_spec if scenes is not None else None
    if not poses:
        return add

    def hook(spec) -> None:
        if add is not None:
            add(spec)
        add_body_pose_sensors(spec, robot)

    return hook
