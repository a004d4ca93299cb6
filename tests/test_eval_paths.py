"""Each trial's root path (``cat.eval.paths``) on real MuJoCo rollouts, and ``play.py paths=``."""

from __future__ import annotations

import csv
import math
from dataclasses import replace

import numpy as np
import pytest

from cat.envs.config import EnvCfg, NoiseCfg
from cat.eval.paths import COLUMNS, Paths, write_paths
from cat.eval.runner import EvalCfg, HoldPolicy, SceneGroup, make_eval_env, run_trials
from cat.eval.trials import Trial


@pytest.mark.parametrize("per_world", [False, True])
def test_paths_start_at_each_trials_pose_in_its_scene_frame_and_flag_the_touch(tmp_path, per_world):
    """Two scenes, tiled side by side in one world or one per world: each path starts at its trial's start and yaw
    in its own scene's frame, the trial placed astride the bar is touched from the first steps, the free one never."""
    group = SceneGroup.typical("hurdle-pass", 2, 0)
    v = np.asarray(group.scenes[1].mesh.vertices)
    bar = v[(v[:, 2] > 1e-3) & (v[:, 2] < 0.4)]  # the corridor's boxes have no vertex between floor and top
    xc = 0.5 * (bar[:, 0].min() + bar[:, 0].max())
    goal = tuple(float(c) for c in group.scenes[0].goals[0])
    free = Trial(scene=0, goal=0, start=0, start_xy=(-0.1, 0.2), yaw=0.5, goal_xyz=goal)
    on_bar = replace(free, scene=1, start=1, start_xy=(float(xc), 0.0), yaw=-0.3)
    opts = EvalCfg(success=replace(EvalCfg().success, time_s=0.3), per_world_scenes=per_world)
    task = EnvCfg(num_envs=2, scene_kind="hurdle-pass", scene_variants=2, noise=NoiseCfg(enabled=False))
    env = make_eval_env(task, group, 2, opts)
    apart = np.abs(env.scenes.offsets[1] - env.scenes.offsets[0]).max()
    assert apart > 1.0 if not per_world else apart == 0.0
    rec = Paths(env)
    trials = [free, on_bar, free]  # two batches; the second leaves world 1 idle
    results = run_trials(env, HoldPolicy(env.num_actions), trials, on_step=rec.on_step)
    paths = rec.paths(len(trials))
    steps = env.trial.window
    for t, p in zip(trials, paths, strict=True):
        assert p.shape == (steps + 1, 6)
        assert np.allclose(p[0, :2].numpy(), t.start_xy, atol=1e-4), (p[0, :2], t.start_xy)
        assert math.isclose(float(p[0, 3]), t.yaw, abs_tol=1e-3)
    assert paths[1][:, 4].max() == 1.0 and paths[1][-1, 4] == 1.0  # touched, and stays so
    assert paths[0][:, 4].max() == 0.0 and paths[2][:, 4].max() == 0.0
    with pytest.raises(ValueError, match="fewer than the 5 trials"):
        rec.paths(5)

    out = write_paths(tmp_path / "paths.csv", trials, results, paths, env.dt)
    rows = list(csv.DictReader(out.open()))
    assert tuple(rows[0]) == COLUMNS and len(rows) == 3 * (steps + 1)
    assert {r["scene"] for r in rows if r["trial"] == "1"} == {"1"}
    last = [r for r in rows if r["trial"] == "1"][-1]
    assert int(last["step"]) == steps and math.isclose(float(last["time_s"]), steps * env.dt, abs_tol=1e-3)
    assert last["touched"] == "1" and last["success"] == str(int(results[1].success))
    assert not list(tmp_path.glob("*.part"))
    with pytest.raises(ValueError, match="does not exist"):
        write_paths(tmp_path / "no" / "paths.csv", trials, results, paths, env.dt)
    with pytest.raises(ValueError, match="must be equal"):
        write_paths(tmp_path / "p.csv", trials[:2], results, paths, env.dt)


def test_play_paths_into_a_missing_folder_fails_before_anything_is_built(tmp_path):
    from pathlib import Path

    from cat.learning.play import PlayCfg, play_trials

    flat = Path(__file__).resolve().parents[1] / "checkpoints" / "flat" / "model_770.pt"
    with pytest.raises(ValueError, match=r"paths=.*: folder .* does not exist"):
        play_trials(PlayCfg(checkpoint=str(flat), episodes=2, paths=str(tmp_path / "missing" / "p.csv")))
