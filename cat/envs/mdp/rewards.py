"""Reward terms (per control step, before weighting): ``fn(env, **constants)`` under ``@reward_term()``
(``cat.envs.mdp.terms``), the constants as keyword parameters. Weights live in ``RewardCfg`` (the name matches),
the constants in ``RewardCfg.params``: config, recorded in every run's config.yaml, resolved once per env
(``cat.envs.mdp.registry.reward_terms``) and passed in; no term reads the reward config itself."""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import torch
import torch.nn.functional as F

from cat.envs.mdp.terms import reward_term
from cat.fields import field_reward

LOG_4PI = math.log(4 * math.pi)

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv


@reward_term()
def field_vmf(env: TraversalEnv, field_vmf_uniform_offset: bool) -> torch.Tensor:
    """R_field = sum_k [log C_3(kappa_k) + kappa_k mu_k . v_k/|v_k|] (paper, eq. R_field), plus K log 4 pi.

    The constant K log 4 pi (minus the log-density of a uniform direction) makes an uninformative motion score
    0 instead of about -2.5 per link; without it the term is a large negative per-step constant that rewards
    ending episodes early. It changes no gradient of the per-step reward (``RewardCfg.field_vmf_uniform_offset``).
    """
    fc = env.field_cfg
    r = field_reward(env.humanoid_pf, env.state.link_vel, kappa_max=fc.kappa_max, kappa_cap=fc.kappa_cap)
    if field_vmf_uniform_offset:
        r = r + env.humanoid_pf.shape[1] * LOG_4PI
    return r


@reward_term()
def track_velocity(env: TraversalEnv, velocity_sigma: float) -> torch.Tensor:
    """Root horizontal velocity tracks the field command (speed along F_H at the root)."""
    err = (env.state.root_lin_vel[:, :2] - env.command_vel).square().sum(dim=-1)
    return torch.exp(-err / velocity_sigma)


def _gate_field(env: TraversalEnv, heading_clearance: float) -> torch.Tensor:
    """Open space by HumanoidPF's SDF: every query link at least ``heading_clearance`` from obstacles."""
    return env.field.sdf.amin(dim=-1) > heading_clearance


def _gate_none(env: TraversalEnv, heading_clearance: float) -> torch.Tensor:
    return torch.ones(env.num_envs, dtype=torch.bool, device=env.device)


HEADING_GATES = {"field": _gate_field, "none": _gate_none}


def heading_gate(name: str):
    """The gate of ``params.heading_gate``, or ``ValueError`` naming it and the valid gates."""
    if name not in HEADING_GATES:
        raise ValueError(f"unknown heading gate {name!r}; valid: {', '.join(HEADING_GATES)}")
    return HEADING_GATES[name]


@reward_term()
def track_heading(
    env: TraversalEnv, standing_speed: float, heading_gate: str, heading_clearance: float
) -> torch.Tensor:
    """Face the commanded direction in open space; 1 (free) near obstacles, where side-stepping may be needed.

    Gated off where ``heading_gate`` says the robot is near obstacles (``field``: a query link within
    ``heading_clearance`` by the SDF; side passes need the body turned across the direction of travel;
    ``none``: never) and while the command is slower than ``standing_speed``.
    """
    cmd = env.command_vel
    speed = cmd.norm(dim=-1)
    heading = torch.stack((torch.cos(env.state.yaw), torch.sin(env.state.yaw)), dim=-1)
    cos = (heading * cmd).sum(dim=-1) / speed.clamp_min(1e-6)
    active = (speed > standing_speed) & HEADING_GATES[heading_gate](env, heading_clearance)
    return torch.where(active, cos, torch.ones_like(cos))


@reward_term()
def goal_proximity(env: TraversalEnv, proximity_scale: float) -> torch.Tensor:
    return torch.exp(-env.goal_distance / proximity_scale)


@reward_term()
def alive(env: TraversalEnv) -> torch.Tensor:
    return torch.ones(env.num_envs, device=env.device)


@reward_term()
def orientation(env: TraversalEnv) -> torch.Tensor:
    return env.state.gravity[:, :2].square().sum(dim=-1)


@reward_term()
def lin_vel_z(env: TraversalEnv) -> torch.Tensor:
    return env.state.root_lin_vel[:, 2].square()


@reward_term()
def ang_vel_xy(env: TraversalEnv) -> torch.Tensor:
    return env.state.gyro[:, :2].square().sum(dim=-1)


@reward_term()
def action_rate(env: TraversalEnv) -> torch.Tensor:
    return (env.actions - env.prev_actions).square().sum(dim=-1)


@reward_term()
def torques(env: TraversalEnv) -> torch.Tensor:
    """PD torque estimate kp (q* - q) - kd qdot on the policy joints."""
    ids = env.policy_ids
    tau = (
        env.kp[:, ids] * (env.targets[:, ids] - env.state.joint_pos[:, ids])
        - env.kd[:, ids] * env.state.joint_vel[:, ids]
    )
    return tau.square().sum(dim=-1)


@reward_term()
def joint_limits(env: TraversalEnv) -> torch.Tensor:
    q = env.state.joint_pos
    return ((env.soft_lower - q).clamp_min(0) + (q - env.soft_upper).clamp_min(0)).sum(dim=-1)


def _stance(env: TraversalEnv, standing_speed: float) -> torch.Tensor:
    """Phase-defined stance of (left, right) feet: left stands in the first half period; both while the command
    is slower than ``standing_speed``."""
    s = torch.sin(2 * torch.pi * env.phase)
    standing = env.command_vel.norm(dim=-1) < standing_speed
    left, right = s >= 0, s < 0
    stance = torch.stack((left, right), dim=-1)
    return stance | standing[:, None]


@reward_term()
def feet_phase_contact(env: TraversalEnv, standing_speed: float) -> torch.Tensor:
    """+1 per foot whose floor contact matches the gait clock."""
    return (env.state.foot_contact == _stance(env, standing_speed)).float().sum(dim=-1)


@reward_term()
def feet_clearance(
    env: TraversalEnv,
    standing_speed: float,
    foot_clearance: float,
    foot_clearance_min_only: bool,
    foot_clearance_lookahead: float,
    foot_clearance_step_max: float,
) -> torch.Tensor:
    """Swing feet should lift to ``foot_clearance`` (weighted by their horizontal speed); with
    ``foot_clearance_min_only`` only a foot below it is penalised (higher is free: hurdles).

    With ``foot_clearance_lookahead`` > 0 the target is measured from the obstacles' top (the elevation
    map's ground layer, the highest of the cell under the foot and the cell that far ahead along the foot's
    motion), so a swing foot must rise over a bar before it reaches it rather than graze its base. Cells taller
    than ``foot_clearance_step_max`` (walls) raise no target.
    """
    swing = ~_stance(env, standing_speed)
    z = env.state.foot_pos[..., 2]
    vel = env.state.foot_vel[..., :2]
    speed = vel.norm(dim=-1)
    target = torch.full_like(z, foot_clearance)
    if foot_clearance_lookahead > 0:
        xy = env.state.foot_pos[..., :2]
        ahead = xy + foot_clearance_lookahead * vel / speed.clamp_min(1e-3)[..., None]
        ground, _ = env.perception.layers_at(torch.cat((xy, ahead), dim=1))
        ground = ground * (ground <= foot_clearance_step_max)  # walls are side-stepped, not hurdled
        under, front = ground.split(z.shape[1], dim=1)
        target = target + torch.maximum(under, front)
    error = z - target
    if foot_clearance_min_only:
        error = error.clamp_max(0.0)
    return (error.square() * speed * swing).sum(dim=-1)


@reward_term()
def feet_slip(env: TraversalEnv) -> torch.Tensor:
    return (env.state.foot_vel[..., :2].square().sum(dim=-1) * env.state.foot_contact).sum(dim=-1)


@reward_term()
def knee_straight(env: TraversalEnv, knee_min: float) -> torch.Tensor:
    """Penalise nearly straight knees (locked knees make stepping brittle)."""
    knees = env.state.joint_pos[:, env.knee_ids]
    return (knee_min - knees).clamp_min(0).sum(dim=-1)


@reward_term()
def sdf_barrier(env: TraversalEnv, barrier_margin: float, barrier_width: float) -> torch.Tensor:
    """Soft barrier on the signed distance at the query links: sum_k softplus((margin - d_k) / width)."""
    return F.softplus((barrier_margin - env.field.sdf) / barrier_width).sum(dim=-1)


@reward_term()
def foot_sole_barrier(env: TraversalEnv, sole_margin: float, barrier_width: float) -> torch.Tensor:
    """``sdf_barrier`` at each foot's heel and toe (``RobotCfg.foot_sole`` along the foot's x axis), with margin
    ``sole_margin``: the sole is ~20 cm long, so a foot landing on a bar or tripping on it touches with a
    heel or toe whose SDF the query point at the sole's centre does not see (hurdles; docs/training.md)."""
    sole = env.robot.foot_sole
    if sole is None:
        raise ValueError("the foot_sole_barrier reward needs foot_sole: [heel, toe] in the robot description")
    st = env.state
    ends = torch.tensor(sole, device=env.device, dtype=st.foot_pos.dtype)
    points = st.foot_pos[:, :, None] + st.foot_axis[:, :, None] * ends[:, None]  # (N, feet, 2, 3)
    sdf = env.field_source.sample(points.flatten(1, 2), env.goals).sdf
    return F.softplus((sole_margin - sdf) / barrier_width).sum(dim=-1)


SHIN_FRACTIONS = (0.25, 0.5, 0.75)
"""Where ``shin_barrier`` samples each shin: fractions of the way from the knee's query point to the foot's."""


@functools.cache
def _knee_links(names: tuple[str, ...]) -> list[int]:
    """Indices of the left and right knee query links (resolved once per robot, not every step)."""
    missing = [n for n in ("left_knee", "right_knee") if n not in names]
    if missing:
        raise ValueError(f"the shin_barrier reward needs query links {', '.join(missing)}; the robot has {list(names)}")
    return [names.index("left_knee"), names.index("right_knee")]


@reward_term()
def shin_barrier(env: TraversalEnv, shin_margin: float, shin_radius: float, barrier_width: float) -> torch.Tensor:
    """``sdf_barrier`` along each shin: points between the knee and foot query points (``SHIN_FRACTIONS``), their
    SDF less ``shin_radius`` (the shank's half-thickness about that axis), with margin ``shin_margin``. The knee's
    query point is the joint, ~35 cm up: a shank that brushes a tall bar on the way over touches 10-25 cm below it,
    where no query point looks (hurdles: the graze that fails the tallest bars; docs/training.md)."""
    st = env.state
    knees = _knee_links(tuple(q.name for q in env.robot.query_links))
    frac = torch.tensor(SHIN_FRACTIONS, device=env.device, dtype=st.link_pos.dtype)[None, None, :, None]
    knee, foot = st.link_pos[:, knees, None], st.foot_pos[:, :, None]  # (N, 2, 1, 3), feet left then right
    points = knee + frac * (foot - knee)  # (N, 2, S, 3)
    sdf = env.field_source.sample(points.flatten(1, 2), env.goals).sdf - shin_radius
    return F.softplus((shin_margin - sdf) / barrier_width).sum(dim=-1)


@reward_term()
def map_clearance(env: TraversalEnv, barrier_margin: float, barrier_width: float) -> torch.Tensor:
    """ASTraversal-style obstacle avoidance on the elevation map (no HumanoidPF), summed over the 13 links:

    softplus((g + margin - z) / width) where the ground layer g under a link is an obstacle (g > 1 cm), plus
    softplus((z + margin - o) / width) where the overhead layer o above it is an obstacle (o < cap). The same
    margin / width as ``sdf_barrier``, measured vertically against the map cell (pooled over its footprint)
    under each link instead of by the SDF.
    """
    cap = env.cfg.perception.height_map.overhead_cap
    z = env.state.link_pos[..., 2]
    ground, overhead = env.perception.layers_at(env.state.link_pos[..., :2])
    below = F.softplus((ground + barrier_margin - z) / barrier_width) * (ground > 0.01)
    above = F.softplus((z + barrier_margin - overhead) / barrier_width) * (overhead < cap)
    return (below + above).sum(dim=-1)


@reward_term()
def collision(env: TraversalEnv) -> torch.Tensor:
    return env.state.collision.float()


@reward_term()
def termination(env: TraversalEnv) -> torch.Tensor:
    """1 on a failure termination (not a timeout)."""
    return env.failed.float()
