"""Perception in the loop (issue 32): the deploy runtime's voxel grid and elevation layers from its live map equal
the env's ground-truth terms when the map holds the scene, and stay close with a noiseless LiDAR that has seen the
scene from all sides; a map-reading policy gets no field built; ``eval_table.py perception=lidar`` scores a
shipped policy end to end on the same trials under both settings; bad input is refused by name.

Tolerances (analytic scene: a box hurdle and a ceiling on 4 cm voxel edges, tests/test_perception.py's):
- map loaded with the scene's occupancy: every layer cell and every voxel-grid cell below the map's 1.4 m top
  equal, exactly;
- noiseless LiDAR, 24 scans from 6 standing poses: ground layer >= 97 % of cells within one map voxel (0.04 m)
  (measured 99.5 %); overhead layer: the LiDAR (upside down, sees up to +7 deg) reaches a ceiling's underside only
  near its edges: of the cells it reports, >= 90 % within 0.04 m of the truth in their 3x3 neighbourhood
  (measured 100 %; 36 % of the truth's overhead cells seen), the rest read 'nothing overhead'; voxel grid IoU
  >= 0.3 (measured 0.39: the LiDAR maps shells, not solids) and >= 80 % of the live occupied cells occupied in
  the truth (measured 86 %: a hit marks the voxel a surface passes through, the truth a voxel whose centre is
  inside);
- the demo's default noise (2 cm, 5 % dropouts): ground layer >= 90 % within 0.04 m (measured 98.7 %; overhead
  100 % -> 94 %, voxel precision 86 % -> 81 %; the harsh setting 98.3 %, 93 %, 77 %).
"""

from __future__ import annotations

import csv
import importlib.util
import logging
import math
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from scipy import ndimage

from cat.deploy.live_eval import LiveSettingCfg, check_live, deploy_cfg, load_setting
from cat.deploy.policy import PolicySpec
from cat.deploy.runtime import Runtime
from cat.envs.config import EnvCfg, ObsGroupCfg
from cat.envs.mdp.observations import elevation_map, voxel_grid
from cat.envs.perception import ScenePerception, map_shape, voxel_points
from cat.envs.scene_set import SceneSet, scene_fields
from cat.eval.manifest import ManifestError, MethodRun
from cat.run.config import TrainCfg
from cat.terrain import Scene
from cat.terrain.primitives import box, combine

BOUNDS = np.array([[-0.5, -1.0, 0.0], [2.5, 1.0, 1.5]])
HURDLE = ((0.62, 0.2, 0.0), (1.02, 0.8, 0.32))  # faces on voxel edges: the occupancy is exact
CEILING = ((0.62, -0.8, 1.0), (1.42, -0.2, 1.5))
POSES = [
    ((0.0, 0.0), 0.0),
    ((0.3, 0.5), -0.5),
    ((1.0, 0.0), 1.0),
    ((1.9, 0.4), 2.5),
    ((2.0, -0.5), -2.8),
    ((0.2, -0.6), 0.4),
]
REPO = Path(__file__).resolve().parents[1]
MAP_TOP = 1.4  # the map's height (MapCfg.height): voxel-grid levels above it are not mapped


def _scene() -> Scene:
    parts = [box(lo, hi) for lo, hi in (HURDLE, CEILING)]
    return Scene(combine(parts), BOUNDS, start=(0.0, 0.0, 0.75), goals=[(2.0, 0.0, 0.75)], kind="analytic")


def _task(terms: list[str]) -> EnvCfg:
    task = EnvCfg()
    task.observations = {"actor": ObsGroupCfg(terms=["gyro", "goal_command", *terms])}
    return task


@pytest.fixture(scope="module")
def scene() -> Scene:
    return _scene()


@pytest.fixture(scope="module")
def truth(scene) -> ScenePerception:
    """The env's ground-truth maps of the scene (one env)."""
    task = _task([])
    return ScenePerception(task.perception, SceneSet([scene], [scene_fields(scene, None, None)], num_envs=1), "cpu")


def _runtime(scene: Scene, setting: LiveSettingCfg) -> Runtime:
    spec = PolicySpec("hold", _task(["elevation_map", "voxel_grid"]), obs_groups=["actor"])
    return Runtime(scene, spec, deploy_cfg(setting, seed=0))


def _compare(rt: Runtime, truth: ScenePerception) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(live, true) elevation maps and (live, true) voxel grids below the map top, over POSES."""
    live_e, true_e, live_v, true_v = [], [], [], []
    low = voxel_points(rt.task.perception.voxel_grid)[:, 2] < MAP_TOP
    for xy, yaw in POSES:
        rt.reset(start_xy=xy, yaw=yaw)
        st = rt.state
        live_e.append(elevation_map(rt)), live_v.append(voxel_grid(rt)[:, low])
        (
            true_e.append(torch.cat(truth.elevation(st.root_pos, st.yaw), -1)),
            true_v.append(truth.voxels(st.root_pos, st.yaw)[:, low]),
        )
    return tuple(torch.cat(x).numpy() for x in (live_e, true_e, live_v, true_v))


def _scan_everywhere(rt: Runtime) -> None:
    for xy, _ in POSES:
        for yaw in (0.0, 0.5 * math.pi, math.pi, -0.5 * math.pi):
            rt.reset(start_xy=xy, yaw=yaw)
            rt.perception.cycle(rt.snapshot())


def test_map_holding_the_scene_gives_the_ground_truth_block(scene, truth):
    """The live block is the ground-truth term's geometry: with the map holding the scene's occupancy, the runtime's
    elevation_map / voxel_grid terms equal the env's at every pose (different frames, yaws, map lattice)."""
    rt = _runtime(scene, LiveSettingCfg())
    assert rt.reads_maps and not rt.reads_field
    rt.perception.map.load_occupancy(scene.occupancy(), scene.grid())
    rt.perception.cycle(rt.snapshot(), scan=False)
    rt.perception.publish(float("inf"))  # past its latency
    live_e, true_e, live_v, true_v = _compare(rt, truth)
    assert (true_e[:, : true_e.shape[1] // 2] > 0).any() and (true_v > 0).sum() > 20  # the poses see obstacles
    np.testing.assert_array_equal(live_e, true_e)
    np.testing.assert_array_equal(live_v, true_v)


def _layer_agreement(rt: Runtime, live_e: np.ndarray, true_e: np.ndarray) -> tuple[float, float, float]:
    """(ground cells within 0.04 m, seen overhead cells within 0.04 m of the truth in their 3x3 neighbourhood,
    overhead cells seen) of elevation maps (poses, 2 * cells)."""
    nx, ny = map_shape(rt.task.perception.height_map)
    cap = rt.task.perception.height_map.overhead_cap
    p = nx * ny
    ground = np.abs(live_e[:, :p] - true_e[:, :p]) <= 0.04 + 1e-6
    lo = ndimage.minimum_filter(true_e[:, p:].reshape(-1, nx, ny), size=(1, 3, 3), mode="nearest").reshape(-1, p)
    hi = ndimage.maximum_filter(true_e[:, p:].reshape(-1, nx, ny), size=(1, 3, 3), mode="nearest").reshape(-1, p)
    over = live_e[:, p:]
    seen = over < cap
    near = (over >= lo - 0.04 - 1e-6) & (over <= hi + 0.04 + 1e-6)
    return float(ground.mean()), float(near[seen].mean()), float(seen.sum() / max((true_e[:, p:] < cap).sum(), 1))


def test_noiseless_lidar_maps_the_scene_and_noise_degrades_it(scene, truth):
    """A head LiDAR sees surfaces, and upwards only to +7 deg: the ground layer is mapped, a ceiling's underside
    only near its edges (the rest reads 'nothing overhead' until seen), the voxel grid holds shells."""
    rt = _runtime(scene, LiveSettingCfg(range_noise=0.0, dropout=0.0, latency_s=0.0))
    _scan_everywhere(rt)
    live_e, true_e, live_v, true_v = _compare(rt, truth)
    ground, over, seen = _layer_agreement(rt, live_e, true_e)
    assert ground >= 0.97 and over >= 0.9 and seen > 0.05, (ground, over, seen)
    both = (live_v * true_v).sum()
    assert both / ((live_v + true_v) > 0).sum() >= 0.3  # IoU: shells, not solids
    assert both / live_v.sum() >= 0.8  # what it marks is mostly there (one voxel outward at the faces)
    assert not rt.perception.update_times  # no field was built: the policy reads none

    noisy = _runtime(scene, load_setting("default"))
    _scan_everywhere(noisy)
    noisy.perception.publish(float("inf"))
    ground_n, _, _ = _layer_agreement(noisy, *_compare(noisy, truth)[:2])
    assert 0.9 <= ground_n <= ground + 1e-9, ground_n


def test_live_block_before_any_map_is_free_space(scene):
    rt = _runtime(scene, LiveSettingCfg())
    ground, over = torch.chunk(elevation_map(rt), 2, dim=-1)
    assert (ground == 0).all() and (over == rt.task.perception.height_map.overhead_cap).all()
    assert (voxel_grid(rt) == 0).all()


def test_latency_and_odometry_drift(scene):
    """A cycle's map reaches the policy latency_s of robot time after its scan; the odometry error is a random walk
    from zero at each reset (std sigma sqrt(t)), and it moves the robot's own pose estimate."""
    rt = _runtime(scene, LiveSettingCfg(latency_s=0.2, odom_drift_xy=0.05, odom_drift_yaw=0.02))
    rt.perception.cycle(rt.snapshot())
    assert rt.perception.latest_map is None
    errors = []
    for _ in range(30):  # 0.6 s on the gantry (no goal: physics paused, the clock and the drift run)
        rt.step()
        if rt.perception.latest_map is None:
            assert rt.sim_time < 0.2 + 1e-9
        est = rt.estimate()
        errors.append(np.linalg.norm(est.root_pos[:2] - rt.data.qpos[:2]))
    assert rt.perception.latest_map is not None
    assert 0.0 < errors[-1] < 0.5 and len(set(errors)) > 1
    rt.reset()
    assert np.allclose(rt.estimate().root_pos[:2], rt.data.qpos[:2])


def test_a_block_the_live_pipeline_cannot_build_is_refused_by_name():
    cfg = TrainCfg()
    cfg.task.observations["actor"].terms.append("base_lin_vel")  # privileged: no robot measures it
    with pytest.raises(ManifestError, match=r"perception=lidar cannot score it.*base_lin_vel"):
        check_live(MethodRun("Priv", 0, "x/model_1.pt", cfg))
    with pytest.raises(ValueError, match="known: default, harsh"):
        load_setting("gentle")


def _eval_table():
    spec = importlib.util.spec_from_file_location("eval_table", REPO / "scripts" / "eval_table.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _rows_of(path: Path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


def _rows(folder: Path) -> list[dict]:
    return _rows_of(folder / "trials.csv")


def test_eval_table_scores_a_shipped_policy_through_perception(tmp_path, monkeypatch, caplog):
    """One trial of the shipped 5-group generalist (HumanoidPF at the odometry pose) through LiDAR -> map -> field
    under both settings: the same trial (scene, start, yaw, goal), scored, the setting named in the table."""
    monkeypatch.chdir(REPO)
    man = tmp_path / "m.yaml"
    man.write_text(
        yaml.safe_dump(
            {
                "methods": {"G5": ["checkpoints/generalist5/model_607.pt"]},
                "table3": {"scene_seed": 0, "variants": 1, "kinds": ["hurdle-crouch"]},
            }
        )
    )
    script = _eval_table()
    trials = {}
    for setting in ("default", "harsh"):
        out = tmp_path / setting
        args = [f"manifest={man}", f"out={out}", "trials_per_scene=1", "perception=lidar"]
        assert script.main([*args, f"perception_setting={setting}"]) == 0
        (row,) = _rows(out)
        assert row["table"] == "table3" and row["group"] == "hurdle-crouch" and row["success"] in ("0", "1")
        assert 0.0 <= float(row["de"]) < 3.0
        assert f"setting '{setting}'" in (out / "table3.md").read_text()
        trials[setting] = {k: row[k] for k in ("scene", "goal", "start", "start_x", "start_y", "start_yaw")}
    assert trials["default"] == trials["harsh"]
    caplog.clear()
    with caplog.at_level(logging.ERROR):
        assert script.main([f"manifest={man}", f"out={tmp_path / 'bad'}", "perception=lidr"]) == 2
        assert (
            script.main([f"manifest={man}", f"out={tmp_path / 'bad'}", "perception=lidar", "perception_setting=x"]) == 2
        )
    errors = " ".join(r.getMessage() for r in caplog.records)
    assert "perception must be ground_truth or lidar" in errors and "perception setting 'x'" in errors
    assert not (tmp_path / "bad").exists()


def test_table3_recipe_differs_only_in_the_exteroceptive_block(tmp_path):
    """experiment=table3: three students of the same four teachers, budget, seeds and network; their configs equal
    generalist5's groups but for the student block; every table scores 4 types x >= 50 trials per cell, at the
    ground truth and both perception settings."""
    from cat.experiment.plan import Plan
    from cat.experiment.spec import check_equal_budget, load_experiment
    from cat.learning.hydra_cfg import load_config
    from cat.run.config_file import load_run_config

    exp = load_experiment("table3")
    plan = Plan(exp, str(tmp_path))
    shipped = load_run_config(REPO / "checkpoints" / "generalist5" / "model_607.pt")
    blocks = {}
    for name, cell in exp.cells.items():
        unit = plan.units[f"{name}@0"]
        cfg = load_config(unit.base)
        obs = cfg.task.observations
        for group in ("student_proprio", "teacher", "route"):
            assert obs[group] == shipped.task.observations[group], (name, group)
        assert obs["student"].terms[0] == "goal_command" and len(obs["student"].terms) == 2
        blocks[name] = obs["student"].terms[1]
        assert cfg.task.noise == shipped.task.noise and cfg.algo.distill == shipped.algo.distill, name
        assert len(cell.teachers) == 4 and all((REPO / t).is_file() for t in cell.teachers)
        assert unit.iterations == plan.units["field@0"].iterations
    assert blocks == {"field": "field_block_odometry", "voxel": "voxel_grid", "elevation": "elevation_map"}
    settings = set()
    for table in exp.tables.values():
        check_equal_budget(exp, table)
        assert table.table3 is not None and table.trials_per_scene * table.table3.get("variants", 10) >= 50
        settings.add((table.perception, table.perception_setting))
    assert {("lidar", "default"), ("lidar", "harsh")} <= settings


def test_perception_sweep_scores_each_level_and_plots(tmp_path, monkeypatch, caplog):
    """scripts/perception_sweep.py: one row per (axis, level, method) on the same trials, the plot written; a bad
    axis refused by name, nothing written."""
    monkeypatch.chdir(REPO)
    man = tmp_path / "m.yaml"
    man.write_text(yaml.safe_dump({"methods": {"Hold": ["hold"]}, "table3": {"variants": 1, "kinds": ["crouch-pass"]}}))
    sweep = tmp_path / "s.yaml"
    sweep.write_text(yaml.safe_dump({"base": "default", "axes": {"dropout": [0.0, 0.5]}}))
    spec = importlib.util.spec_from_file_location("perception_sweep", REPO / "scripts" / "perception_sweep.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = tmp_path / "out"
    assert script.main([f"manifest={man}", f"out={out}", f"sweep={sweep}", "time_s=0.5"]) == 0
    rows = _rows_of(out / "sweep.csv")
    assert [(r["axis"], r["level"], r["method"], r["trials"]) for r in rows] == [
        ("dropout", "0", "Hold", "1"),
        ("dropout", "0.5", "Hold", "1"),
    ]
    assert (out / "perception_sweep.png").stat().st_size > 0
    # a rerun on the same out plays only the levels not kept (a sweep is resumable); a changed window replays all
    assert len(list((out / "levels").glob("*.csv"))) == 2
    sweep.write_text(yaml.safe_dump({"base": "default", "axes": {"dropout": [0.0, 0.5, 0.25]}}))
    caplog.clear()
    with caplog.at_level(logging.INFO):
        assert script.main([f"manifest={man}", f"out={out}", f"sweep={sweep}", "time_s=0.5"]) == 0
    kept = [r.getMessage() for r in caplog.records if "kept from a previous sitting" in r.getMessage()]
    assert len(kept) == 2 and _rows_of(out / "sweep.csv")[:2] == rows
    assert [r["level"] for r in _rows_of(out / "sweep.csv")] == ["0", "0.5", "0.25"]
    caplog.clear()
    with caplog.at_level(logging.INFO):
        assert script.main([f"manifest={man}", f"out={out}", f"sweep={sweep}", "time_s=0.4"]) == 0
    assert not [r for r in caplog.records if "kept from a previous sitting" in r.getMessage()]
    # a level whose setting equals one kept under another axis (the base setting's) is read from it
    sweep.write_text(yaml.safe_dump({"base": "default", "axes": {"dropout": [0.05], "latency_s": [0.1]}}))
    caplog.clear()
    with caplog.at_level(logging.INFO):
        assert script.main([f"manifest={man}", f"out={out}", f"sweep={sweep}", "time_s=0.4"]) == 0
    kept = [r.getMessage() for r in caplog.records if "kept from a previous sitting" in r.getMessage()]
    both = _rows_of(out / "sweep.csv")
    assert len(kept) == 1 and [(r["axis"], r["level"]) for r in both] == [("dropout", "0.05"), ("latency_s", "0.1")]
    assert both[0]["sr"] == both[1]["sr"] and both[0]["de"] == both[1]["de"]
    sweep.write_text(yaml.safe_dump({"axes": {"droput": [0.1]}}))
    caplog.clear()
    with caplog.at_level(logging.ERROR):
        assert script.main([f"manifest={man}", f"out={tmp_path / 'bad'}", f"sweep={sweep}"]) == 2
    assert "unknown axis 'droput'" in " ".join(r.getMessage() for r in caplog.records)
    assert not (tmp_path / "bad").exists()


def test_parallel_workers_give_the_same_trials(tmp_path, monkeypatch):
    """live_workers=2 shares the scenes out to two processes; every trial's result is the one of live_workers=1."""
    monkeypatch.chdir(REPO)
    man = tmp_path / "m.yaml"
    man.write_text(yaml.safe_dump({"methods": {"Hold": ["hold"]}, "table3": {"variants": 2, "kinds": ["crouch-pass"]}}))
    script = _eval_table()
    csvs = []
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        args = [f"manifest={man}", f"out={out}", "trials_per_scene=1", "time_s=1.0", "perception=lidar"]
        args.append(f"live_workers={workers}")
        assert script.main(args) == 0
        csvs.append((out / "trials.csv").read_text())
    assert csvs[0] == csvs[1] and len(_rows(tmp_path / "w1")) == 2
