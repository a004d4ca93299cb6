"""The paper's baselines as one-word methods (``method=``): composition and recording, no reward term reading
HumanoidPF where the paper removes it, the straight-line command, ASTraversal's map clearance reward on an
analytic scene, and every method training for one iteration, loading and playing from its own config.yaml."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from cat.envs.config import EnvCfg
from cat.envs.field_source import FieldSample
from cat.envs.mdp import rewards as rew
from cat.envs.scene_source import graded
from cat.envs.trial_metrics import TrialResult, summarize
from cat.eval.manifest import ManifestError, load_manifest
from cat.eval.runner import run_scene_group
from cat.learning.hydra_cfg import ConfigError, load_config
from cat.learning.play import PlayCfg, play, play_trials, scene_lines, slit_grading_keys
from cat.learning.runs import load_run_config, make_env, resume_config, train
from cat.terrain import Graded
from cat.terrain.typical import make_typical, warmup_variants

METHODS = ("ours", "wo_obs_field", "wo_r_field", "astraversal", "humanoid_parkour")
FIELD_FREE_REWARD = ("wo_r_field", "astraversal", "humanoid_parkour")
TASK = ["task=hurdle_crouch", "task.scene_variants=1", "task.warmup_variants=0", "num_envs=2"]


def test_methods_compose_and_are_recorded():
    got = {m: load_config([f"method={m}"]) for m in METHODS}
    for m, cfg in got.items():
        assert cfg.method == m
    actor = {m: cfg.task.observations["actor"].terms for m, cfg in got.items()}
    assert actor["ours"][-1] == actor["wo_r_field"][-1] == "field_block"
    assert actor["wo_obs_field"][-1] == actor["astraversal"][-1] == "elevation_map"
    assert actor["humanoid_parkour"][-2:] == ["ground_map", "overhead_map"]
    assert all(a[:-1] == actor["ours"][:-1] for m, a in actor.items() if m != "humanoid_parkour")
    for m in FIELD_FREE_REWARD:
        t = got[m].task
        assert t.command.source == "straight" and t.rewards.params.heading_gate == "none"
        assert t.rewards.field_vmf == 0 and t.rewards.sdf_barrier == 0 == t.rewards.foot_sole_barrier
    assert got["wo_r_field"].task.rewards.collision == got["humanoid_parkour"].task.rewards.collision == -20.0
    assert got["astraversal"].task.rewards.map_clearance < 0 and got["astraversal"].task.rewards.collision == -5.0
    assert got["ours"].task == load_config([]).task  # ours is the task as configured
    with pytest.raises(ConfigError, match="unknown method 'astraversl'; valid method options: astraversal, "):
        load_config(["method=astraversl"])


def _reward_terms(env) -> dict[str, torch.Tensor]:
    return {name: getattr(rew, name)(env, **params) for name, (_, params) in env.reward_terms.items()}


@pytest.mark.parametrize("method", METHODS)
def test_which_rewards_read_humanoidpf(method):
    """Rewards recomputed after replacing every field sample (F, d, grad d) by random values: unchanged for the
    methods without R_field, changed for those with it (so the check can fail)."""
    env = make_env(load_config(TASK + [f"method={method}"]))
    env.step(torch.zeros(env.num_envs, env.num_actions))
    before = _reward_terms(env)
    gen = torch.Generator().manual_seed(0)

    def random_field(points, goals, env_ids=None):
        shape = points.shape[:-1]
        return FieldSample(
            force=torch.randn(*shape, 3, generator=gen),
            sdf=0.3 * torch.rand(*shape, generator=gen) - 0.1,
            grad_sdf=torch.randn(*shape, 3, generator=gen),
            outside=torch.zeros(shape[0]),
        )

    env.field_source.sample = random_field
    env._update_field()
    after = _reward_terms(env)
    changed = sorted(k for k in before if not torch.allclose(before[k], after[k]))
    if method in FIELD_FREE_REWARD:
        assert changed == [], changed
    else:
        assert {"field_vmf", "sdf_barrier", "track_velocity"} <= set(changed), changed


def test_straight_command_points_at_the_goal():
    env = make_env(load_config(TASK + ["method=wo_r_field"]))
    env.step(torch.zeros(env.num_envs, env.num_actions))
    to_goal = env.goals[:, :2] - env.state.root_pos[:, :2]
    cos = torch.nn.functional.cosine_similarity(env.command_vel, to_goal, dim=-1)
    assert (cos > 0.9999).all()
    assert torch.allclose(env.command_vel.norm(dim=-1), torch.full((env.num_envs,), env.cfg.command.speed))


def test_map_clearance_on_an_analytic_scene():
    """A typical scene replaced by its elevation layers: one link at a hurdle's top height penalised, the same link
    0.3 m above it not; under a ceiling the head near its underside is penalised; open floor costs nothing."""
    env = make_env(
        load_config(
            [
                "task=hurdle_crouch",
                "task.scene_variants=1",
                "task.warmup_variants=0",
                "num_envs=1",
                "method=astraversal",
            ]
        )
    )
    ground, over = env.perception.layers_at(torch.tensor([[[x, y] for x in np.arange(0, 2, 0.02) for y in [0.0]]]))
    g, o = ground[0].numpy(), over[0].numpy()
    xs = np.arange(0, 2, 0.02)
    assert g.max() > 0.05 and o.min() < 1.3, "the scene has a hurdle and a ceiling on its course"
    x_hurdle, x_ceiling, x_open = xs[g.argmax()], xs[o.argmin()], xs[(g == 0) & (o == o.max())][0]
    links = env.state.link_pos
    weight, params = env.reward_terms["map_clearance"]
    assert weight < 0 and params == {"barrier_margin": 0.05, "barrier_width": 0.02}

    def penalty() -> float:
        return float(rew.map_clearance(env, **params))

    links[:] = torch.tensor([x_open, 0.0, 0.6])  # every link in the open: no penalty
    assert penalty() == 0.0
    links[0, 0] = torch.tensor([x_hurdle, 0.0, float(g.max())])  # one link at the hurdle's top
    at_top = penalty()
    links[0, 0, 2] += 0.3
    assert at_top == pytest.approx(math.log1p(math.exp(0.05 / 0.02)), rel=1e-3)
    assert penalty() < 1e-4
    links[0, 0] = torch.tensor([x_ceiling, 0.0, float(o.min()) - 0.05])  # 5 cm below the underside
    assert penalty() == pytest.approx(math.log(2.0), rel=1e-3)


@pytest.fixture(scope="module")
def method_runs(tmp_path_factory) -> dict[str, Path]:
    """One 1-iteration run per method on a one-variant typical task."""
    root = tmp_path_factory.mktemp("methods")
    out = {}
    for m in METHODS:
        cfg = load_config(
            TASK + [f"method={m}", "max_iterations=1", "algo.num_steps_per_env=4", f"run_root={root}", f"run_name={m}"]
        )
        out[m] = sorted(train(cfg).glob("model_*.pt"))[-1]
    return out


@pytest.mark.parametrize("method", METHODS)
def test_each_method_trains_loads_and_plays(method_runs, method):
    ckpt = method_runs[method]
    raw = yaml.safe_load((ckpt.parent / "config.yaml").read_text())
    assert raw["method"] == method
    cfg = load_run_config(ckpt)
    assert cfg.task.observations == load_config(TASK + [f"method={method}"]).task.observations
    summary = play(PlayCfg(checkpoint=str(ckpt), episodes=2, time_s=0.5))
    assert summary.trials == 2 and 0.0 <= summary.distance_error < 3.0
    with pytest.raises(ValueError, match=f"continues method {method!r}; drop method=other"):
        resume_config(ckpt, ["method=other"])


def test_play_on_the_mirror_images(method_runs):
    """play.py mirror=true evaluates the same trials on the left/right mirrored scenes."""
    summary = play(PlayCfg(checkpoint=str(method_runs["ours"]), episodes=2, time_s=0.5, mirror=True))
    assert summary.trials == 2 and 0.0 <= summary.distance_error < 3.0


def test_manifest_rejects_a_row_mixing_observation_layouts(method_runs, tmp_path):
    ok = {"methods": {"A": [str(method_runs["ours"]), str(method_runs["wo_r_field"])]}, "table1": {}}
    (tmp_path / "ok.yaml").write_text(yaml.safe_dump(ok))
    load_manifest(tmp_path / "ok.yaml")  # same observation layout: one row may hold both
    bad = {"methods": {"A": [str(method_runs["ours"]), str(method_runs["wo_obs_field"])]}, "table1": {}}
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(bad))
    with pytest.raises(ManifestError, match=f"checkpoint {method_runs['wo_obs_field']} observation layout"):
        load_manifest(tmp_path / "bad.yaml")


def test_play_by_scene_lines_add_up_to_the_summary(method_runs):
    """play.py by_scene=true: one line per scene, each the summary of that scene's own trials."""
    trials, results, scenes, *_ = play_trials(PlayCfg(checkpoint=str(method_runs["ours"]), episodes=3, time_s=0.5))
    assert len(scenes) == 1 and scenes[0].kind == "hurdle-crouch"  # the run's one variant; a second one by hand:
    other = make_typical("crouch-pass", 0.75, seed=3)
    trials = trials + [replace(trials[0], scene=1)]
    results = results + [TrialResult(success=True, de=0.02, collided=False, fell=False, reach_time=1.0)]
    lines = scene_lines(trials, results, [scenes[0], other])
    assert lines[0].startswith(
        f"scene=0 kind=hurdle-crouch difficulty={scenes[0].difficulty:.2f} {summarize(results[:3]).line()} layout="
    )
    lay = other.meta["layout"]  # then the typical scene's layout (cat.terrain.typical.LAYOUT_KEYS)
    assert lines[1] == (
        f"scene=1 kind=crouch-pass difficulty=0.75 {summarize(results[3:]).line()} "
        f"layout=corridor_width:{lay['corridor_width'][0]:.2f},ceiling_bottom:{lay['ceiling_bottom'][0]:.2f},"
        f"x:{lay['x'][0]:.2f}"
    )
    assert len(lines) == 2
    first = [None, "left_wrist_yaw_link", "left_wrist_yaw_link", "torso_link"]  # contacts=true: each scene's own
    lines = scene_lines(trials, results, [scenes[0], other], first)
    assert lines[0].endswith(" first_contact=left_wrist_yaw_link:2")
    assert lines[1].endswith(" first_contact=torso_link:1")


def test_play_chooses_the_slit_grading_of_the_warmups():
    """play.py warmup_slit=: the task keys of one slit grading on, the others off (none: all off); the warm-ups
    built from them are that grading's."""
    task = EnvCfg(scene_kind="side-hurdle", warmup_variants=2, warmup_slit_narrow=True)
    for name, field in (("offset", "slit_offset"), ("narrow", "slit_narrow"), ("tight", "slit_tight")):
        chosen = replace(task, **slit_grading_keys(name))
        assert graded(chosen) == Graded(**{field: True}), name
        group = run_scene_group(chosen, warmup=True)
        expect = warmup_variants("side-hurdle", 2, 0, Graded(**{field: True}))
        assert [s.meta["layout"] for s in group.scenes] == [s.meta["layout"] for s in expect], name
    assert graded(replace(task, **slit_grading_keys("none"))) == Graded()
    with pytest.raises(ValueError, match="warmup_slit='both': valid: offset, narrow, tight, none"):
        slit_grading_keys("both")


def test_play_on_the_warmup_scenes(method_runs):
    """play.py warmup=true: the run's training-only warm-up scenes, as training builds them (d < 0)."""
    task = EnvCfg(scene_kind="hurdle-pass", warmup_variants=3, scene_seed=2)
    group = run_scene_group(task, warmup=True)
    expect = warmup_variants("hurdle-pass", 3, 2)
    assert [s.difficulty for s in group.scenes] == [s.difficulty for s in expect]
    assert np.allclose([s.difficulty for s in expect], [-1.0, -2 / 3, -1 / 3])
    assert all(np.allclose(a.mesh.vertices, b.mesh.vertices) for a, b in zip(group.scenes, expect, strict=True))
    with pytest.raises(ValueError, match="warmup=true evaluates a typical kind's warm-up scenes"):
        run_scene_group(task, scene_dir="somewhere", warmup=True)
    ckpt = str(method_runs["ours"])  # trained with task.warmup_variants=0
    with pytest.raises(ValueError, match="warmup=true: the run's task 'hurdle-crouch' has no warm-up scenes"):
        play_trials(PlayCfg(checkpoint=ckpt, episodes=2, warmup=True))


def test_play_scene_variants_and_paths(method_runs, tmp_path):
    """play.py scene_variants=: Table I's count of variants for a run trained on another (the run's one variant
    here: two are built, d = 0 and 1); paths= writes each trial's path. Bad counts fail before anything is built."""
    import csv
    from pathlib import Path

    ckpt = str(method_runs["ours"])
    out = tmp_path / "paths.csv"
    played = play_trials(PlayCfg(checkpoint=ckpt, episodes=4, time_s=0.2, scene_variants=2, paths=str(out)))
    assert [s.difficulty for s in played.scenes] == [0.0, 1.0]
    assert sorted({t.scene for t in played.trials}) == [0, 1]
    rows = list(csv.DictReader(out.open()))
    assert sorted({r["trial"] for r in rows}) == ["0", "1", "2", "3"]
    assert {(r["trial"], r["scene"]) for r in rows} == {(str(k), str(t.scene)) for k, t in enumerate(played.trials)}
    with pytest.raises(ValueError, match="scene_variants must be >= 1, got 0"):
        play_trials(PlayCfg(checkpoint=ckpt, episodes=2, scene_variants=0))
    flat = Path(__file__).resolve().parents[1] / "checkpoints" / "flat" / "model_770.pt"
    with pytest.raises(ValueError, match="scene_variants= counts typical variants"):
        play_trials(PlayCfg(checkpoint=str(flat), episodes=2, scene_variants=3))
