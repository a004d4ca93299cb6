"""The first-contact body of each trial (``cat.eval.contacts``) on real MuJoCo contacts."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cat.envs.config import EnvCfg, NoiseCfg
from cat.eval.contacts import Clearance, FirstContacts, clearance_line, contact_line, tolerant_success
from cat.eval.runner import EvalCfg, HoldPolicy, SceneGroup, make_eval_env, run_trials
from cat.eval.trials import Trial


def test_first_contact_names_the_feet_standing_on_a_bar_and_none_in_free_space():
    group = SceneGroup.typical("hurdle-pass", 1, 0)
    v = np.asarray(group.scenes[0].mesh.vertices)
    bar = v[(v[:, 2] > 1e-3) & (v[:, 2] < 0.4)]  # the corridor's boxes have no vertex between floor and top
    xc = 0.5 * (bar[:, 0].min() + bar[:, 0].max())
    goal = tuple(float(c) for c in group.scenes[0].goals[0])
    free = Trial(scene=0, goal=0, start=0, start_xy=(0.0, 0.0), yaw=0.0, goal_xyz=goal)
    on_bar = replace(free, start=1, start_xy=(float(xc), 0.0))  # feet straddle the bar's axis
    opts = EvalCfg(success=replace(EvalCfg().success, time_s=0.3))
    env = make_eval_env(EnvCfg(num_envs=2, scene_kind="hurdle-pass", noise=NoiseCfg(enabled=False)), group, 2, opts)
    rec, depth = FirstContacts(env), Clearance(env)
    trials = [free, on_bar, free]  # two batches; the second leaves world 1 idle (and still on the bar)

    def both(e):
        rec.on_step(e)
        depth.on_step(e)

    results = run_trials(env, HoldPolicy(env.num_actions), trials, on_step=both)
    first = rec.first_bodies(len(trials))
    # the clearance agrees: the feet on the bar are inside it, the free trials keep clear of every obstacle
    clear = depth.clearances(len(trials))
    assert clear[1] < 0.0 < min(clear[0], clear[2]), clear
    with pytest.raises(ValueError, match="fewer than the 5 trials"):
        depth.clearances(5)
    assert [r.collided for r in results] == [False, True, False]
    assert first[0] is None and first[2] is None
    assert first[1] is not None and "ankle_roll_link" in first[1], first[1]
    assert contact_line(first) == f"first_contact={first[1]}:1 trials_with_contact=1/3"
    with pytest.raises(ValueError, match="fewer than the 5 trials"):
        rec.first_bodies(5)


def test_tolerant_success_reads_the_depth_of_each_trials_contacts():
    """Success at a depth tolerance: reached, no fall, no penetration deeper than the tolerance."""
    from cat.envs.trial_metrics import TrialResult

    reached = TrialResult(False, 0.05, True, False, 1.0)  # reached, but touched
    results = [reached, reached, TrialResult(True, 0.02, False, False, 2.0), TrialResult(False, 0.5, True, True, 1.5)]
    clearance = [-0.005, -0.03, 0.2, -0.001]  # 5 mm and 3 cm deep, clear, shallow but fell
    assert tolerant_success(results, clearance, 0.01) == 0.5  # the 5 mm graze counts, the 3 cm one does not
    assert tolerant_success(results, clearance, 0.04) == 0.75
    assert clearance_line(results, clearance) == (
        "tolerant_success=1cm:0.500,2cm:0.500,4cm:0.750 deepest_mm_median=5.0 contact_trials=3"
    )


@pytest.mark.parametrize("option", ["contacts", "mirror", "clearance"])
def test_scene_options_on_a_flat_run_fail_before_anything_is_built(option):
    """A flat-ground run has no obstacles to touch or mirror: one clear error, raised before the env is built."""
    from pathlib import Path

    from cat.learning.play import PlayCfg, play_trials

    flat = Path(__file__).resolve().parents[1] / "checkpoints" / "flat" / "model_770.pt"
    with pytest.raises(ValueError, match=f"{option}=true needs obstacle scenes; this run trained on flat ground"):
        play_trials(PlayCfg(checkpoint=str(flat), episodes=2, **{option: True}))
