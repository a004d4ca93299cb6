"""Reward terms (per control step, before weighting), each declared with the constants it reads
(``@reward_term(params=...)``, ``cat.envs.mdp.terms``). Weights live in ``RewardCfg`` (the name matches), the
constants in ``RewardCfg.params``: config, recorded in every run's config.yaml."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import torch
import torch.nn.functional as F

from cat.envs.mdp.terms import reward_term
from cat.fields import field_reward

LOG_4PI = math.log(4 * math.pi)

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv


@reward_term(params=("field_vmf_uniform_offset",))
def field_vmf(env: TraversalEnv) -> torch.Tensor:
    """R_field = sum_k [log C_3(kappa_k) + kappa_k mu_k . v_k/|v_k|] (paper, eq. R_field), plus K log 4 pi.

    The constant K log 4 pi (minus the log-density of a uniform direction) makes an uninformative motion score
    0 instead of about -2.5 per link; without it the term is a large negative per-step constant that rewards
    ending episodes early. It changes no gradient of the per-step reward (``RewardCfg.field_vmf_uniform_offset``).
    """
    fc = env.field_cfg
    r = field_reward(env.humanoid_pf, env.state.link_vel, kappa_max=fc.kappa_max, kappa_cap=fc.kappa_cap)
    if env.cfg.rewards.field_vmf_uniform_offset:
        r = r + env.humanoid_pf.shape[1] * LOG_4PI
    return r


@reward_term(params=("velocity_sigma",))
def track_velocity(env: TraversalEnv) -> torch.Tensor:
    """Root horizontal velocity tracks the field command (speed along F_H at the root)."""
    err = (env.state.root_lin_vel[:, :2] - env.command_vel).square().sum(dim=-1)
    return torch.exp(-err / env.cfg.rewards.params.velocity_sigma)


def _gate_field(env: TraversalEnv) -> torch.Tensor:
    """Open space by HumanoidPF's SDF: every query link at least ``heading_clearance`` from obstacles."""
    return env.field.sdf.amin(dim=-1) > env.cfg.rewards.params.heading_clearance


def _gate_none(env: TraversalEnv) -> torch.Tensor:
    return torch.ones(env.num_envs, dtype=torch.bool, device=env.device)


HEADING_GATES = {"field": _gate_field, "none": _gate_none}


def heading_gate(name: str):
    """The gate of ``params.heading_gate``, or ``ValueError`` naming it and the valid gates."""
    if name not in HEADING_GATES:
        raise ValueError(f"unknown heading gate {name!r}; valid: {', '.join(HEADING_GATES)}")
    return HEADING_GATES[name]


@reward_term(params=("standing_speed", "heading_gate", "heading_clearance"))
def track_heading(env: TraversalEnv) -> torch.Tensor:
    """Face the commanded direction in open space; 1 (free) near obstacles, where side-stepping may be needed.

    Gated off where ``params.heading_gate`` says the robot is near obstacles (``field``: a query link within
    ``heading_clearance`` by the SDF; side passes need the body turned across the direction of travel;
    ``none``: never) and while the command is slower than ``standing_speed``.
    """
    p = env.cfg.rewards.params
    cmd = env.command_vel
    speed = cmd.norm(dim=-1)
    heading = torch.stack((torch.cos(env.state.yaw), torch.sin(env.state.yaw)), dim=-1)
    cos = (heading * cmd).sum(dim=-1) / speed.clamp_min(1e-6)
    active = (speed > p.standing_speed) & HEADING_GATES[p.heading_gate](env)
    return torch.where(active, cos, torch.ones_like(cos))


@reward_term(params=("proximity_scale",))
def goal_proximity(env: TraversalEnv) -> torch.Tensor:
    return torch.exp(-env.goal_distance / env.cfg.rewards.params.proximity_scale)


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


def _stance(env: TraversalEnv) -> torch.Tensor:
    """Phase-defined stance of (left, right) feet: left stands in the first half period."""
    s = torch.sin(2 * torch.pi * env.phase)
    standing = env.command_vel.norm(dim=-1) < env.cfg.rewards.params.standing_speed
    left, right = s >= 0, s < 0
    stance = torch.stack((left, right), dim=-1)
    return stance | standing[:, None]


@reward_term(params=("standing_speed",))
def feet_phase_contact(env: TraversalEnv) -> torch.Tensor:
    """+1 per foot whose floor contact matches the gait clock."""
    return (env.state.foot_contact == _stance(env)).float().sum(dim=-1)


@reward_term(
    params=(
        "standing_speed",
        "foot_clearance",
        "foot_clearance_min_only",
        "foot_clearance_lookahead",
        "foot_clearance_step_max",
    )
)
def feet_clearance(env: TraversalEnv) -> torch.Tensor:
    """Swing feet should lift to ``params.foot_clearance`` (weighted by their horizontal speed); with
    ``params.foot_clearance_min_only`` only a foot below it is penalised (higher is free: hurdles).

    With ``params.foot_clearance_lookahead`` > 0 the target is measured from the obstacles' top (the elevation
    map's ground layer, the highest of the cell under the foot and the cell that far ahead along the foot's
    motion), so a swing foot must rise over a bar before it reaches it rather than graze its base. Cells taller
    than ``params.foot_clearance_step_max`` (walls) raise no target.
    """
    p = env.cfg.rewards.params
    swing = ~_stance(env)
    z = env.state.foot_pos[..., 2]
    vel = env.state.foot_vel[..., :2]
    speed = vel.norm(dim=-1)
    target = torch.full_like(z, p.foot_clearance)
    if p.foot_clearance_lookahead > 0:
        xy = env.state.foot_pos[..., :2]
        ahead = xy + p.foot_clearance_lookahead * vel / speed.clamp_min(1e-3)[..., None]
        ground, _ = env.perception.layers_at(torch.cat((xy, ahead), dim=1))
        ground = ground * (ground <= p.foot_clearance_step_max)  # walls are side-stepped, not hurdled
        under, front = ground.split(z.shape[1], dim=1)
        target = target + torch.maximum(under, front)
    error = z - target
    if p.foot_clearance_min_only:
        error = error.clamp_max(0.0)
    return (error.square() * speed * swing).sum(dim=-1)


@reward_term()
def feet_slip(env: TraversalEnv) -> torch.Tensor:
    return (env.state.foot_vel[..., :2].square().sum(dim=-1) * env.state.foot_contact).sum(dim=-1)


@reward_term(params=("knee_min",))
def knee_straight(env: TraversalEnv) -> torch.Tensor:
    """Penalise nearly straight knees (locked knees make stepping brittle)."""
    knees = env.state.joint_pos[:, env.knee_ids]
    return (env.cfg.rewards.params.knee_min - knees).clamp_min(0).sum(dim=-1)


@reward_term(params=("barrier_margin", "barrier_width"))
def sdf_barrier(env: TraversalEnv) -> torch.Tensor:
    """Soft barrier on the signed distance at the query links: sum_k softplus((margin - d_k) / width)."""
    p = env.cfg.rewards.params
    return F.softplus((p.barrier_margin - env.field.sdf) / p.barrier_width).sum(dim=-1)


@reward_term(params=("sole_margin", "barrier_width"))
def foot_sole_barrier(env: TraversalEnv) -> torch.Tensor:
    """``sdf_barrier`` at each foot's heel and toe (``RobotCfg.foot_sole`` along the foot's x axis), with margin
    ``params.sole_margin``: the sole is ~20 cm long, so a foot landing on a bar or tripping on it touches with a
    heel or toe whose SDF the query point at the sole's centre does not see (hurdles; docs/training.md)."""
    sole = env.robot.foot_sole
    if sole is None:
        raise ValueError("the foot_sole_barrier reward needs foot_sole: [heel, toe] in the robot description")
    p = env.cfg.rewards.params
    st = env.state
    ends = torch.tensor(sole, device=env.device, dtype=st.foot_pos.dtype)
    points = st.foot_pos[:, :, None] + st.foot_axis[:, :, None] * ends[:, None]  # (N, feet, 2, 3)
    sdf = env.field_source.sample(points.flatten(1, 2), env.goals).sdf
    return F.softplus((p.sole_margin - sdf) / p.barrier_width).sum(dim=-1)


@reward_term(params=("barrier_margin", "barrier_width"))
def map_clearance(env: TraversalEnv) -> torch.Tensor:
    """ASTraversal-style obstacle avoidance on the elevation map (no HumanoidPF), summed over the 13 links:

    softplus((g + margin - z) / width) where the ground layer g under a link is an obstacle (g > 1 cm), plus
    softplus((z + margin - o) / width) where the overhead layer o above it is an obstacle (o < cap). The same
    margin / width as ``sdf_barrier``, measured vertically against the map cell (pooled over its footprint)
    under each link instead of by the SDF.
    """
    p = env.cfg.rewards.params
    cap = env.cfg.perception.height_map.overhead_cap
    z = env.state.link_pos[..., 2]
    ground, overhead = env.perception.layers_at(env.state.link_pos[..., :2])
    below = F.softplus((ground + p.barrier_margin - z) / p.barrier_width) * (ground > 0.01)
    above = F.softplus((z + p.barrier_margin - overhead) / p.barrier_width) * (overhead < cap)
    return (below + above).sum(dim=-1)


@reward_term()
def collision(env: TraversalEnv) -> torch.Tensor:
    return env.state.collision.float()


@reward_term()
def termination(env: TraversalEnv) -> torch.Tensor:
    """1 on a failure termination (not a timeout)."""
    return env.failed.float()
