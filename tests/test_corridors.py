"""The corridor-width reading of trials (cat.eval.corridors) on constructed scenes."""

from __future__ import annotations

import csv
import gzip

import pytest
import trimesh

from cat.eval.corridors import SceneCorridors, classify, read_trials, summary
from cat.terrain import Scene


def _scene(boxes) -> Scene:
    return Scene(
        trimesh.util.concatenate([trimesh.creation.box(bounds=b) for b in boxes]),
        bounds=[[-2.0, -2.0, 0.0], [2.0, 2.0, 2.0]],
        start=(-1.5, 0.0),
        goals=[(1.5, 0.0)],
        kind="user",
    )


def wall_with_gap(gap: float) -> Scene:
    """A 2 m wall across the scene at x = 0 with one doorway |y| < gap / 2."""
    return _scene([[[-0.1, -2.0, 0.0], [0.1, -gap / 2, 2.0]], [[-0.1, gap / 2, 0.0], [0.1, 2.0, 2.0]]])


@pytest.mark.parametrize("gap", [0.4, 0.5, 0.7])
def test_widest_radius_is_half_the_doorway(gap):
    sc = SceneCorridors(wall_with_gap(gap))
    for model in ("walk", "upright"):
        r = sc.widest_radius((-1.5, 0.0), (1.5, 0.0), model)
        assert gap / 2 - 0.08 <= r <= gap / 2, (model, r)
    # the same side of the wall: every radius connects
    assert sc.widest_radius((-1.5, 0.0), (-1.5, 1.0)) == pytest.approx(0.30)


def test_a_low_bar_is_stepped_over_only_in_the_walk_model():
    sc = SceneCorridors(_scene([[[-0.1, -2.0, 0.0], [0.1, 2.0, 0.15]]]))
    assert sc.widest_radius((-1.5, 0.0), (1.5, 0.0), "walk") == pytest.approx(0.30)
    assert sc.widest_radius((-1.5, 0.0), (1.5, 0.0), "upright") == 0.0


def test_trials_are_classified_and_summarised(tmp_path):
    scene = wall_with_gap(0.5)
    scene.save(tmp_path / "scenes" / "easy" / "door")
    path = tmp_path / "t_trials.csv.gz"
    rows = [
        {
            "method": "m",
            "table": "table2",
            "group": "easy",
            "scene": "door",
            "start_x": -1.5,
            "start_y": 0.0,
            "goal_x": gx,
            "goal_y": gy,
            "success": s,
            "collided": 1 - s,
        }
        for gx, gy, s in [(1.5, 0.0, 0), (-1.5, 1.0, 1)]
    ]
    with gzip.open(path, "wt", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    out = classify(read_trials(path, "table2"), tmp_path / "scenes")
    assert out[0]["widest_walk"] < 0.30 and out[1]["widest_walk"] == pytest.approx(0.30)
    lines = summary(out)
    assert any("widest radius 0.30 m:     1 trials" in line and "SR 100.0 %" in line for line in lines)
    with pytest.raises(ValueError, match="no trials of table='table1'"):
        read_trials(path, "table1")
    with pytest.raises(FileNotFoundError, match="no scene folder easy/other"):
        classify([rows[0] | {"scene": "other"}], tmp_path / "scenes")
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_trials(tmp_path / "missing.csv", "table2")
    with pytest.raises(ValueError, match="floor model 'fly'"):
        SceneCorridors(scene).widest_radius((-1.5, 0.0), (1.5, 0.0), "fly")
