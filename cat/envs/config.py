"""Env configuration: plain dataclasses built by task factories (``cat.envs.tasks``), overridable by hydra."""

from __future__ import annotations

from dataclasses import dataclass, field

from cat.envs.curriculum import CurriculumCfg


@dataclass
class CommandCfg:
    """Goal sampling and the velocity command derived from the field at the root."""

    goal_radius: tuple[float, float] = (1.5, 2.5)  # flat task: goal distance from the start [m]
    goal_height: float = 0.75  # z of the goal point (about pelvis height) [m]
    start_xy_range: float = 1.0  # start offset U(-r, r) per axis (flat task; scenes use their start)
    start_yaw_range: float = 1.5708  # start yaw U(-r, r) relative to the goal direction [rad]
    speed: float = 0.9  # commanded root speed along the field [m/s]: 2 m in ~2.5 s, well inside the 5 s trial
    slow_radius: float = 0.4  # inside this goal distance the speed decays as (d/slow_radius)^slow_power [m]
    slow_power: float = 1.0  # 1 = linear: arrives (0.4 m -> 0.1 m in ~0.6 s); 3 (the release) never gets within 0.1 m


@dataclass
class FieldObsCfg:
    """How HumanoidPF enters the observation (paper eq. OBS_field)."""

    enabled: bool = True  # False = the "w/o OBS_field" ablation (field block zeroed)
    refresh_hz: float = 10.0  # field block refresh rate, mimics 10 Hz odometry / mapping
    sdf_clip: float = 1.0  # SDF values are clipped to [-sdf_clip, sdf_clip] in the observation [m]


@dataclass
class ObsCfg:
    """Observation terms (functions of ``cat.envs.mdp.observations``) per group, in order."""

    actor: list[str] = field(
        default_factory=lambda: [
            "gyro",
            "projected_gravity",
            "joint_pos",
            "joint_vel",
            "last_action",
            "leg_targets",
            "goal_command",
            "gait_phase",
            "field_block",
        ]
    )
    # the critic sees the actor terms without noise, plus these
    privileged: list[str] = field(
        default_factory=lambda: ["base_lin_vel", "base_height", "link_positions", "foot_contacts", "dr_scales"]
    )


@dataclass
class NoiseCfg:
    """Uniform observation noise U(-s, s) per actor term, keyed by term name (zero or absent: no noise)."""

    enabled: bool = True
    gyro: float = 0.2
    projected_gravity: float = 0.05
    joint_pos: float = 0.01
    joint_vel: float = 1.5
    field_block: float = 0.05


@dataclass
class DomainRandCfg:
    """Per-episode physics randomisation."""

    enabled: bool = False
    kp_scale: tuple[float, float] = (0.75, 1.25)
    kd_scale: tuple[float, float] = (0.75, 1.25)
    mass_scale: tuple[float, float] = (0.9, 1.1)


@dataclass
class PushCfg:
    enabled: bool = False
    interval_s: tuple[float, float] = (5.0, 10.0)
    speed: tuple[float, float] = (0.1, 1.0)  # horizontal root velocity kick [m/s]


@dataclass
class RewardParamsCfg:
    """Shape parameters of the reward terms (widths, heights, margins); the weights are in ``RewardCfg``."""

    velocity_sigma: float = 0.25  # track_velocity: exp(-|v_xy - v_cmd|^2 / sigma) [m^2/s^2]
    heading_clearance: float = 0.3  # track_heading only where every query link is this far from obstacles [m]
    standing_speed: float = 0.05  # commands slower than this mean "stand": no heading term, both feet in stance [m/s]
    proximity_scale: float = 0.3  # goal_proximity: exp(-d / scale) [m]
    foot_clearance: float = 0.07  # feet_clearance: swing-foot target height [m]
    knee_min: float = 0.2  # knee_straight: penalise knee angles below this [rad]
    barrier_margin: float = 0.05  # sdf_barrier: softplus((margin - d) / width) at each query link [m]
    barrier_width: float = 0.02  # [m]


@dataclass
class RewardCfg:
    """Reward weights; a zero weight removes the term. Terms live in ``cat.envs.mdp.rewards``."""

    field_vmf: float = 0.05  # R_field, the paper's vMF log-likelihood (eq. R_field)
    field_vmf_uniform_offset: bool = True  # add K log 4 pi so random motion scores ~0 (see rewards.field_vmf)
    track_velocity: float = 1.5
    track_heading: float = 0.5
    goal_proximity: float = 1.0
    alive: float = 0.5
    orientation: float = -2.0
    lin_vel_z: float = -0.5
    ang_vel_xy: float = -0.05
    action_rate: float = -0.01
    torques: float = -1.0e-5
    joint_limits: float = -1.0
    feet_phase_contact: float = 0.3
    feet_clearance: float = -5.0
    feet_slip: float = -0.1
    knee_straight: float = -0.1
    sdf_barrier: float = -2.0  # obstacle proximity at the 13 links (anticipatory; the release used -20 at 11 sites)
    collision: float = -5.0  # per control step with robot-obstacle contact at any substep
    termination: float = -20.0
    params: RewardParamsCfg = field(default_factory=RewardParamsCfg)


@dataclass
class TerminationCfg:
    terms: list[str] = field(default_factory=lambda: ["fallen", "collided", "non_finite", "left_field_grid"])
    min_base_height: float = 0.35  # [m]
    max_tilt: float = 1.0  # [rad] angle between the pelvis z axis and the vertical
    on_collision: bool = False  # end the episode on any robot-obstacle contact
    field_grid_margin: float = 0.15  # [m] a query link this far outside its scene's field grid ends the episode


@dataclass
class SuccessCfg:
    """The paper's metric: within ``radius`` of the goal within ``time_s`` of simulated time, no collision."""

    radius: float = 0.1  # horizontal root-goal distance [m]
    time_s: float = 5.0


@dataclass
class EnvCfg:
    """A traversal task: scene source + MDP terms."""

    task: str = "flat"
    num_envs: int = 64
    episode_length_s: float = 20.0
    scene_dir: str | None = None  # folder of scene folders (scripts/gen_scenes.py); None: see scene_kind
    scene_kind: str | None = None  # keep only scenes of this kind; with no scene_dir, build its typical variants
    scene_variants: int = 10  # typical variants built when scene_dir is None (difficulty spread over [0, 1])
    scene_seed: int = 0  # seed of the typical variants (seeds scene_seed..+variants-1); not the RL seed
    action_clip: float = 1.0
    gait_freq: tuple[float, float] = (1.3, 1.5)  # gait clock frequency [Hz]
    command: CommandCfg = field(default_factory=CommandCfg)
    observations: ObsCfg = field(default_factory=ObsCfg)
    field_obs: FieldObsCfg = field(default_factory=FieldObsCfg)
    noise: NoiseCfg = field(default_factory=NoiseCfg)
    domain_rand: DomainRandCfg = field(default_factory=DomainRandCfg)
    push: PushCfg = field(default_factory=PushCfg)
    rewards: RewardCfg = field(default_factory=RewardCfg)
    terminations: TerminationCfg = field(default_factory=TerminationCfg)
    success: SuccessCfg = field(default_factory=SuccessCfg)
    curriculum: CurriculumCfg = field(default_factory=CurriculumCfg)  # scene tasks only
