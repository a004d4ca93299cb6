"""A specialist trained on a scene folder teaches every scene kind it trained on there (indoor + procedural)."""

from __future__ import annotations

import pytest
import trimesh

from cat.learning.distill import TeacherError, teacher_groups
from cat.run.config import TrainCfg
from cat.terrain import Scene


def _save(folder, kind: str, difficulty: float) -> None:
    box = trimesh.creation.box(bounds=[[1.0, -0.5, 0.0], [1.2, 0.5, 0.2]])
    s = Scene(box, [[-1, -1, 0], [2, 1, 1.5]], start=(0, 0), goals=[(1.8, 0)], kind=kind, difficulty=difficulty)
    s.save(folder)


def test_a_scene_folder_specialist_teaches_its_kinds(tmp_path):
    _save(tmp_path / "indoor" / "a", "indoor", 0.2)
    _save(tmp_path / "procedural" / "b", "procedural", 0.9)
    cfg = TrainCfg()
    cfg.task.scene_dir = str(tmp_path)
    assert teacher_groups(cfg, "t.pt") == ["indoor", "procedural"]
    cfg.task.data = "base"  # indoor crops only
    assert teacher_groups(cfg, "t.pt") == ["indoor"]
    cfg.task.data, cfg.task.scene_kind = None, "procedural"
    assert teacher_groups(cfg, "t.pt") == ["procedural"]
    cfg.task.scene_kind, cfg.task.scene_dir = None, str(tmp_path / "gone")
    with pytest.raises(TeacherError, match="holds no scenes here"):
        teacher_groups(cfg, "t.pt")
