"""Click demo pieces without a browser: FK of the 13 links, the LiDAR voxel map of a known box, goal checks,
the observation against the env's own actor group, and the click handler's refusals."""

from __future__ import annotations

from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import torch
import trimesh
from scipy import ndimage

from cat.deploy.kinematics import RobotFK, robot_model
from cat.deploy.lidar import Lidar, LidarCfg
from cat.deploy.scenes import GoalChecker, GoalError, floor_hit, load_scene
from cat.deploy.voxel_map import MapCfg, VoxelMap, map_grid
from cat.envs.math_utils import yaw_quat
from cat.envs.robot import home_qpos
from cat.envs.scene import build_env_model
from cat.terrain import Scene, SceneError
from cat.terrain.mujoco_export import add_obstacles_to_spec
from cat.terrain.voxel import GridSpec, occupancy


def _random_qpos(model: mujoco.MjModel, robot, rng: np.random.Generator) -> np.ndarray:
    q = home_qpos(robot)
    q[:3] = rng.uniform(-3, 3, 3)
    quat = rng.normal(size=4)
    q[3:7] = quat / np.linalg.norm(quat)
    lo, hi = model.jnt_range[1:, 0], model.jnt_range[1:, 1]
    q[7:] = rng.uniform(lo, hi)
    return q


def test_fk_links_equal_mujoco_sites(robot_cfg):
    """pytorch-kinematics FK of the 13 query links = MuJoCo's query sites within 1 mm, random poses."""
    model = robot_model(robot_cfg)
    fk = RobotFK(robot_cfg, model)
    rng = np.random.default_rng(0)
    qs = np.stack([_random_qpos(model, robot_cfg, rng) for _ in range(64)])
    got = fk.link_positions(qs[:, :3], qs[:, 3:7], qs[:, 7:]).numpy()
    d = mujoco.MjData(model)
    ref = np.zeros_like(got)
    for b, q in enumerate(qs):
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        ref[b] = [d.site(s).xpos for s in robot_cfg.query_site_names]
    err = np.abs(got - ref).max()
    assert err < 1e-3, f"FK differs from MuJoCo by {err * 1e3:.3f} mm"
    # the same holds for a body frame (the LiDAR mount): position and orientation
    p = fk.poses(qs[-1:, :3], qs[-1:, 3:7], qs[-1:, 7:], ["torso_link"])
    assert np.allclose(p.pos[0, 0].numpy(), d.body("torso_link").xpos, atol=1e-6)
    assert np.allclose(p.rot[0, 0].numpy(), d.body("torso_link").xmat.reshape(3, 3), atol=1e-6)


def _box_map(robot_cfg, lidar_cfg: LidarCfg):
    """Scan a 0.62 x 0.82 x 0.63 m box from four standing poses around it; return (map occupancy, truth, grid)."""
    # faces a quarter voxel inside boundary voxels, so "voxel centre inside" and "hit in voxel" agree exactly
    box = trimesh.creation.box(bounds=[[0.61, -0.39, 0.0], [1.23, 0.43, 0.63]])
    model = build_env_model(robot_cfg, lambda s: add_obstacles_to_spec(s, box))
    d = mujoco.MjData(model)
    grid = map_grid((-1.0, -1.6), (2.8, 1.6), MapCfg())
    vm = VoxelMap(grid)
    lidar = Lidar(model, lidar_cfg, seed=1)
    for xy, yaw in [((0.0, 0.0), 0.0), ((0.9, -1.2), np.pi / 2), ((2.0, 0.0), np.pi), ((0.9, 1.2), -np.pi / 2)]:
        d.qpos[:] = home_qpos(robot_cfg)
        d.qpos[:2] = xy
        d.qpos[3:7] = yaw_quat(torch.tensor([yaw], dtype=torch.float64))[0].numpy()
        mujoco.mj_kinematics(model, d)
        for _ in range(5):
            scan = lidar.scan(d)
            pos, rot = lidar.sensor_pose(d.xpos[lidar.body_id], d.xmat[lidar.body_id].reshape(3, 3))
            vm.integrate(pos, pos + scan.points_sensor() @ rot.T)
    truth = occupancy(box, GridSpec(grid.origin, grid.voxel, grid.shape))
    return vm.occupied(), truth, grid


def _shell(truth: np.ndarray, grid) -> np.ndarray:
    """The part of the box a LiDAR can see: voxels on its surface, above the floor cut."""
    above = grid.centers()[..., 2] > MapCfg().ground_z
    return truth & ~ndimage.binary_erosion(truth) & above


def test_voxel_map_of_box_noise_free(robot_cfg):
    """Exact ranges: every occupied voxel is box, and the map covers the visible shell (IoU 0.93 measured)."""
    occ, truth, grid = _box_map(robot_cfg, LidarCfg(range_noise=0.0, dropout=0.0))
    shell = _shell(truth, grid)
    iou = (occ & shell).sum() / (occ | shell).sum()
    assert (occ & truth).sum() / occ.sum() > 0.99
    assert iou > 0.9, f"IoU {iou:.3f}"


def test_voxel_map_of_box_with_noise(robot_cfg):
    """Mid-360 noise (2 cm, 5 % dropouts): IoU with the visible shell 0.76 measured; no occupied voxel farther
    than one voxel from the box; 96 % of the shell found. Floor returns never become obstacles."""
    occ, truth, grid = _box_map(robot_cfg, LidarCfg())
    shell = _shell(truth, grid)
    iou = (occ & shell).sum() / (occ | shell).sum()
    assert iou > 0.65, f"IoU {iou:.3f}"
    assert (occ & ndimage.binary_dilation(truth)).sum() / occ.sum() > 0.98
    assert (occ & shell).sum() / shell.sum() > 0.9
    assert not occ[..., 0].any()  # the floor layer (z < 4 cm) stays free


def test_window_is_on_the_map_lattice_and_geofenced():
    grid = map_grid((-1.0, -1.0), (1.0, 1.0), MapCfg())
    vm = VoxelMap(grid)
    occ, wg = vm.window((0.013, -0.02), (16, 16, 35), outside_blocked=True)
    offset = (np.asarray(wg.origin) - np.asarray(grid.origin)) / grid.voxel
    assert np.allclose(offset, np.round(offset))
    assert not occ.any()  # 0.64 m window inside the 2 m map: all unknown = free
    occ, _ = vm.window((0.9, 0.0), (16, 16, 35), outside_blocked=True)
    assert occ[-1].all() and not occ[0].any()  # beyond x = 1 m it is fenced


def test_goal_checks():
    ring = [
        trimesh.creation.box(bounds=b) for b in ([[1.0, -0.6, 0], [1.1, 0.6, 1.4]], [[2.1, -0.6, 0], [2.2, 0.6, 1.4]])
    ]
    ring += [
        trimesh.creation.box(bounds=b) for b in ([[1.0, -0.7, 0], [2.2, -0.6, 1.4]], [[1.0, 0.6, 0], [2.2, 0.7, 1.4]])
    ]
    ring.append(trimesh.creation.box(bounds=[[-0.5, 1.0, 0], [0.5, 1.4, 1.0]]))
    scene = Scene(trimesh.util.concatenate(ring), [[-1, -2, 0], [3, 2, 1.5]], start=(0, 0), goals=[(0, -1)])
    check = GoalChecker(scene)
    assert np.allclose(check.check((0.5, -1.0), (0.0, 0.0)), [0.5, -1.0, 0.75])
    with pytest.raises(GoalError, match="inside an obstacle"):
        check.check((0.0, 1.2), (0.0, 0.0))
    with pytest.raises(GoalError, match="outside the map"):
        check.check((5.0, 0.0), (0.0, 0.0))
    with pytest.raises(GoalError, match="unreachable"):
        check.check((1.6, 0.0), (0.0, 0.0))  # inside the closed ring
    assert np.allclose(floor_hit((0, 0, 2), (0.5, 0, -1)), [1.0, 0.0])
    assert floor_hit((0, 0, 2), (0, 0, 1)) is None


def test_scene_argument(tmp_path):
    assert load_scene("flat").kind == "flat"
    assert load_scene("hurdle-crouch").kind == "hurdle-crouch"
    with pytest.raises(SceneError, match="not a typical type"):
        load_scene("no-such-scene")
    with pytest.raises(SceneError, match="not found"):
        load_scene(str(tmp_path / "missing.obj"))
    with pytest.raises(SceneError, match="not a scene folder"):
        load_scene(str(tmp_path))


def test_observation_matches_env_actor_group(robot_cfg):
    """Same robot state, same goal: the demo's actor observation = the env's (noise off); the field block agrees
    up to the live field's numerical geodesic (vs the env's analytic flat-ground field)."""
    from cat.deploy.policy import policy_spec
    from cat.deploy.runtime import DeployCfg, Runtime
    from cat.envs.config import EnvCfg, NoiseCfg
    from cat.envs.traversal_env import TraversalEnv

    env = TraversalEnv(EnvCfg(num_envs=1, noise=NoiseCfg(enabled=False)), seed=3)
    start = env.sim.qpos[0, :2].numpy().astype(np.float64)
    goal = np.r_[start + [1.2, 0.5], 0.75]
    env.goals[0] = torch.tensor(goal, dtype=torch.float32)
    env._update_field()
    env._refresh_field_obs()
    env._compute_obs()

    cfg = DeployCfg(realtime=False)
    cfg.perception.geofence = False  # nothing but free space in the window, like the env's flat-ground field
    rt = Runtime(load_scene("flat"), policy_spec("hold"), cfg)
    rt.data.qpos[:] = env.sim.qpos[0].numpy()
    rt.data.qvel[:] = 0.0
    mujoco.mj_forward(rt.model, rt.data)
    rt.set_goal(goal[:2])
    rt.phase[:] = env.phase[0]
    rt.targets[:] = env.targets[0]
    rt.perception.cycle(rt.snapshot())
    rt.step_count = 0
    rt._prev_link_pos = None
    rt._update_state(rt.estimate())
    rt._update_state(rt.estimate())  # at rest: FK twice at the same pose -> zero link velocity, as the env's
    rt._refresh_field_obs()
    ours = rt.observation()["actor"][0]
    theirs = env.obs_buf["actor"][0]
    assert ours.shape == theirs.shape
    k = 13 * 7
    assert torch.allclose(ours[:-k], theirs[:-k], atol=1e-5)
    f_ours, f_env = ours[-k:].view(13, 7), theirs[-k:].view(13, 7)
    assert torch.allclose(f_ours[:, 3:], f_env[:, 3:], atol=1e-5)  # grad d = 0, d clipped to 1 m: free space
    cos = torch.nn.functional.cosine_similarity(f_ours[:, :3], f_env[:, :3], dim=-1)
    assert cos.min() > 0.98, cos
    assert torch.allclose(f_ours[:, :3].norm(dim=-1), f_env[:, :3].norm(dim=-1), rtol=0.05)


def test_click_handler_refuses_and_keeps_goal():
    """Clicks in an obstacle, outside the map or at the sky leave a message and the previous goal."""
    import socket

    from cat.deploy.cli import ClickCfg, build_runtime
    from cat.deploy.viewer import ClickApp, ViewerCfg

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    rt = build_runtime(ClickCfg(scene="side-pass", checkpoint="hold", realtime=False))
    app = ClickApp(rt, ViewerCfg(port=port))
    eye = np.array([0.0, -2.0, 2.5])
    try:

        def click(direction):
            app._handle_click(SimpleNamespace(ray_origin=tuple(eye), ray_direction=tuple(direction), client=None))

        def click_floor(xy):
            click(np.r_[xy, 0.0] - eye)

        click_floor((1.8, 0.0))
        first = rt.goal.copy()
        assert app.message.startswith("Goal set to") and np.allclose(first[:2], (1.8, 0.0))
        # side-pass: blocks press in from both sides of the course; find a floor point under solid block
        pts = np.array([(x, y, 0.75) for x in np.arange(0.5, 1.7, 0.02) for y in np.arange(-0.95, 0.95, 0.05)])
        clearance = rt.scene.clearance(pts)
        assert clearance.min() < -0.04, "no solid point found in the side-pass course"
        click_floor(pts[np.argmin(clearance), :2])
        assert "inside an obstacle" in app.message and "keeping the previous goal" in app.message
        click_floor((9.0, 0.0))
        assert "outside the map" in app.message
        click((0.0, 1.0, 0.5))  # above the horizon
        assert "floor" in app.message
        assert np.allclose(rt.goal, first)
    finally:
        app.stop()
