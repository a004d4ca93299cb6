"""The unseen Table II test set: deterministic, split by density, drawn from a stream training never uses."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cat.eval.test_set import UnseenSetCfg, build_test_set, candidate
from cat.terrain import Scene, make_indoor


def test_test_set_is_deterministic_split_and_held_out(tmp_path):
    cfg = UnseenSetCfg(out=str(tmp_path / "a"), num_scenes=4, fields=False)
    index = build_test_set(cfg, progress=False)
    again = build_test_set(UnseenSetCfg(out=str(tmp_path / "b"), num_scenes=4, fields=False), progress=False)
    assert index == again
    for e in index:
        a, b = Scene.load(tmp_path / "a" / e["folder"]), Scene.load(tmp_path / "b" / e["folder"])
        np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
        np.testing.assert_array_equal(a.goals, b.goals)
        assert 1 <= len(a.goals) <= cfg.goals_per_scene
        assert (tmp_path / "a" / e["folder"] / "done").is_file()
    easy = [e["density"] for e in index if e["split"] == "easy"]
    hard = [e["density"] for e in index if e["split"] == "hard"]
    assert len(easy) == len(hard) == 2 and max(easy) <= min(hard)
    meta = json.loads((tmp_path / "a" / "index.json").read_text())
    assert "lower half easy" in meta["rule"] and meta["test_stream"] == 1
    # a training scene with the same seed (stream 0) is a different scene
    seed = index[0]["seed"]
    test_scene = candidate(seed, goals_per_scene=100)
    train_scene = make_indoor(seed)
    assert test_scene.meta["source"] != train_scene.meta["source"] or not np.array_equal(
        test_scene.mesh.vertices, train_scene.mesh.vertices
    )


def test_starts_are_standing_poses_and_the_first_set_is_still_buildable(tmp_path):
    """Every start region of the set stands at ``start_stand_radius`` (no furniture within it up to standing
    height); a crop whose start is next to furniture is refused; ``start_stand_radius=0`` keeps every crop (the
    first set's rule), so the seeds the new rule skips are exactly those failing the check."""
    from cat.eval.test_set import start_is_standing

    cfg = UnseenSetCfg(out=str(tmp_path / "s"), num_scenes=4, fields=False)
    index = build_test_set(cfg, progress=False)
    for e in index:
        assert start_is_standing(Scene.load(tmp_path / "s" / e["folder"]), cfg.stand_height, cfg.start_stand_radius)
    kept = {e["seed"] for e in index}
    first = {s for s in range(max(kept) + 1) if candidate(s, 4) is not None}
    skipped = first - kept
    for s in skipped:
        assert not start_is_standing(candidate(s, 4), cfg.stand_height, cfg.start_stand_radius)
    for s in kept:
        assert candidate(s, 4, 0.0) is not None
    scene = candidate(min(kept), 4)
    wall = scene.start_region[1, 0] + 0.05  # a wall 5 cm beyond the start region's edge
    from cat.terrain.primitives import box, combine

    scene.mesh = combine([scene.mesh, box((wall, -2.0, 0.0), (wall + 0.1, 2.0, 1.5))])
    scene._occ.clear()
    assert not start_is_standing(scene, cfg.stand_height, cfg.start_stand_radius)


def test_goal_stand_radius_measures_and_filters_goals_next_to_furniture(tmp_path):
    """``goal_stand_radii``: a goal 0.15 m from a wall stands at 0.12 m but not at 0.24 m, a goal in the open at
    the largest radius; with ``goal_stand_radius`` > 0 the set keeps only goals standing at it (each listed in
    index.json with its radius), and a negative radius is refused."""
    from cat.envs.episodes import GOAL_RADII, goal_stand_radii
    from cat.terrain.primitives import box

    wall = box((1.85, -1.0, 0.0), (1.95, 1.0, 1.5))
    bounds = np.array([[-2.5, -2.5, 0.0], [2.5, 2.5, 2.0]])
    scene = Scene(wall, bounds, start=(0.0, 0.0), goals=[(1.7, 0.0), (0.0, 1.5)])
    near, free = goal_stand_radii(scene)
    assert 0.08 <= near < 0.24 and free == max(GOAL_RADII)

    cfg = UnseenSetCfg(out=str(tmp_path / "g"), num_scenes=2, fields=False, goal_stand_radius=0.24)
    index = build_test_set(cfg, progress=False)
    for e in index:
        assert len(e["goal_stand_radius"]) == e["goals"] and min(e["goal_stand_radius"]) >= 0.24
        assert (goal_stand_radii(Scene.load(tmp_path / "g" / e["folder"])) >= 0.24).all()
    with pytest.raises(ValueError, match="goal_stand_radius must be >= 0"):
        build_test_set(UnseenSetCfg(out=str(tmp_path / "x"), goal_stand_radius=-0.1), progress=False)


def test_validation_twin_is_held_out_from_training_and_test(tmp_path):
    """``split=val`` draws from stream 2: none of its crops is a training (stream 0) or test (stream 1) crop of the
    same seeds (by mesh), its folders are ``val_<seed>``, its index says so; an unknown split is refused."""

    def _mesh_hash(scene: Scene) -> bytes:
        return np.round(scene.mesh.vertices, 5).tobytes() + scene.mesh.faces.tobytes()

    index = build_test_set(UnseenSetCfg(out=str(tmp_path / "v"), split="val", num_scenes=2, fields=False), False)
    meta = json.loads((tmp_path / "v" / "index.json").read_text())
    assert meta["split"] == "val" and meta["test_stream"] == 2
    val = [Scene.load(tmp_path / "v" / e["folder"]) for e in index]
    assert all(e["folder"].split("/")[1].startswith("val_") for e in index)
    seeds = [e["seed"] for e in index]
    others = {_mesh_hash(make_indoor(s)) for s in seeds}
    others |= {_mesh_hash(t) for t in (candidate(s, 4) for s in seeds) if t is not None}
    assert not others & {_mesh_hash(v) for v in val}
    with pytest.raises(ValueError, match="split='train'; valid: test, val"):
        build_test_set(UnseenSetCfg(out=str(tmp_path / "x"), split="train"), progress=False)
    assert not (tmp_path / "x").exists()
