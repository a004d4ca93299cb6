"""Elevation maps and voxel grids from scene occupancy: exact layers of analytic columns, the env's robot-centric
maps against an analytic scene (a box hurdle and a ceiling at known heights) at any yaw, flat ground, and the
left/right mirror of the new terms against the env itself (observation of a mirrored state in a mirrored scene)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from cat.envs.config import EnvCfg, NoiseCfg, ObsGroupCfg
from cat.envs.perception import map_points, map_shape, voxel_points, voxel_shape
from cat.envs.scene_set import SceneSet, scene_fields
from cat.envs.symmetry import mirror_state
from cat.envs.traversal_env import TraversalEnv
from cat.terrain import GridSpec, Scene
from cat.terrain.elevation import elevation_layers
from cat.terrain.primitives import box, combine

BOUNDS = np.array([[-0.5, -1.0, 0.0], [2.5, 1.0, 1.5]])
# faces on voxel edges (origin + k * 0.04), so the occupancy of the boxes is exact
HURDLE = ((0.62, 0.2, 0.0), (1.02, 0.8, 0.32))  # top 0.32 m, left of the course
CEILING = ((0.62, -0.8, 1.0), (1.42, -0.2, 1.5))  # underside 1.0 m, right of the course
CAP = 2.0


def _scene(mirrored: bool = False) -> Scene:
    flip = np.array([1.0, -1.0, 1.0])
    parts = []
    for lo, hi in (HURDLE, CEILING):
        lo, hi = np.array(lo), np.array(hi)
        if mirrored:
            lo, hi = np.minimum(lo * flip, hi * flip), np.maximum(lo * flip, hi * flip)
        parts.append(box(tuple(lo), tuple(hi)))
    return Scene(combine(parts), BOUNDS, start=(0.0, 0.0, 0.75), goals=[(2.0, 0.0, 0.75)], kind="analytic")


def _expected(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Analytic (ground, overhead) at world points (P, 2), and a mask of points > 0.1 m from any box edge."""
    ground, over = np.zeros(len(xy)), np.full(len(xy), CAP)
    clear = np.ones(len(xy), dtype=bool)
    for (lo, hi), kind in ((HURDLE, "ground"), (CEILING, "overhead")):
        inside = np.all((xy >= np.array(lo[:2])) & (xy <= np.array(hi[:2])), axis=1)
        near = np.all((xy >= np.array(lo[:2]) - 0.1) & (xy <= np.array(hi[:2]) + 0.1), axis=1)
        deep = np.all((xy >= np.array(lo[:2]) + 0.1) & (xy <= np.array(hi[:2]) - 0.1), axis=1)
        clear &= ~near | deep
        if kind == "ground":
            ground[inside] = hi[2]
        else:
            over[inside] = lo[2]
    return ground, over, clear


def test_layers_of_analytic_columns():
    """One column per case on a 4 cm grid: floor only, a box from the floor, a floating bar (ground: it starts
    below the split), a ceiling slab, a wall (ground = its top), and a bar below a ceiling (both layers)."""
    grid = GridSpec((0.0, 0.0, 0.0), 0.04, (6, 1, 40))  # z up to 1.6 m
    occ = np.zeros(grid.shape, dtype=bool)
    z = lambda a, b: slice(round(a / 0.04), round(b / 0.04))  # noqa: E731
    occ[1, 0, z(0.0, 0.32)] = True  # box 0.32 m
    occ[2, 0, z(0.08, 0.24)] = True  # bar 0.08-0.24 m
    occ[3, 0, z(1.0, 1.6)] = True  # ceiling from 1.0 m
    occ[4, 0, z(0.0, 1.6)] = True  # wall
    occ[5, 0, z(0.12, 0.2)] = True  # bar ...
    occ[5, 0, z(1.12, 1.4)] = True  # ... under a ceiling
    ground, over = elevation_layers(occ, grid, split_height=0.5, cap=CAP)
    np.testing.assert_allclose(ground[:, 0], [0.0, 0.32, 0.24, 0.0, 1.6, 0.2], atol=1e-6)
    np.testing.assert_allclose(over[:, 0], [CAP, CAP, CAP, 1.0, CAP, 1.12], atol=1e-6)
    # pooling one voxel either side: each cell reports the highest ground / lowest overhead of its neighbours
    ground_p, over_p = elevation_layers(occ, grid, split_height=0.5, cap=CAP, pool=1)
    np.testing.assert_allclose(ground_p[:, 0], [0.32, 0.32, 0.32, 1.6, 1.6, 1.6], atol=1e-6)
    np.testing.assert_allclose(over_p[:, 0], [CAP, CAP, 1.0, 1.0, 1.0, 1.12], atol=1e-6)


@pytest.fixture(scope="module")
def scene_env() -> TraversalEnv:
    """Two scenes side by side: the analytic scene (env 0, 2) and its mirror image (env 1, 3)."""
    a, b = _scene(), _scene(mirrored=True)
    b.set_occupancy(a.occupancy()[:, ::-1, :].copy())  # the exact mirror (the grid is symmetric about y = 0)
    scenes = SceneSet([a, b], [scene_fields(s, None, None) for s in (a, b)], num_envs=4)
    cfg = EnvCfg(num_envs=4, scene_kind="analytic", noise=NoiseCfg(enabled=False))
    cfg.perception.height_map.overhead_cap = CAP
    cfg.observations["actor"].terms[-1] = "elevation_map"  # method=wo_obs_field's actor
    cfg.observations["student"] = ObsGroupCfg(terms=["goal_command", "voxel_grid", "ground_map", "overhead_map"])
    cfg.curriculum.enabled = False
    return TraversalEnv(cfg, sim="mujoco", scenes=scenes, seed=0)


def _place(env: TraversalEnv, root_xy, yaw) -> None:
    """Put the robots' state (as the terms read it) at given root positions / yaws, no physics."""
    env.state.root_pos[:, :2] = torch.as_tensor(root_xy, dtype=torch.float32)
    env.state.yaw[:] = torch.as_tensor(yaw, dtype=torch.float32)


@pytest.mark.parametrize("yaw", [0.0, 0.7, math.pi / 2, -2.5])
def test_elevation_map_matches_the_analytic_scene(scene_env, yaw):
    env = scene_env
    root = np.array([[0.5, 0.0], [0.9, 0.3], [1.0, -0.4], [0.2, 0.1]])
    _place(env, root, [yaw] * 4)
    from cat.envs.mdp.observations import elevation_map, voxel_grid

    maps = elevation_map(env).reshape(4, 2, -1).numpy()
    local = map_points(env.cfg.perception.height_map).numpy()
    c, s = math.cos(yaw), math.sin(yaw)
    for e in (0, 2):  # envs in the analytic scene (tile offset 0)
        world = root[e] + local @ np.array([[c, s], [-s, c]])
        ground, over, clear = _expected(world)
        assert clear.sum() > 50
        np.testing.assert_allclose(maps[e, 0, clear], ground[clear], atol=1e-5)
        np.testing.assert_allclose(maps[e, 1, clear], over[clear], atol=1e-5)
    assert maps[0, 0].max() == pytest.approx(0.32) and maps[0, 1].min() == pytest.approx(1.0)
    # voxel grid: occupied exactly where a cell centre is inside a box (cells well inside / outside)
    vox = voxel_grid(env).numpy()
    pts = voxel_points(env.cfg.perception.voxel_grid).numpy()
    world = root[0] + pts[:, :2] @ np.array([[c, s], [-s, c]])
    ground, over, clear = _expected(world)
    z = pts[:, 2]
    top = CEILING[1][2]  # the slab ends at the scene's top, 1.5 m: cells above it are free
    occupied = ((ground > 0) & (z < ground - 0.1)) | ((over < CAP) & (z > over + 0.1) & (z < top - 0.1))
    free = ((ground == 0) | (z > ground + 0.1)) & ((over == CAP) | (z < over - 0.1) | (z > top + 0.1))
    assert occupied[clear].sum() > 20
    assert (vox[0][clear & occupied] == 1).all() and (vox[0][clear & free] == 0).all()


def test_flat_ground_maps_are_floor_and_cap():
    cfg = EnvCfg(num_envs=2, noise=NoiseCfg(enabled=False))
    cfg.observations["actor"].terms[-1] = "elevation_map"
    cfg.observations["student"] = ObsGroupCfg(terms=["voxel_grid"])
    env = TraversalEnv(cfg, sim="mujoco", seed=0)
    obs = env.get_observations()
    n = map_shape(cfg.perception.height_map)
    p = n[0] * n[1]
    maps = obs["actor"][:, -2 * p :]
    assert (maps[:, :p] == 0).all() and (maps[:, p:] == cfg.perception.height_map.overhead_cap).all()
    assert obs["student"].shape == (2, int(np.prod(voxel_shape(cfg.perception.voxel_grid))))
    assert (obs["student"] == 0).all()


def test_map_noise_only_in_noisy_groups():
    cfg = EnvCfg(num_envs=2)
    cfg.observations["actor"].terms[-1] = "elevation_map"
    env = TraversalEnv(cfg, sim="mujoco", seed=0)
    obs = env.get_observations()
    p = 2 * int(np.prod(map_shape(cfg.perception.height_map)))
    noisy, clean = obs["actor"][:, -p:], obs["critic"][:, obs["actor"].shape[1] - p : obs["actor"].shape[1]]
    diff = (noisy - clean).abs()
    assert 0 < diff.max() <= cfg.noise.elevation_map and diff.mean() > 0.25 * cfg.noise.elevation_map


def test_mirror_of_mirrored_state_in_mirrored_scene(scene_env):
    """World 1 is world 0 reflected (y -> -y) into the mirrored scene's tile: every group, including the elevation
    map, ground / overhead layers and voxel grid, must equal the mirror map applied to world 0's observation."""
    env = scene_env
    gen = torch.Generator().manual_seed(0)
    env.sim.reset(torch.arange(4), env.sim.qpos.clone(), env.sim.qvel.clone())
    qpos = env.sim.qpos[:1].clone()
    qpos[0, :2] = torch.tensor([0.45, 0.25], dtype=qpos.dtype)
    yaw = torch.tensor(0.4)
    qpos[0, 3:7] = torch.tensor([torch.cos(yaw / 2), 0.0, 0.0, torch.sin(yaw / 2)], dtype=qpos.dtype)
    qpos[0, 7:] += 0.03 * torch.randn(qpos.shape[1] - 7, generator=gen, dtype=qpos.dtype)
    qvel = 0.05 * torch.randn(1, env.sim.qvel.shape[1], generator=gen, dtype=qpos.dtype)
    mq, mv = mirror_state(env, qpos, qvel)
    shift = float(env.scenes.offsets[1, 0])
    mq[0, 0] += shift
    env.sim.reset(torch.tensor([0, 1]), torch.cat((qpos, mq)), torch.cat((qvel, mv)))
    env.goals[0] = torch.tensor([2.0, -0.3, 0.75])
    env.goals[1] = torch.tensor([2.0 + shift, 0.3, 0.75])
    env.phase[1] = torch.remainder(env.phase[0] + 0.5, 1.0)
    tq, _ = mirror_state(env, torch.cat((qpos[:, :7], env.targets[:1].double()), -1), qvel)
    env.targets[1] = tq[0, 7:].float()
    env.actions[1] = env.mirror_map.mirror_actions(env.actions[:1])[0]
    env._update_state()
    env._compute_obs()
    obs = env.get_observations()
    mirrored = env.mirror_map.mirror_obs(obs[:1])
    assert set(obs.keys()) == {"actor", "critic", "student"}
    for group in obs.keys():
        torch.testing.assert_close(obs[group][1:2], mirrored[group], atol=5e-3, rtol=1e-3)
    p = int(np.prod(map_shape(env.cfg.perception.height_map)))
    ground = obs["actor"][0, -2 * p : -p]
    assert ground.max() == pytest.approx(0.32) and not torch.equal(ground, mirrored["actor"][0, -2 * p : -p])
    assert obs["student"][0].sum() > 0


def test_terrain_aware_foot_clearance_targets_the_obstacle_top(scene_env):
    """feet_clearance with a lookahead: a swing foot 15 cm up, 0.22 m before the 0.32 m box and moving towards it
    (0.3 m lookahead), must be at 0.32 + foot_clearance; the same foot beside the box (flat floor ahead) is not
    penalised."""
    from cat.envs.mdp import rewards as rew

    env = scene_env
    p = dict(env.reward_terms["feet_clearance"][1])
    env.command_vel[:] = torch.tensor([0.5, 0.0])  # walking: the gait clock decides swing
    env.phase[:] = 0.25  # left foot in stance, right foot swinging
    swing = ~rew._stance(env, p["standing_speed"])
    assert swing[:, 1].all() and not swing[:, 0].any()
    env.state.foot_vel[:] = torch.tensor([1.0, 0.0, 0.0])
    z = 0.15
    env.state.foot_pos[..., 2] = z
    scenes = env.perception.scenes
    offset = torch.as_tensor(np.asarray(scenes.offsets)[scenes.scene_of_env[:4].numpy(), :2], dtype=torch.float32)
    # 0.22 m before the box's near face at x = 0.62; env 0, 2 in the scene (box at y > 0), 1, 3 in its mirror image
    lane = torch.tensor([0.5, -0.5, 0.5, -0.5])
    env.state.foot_pos[..., :2] = (torch.stack((torch.full((4,), 0.4), lane), dim=-1) + offset)[:, None]
    p.update(foot_clearance_min_only=True, foot_clearance_lookahead=0.0)
    assert torch.equal(rew.feet_clearance(env, **p), torch.zeros(4))  # 15 cm is above the flat 7 cm target
    p["foot_clearance_lookahead"] = 0.3
    expected = (HURDLE[1][2] + p["foot_clearance"] - z) ** 2  # speed 1, one swing foot
    got = rew.feet_clearance(env, **p)
    torch.testing.assert_close(got, torch.full((4,), expected), atol=1e-5, rtol=0)
    p["foot_clearance_step_max"] = 0.3  # a 0.32 m box counts as a wall: no target over it
    assert torch.equal(rew.feet_clearance(env, **p), torch.zeros(4))
    p["foot_clearance_step_max"] = 0.4
    env.state.foot_pos[..., 1] -= 2 * lane[:, None]  # the other side of the course: flat floor
    assert torch.equal(rew.feet_clearance(env, **p), torch.zeros(4))
