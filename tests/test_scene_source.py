"""One scene source (cat.envs.scene_source): training, evaluation and the demo read a task's scenes the same way."""

from __future__ import annotations

import copy
from dataclasses import replace
from pathlib import Path

import pytest
import trimesh

from cat.deploy.scenes import load_scene
from cat.envs.config import EnvCfg
from cat.envs.scene_source import (
    SceneSource,
    check_scene_task,
    eval_scene_source,
    scene_set_for,
    scene_source,
    typical_kind_or_none,
)
from cat.eval.runner import run_scene_group
from cat.run.config_file import load_run_config
from cat.terrain import Graded, Scene, typical_variants, warmup_variants

REPO = Path(__file__).resolve().parents[1]
SHIPPED = sorted(p.parent for p in (REPO / "checkpoints").glob("*/config.yaml"))


def _task(**kw) -> EnvCfg:
    task = EnvCfg()
    for k, v in kw.items():
        setattr(task, k, v)
    return task


def _save(folder: Path, kind: str, difficulty: float) -> None:
    box = trimesh.creation.box((0.3, 0.3, 0.3))
    box.apply_translation((1.0, 0.0, 0.15))
    s = Scene(box, [[-1, -1, 0], [2, 1, 1.5]], start=(0, 0), goals=[(1.8, 0)], kind=kind, difficulty=difficulty)
    s.save(folder)


def test_flat_ground_has_no_scenes():
    assert scene_source(EnvCfg()) is None
    assert scene_set_for(EnvCfg(), 2) is None
    assert eval_scene_source(EnvCfg()) is None


def test_typical_training_scenes_with_warmups_and_mirrors():
    task = _task(scene_kind="hurdle_crouch", scene_variants=1, scene_seed=3, warmup_variants=1, mirror_scenes=True)
    src = scene_source(task)
    assert src == SceneSource(("hurdle-crouch",), variants=1, seed=3, warmup=1, mirror=True, episodes=task.episodes)
    assert task.scene_kind == "hurdle_crouch"  # the checks do not change the config
    ss = scene_set_for(task, 4, per_world=True)
    want = warmup_variants("hurdle-crouch", 1, 3) + typical_variants("hurdle-crouch", 1, 3)
    assert len(ss.scenes) == 4 and ss.per_world  # each scene then its mirror image
    assert [float(s.difficulty) for s in ss.scenes[::2]] == [float(s.difficulty) for s in want]
    assert ss.episode_cfg == task.episodes


def test_the_run_chooses_the_bank_storage(tmp_path):
    """sim.field_storage reaches the training bank (a typical set and a folder); a bad value is one clear error."""
    from cat.learning.hydra_cfg import load_config

    task = _task(scene_kind="crouch_pass", scene_variants=1)
    assert scene_set_for(task, 2).bank.storage.goal.itemsize == 4  # default: float32, what every run used
    ss = scene_set_for(task, 2, storage="compact")
    assert ss.bank.dtype_name == "compact" and ss.bank.goal_data.dtype.itemsize == 1
    _save(tmp_path / "indoor" / "a", "indoor", 0.2)
    assert scene_set_for(_task(scene_dir=str(tmp_path)), 2, storage="float16").bank.dtype_name == "float16"
    assert load_config(["sim.field_storage=compact"]).sim.field_storage == "compact"
    with pytest.raises(Exception, match="sim.field_storage='int4'; valid: float32, float16, compact"):
        load_config(["sim.field_storage=int4"])


def test_scene_groups_win_over_scene_kind():
    task = _task(scene_kind="side-pass", scene_groups=["crouch_pass", "side-pass"], scene_variants=2)
    src = scene_source(task)
    assert src.typical == ("crouch-pass", "side-pass") and src.variants == 2


def test_a_scene_folder_by_kind_and_data_group(tmp_path):
    _save(tmp_path / "indoor" / "a", "indoor", 0.2)
    _save(tmp_path / "procedural" / "b", "procedural", 0.9)
    task = _task(scene_dir=str(tmp_path), data="base")  # base: the indoor crops only
    ss = scene_set_for(task, 2)
    assert [s.kind for s in ss.scenes] == ["indoor"] and not ss.per_world
    assert [s.kind for s in scene_set_for(_task(scene_dir=str(tmp_path), scene_kind="procedural"), 2).scenes] == [
        "procedural"
    ]
    # evaluation reads the folder by kind and plays every data group (trials, not training episodes)
    assert eval_scene_source(task) == SceneSource(scene_dir=str(tmp_path))
    assert [s.kind for s in run_scene_group(task).scenes] == ["indoor", "procedural"]
    group = run_scene_group(_task(scene_dir=str(tmp_path), scene_kind="procedural"))
    assert group.name == "procedural" and group.scene_names == ["procedural/b"]


def test_a_folder_of_links_plays_as_it_trains(tmp_path):
    _save(tmp_path / "real" / "a", "indoor", 0.2)
    (tmp_path / "links").mkdir()
    (tmp_path / "links" / "a").symlink_to(tmp_path / "real" / "a")
    task = _task(scene_dir=str(tmp_path / "links"))
    assert [s.kind for s in scene_set_for(task, 1).scenes] == ["indoor"]
    assert run_scene_group(task).scene_names == ["a"]


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(scene_kind="stairs"), r"task.scene_kind \(without task.scene_dir\)='stairs' is not a typical kind"),
        (dict(scene_groups=["side-pass", "stairs"]), "task.scene_groups entry='stairs' is not a typical kind"),
        (dict(scene_groups=["side-pass"], scene_dir="x"), "scene_groups builds typical scenes"),
        (dict(scene_kind="side-pass", data="base"), "task.data='base' selects from a hybrid scene folder"),
        (dict(scene_dir="x", data="nope"), "nope"),
        (dict(scene_dir="x", warmup_variants=2), "warmup_variants builds typical scenes"),
        (dict(scene_kind="side-pass", warmup_variants=-1), "must be >= 0"),
        (dict(scene_kind="side-pass", warmup_variants=2, warmup_bar_pitch=True), "grades multi-hurdle's warm-ups"),
        (dict(scene_kind="multi-hurdle", warmup_bar_pitch=True), "task.warmup_variants > 0"),
        (dict(scene_kind="multi-hurdle", warmup_variants=2, warmup_bars=3), "needs task.warmup_bar_pitch=true"),
        (dict(scene_kind="side-pass", warmup_variants=2, warmup_slit_offset=True), "grades side-hurdle's warm-ups"),
        (dict(scene_kind="side-hurdle", warmup_slit_offset=True), "task.warmup_variants > 0"),
        (
            dict(scene_kind="crouch-pass", warmup_variants=2, warmup_slit_narrow=True),
            "grades side-hurdle-crouch, side-hurdle or side-pass's warm-ups",
        ),
        (
            dict(scene_kind="side-hurdle", warmup_variants=2, warmup_slit_narrow=True, warmup_slit_offset=True),
            "task.warmup_slit_offset and task.warmup_slit_narrow both grade side-hurdle's warm-up slit",
        ),
        (
            dict(scene_kind="side-crouch", warmup_variants=2, warmup_slit_tight=True),
            "task.warmup_slit_tight grades side-hurdle-crouch, side-hurdle or side-pass's warm-ups",
        ),
        (dict(scene_kind="multi-hurdle", warmup_variants=2, warmup_bar_pitch=True, warmup_bars=4), "holds 2 bars"),
    ],
)
def test_bad_scene_keys_are_refused_everywhere(kw, match):
    task = _task(**kw)
    for check in (check_scene_task, scene_source, lambda t: scene_set_for(t, 2)):
        with pytest.raises(ValueError, match=match):
            check(task)


def test_evaluation_overrides_and_warmup_scenes():
    task = _task(scene_kind="hurdle-crouch", scene_variants=2, scene_seed=4, warmup_variants=3)
    assert eval_scene_source(task) == SceneSource(("hurdle-crouch",), variants=2, seed=4)
    assert eval_scene_source(task, scene_seed=9).seed == 9
    assert eval_scene_source(task, warmup=True) == SceneSource(("hurdle-crouch",), variants=0, seed=4, warmup=3)
    group = run_scene_group(_task(scene_kind="side-pass", scene_variants=1, warmup_variants=1), warmup=True)
    assert group.name == "side-pass_warmup" and float(group.scenes[0].difficulty) < 0
    gen = _task(scene_groups=["crouch-pass", "side-pass"], scene_variants=2)
    before = copy.deepcopy(gen)
    assert eval_scene_source(gen, scene_kind="side_pass").typical == ("side-pass",)
    assert gen == before


def test_the_demo_reads_typical_kinds_as_the_task_does():
    assert typical_kind_or_none("hurdle_crouch") == "hurdle-crouch" and typical_kind_or_none("stairs") is None
    assert load_scene("side_pass").kind == "side-pass"


@pytest.mark.skipif(not SHIPPED, reason="no checkpoints/ in this tree")
@pytest.mark.parametrize("run", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_runs_name_the_scenes_their_config_says(run):
    task = load_run_config(next(run.glob("model_*.pt"))).task
    src = scene_source(task)
    if not (task.scene_dir or task.scene_kind or task.scene_groups):
        assert src is None
        return
    assert src.mirror == task.mirror_scenes and src.episodes == task.episodes
    if task.scene_dir:
        assert (src.scene_dir, src.kind, src.data) == (task.scene_dir, task.scene_kind or None, task.data)
    else:
        kinds = tuple(task.scene_groups) or (task.scene_kind,)
        assert (src.typical, src.variants, src.seed, src.warmup) == (
            kinds,
            task.scene_variants,
            task.scene_seed,
            task.warmup_variants,
        )


def test_graded_bar_pitch_reaches_training_and_the_warmup_diagnostic():
    """``task.warmup_bar_pitch``: the training scene set and ``warmup=true`` build the same graded warm-ups;
    the diagnostic refuses it for a kind it does not grade."""
    task = _task(scene_kind="multi-hurdle", scene_variants=1, warmup_variants=2, warmup_bar_pitch=True)
    source = eval_scene_source(task, warmup=True)
    assert source == SceneSource(("multi-hurdle",), variants=0, seed=0, warmup=2, warmup_graded=Graded(bars=2))
    trained = [s for s in scene_set_for(task, 2).scenes if s.difficulty < 0]
    played = run_scene_group(task, warmup=True).scenes
    assert [s.mesh.bounds.tolist() for s in trained] == [s.mesh.bounds.tolist() for s in played]
    random = run_scene_group(_task(scene_kind="multi-hurdle", scene_variants=1, warmup_variants=2), warmup=True)
    assert [s.mesh.bounds.tolist() for s in random.scenes] != [s.mesh.bounds.tolist() for s in played]
    with pytest.raises(ValueError, match="not 'hurdle-crouch'"):
        eval_scene_source(task, scene_kind="hurdle_crouch", warmup=True)
    three = replace(task, warmup_variants=10, warmup_bars=3)  # task.warmup_bars reaches both as well
    assert eval_scene_source(three, warmup=True).warmup_graded == Graded(bars=3)
    bars = [len(s.meta["layout"]["bar_top"]) for s in scene_set_for(three, 2).scenes if s.difficulty < 0]
    assert bars == [len(s.meta["layout"]["bar_top"]) for s in run_scene_group(three, warmup=True).scenes]
    assert bars[0] == 2 and bars[-1] == 3, bars


def test_graded_slit_offset_reaches_training_and_the_warmup_diagnostic():
    """``task.warmup_slit_offset``: the training scene set and ``warmup=true`` build the same offset-slit warm-ups
    (a generalist's other groups untouched); the diagnostic refuses it for another kind."""
    task = _task(scene_kind="side-hurdle", scene_variants=1, warmup_variants=4, warmup_slit_offset=True)
    assert eval_scene_source(task, warmup=True).warmup_graded == Graded(slit_offset=True)
    trained = [s.meta["layout"] for s in scene_set_for(task, 2).scenes if s.difficulty < 0]
    played = [s.meta["layout"] for s in run_scene_group(task, warmup=True).scenes]
    assert trained == played and abs(played[-1]["slit_y"][0]) > 0.25 and played[0]["slit_gap"][0] < 0.5
    mixed = _task(scene_groups=["side-hurdle", "side-pass"], scene_variants=1, warmup_variants=2)
    plain = [s.meta["layout"] for s in scene_set_for(mixed, 2).scenes if s.kind == "side-pass"]
    graded = replace(mixed, warmup_slit_offset=True)
    assert plain == [s.meta["layout"] for s in scene_set_for(graded, 2).scenes if s.kind == "side-pass"]
    with pytest.raises(ValueError, match="not 'side-pass'"):
        eval_scene_source(replace(task, scene_kind="side-pass"), warmup=True)
