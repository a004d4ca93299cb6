"""When each trial fell and how far along (``cat.eval.falls``), on real MuJoCo physics."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from cat.envs.config import EnvCfg, NoiseCfg
from cat.envs.trial_metrics import TrialResult
from cat.eval.falls import Falls, falls_line
from cat.eval.runner import EvalCfg, HoldPolicy, make_eval_env, run_trials
from cat.eval.trials import Trial


def test_falls_times_the_collapse_of_a_policy_that_throws_its_joints_and_not_the_standing_one():
    opts = EvalCfg(success=replace(EvalCfg().success, time_s=0.5))
    env = make_eval_env(EnvCfg(num_envs=2, noise=NoiseCfg(enabled=False)), None, 2, opts)
    hold = HoldPolicy(env.num_actions)

    def policy(obs):
        a = hold(obs)
        a[1] = 4.0  # world 1: every joint target far off the default pose
        return a

    trial = Trial(scene=0, goal=0, start=0, start_xy=(0.0, 0.0), yaw=0.0, goal_xyz=(2.0, 0.0, 0.0))
    falls = Falls(env)
    results = run_trials(env, policy, [trial, trial, trial], on_step=falls.on_step)  # the third: world 0 again
    records = falls.records(3)
    assert [r.fell for r in results] == [False, True, False]
    assert records[0][0] == math.inf and math.isnan(records[0][1]) and records[0][2] is False
    t, progress, touched = records[1]
    assert 0.0 < t <= 0.5 and abs(progress) < 0.2 and touched is False  # collapses where it stands, on flat ground
    assert falls_line(results, records) == f"falls=1/3 fall_time_s={t:.2f}/{t:.2f}/{t:.2f} " + (
        f"fall_progress_median={progress:.2f} falls_without_contact=1"
    )
    with pytest.raises(ValueError, match="fewer than the 5 trials"):
        falls.records(5)


def test_falls_line_without_falls_and_with_a_touch_first():
    results = [TrialResult(True, 0.02, False, False, 2.0), TrialResult(False, 1.0, True, True, math.inf)]
    assert falls_line(results[:1], [(math.inf, math.nan, False)]) == "falls=0/1"
    line = falls_line(results, [(math.inf, math.nan, False), (2.5, 0.6, True)])
    assert line == "falls=1/2 fall_time_s=2.50/2.50/2.50 fall_progress_median=0.60 falls_without_contact=0"


def test_play_reports_the_fall_record_of_every_trial():
    from pathlib import Path

    from cat.learning.play import PlayCfg, play_trials

    flat = Path(__file__).resolve().parents[1] / "checkpoints" / "flat" / "model_770.pt"
    played = play_trials(PlayCfg(checkpoint=str(flat), episodes=3, num_envs=2, falls=True))
    assert played.falls is not None and len(played.falls) == 3
    for result, (t, _, _) in zip(played.results, played.falls, strict=True):
        assert result.fell == math.isfinite(t)
