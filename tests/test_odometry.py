"""Odometry drift of the student's HumanoidPF block (``field_block_odometry``, ``cat.envs.odometry``): zero drift
gives ``field_block`` bit for bit; the pose error starts at zero, grows as a random walk (std sigma sqrt(T)),
draws from the env's generator and is part of the env snapshot; the block is the field queried at the displaced
links, checked against an independent computation; the mirror map and the deploy runtime know the term."""

from __future__ import annotations

import math

import pytest
import torch

from cat.envs.config import EnvCfg, NoiseCfg, ObsGroupCfg, default_obs_groups
from cat.envs.odometry import OdometryDrift
from cat.envs.scene_set import SceneSet
from cat.envs.traversal_env import TraversalEnv
from cat.fields import humanoid_pf

K7 = 13 * 7
TERMS = ["field_block", "field_block_odometry"]  # group "student": clean block, then the drifting one


def _cfg(n: int, xy: float, yaw: float, noise: bool = True, **kw) -> EnvCfg:
    """A task whose noise-free ``student`` group reads both blocks (no value noise: exact comparisons)."""
    groups = {"student": ObsGroupCfg(terms=list(TERMS))}
    return EnvCfg(
        num_envs=n, observations=groups, noise=NoiseCfg(enabled=noise, odometry_xy=xy, odometry_yaw=yaw), **kw
    )


def _scene_env(n: int, xy: float, yaw: float, seed: int = 0) -> TraversalEnv:
    """Hurdle-crouch tiles: a field with obstacles near the links (grad d and clipped d are not constant)."""
    scenes = SceneSet.typical("hurdle-crouch", num_envs=n, variants=1)
    return TraversalEnv(_cfg(n, xy, yaw, scene_kind="hurdle-crouch"), scenes=scenes, seed=seed)


def _blocks(env: TraversalEnv) -> tuple[torch.Tensor, torch.Tensor]:
    x = env.get_observations()["student"]
    return x[:, :K7], x[:, K7:]


def _rot(angle: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate (n, K, 3) vectors by (n,) angles about z with an explicit matrix."""
    c, s = angle.cos()[:, None], angle.sin()[:, None]
    return torch.stack((c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]), dim=-1)


def test_zero_drift_is_field_block_exactly():
    """sigma = 0 with noise on: the drift path runs (an extra query at the undisplaced links) and reads
    ``field_block`` bit for bit, through refreshes and resets; with noise off, or without the term, no drift."""
    env = _scene_env(4, 0.0, 0.0)
    assert env.odometry is not None
    for t in range(12):
        env.step(0.3 * torch.sin(torch.arange(12.0) + t).expand(4, 12))
        clean, odom = _blocks(env)
        assert torch.equal(clean, odom), t
    assert (env.field_obs_buf[..., 3:6] != 0).any()  # obstacles in range: grad d is part of the comparison
    off = TraversalEnv(_cfg(2, 0.02, 0.01, noise=False), seed=0)
    assert off.odometry is None and off.field_obs_odom_buf is None
    for _ in range(5):
        off.step(torch.zeros(2, 12))
    assert torch.equal(*_blocks(off))
    plain = TraversalEnv(EnvCfg(num_envs=2, observations=default_obs_groups()), seed=0)
    assert plain.odometry is None and "odometry_error" not in plain.get_state()  # no cost, old snapshots valid


def test_both_placements_of_the_block_share_one_noise_draw():
    """A noisy group reads ``field_block`` and ``field_block_odometry`` with the same value-noise draw (one
    reading, two placements): with zero drift the two noisy blocks are equal, and differ from the clean ones."""
    cfg = _cfg(3, 0.0, 0.0, scene_kind="hurdle-crouch")
    cfg.observations["noisy"] = ObsGroupCfg(terms=list(TERMS), noise=True)
    scenes = SceneSet.typical("hurdle-crouch", num_envs=3, variants=1)
    env = TraversalEnv(cfg, scenes=scenes, seed=2)
    for t in range(4):
        obs, *_ = env.step(0.2 * torch.cos(torch.arange(12.0) + t).expand(3, 12))
        noisy, clean = obs["noisy"], obs["student"]
        assert torch.equal(noisy[:, :K7], noisy[:, K7:]), t
        assert 0 < (noisy - clean).abs().max() <= cfg.noise.field_block + 1e-6


def test_random_walk_statistics():
    """The class alone, 200k envs: after T s in refresh steps the error per axis has std sigma sqrt(T)."""
    g = torch.Generator().manual_seed(0)
    odom = OdometryDrift(200_000, 0.02, 0.01, "cpu")
    dt = torch.full((200_000,), 0.1)
    for _ in range(30):  # 3 s
        odom.advance(dt, g)
    std = odom.error.std(dim=0)
    want = torch.tensor([0.02, 0.02, 0.01]) * math.sqrt(3.0)
    torch.testing.assert_close(std, want, rtol=0.01, atol=0.0)  # std of the std estimate: 0.16 %
    assert odom.error.mean(dim=0).abs().max() < 4 * want.max() / math.sqrt(200_000)
    odom.reset(torch.arange(10))
    assert (odom.error[:10] == 0).all() and (odom.error[10:] != 0).all()


def test_env_drift_starts_at_zero_and_grows_as_sigma_sqrt_t():
    """The env's drift: zero at reset; after T = 0.5 s of steps its std across 192 envs is sigma sqrt(T)
    (pooled over x, y, yaw scaled by their sigmas: 576 samples, std of the estimate 3 %; tolerance 12 %)."""
    n, sx, sy = 192, 0.05, 0.03
    env = TraversalEnv(_cfg(n, sx, sy), seed=1)
    assert (env.odometry.error == 0).all()
    steps = 25  # 5 refreshes at 10 Hz
    for _ in range(steps):
        env.step(torch.zeros(n, 12))
    kept = env.step_count == steps  # envs that did not fall and reset
    assert kept.sum() > n // 2
    t = steps * env.dt
    scaled = env.odometry.error[kept] / torch.tensor([sx, sx, sy])
    ratio = float(scaled.pow(2).mean().sqrt()) / math.sqrt(t)
    assert abs(ratio - 1.0) < 0.12, ratio
    ids = torch.arange(0, n, 3)
    env.reset_idx(ids)
    assert (env.odometry.error[ids] == 0).all()
    env._compute_obs()
    clean, odom = _blocks(env)
    assert torch.equal(clean[ids], odom[ids])  # odometry initialised at the start pose


def test_increments_follow_time_since_reset_and_the_env_generator():
    """Replaying the env's generator gives the refresh's increment exactly: N(0, sigma^2 dt) with dt the refresh
    period, or the time since the reset for envs reset after the last refresh."""
    n, sx, sy = 6, 0.05, 0.03
    env = TraversalEnv(_cfg(n, sx, sy), seed=2)
    for _ in range(env.field_refresh):  # one refresh (common_step 5)
        env.step(torch.zeros(n, 12))
    for _ in range(2):
        env.step(torch.zeros(n, 12))
    reset = torch.tensor([1, 4])
    env.reset_idx(reset)  # 3 control steps before the next refresh
    for _ in range(env.field_refresh - 3):
        env.step(torch.zeros(n, 12))
    before, state = env.odometry.error.clone(), env.generator.get_state()
    env.step(torch.zeros(n, 12))  # the refresh step
    assert env.common_step % env.field_refresh == 0 and (env.step_count[reset] == 3).all()
    g = torch.Generator()
    g.set_state(state)
    dt = torch.full((n,), env.field_refresh * env.dt)
    dt[reset] = 3 * env.dt
    want = before + torch.randn(n, 3, generator=g) * torch.tensor([sx, sx, sy]) * dt.sqrt()[:, None]
    torch.testing.assert_close(env.odometry.error, want, rtol=1e-6, atol=1e-8)


def _by_hand(env: TraversalEnv) -> torch.Tensor:
    """The drifting block of every env from the env's state and pose error, computed independently."""
    st, err, clip = env.state, env.odometry.error, env.cfg.field_obs.sdf_clip
    root = st.root_pos[:, None, :]
    points = root + _rot(err[:, 2], st.link_pos - root)
    points[..., :2] += err[:, None, :2]
    field = env.field_source.sample(points, env.goals)
    vel = _rot(err[:, 2], st.link_vel)
    f_h = humanoid_pf(field.force, field.grad_sdf, field.sdf, vel, env.w0, env.field_cfg.lam)
    yaw = st.yaw + err[:, 2]
    return torch.cat((_rot(-yaw, f_h), _rot(-yaw, field.grad_sdf), field.sdf.clamp(-clip, clip)[..., None]), -1)


def test_block_is_field_obs_at_the_displaced_links():
    """Independent computation: links rotated by dyaw about the root and shifted by (dx, dy), the field sampled
    there, link velocities rotated by dyaw, F_H and grad d expressed in the frame of yaw + dyaw, d clipped."""
    n = 4
    env = _scene_env(n, 0.3, 0.3, seed=3)  # large drift: a visible displacement within half a second
    for t in range(2 * env.field_refresh):
        env.step(0.2 * torch.cos(torch.arange(12.0) + t).expand(n, 12))
    assert env.common_step % env.field_refresh == 0
    assert (env.step_count == 2 * env.field_refresh).all()  # none reset after the refresh
    assert env.odometry.error.abs().min() > 0
    want = _by_hand(env)
    clean, odom = _blocks(env)
    torch.testing.assert_close(odom, want.reshape(n, -1), rtol=1e-5, atol=1e-5)
    assert (want[..., 3:6] != 0).any() and (want[..., 6] < env.cfg.field_obs.sdf_clip).any()  # near obstacles
    assert (odom - clean).abs().max() > 0.01  # the drift shows
    # fast links (3 m/s), where -grad d . v exceeds w1's floor: the velocities must be in the odometry's frame
    env.state.link_vel[:] = 3.0 * torch.nn.functional.normalize(torch.randn(n, 13, 3), dim=-1)
    env.odometry.error[:, 2] = 0.5
    env._refresh_field_obs()
    env._compute_obs()
    torch.testing.assert_close(_blocks(env)[1], _by_hand(env).reshape(n, -1), rtol=1e-5, atol=1e-5)


def test_snapshot_restores_the_next_observations_exactly():
    """A fresh env restored from a snapshot (and the env generator's state, as a resumed run restores it) gives
    the same next observations as the original, across refreshes; a drift-free env refuses the snapshot."""
    n = 4
    a = _scene_env(n, 0.1, 0.05, seed=4)
    act = [0.2 * torch.sin(torch.arange(12.0) * (t + 1)).expand(n, 12) for t in range(14)]
    for x in act[:7]:
        a.step(x)
    snap, rng = a.get_state(), a.generator.get_state()
    assert {"odometry_error", "field_obs_odom_buf"} <= set(snap)
    want = [a.step(x)[0]["student"].clone() for x in act[7:]]
    b = _scene_env(n, 0.1, 0.05, seed=99)
    b.set_state(snap)
    b.generator.set_state(rng)
    torch.testing.assert_close(b.get_observations()["student"], snap["obs"]["student"], rtol=0, atol=0)
    for t, x in enumerate(act[7:]):
        torch.testing.assert_close(b.step(x)[0]["student"], want[t], rtol=0, atol=0, msg=f"step {t}")
    assert not torch.equal(want[-1][:, :K7], want[-1][:, K7:])
    off = TraversalEnv(_cfg(n, 0.1, 0.05, noise=False), seed=0)
    with pytest.raises(ValueError, match="odometry drift"):
        off.set_state(snap)


def test_mirror_map_is_the_field_blocks_and_an_involution():
    env = TraversalEnv(_cfg(3, 0.1, 0.05), seed=5)
    env.step(torch.zeros(3, 12))
    perm, sign = env.mirror_map.obs["student"]
    torch.testing.assert_close(perm[K7:] - K7, perm[:K7], rtol=0, atol=0)
    torch.testing.assert_close(sign[K7:], sign[:K7], rtol=0, atol=0)
    obs = env.get_observations()
    m = env.mirror_map
    torch.testing.assert_close(m.mirror_obs(m.mirror_obs(obs))["student"], obs["student"], rtol=0, atol=0)


def test_runtime_reads_its_field_block(robot_cfg):
    """On the robot the block already comes from the odometry pose: the term is ``field_block``, deployable,
    and described in the layout metadata like it."""
    from cat.deploy.metadata import term_info
    from cat.deploy.policy import PolicySpec
    from cat.deploy.runtime import DeployCfg, Runtime
    from cat.deploy.scenes import load_scene

    task = EnvCfg(observations={**default_obs_groups(), "student": ObsGroupCfg(terms=["goal_command", *TERMS])})
    rt = Runtime(load_scene("flat"), PolicySpec("hold", task, obs_groups=["student"]), DeployCfg(realtime=False))
    rt.set_goal((1.5, 0.4))
    rt.perception.cycle(rt.snapshot())
    rt._refresh_field_obs()
    x = rt.observation()["student"]
    assert rt.used_field is not None and (x[:, 3 : 3 + K7] != 0).any()
    assert torch.equal(x[:, 3 : 3 + K7], x[:, 3 + K7 :])
    terms = rt.layout.observation["student"]["terms"]
    assert [(t["name"], t["size"]) for t in terms] == [("goal_command", 3), ("field_block", K7), (TERMS[1], K7)]
    a, b = term_info("field_block", task, robot_cfg), term_info(TERMS[1], task, robot_cfg)
    assert (a.size, a.clip) == (b.size, b.clip)


def test_a_snapshot_of_another_model_is_refused_before_anything_changes():
    """A snapshot whose sensors (or any tensor) have another shape, e.g. saved before sensors were added,
    raises naming the tensor and leaves the env as it was (a resumed run then starts fresh episodes)."""
    env = _scene_env(2, 0.1, 0.05, seed=3)
    env.step(torch.full((2, 12), 0.1))
    snap = env.get_state()
    snap["sim"]["sensordata"] = snap["sim"]["sensordata"][:, :-18]
    env.step(torch.full((2, 12), -0.1))
    before = env.get_state()
    with pytest.raises(ValueError, match=r"sim\.sensordata has shape"):
        env.set_state(snap)
    after = env.get_state()
    torch.testing.assert_close(after["sim"], before["sim"], rtol=0, atol=0)
    torch.testing.assert_close(after["targets"], before["targets"], rtol=0, atol=0)
