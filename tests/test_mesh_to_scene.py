"""scripts/mesh_to_scene.py: a user mesh plus start and goal becomes a scene folder, or one clear error."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import trimesh

from cat.terrain import Scene

REPO = Path(__file__).resolve().parents[1]


def _run(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, str(REPO / "scripts" / "mesh_to_scene.py"), *args],
        capture_output=True, text=True, timeout=300, env=env,
    )  # fmt: skip


def test_mesh_becomes_a_scene_folder(tmp_path):
    bar = trimesh.creation.box(extents=[0.3, 2.0, 0.2])
    bar.apply_translation([1.0, 0.0, 0.1])
    bar.export(tmp_path / "hurdle.obj")
    out = tmp_path / "scenes" / "hurdle"
    res = _run(f"mesh={tmp_path / 'hurdle.obj'}", "start=0,0", "goal=2,0;2,0.5", f"out={out}")
    assert res.returncode == 0, res.stderr
    scene = Scene.load(out)
    assert len(scene.goals) == 2 and abs(scene.goals[0][0] - 2.0) < 1e-9
    assert scene.occupancy().any()


def test_bad_input_is_one_line_and_writes_nothing(tmp_path):
    (tmp_path / "junk.stl").write_text("not a mesh at all")
    bar = trimesh.creation.box(extents=[0.4, 0.4, 1.5])
    bar.apply_translation([1.0, 0.0, 0.75])
    bar.export(tmp_path / "pillar.ply")
    cases = [
        ([f"mesh={tmp_path / 'junk.stl'}", "start=0,0", "goal=2,0"], "junk.stl"),
        ([f"mesh={tmp_path / 'nope.obj'}", "start=0,0", "goal=2,0"], "not found"),
        ([f"mesh={tmp_path / 'pillar.ply'}", "start=0,0", "goal=1,0"], "goal"),  # goal inside the pillar
        ([f"mesh={tmp_path / 'pillar.ply'}", "start=0,0", "goal=two"], "expected x,y"),
        ([f"mesh={tmp_path / 'pillar.ply'}", "start=0,0"], "missing goal="),
        ([f"mesh={tmp_path / 'pillar.ply'}", "start=0,0", "gaol=2,0"], "did you mean goal"),
    ]
    for i, (args, message) in enumerate(cases):
        out = tmp_path / f"out{i}"
        res = _run(*args, f"out={out}")
        assert res.returncode == 2, (args, res.stderr)
        lines = [ln for ln in res.stderr.splitlines() if ln.startswith("ERROR")]
        assert len(lines) == 1 and message in lines[0], res.stderr
        assert "Traceback" not in res.stderr and not out.exists()
