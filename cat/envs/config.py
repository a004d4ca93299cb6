"""Env configuration: plain dataclasses built by task factories (``cat.envs.tasks``), overridable by hydra."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cat.envs.curriculum import CurriculumCfg
from cat.envs.episodes import EpisodeCfg


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
    # direction of the command (cat.envs.mdp.commands.COMMAND_SOURCES): "field" = along F_H at the root (ours);
    # "straight" = the straight line to the goal (the baselines: no reward reads HumanoidPF)
    source: str = "field"


@dataclass
class FieldObsCfg:
    """How HumanoidPF enters the observation (paper eq. OBS_field)."""

    enabled: bool = True  # False: the field block reads zeros (the paper's w/o OBS_field is method=wo_obs_field)
    refresh_hz: float = 10.0  # field block refresh rate, mimics 10 Hz odometry / mapping
    sdf_clip: float = 1.0  # SDF values are clipped to [-sdf_clip, sdf_clip] in the observation [m]


ACTOR_TERMS = (
    "gyro",
    "projected_gravity",
    "joint_pos",
    "joint_vel",
    "last_action",
    "leg_targets",
    "goal_command",
    "gait_phase",
    "field_block",
)
PRIVILEGED_TERMS = ("base_lin_vel", "base_height", "link_positions", "foot_contacts", "dr_scales")


@dataclass
class ObsGroupCfg:
    """One named observation group: terms of ``cat.envs.mdp.observations``, concatenated in order.

    ``extends`` names another group whose (resolved) terms come first, so a critic or teacher follows its actor
    when a method swaps an actor term. ``noise`` adds ``NoiseCfg``'s per-term noise (when ``noise.enabled``).
    ``history`` > 1 stacks the group's whole vector over the last ``history`` control steps, oldest first
    (filled with the current value at reset): a deployable student's short proprioceptive memory.
    """

    terms: list[str] = field(default_factory=list)
    extends: str = ""
    noise: bool = False
    history: int = 1


def default_obs_groups() -> dict[str, ObsGroupCfg]:
    """``actor`` (deployable, noisy) and ``critic`` (the actor terms without noise + privileged state)."""
    return {
        "actor": ObsGroupCfg(terms=list(ACTOR_TERMS), noise=True),
        "critic": ObsGroupCfg(terms=list(PRIVILEGED_TERMS), extends="actor"),
    }


@dataclass
class HeightMapCfg:
    """Robot-centric two-layer elevation map (``elevation_map``, ``ground_map``, ``overhead_map`` terms).

    Cells on a yaw-aligned grid around the root; the ground layer is the top of the obstacles under each cell
    (the floor, 0, where there are none), the overhead layer the underside of the obstacles above it
    (``overhead_cap`` where there are none). Heights are world z (the floor is z = 0). See docs/baselines.md.
    """

    length: float = 1.6  # extent along the heading [m]
    width: float = 1.2  # lateral extent, symmetric about the root (so the map mirrors cell to cell) [m]
    resolution: float = 0.1  # cell spacing [m]
    forward_offset: float = 0.3  # map centre ahead of the root: it looks where the robot walks [m]
    split_height: float = 0.5  # an obstacle whose underside is below this is ground, otherwise overhead [m]
    overhead_cap: float = 2.0  # overhead value where nothing is above (and the clip of the layer) [m]


@dataclass
class VoxelGridCfg:
    """Robot-centric occupancy grid (``voxel_grid`` term; the Table III voxel baseline). See docs/baselines.md."""

    length: float = 1.6  # extent along the heading [m]
    width: float = 1.2  # lateral extent, symmetric about the root [m]
    height: float = 1.6  # vertical extent from the floor [m]
    resolution: float = 0.1  # cell size [m]
    forward_offset: float = 0.3  # grid centre ahead of the root [m]


@dataclass
class PerceptionCfg:
    """Scene-occupancy observations for the baselines (computed per env every step, in the yaw frame)."""

    height_map: HeightMapCfg = field(default_factory=HeightMapCfg)
    voxel_grid: VoxelGridCfg = field(default_factory=VoxelGridCfg)


@dataclass
class NoiseCfg:
    """Observation noise scale per term, keyed by term name (zero or absent: no noise), in groups with
    ``noise: true``; how a term reads it is its declaration's ``TermNoise`` (``cat.envs.mdp.observations``).

    Uniform U(-s, s) added to every value; for the occupancy term ``voxel_grid``, s is the probability that a
    cell reads flipped. ``odometry_xy`` / ``odometry_yaw`` are not value noise: they drive the random-walk pose
    error of the ``field_block_odometry`` term (``cat.envs.odometry``), on whenever ``enabled`` and some group
    lists that term. ``extra``: the scale of terms without a field here (a new or registered term declared with
    noise: ``+task.noise.extra.<term>=<scale>``).
    """

    enabled: bool = True
    gyro: float = 0.2
    projected_gravity: float = 0.05
    joint_pos: float = 0.01
    joint_vel: float = 1.5
    field_block: float = 0.05
    field_block_odometry: float = 0.05  # the same per-value noise on top of the drift
    # Odometry drift (random walk, std sigma sqrt(T) after T s, per axis): 0.02 m/sqrt(s) is 4.5 cm after a 5 s
    # trial (~1 % of the 4.5 m walked at 0.9 m/s), 9 cm after a 20 s episode; 0.01 rad/sqrt(s) is 1.3 deg after 5 s.
    # LiDAR-inertial odometry (FAST-LIO2 class) drifts well under 1 % of distance and the robot's map is built
    # from the same odometry, so its pose error against its own map is smaller still: these are upper bounds.
    odometry_xy: float = 0.02  # [m/sqrt(s)]
    odometry_yaw: float = 0.01  # [rad/sqrt(s)]
    elevation_map: float = 0.03  # [m] per cell, about a depth camera's error at 1-2 m
    ground_map: float = 0.03
    overhead_map: float = 0.03
    voxel_grid: float = 0.02  # flip probability per cell
    extra: dict[str, float] = field(default_factory=dict)


@dataclass
class DomainRandCfg:
    """Per-episode physics randomisation."""

    enabled: bool = False
    kp_scale: tuple[float, float] = (0.75, 1.25)
    kd_scale: tuple[float, float] = (0.75, 1.25)
    mass_scale: tuple[float, float] = (0.9, 1.1)
    # per-world scenes (sim.per_world_scenes): randomised model copies per scene; an env draws one at reset
    pool_size: int = 8


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
    # feet_clearance penalises only swing feet *below* the target (a hurdle needs more than 7 cm; the two-sided
    # release term trains the feet to graze an 8 cm bar). Off (two-sided) for flat ground, on for obstacle tasks.
    foot_clearance_min_only: bool = False
    # > 0: the swing-foot target rides on the obstacles: foot_clearance above the highest ground-layer cell of the
    # elevation map under the foot and this far ahead along its horizontal motion (hurdles); 0: above the floor
    foot_clearance_lookahead: float = 0.0  # [m]
    foot_clearance_step_max: float = 0.4  # taller ground-layer cells are walls, not hurdles: they raise no target [m]
    knee_min: float = 0.2  # knee_straight: penalise knee angles below this [rad]
    barrier_margin: float = 0.05  # sdf_barrier: softplus((margin - d) / width) at each query link [m]
    barrier_width: float = 0.02  # [m]; map_clearance uses the same margin and width on the elevation map
    sole_margin: float = 0.02  # foot_sole_barrier: softplus((margin - d) / barrier_width) at each heel and toe [m]
    shin_margin: float = 0.02  # shin_barrier: softplus((margin - d + shin_radius) / barrier_width) along each shin [m]
    shin_radius: float = 0.045  # the G1 shank's half-thickness about the knee-foot axis (its mesh: 4.8 x 5.7 cm) [m]
    # track_heading's gate (cat.envs.mdp.rewards.HEADING_GATES): "field" = free wherever a query link is within
    # heading_clearance of an obstacle by HumanoidPF's SDF (ours); "none" = always tracked (reads no field)
    heading_gate: str = "field"


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
    foot_sole_barrier: float = 0.0  # the same barrier at each foot's heel and toe (hurdles: feet landing on bars)
    shin_barrier: float = 0.0  # the same barrier along each shin, below the knee's query point (hurdles: shin grazes)
    map_clearance: float = 0.0  # ASTraversal's obstacle avoidance: the same barrier on elevation-map clearance
    collision: float = -5.0  # per control step with robot-obstacle contact at any substep
    termination: float = -20.0
    params: RewardParamsCfg = field(default_factory=RewardParamsCfg)
    # reward terms registered outside the package (cat.envs.mdp.registry.register_reward): <name>: <weight>, or
    # <name>: {weight: <w>, params: {<constant>: <value>}} (constants default to the term's signature); extending.md
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class TerminationCfg:
    terms: list[str] = field(default_factory=lambda: ["fallen", "collided", "non_finite", "left_field_grid"])
    min_base_height: float = 0.35  # [m]
    max_tilt: float = 1.0  # [rad] angle between the pelvis z axis and the vertical
    on_collision: bool = False  # end the episode on a robot-obstacle contact that pushes (ghost ones never do)
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
    # with scene_dir: the paper's training data group (cat.terrain.data_groups: base | syn_partial_easy |
    # syn_full_easy | syn_full_hard), a selection of the folder's indoor and procedural scenes; None: all of them
    data: str | None = None
    # with no scene_dir: typical kinds mixed in one scene set (scene_variants of each); each kind is a scene group,
    # taught by its own specialist in distillation (algo=distill). Overrides scene_kind.
    scene_groups: list[str] = field(default_factory=list)
    # training aid: robot-obstacle contacts are detected (collision sensor, penalty, success rule) but exert no
    # force, as in the authors' release (no physical obstacles). A trip no longer ends in a fall, so the policy
    # learns to avoid contact before it must survive it. Evaluation is always physical (cat.eval.runner).
    ghost_obstacles: bool = False
    # training aid: the same for some robot bodies only (cat.envs.scene.make_parts_ghost), e.g. the feet and
    # shanks for hurdles. Their obstacle contacts are collisions (penalty, success rule) but neither push nor end
    # the episode; the other bodies meet physical obstacles. Stepping over a bar is foot placement: this gives
    # the per-step signal of where the foot went wrong that a contact-ends-the-episode rule does not.
    ghost_parts: list[str] = field(default_factory=list)
    # the way from ghost parts back to physical ones: this fraction of the domain-randomisation pool members of
    # every scene keeps the parts physical (needs sim.per_world_scenes and domain_rand; the pool member is drawn
    # per episode), so that share of episodes meets the bars as evaluation does. Raise it across sittings.
    ghost_parts_physical: float = 0.0
    scene_variants: int = 10  # typical variants built when scene_dir is None (difficulty spread over [0, 1])
    scene_seed: int = 0  # seed of the typical variants (seeds scene_seed..+variants-1); not the RL seed
    # training aid: this many extra typical scenes per kind, easier than the paper's easiest (difficulty in
    # [-1, 0): lower bars, higher ceilings, wider gaps; cat.terrain.typical.warmup_variants), so the difficulty
    # curriculum starts where the walking prior succeeds. Never evaluated (cat.eval builds the paper's variants).
    warmup_variants: int = 0
    # training aid: multi-hurdle's warm-ups place their two bars at a floor gap shrinking with d (0.85 -> 0.25 m)
    # instead of random gaps, so the curriculum's levels are ordered by the pitch that sets their success
    # (cat.terrain.graded.GRADED_GAP; docs/multi_hurdle.md). Needs multi-hurdle among the kinds and warm-ups.
    warmup_bar_pitch: bool = False
    # with warmup_bar_pitch: 3 puts a third bar at the warm-up's gap wherever three fit on the course (the last
    # warm-ups, gaps up to ~0.4 m), a step between the graded pairs and the paper's three-bar variants.
    warmup_bars: int = 2
    # training aid: side-hurdle's warm-ups hold a narrow slit (0.45 m) whose centre moves off the course's axis as d
    # grows (0 -> 0.4 m, either side), so the curriculum grades lining up with an offset slit, which the paper's
    # variants only ask at their narrowest gaps (cat.terrain.graded.GRADED_SLIT_OFFSET; docs/results.md).
    warmup_slit_offset: bool = False
    # training aid: side-hurdle-crouch's and side-hurdle's warm-ups hold a slit near the axis narrowing as d grows
    # (0.90 -> 0.40 m) ahead of the type's easiest paper bar (and ceiling), side-pass's two such slits, so the
    # curriculum grades the side-on turn through a narrow slit (cat.terrain.graded.GRADED_NARROW_GAP; training.md).
    warmup_slit_narrow: bool = False
    # training aid: those warm-up slits narrow (0.55 -> 0.32 m) as they leave the axis (0 -> 0.40 m, either side;
    # side-pass's two to opposite sides), so the curriculum grades the paper's narrow off-axis slits, where the
    # width ladder's cells fail (cat.terrain.graded.GRADED_TIGHT_GAP; training.md). At most one slit grading.
    warmup_slit_tight: bool = False
    # training aid: add the left/right mirror image of every scene (cat.terrain.Scene.mirrored), so a scene set
    # that is not balanced (eight of the paper's ten side-pass variants open to the left first) cannot teach one
    # handedness only. Real experience on both sides, unlike PPO's symmetry augmentation. Never evaluated.
    mirror_scenes: bool = False
    action_clip: float = 1.0
    gait_freq: tuple[float, float] = (1.3, 1.5)  # gait clock frequency [Hz]
    command: CommandCfg = field(default_factory=CommandCfg)
    observations: dict[str, ObsGroupCfg] = field(default_factory=default_obs_groups)
    perception: PerceptionCfg = field(default_factory=PerceptionCfg)
    field_obs: FieldObsCfg = field(default_factory=FieldObsCfg)
    noise: NoiseCfg = field(default_factory=NoiseCfg)
    domain_rand: DomainRandCfg = field(default_factory=DomainRandCfg)
    push: PushCfg = field(default_factory=PushCfg)
    rewards: RewardCfg = field(default_factory=RewardCfg)
    terminations: TerminationCfg = field(default_factory=TerminationCfg)
    success: SuccessCfg = field(default_factory=SuccessCfg)
    curriculum: CurriculumCfg = field(default_factory=CurriculumCfg)  # scene tasks only
    episodes: EpisodeCfg = field(default_factory=EpisodeCfg)  # scene tasks only: start / goal sampling
