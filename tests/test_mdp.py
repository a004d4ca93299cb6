"""MDP fixes that make the paper's metric reachable and the training signal honest (each fails without its fix)."""

from __future__ import annotations

import functools
import math

import mujoco
import numpy as np
import pytest
import torch
import torch.nn.functional as F

from cat.envs.config import CommandCfg, EnvCfg, NoiseCfg
from cat.envs.mdp import rewards as rew
from cat.envs.mdp.commands import command_speed
from cat.envs.scene_set import SceneSet
from cat.envs.traversal_env import TraversalEnv


def _time_to_reach(cfg: CommandCfg, start: float = 2.0, radius: float = 0.1, dt: float = 0.02) -> float:
    """Simulated time for a point that tracks the command perfectly to get within ``radius`` of the goal."""
    d, t = torch.tensor([start]), 0.0
    while d.item() > radius and t < 30.0:
        d = d - dt * command_speed(d, cfg)
        t += dt
    return t


def test_perfect_tracker_reaches_2m_goal_well_inside_5s():
    t = _time_to_reach(CommandCfg())
    assert t < 3.5, f"a perfect tracker needs {t:.2f} s for 2 m"
    # the released command (0.6 m/s, cubic slow-down inside 0.3 m) needs ~4.8 s: the bound above is meaningful
    assert _time_to_reach(CommandCfg(speed=0.6, slow_radius=0.3, slow_power=3.0)) > 4.5


@pytest.fixture(scope="module")
def flat_env():
    return TraversalEnv(EnvCfg(num_envs=4, noise=NoiseCfg(enabled=False)), sim="mujoco", seed=2)


def test_success_time_ignores_runner_random_episode_lengths(flat_env):
    env = flat_env
    env.reset_idx(torch.arange(4))
    env.episode_length_buf[:] = torch.tensor([0, 300, 600, 900])  # what rsl_rl's init_at_random_ep_len does
    env.goals[:, :2] = env.state.root_pos[:, :2]  # goal under the robot: reached at the first step
    env.step(torch.zeros(4, env.num_actions))
    torch.testing.assert_close(env.reached_time, torch.full((4,), env.dt))
    assert env.episode_success(torch.arange(4)).all()


def test_reset_requeries_only_the_reset_envs(flat_env):
    env = flat_env
    env.step(torch.zeros(4, env.num_actions))
    rows = []
    sample = env.field_source.sample

    def counting(points, goals, env_ids=None):
        rows.append(points.shape[0])
        return sample(points, goals, env_ids)

    env.field_source.sample = counting
    try:
        env.reset_idx(torch.tensor([2]))
    finally:
        env.field_source.sample = sample
    assert rows == [1]
    # the partial refresh equals a full re-read
    full = env._read_state(slice(None))
    torch.testing.assert_close(env.state.root_pos, full.root_pos)
    torch.testing.assert_close(env.state.link_pos, full.link_pos)
    before = env.command_vel.clone()
    env._update_field()
    torch.testing.assert_close(env.command_vel, before)


def test_heading_is_free_near_obstacles(flat_env):
    env = flat_env
    env.step(torch.zeros(4, env.num_actions))
    env.command_vel[:] = torch.tensor([0.0, 0.8])  # command along +y
    yaw = env.state.yaw.clone()
    env.state.yaw[:] = 0.0  # facing +x: 90 degrees off
    heading = functools.partial(rew.track_heading, env, **env.reward_terms["track_heading"][1])
    assert torch.allclose(heading(), torch.zeros(4), atol=1e-5)
    env.field.sdf[:2, 5] = 0.1  # a link of envs 0, 1 close to an obstacle: side-stepping allowed
    assert heading().tolist()[:2] == [1.0, 1.0]
    env.state.yaw[:] = yaw
    env.field.sdf[:] = env.cfg.field_obs.sdf_clip


def test_contact_with_an_obstacle_costs_reward():
    scenes = SceneSet.typical("hurdle-crouch", num_envs=1, variants=1)
    env = TraversalEnv(EnvCfg(num_envs=1, scene_kind="hurdle-crouch"), sim="mujoco", scenes=scenes, seed=1)
    centre = scenes.mesh_for_env(0).split(only_watertight=False)[0].centroid
    qpos, qvel = env.sim.qpos.clone(), env.sim.qvel.clone()
    qpos[0, 0], qpos[0, 1] = float(centre[0]), float(centre[1])
    env.sim.reset(torch.tensor([0]), qpos, qvel)
    env.step(torch.zeros(1, env.num_actions))
    assert env.episode_sums["collision"][0] <= env.cfg.rewards.collision < 0
    assert env.episode_sums["sdf_barrier"][0] < -1.0
    assert math.isfinite(float(env.episode_sums["sdf_barrier"][0]))


def test_foot_clearance_min_only_lets_feet_clear_a_hurdle(flat_env):
    env = flat_env
    env.step(torch.zeros(4, env.num_actions))
    params = dict(env.reward_terms["feet_clearance"][1])
    assert params["foot_clearance_min_only"] is False
    swing = ~rew._stance(env, params["standing_speed"])
    if not swing.any():
        pytest.skip("no swing foot in this state")
    env.state.foot_vel[..., :2] = 1.0
    env.state.foot_pos[..., 2] = params["foot_clearance"] + 0.1  # 17 cm: over an 8-15 cm bar
    assert (rew.feet_clearance(env, **params) > 0).any()  # the release's two-sided term punishes hurdling
    params["foot_clearance_min_only"] = True
    assert torch.equal(rew.feet_clearance(env, **params), torch.zeros(4))
    env.state.foot_pos[..., 2] = params["foot_clearance"] - 0.05  # too low is still penalised
    assert (rew.feet_clearance(env, **params) > 0).any()


def _bar_pose(term: str, shift):
    """A 1-env hurdle-pass env with ``term`` on, the robot upright and moved along x by ``shift(env, bar)`` (``bar``:
    the bar's analytic cylinder along y, ``(xc, zc, r)``), its state and field updated; and MuJoCo's data at that pose.
    """
    scenes = SceneSet.typical("hurdle-pass", num_envs=1, variants=1)
    cfg = EnvCfg(num_envs=1, scene_kind="hurdle-pass", noise=NoiseCfg(enabled=False))
    setattr(cfg.rewards, term, -2.0)
    env = TraversalEnv(cfg, sim="mujoco", scenes=scenes, seed=1)
    v = np.asarray(scenes.mesh_for_env(0).vertices)
    bar = v[(v[:, 2] > 1e-3) & (v[:, 2] < 0.4)]  # the corridor's boxes have no vertex between floor and top
    xc, r = 0.5 * (bar[:, 0].min() + bar[:, 0].max()), 0.5 * (bar[:, 0].max() - bar[:, 0].min())
    cylinder = (xc, bar[:, 2].max() - r, r)
    qpos, qvel = env.sim.qpos.clone(), env.sim.qvel.clone()
    qpos[0, 3:7] = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=qpos.dtype)
    env.sim.reset(torch.tensor([0]), qpos, qvel)
    env._update_state()
    qpos[0, 0] += shift(env, cylinder)
    env.sim.reset(torch.tensor([0]), qpos, qvel)
    env._update_state()
    env._update_field()
    d = mujoco.MjData(env.sim.model)
    d.qpos[:] = qpos[0].numpy()
    mujoco.mj_forward(env.sim.model, d)
    return env, cylinder, d


def test_foot_sole_barrier_sees_a_toe_the_sole_centre_does_not():
    """Heel and toe points from MuJoCo's own kinematics, SDF of the bar computed analytically (a cylinder along
    y): the term matches, and it is large where the sole-centre barrier is small (toe over the bar's edge)."""

    def toes_in(env, bar):  # the toes (10 cm ahead of the sole centre) 3 cm into the bar's footprint
        return (bar[0] - bar[2] + 0.03) - (float(env.state.foot_pos[0, 0, 0]) + env.robot.foot_sole[1])

    env, (xc, zc, r), d = _bar_pose("foot_sole_barrier", toes_in)
    m = env.sim.model
    expect = 0.0
    p = env.cfg.rewards.params
    for k, foot in enumerate(env.robot.feet):
        axis = d.xmat[m.body(foot).id].reshape(3, 3)[:, 0]
        torch.testing.assert_close(
            env.state.foot_axis[0, k], torch.tensor(axis, dtype=torch.float32), atol=1e-5, rtol=0
        )
        centre = d.site_xpos[m.site(env.robot.query_site_names[env._foot_link[k]]).id]
        for end in env.robot.foot_sole:
            x, _, z = centre + end * axis
            dist = math.hypot(x - xc, z - zc) - r
            expect += math.log1p(math.exp((p.sole_margin - dist) / p.barrier_width))
    got = float(rew.foot_sole_barrier(env, p.sole_margin, p.barrier_width)[0])
    assert got == pytest.approx(expect, rel=0.15), (got, expect)
    centre_only = F.softplus((p.barrier_margin - env.field.sdf[0, env._foot_link]) / p.barrier_width).sum()
    assert got > 2.0 and got > 3 * float(centre_only)
    env.step(torch.zeros(1, env.num_actions))
    assert env.episode_sums["foot_sole_barrier"][0] < 0


def test_shin_barrier_sees_a_shank_over_the_bar_the_knee_point_does_not():
    """Shin points from MuJoCo's own kinematics (between the knee and foot query sites), the bar's SDF analytic: the
    term matches, and it is large where the knee's query point, at the joint above the bar, sees nothing."""

    def shank_over(env, bar):  # the left shank straight above the bar's axis
        return bar[0] - float(env.state.link_pos[0, [q.name for q in env.robot.query_links].index("left_knee"), 0])

    env, (xc, zc, r), d = _bar_pose("shin_barrier", shank_over)
    m = env.sim.model
    sites = env.robot.query_site_names
    names = [q.name for q in env.robot.query_links]
    knee_k = names.index("left_knee")
    p = env.cfg.rewards.params
    expect = 0.0
    for side in ("left", "right"):
        knee = d.site_xpos[m.site(sites[names.index(f"{side}_knee")]).id]
        foot = d.site_xpos[m.site(sites[names.index(f"{side}_foot")]).id]
        for f in rew.SHIN_FRACTIONS:
            x, _, z = knee + f * (foot - knee)
            dist = math.hypot(x - xc, z - zc) - r - p.shin_radius
            expect += math.log1p(math.exp((p.shin_margin - dist) / p.barrier_width))
    got = float(rew.shin_barrier(env, p.shin_margin, p.shin_radius, p.barrier_width)[0])
    assert got == pytest.approx(expect, rel=0.15), (got, expect)
    knee_only = F.softplus((p.barrier_margin - env.field.sdf[0, knee_k]) / p.barrier_width)
    assert got > 2.0 and got > 10 * float(knee_only)
    env.step(torch.zeros(1, env.num_actions))
    assert env.episode_sums["shin_barrier"][0] < 0
