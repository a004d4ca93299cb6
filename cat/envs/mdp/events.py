"""Events: per-episode physics randomisation and random pushes (``EnvCfg.domain_rand``, ``EnvCfg.push``).

They draw from the env's own generator, so a seeded env replays the same gains, masses and kicks.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from cat.envs.robot import RobotCfg
    from cat.envs.traversal_env import TraversalEnv


def randomise_physics(env: TraversalEnv, env_ids: torch.Tensor) -> None:
    """Draw (kp, kd, mass) scale factors for ``env_ids`` from ``domain_rand`` and apply them."""
    dr, k, g = env.cfg.domain_rand, len(env_ids), env.generator

    def u(rng, *shape):
        return rng[0] + (rng[1] - rng[0]) * torch.rand(*shape, generator=g)

    scales = torch.cat((u(dr.kp_scale, k, 1), u(dr.kd_scale, k, 1), u(dr.mass_scale, k, 1)), dim=-1)
    apply_physics_scales(env, env_ids, scales)


def scaled_gains(robot: RobotCfg, scales: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(kp, kd) (k, nu) of the robot's gains times the (kp, kd, mass) scale factors ``scales`` (k, 3)."""
    base_kp, base_kd = torch.tensor(robot.kp), torch.tensor(robot.kd)
    return base_kp * scales[:, :1], base_kd * scales[:, 1:2]


def apply_physics_scales(env: TraversalEnv, env_ids: torch.Tensor, scales: torch.Tensor) -> None:
    """Set worlds' PD gains and body masses from per-env (kp, kd, mass) scale factors (k, 3)."""
    scales = scales.to("cpu", torch.float32, copy=True)
    kp, kd = scaled_gains(env.robot, scales)
    env.sim.set_actuator_gains(env_ids, kp, kd)
    env.sim.set_body_mass_scale(env_ids, scales[:, 2:3].expand(len(env_ids), env.sim.model.nbody))
    _observe_scales(env, env_ids, scales, kp, kd)


def _observe_scales(env: TraversalEnv, env_ids, scales: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor) -> None:
    env.kp[env_ids] = kp.to(env.device, torch.float32)
    env.kd[env_ids] = kd.to(env.device, torch.float32)
    env.dr_scales[env_ids] = scales.to(env.device)


def assign_world_models(env: TraversalEnv, env_ids: torch.Tensor) -> None:
    """Per-world scenes: each world of ``env_ids`` steps its env's scene model; with domain randomisation a pool
    member drawn at random, whose (kp, kd, mass) scales become the env's ``kp``, ``kd`` and ``dr_scales``."""
    wm, k = env.world_models, len(env_ids)
    scene_ids = env.scenes.scene_of_env[env_ids.cpu()]
    if env.cfg.domain_rand.enabled:
        members = torch.randint(wm.pool, (k,), generator=env.generator)
    else:
        members = torch.zeros(k, dtype=torch.long)
    env.sim.assign_models(env_ids, wm.ids(scene_ids, members))
    if env.cfg.domain_rand.enabled:
        scales = wm.scales[scene_ids, members]
        _observe_scales(env, env_ids, scales, *scaled_gains(env.robot, scales))


def push_robots(env: TraversalEnv) -> None:
    """Kick the roots whose push timer ran out by a random horizontal velocity; restart their timers."""
    p = env.cfg.push
    if not p.enabled:
        return
    env.push_timer -= env.dt
    ids = (env.push_timer <= 0).nonzero(as_tuple=False).flatten()
    if len(ids) == 0:
        return
    k, g = len(ids), env.generator
    angle = 2 * math.pi * torch.rand(k, generator=g)
    speed = p.speed[0] + (p.speed[1] - p.speed[0]) * torch.rand(k, generator=g)
    qpos, qvel = env.sim.qpos[ids].clone(), env.sim.qvel[ids].clone()
    qvel[:, 0] += (speed * angle.cos()).to(qvel)
    qvel[:, 1] += (speed * angle.sin()).to(qvel)
    env.sim.reset(ids, qpos, qvel)
    env.push_timer[ids] = (p.interval_s[0] + (p.interval_s[1] - p.interval_s[0]) * torch.rand(k, generator=g)).to(
        env.device
    )
