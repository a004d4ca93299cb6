"""scripts/gen_scenes.py: builds loadable scene folders, resumes, rejects unknown keys."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from cat.terrain import TYPICAL_KINDS, Scene

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "gen_scenes.py"


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=ROOT, capture_output=True, text=True, timeout=600)


def _check_folders(out: Path, expected: int) -> list[Path]:
    folders = sorted(p.parent for p in out.glob("*/*/scene.json"))
    assert len(folders) == expected
    for folder in folders:
        s = Scene.load(folder)
        assert s.mesh is not None and s.start.shape == (3,) and s.goals.shape[1] == 3 and len(s.goals) >= 1
        assert isinstance(s.kind, str) and 0.0 <= s.difficulty <= 1.0
    return folders


def test_gen_scenes_small_and_resume(tmp_path):
    out = tmp_path / "scenes"
    args = (f"out={out}", "typical_variants=1", "procedural=2", "indoor=2", "seed=0", "fields=false")
    r = _run(*args)
    assert r.returncode == 0, r.stderr
    folders = _check_folders(out, 8 + 2 + 2)
    assert all((f / "done").is_file() for f in folders)
    kinds = {Scene.load(f).kind for f in folders}
    assert kinds == {*TYPICAL_KINDS, "procedural", "indoor"}
    index = json.loads((out / "index.json").read_text())
    assert len(index) == 12
    # resumable: a half-written folder (no scene.json) is rebuilt, complete ones are skipped
    victim = folders[0]
    (victim / "scene.json").unlink()
    (victim / "done").unlink()
    mtime = (folders[1] / "mesh.ply").stat().st_mtime_ns
    r = _run(*args)
    assert r.returncode == 0, r.stderr
    assert "11 already complete" in r.stderr
    assert (folders[1] / "mesh.ply").stat().st_mtime_ns == mtime
    Scene.load(victim)


def test_gen_scenes_rejects_unknown_key(tmp_path):
    r = _run(f"out={tmp_path}", "procedurals=3")
    assert r.returncode == 2
    assert "unknown key 'procedurals'" in r.stderr and "procedural" in r.stderr
    r = _run(f"out={tmp_path}", "procedural=many")
    assert r.returncode == 2 and "procedural" in r.stderr
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    "arg, needle",
    [
        ("indoor=-1", "indoor=-1: must be >= 0"),
        ("typical_variants=-2", "typical_variants=-2: must be >= 0"),
        ("max_field_goals=-5", "max_field_goals=-5"),
        ("field_source=voxels", "field_source must be 'occupancy' or 'mesh'"),
        ("field_dtype=float64", "field_dtype must be 'float32' or 'float16'"),
    ],
)
def test_gen_scenes_refuses_bad_counts_before_building(tmp_path, arg, needle):
    """A negative count is not "none", and a bad field choice is refused before the first scene, not after it."""
    from cat.terrain.dataset import GenScenesCfg, build_dataset

    key, value = arg.split("=")
    cfg = GenScenesCfg(out=str(tmp_path / "ds"), typical_variants=1, procedural=1, indoor=1)
    setattr(cfg, key, type(getattr(cfg, key))(value))
    with pytest.raises(ValueError, match=needle):
        build_dataset(cfg, progress=False)
    assert not (tmp_path / "ds").exists()


@pytest.mark.slow
def test_gen_scenes_command_as_documented(tmp_path):
    """The issue's command verbatim (fields are precomputed if cat.fields is ready, else skipped)."""
    out = tmp_path / "ds"
    r = _run(f"out={out}", "typical_variants=1", "procedural=2", "indoor=2", "seed=0")
    assert r.returncode == 0, r.stderr
    _check_folders(out, 12)


def test_build_dataset_front3d_and_render(tmp_path):
    """In-process builder: 3D-FRONT crops through gen_scenes' code path, previews rendered."""
    from cat.terrain.dataset import GenScenesCfg, build_dataset

    fix = ROOT / "tests" / "fixtures" / "3dfront"
    cfg = GenScenesCfg(
        out=str(tmp_path),
        typical_variants=1,
        typical_kinds=["side-pass"],
        procedural=0,
        indoor=2,
        front3d_dir=str(fix / "house.json"),
        future_dir=str(fix / "future"),
        fields=False,
        render=True,
    )
    index = build_dataset(cfg, progress=False)
    assert [e["kind"] for e in index] == ["side-pass", "indoor", "indoor"]
    for e in index:
        folder = Path(e["folder"])
        assert (folder / "preview.png").stat().st_size > 10_000
        s = Scene.load(folder)
        assert s.mesh.is_watertight
    assert Scene.load(tmp_path / "indoor" / "indoor_000").meta["source"] == "fixture-house"
