"""The first-contact body of each trial (``cat.eval.contacts``) on real MuJoCo contacts."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cat.envs.config import EnvCfg, NoiseCfg
from cat.eval.contacts import FirstContacts, contact_line
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
    rec = FirstContacts(env)
    trials = [free, on_bar, free]  # two batches; the second leaves world 1 idle (and still on the bar)
    results = run_trials(env, HoldPolicy(env.num_actions), trials, on_step=rec.on_step)
    first = rec.first_bodies(len(trials))
    assert [r.collided for r in results] == [False, True, False]
    assert first[0] is None and first[2] is None
    assert first[1] is not None and "ankle_roll_link" in first[1], first[1]
    assert contact_line(first) == f"first_contact={first[1]}:1 trials_with_contact=1/3"
    with pytest.raises(ValueError, match="fewer than the 5 trials"):
        rec.first_bodies(5)


@pytest.mark.parametrize("option", ["contacts", "mirror"])
def test_scene_options_on_a_flat_run_fail_before_anything_is_built(option):
    """A flat-ground run has no obstacles to touch or mirror: one clear error, raised before the env is built."""
    from pathlib import Path

    from cat.learning.play import PlayCfg, play_trials

    flat = Path(__file__).resolve().parents[1] / "checkpoints" / "flat" / "model_770.pt"
    with pytest.raises(ValueError, match=f"{option}=true needs obstacle scenes; this run trained on flat ground"):
        play_trials(PlayCfg(checkpoint=str(flat), episodes=2, **{option: True}))
