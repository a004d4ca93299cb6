"""Difficulty curriculum: promotion / demotion on constructed outcomes, level-respecting scene draws, and its
state surviving a stop/resume of training."""

from __future__ import annotations

import pytest
import torch

from cat.envs.config import EnvCfg
from cat.envs.curriculum import CurriculumCfg, DifficultyCurriculum
from cat.envs.episode_log import episode_log
from cat.envs.scene_set import SceneSet
from cat.envs.traversal_env import TraversalEnv
from cat.eval.runner import run_scene_group
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import validate_train_cfg

DIFF = torch.tensor([0.0, 0.1, 0.5, 0.9, 1.0])  # 5 levels -> scene levels 0, 0, 2, 4, 4


def test_promote_on_success_demote_on_failure():
    cur = DifficultyCurriculum(DIFF, num_envs=3, cfg=CurriculumCfg(num_levels=5))
    assert cur.scene_level.tolist() == [0, 0, 2, 4, 4] and cur.max_level == 4
    ids = torch.tensor([0, 1, 2])
    for _ in range(3):
        cur.update(ids, torch.tensor([True, False, True]))
    assert cur.level.tolist() == [3, 0, 3]  # env 1 is clamped at 0
    cur.update(torch.tensor([2]), torch.tensor([False]))
    assert cur.level.tolist() == [3, 0, 2]
    for _ in range(5):
        cur.update(torch.tensor([0]), torch.tensor([True]))
    assert cur.level[0] == 4  # clamped at the hardest level present
    assert cur.mean_level() == pytest.approx(2.0)


def test_scene_draws_respect_levels():
    cur = DifficultyCurriculum(DIFF, num_envs=600, cfg=CurriculumCfg(num_levels=5))
    cur.level[:200], cur.level[200:400], cur.level[400:] = 0, 3, 4
    picks = cur.pick_scenes(torch.arange(600), torch.Generator().manual_seed(0))
    assert set(picks[:200].tolist()) == {0, 1}  # level 0: both easy scenes
    assert set(picks[200:400].tolist()) == {2}  # level 3 has no scene: the nearest lower level (2)
    assert set(picks[400:].tolist()) == {3, 4}


def test_group_weights_set_each_groups_share_of_a_levels_draws():
    """One typical scene beside three hybrid ones at a level: weights 1 : 1 give it half the draws, not a quarter."""
    d = torch.tensor([0.0, 0.0, 0.0, 0.0, 0.9])
    groups = ["crouch-pass", "indoor", "indoor", "procedural", "indoor"]
    n = 20_000
    uniform = DifficultyCurriculum(d, n, CurriculumCfg(num_levels=5), groups)
    weighted = DifficultyCurriculum(d, n, CurriculumCfg(num_levels=5, group_weights={"crouch-pass": 2.0}), groups)
    share = {}
    for name, cur in (("uniform", uniform), ("weighted", weighted)):
        picks = cur.pick_scenes(torch.arange(n), torch.Generator().manual_seed(0))
        assert set(picks.tolist()) <= {0, 1, 2, 3}  # level 0 only
        share[name] = torch.bincount(picks, minlength=5).double() / n
    assert share["uniform"][0] == pytest.approx(0.25, abs=0.02)
    # crouch-pass : indoor : procedural = 2 : 1 : 1 of the draws; indoor's two scenes split their group's share
    assert share["weighted"][0] == pytest.approx(0.5, abs=0.02)
    assert share["weighted"][1] == pytest.approx(0.125, abs=0.02) and share["weighted"][3] == pytest.approx(
        0.25, abs=0.02
    )
    weighted.level[:] = 4
    assert set(weighted.pick_scenes(torch.arange(100), torch.Generator()).tolist()) == {4}


@pytest.mark.parametrize(
    ("weights", "groups", "message"),
    [
        ({"crouch_pass": 2.0}, ["crouch-pass", "indoor"], r"names \['crouch_pass'\], not a scene group"),
        ({"indoor": 0.0}, ["crouch-pass", "indoor"], r"finite and > 0, got \{'indoor': 0.0\}"),
        ({"indoor": 1.0}, None, "needs each scene's group"),
    ],
)  # fmt: skip
def test_bad_group_weights_are_refused_naming_them(weights, groups, message):
    with pytest.raises(ValueError, match=message):
        DifficultyCurriculum(torch.tensor([0.0, 0.5]), 2, CurriculumCfg(group_weights=weights), groups)


def test_state_round_trip_and_bad_resume():
    cur = DifficultyCurriculum(DIFF, num_envs=4, cfg=CurriculumCfg(num_levels=5, start_level=2))
    assert cur.level.tolist() == [2, 2, 2, 2]
    cur.update(torch.arange(4), torch.tensor([True, True, False, False]))
    other = DifficultyCurriculum(DIFF, num_envs=4, cfg=CurriculumCfg(num_levels=5))
    other.load_state_dict(cur.state_dict())
    assert other.level.tolist() == cur.level.tolist()
    with pytest.raises(ValueError, match="cannot resume a run of 5 envs"):
        DifficultyCurriculum(DIFF, num_envs=5, cfg=CurriculumCfg()).load_state_dict(cur.state_dict())


def test_env_moves_envs_between_scenes_by_level():
    scenes = SceneSet.typical("hurdle-crouch", num_envs=4, variants=2)  # difficulties 0 and 1
    env = TraversalEnv(EnvCfg(num_envs=4, scene_kind="hurdle-crouch"), sim="mujoco", scenes=scenes, seed=1)
    assert env.curriculum is not None and env.curriculum.scene_level.tolist() == [0, 4]
    assert (scenes.scene_of_env == 0).all()  # everyone starts at level 0
    env.curriculum.level[:] = 4
    env.reset_idx(torch.arange(4))
    assert (scenes.scene_of_env == 1).all()
    assert env.training_state()["curriculum"]["level"].tolist() == [4, 4, 4, 4]


def test_env_draws_scenes_by_group_weight():
    """The env hands each scene's group to the curriculum: crouch-pass weighted 3 : 1 gets ~3/4 of the resets."""
    scenes = SceneSet.typical(["hurdle-crouch", "crouch-pass"], num_envs=64, variants=1)  # one level-0 scene each
    cfg = EnvCfg(num_envs=64, scene_kind="typical")
    cfg.curriculum.group_weights = {"crouch-pass": 3.0}
    env = TraversalEnv(cfg, sim="mujoco", scenes=scenes, seed=1)
    counts = torch.zeros(2)
    for _ in range(8):
        env.reset_idx(torch.arange(64))
        counts += torch.bincount(scenes.groups_of_envs(), minlength=2)
    share = counts[scenes.group_names.index("crouch-pass")] / counts.sum()
    assert share == pytest.approx(0.75, abs=0.06)
    cfg.curriculum.group_weights = {"side_pass": 1.0}
    with pytest.raises(ValueError, match=r"names \['side_pass'\], not a scene group of this set"):
        TraversalEnv(cfg, sim="mujoco", scenes=SceneSet.typical("crouch-pass", num_envs=2, variants=1), seed=1)


def test_a_mixed_run_logs_success_per_scene_group():
    """With several scene groups the episode log adds ``Metrics/success_rate/<group>`` (the run is watched on each
    kind of scene); envs of the crouch-pass group that reached their goal count for that group only."""
    scenes = SceneSet.typical(["hurdle-crouch", "crouch-pass"], num_envs=8, variants=1)
    env = TraversalEnv(EnvCfg(num_envs=8, scene_kind="typical"), sim="mujoco", scenes=scenes, seed=1)
    env.reset_idx(torch.arange(8))
    groups = scenes.groups_of_envs()
    crouch = groups == scenes.group_names.index("crouch-pass")
    assert crouch.any() and (~crouch).any()
    env.trial.reach_time[crouch] = 1.0  # reached, no contact, no fall: success
    log = episode_log(env, torch.arange(8))
    assert float(log["Metrics/success_rate/crouch-pass"]) == 1.0
    assert float(log["Metrics/success_rate/hurdle-crouch"]) == 0.0
    assert float(log["Metrics/success_rate"]) == pytest.approx(float(crouch.float().mean()))
    one = TraversalEnv(EnvCfg(num_envs=2, scene_kind="crouch-pass"), sim="mujoco",
                       scenes=SceneSet.typical("crouch-pass", num_envs=2, variants=1), seed=1)  # fmt: skip
    assert not [k for k in episode_log(one, torch.arange(2)) if k.startswith("Metrics/success_rate/")]


def test_warmup_difficulties_take_the_lowest_levels():
    """With warm-up scenes (d in [-1, 0)) the levels are bins of [-1, 1]: warm-ups first, the paper's range after."""
    d = torch.tensor([-1.0, -0.55, -0.1, 0.0, 0.5, 1.0])
    cur = DifficultyCurriculum(d, num_envs=2, cfg=CurriculumCfg(num_levels=4))
    assert cur.scene_level.tolist() == [0, 0, 1, 2, 3, 3]
    assert cur.max_level == 3 and cur.level.tolist() == [0, 0]
    assert cur.log() == {"Curriculum/mean_level": 0.0, "Curriculum/paper_range": 0.0}
    cur.update(torch.tensor([1]), torch.tensor([True]))
    cur.update(torch.tensor([1]), torch.tensor([True]))  # env 1 reaches level 2: the paper's d = 0
    assert cur.log() == {"Curriculum/mean_level": 1.0, "Curriculum/paper_range": 0.5}
    assert "Curriculum/paper_range" not in DifficultyCurriculum(DIFF, 2, CurriculumCfg()).log()  # no warm-ups


def test_warmup_scenes_train_but_are_never_evaluated(tmp_path):
    """``task.warmup_variants`` adds easier scenes to the training set only; evaluation rebuilds the paper's
    variants; a scene dataset refuses the option (it builds typical scenes)."""
    train_set = SceneSet.typical("hurdle-crouch", num_envs=2, variants=1, warmup=2)
    assert sorted(train_set.difficulties.tolist()) == pytest.approx([-1.0, -0.5, 0.5])
    cfg = load_config(["task=hurdle_crouch", "task.warmup_variants=2", "task.scene_variants=3"])
    evaluated = run_scene_group(cfg.task)
    assert [s.difficulty for s in evaluated.scenes] == pytest.approx([0.0, 0.5, 1.0])
    with pytest.raises(ValueError, match="warmup_variants"):
        validate_train_cfg(load_config(["task=hurdle_crouch", f"task.scene_dir={tmp_path}"]))


def test_trials_ignore_how_training_drew_its_scenes():
    """A policy trained with group weights is scored like any other: trials turn the curriculum off and name their
    scenes, so the weights are dropped from the trial env (was: every table of such a run refused to build)."""
    from cat.eval.runner import EvalCfg, eval_task

    cfg = EnvCfg(num_envs=2, scene_kind="typical")
    cfg.curriculum.group_weights = {"crouch-pass": 3.0}
    trial_cfg = eval_task(cfg, 2, EvalCfg())
    scenes = SceneSet.typical(["hurdle-crouch", "crouch-pass"], num_envs=2, variants=1)
    env = TraversalEnv(trial_cfg, sim="mujoco", scenes=scenes, seed=1)
    assert env.curriculum is None and trial_cfg.curriculum.group_weights == {}
    assert cfg.curriculum.group_weights == {"crouch-pass": 3.0}  # the run's own config is untouched
