"""Turn an obstacle mesh into a scene folder that training, play and evaluation read.

``python scripts/mesh_to_scene.py mesh=room.obj start=0,0 goal=2,0 out=data/scenes/room [goal=...;...] [check=true]``

``goal`` takes one or more ``x,y[,z]`` points separated by ``;``. With ``check=true`` (default) the start and
every goal must be in free space and reachable through it. The folder is written completely or not at all.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from cat.cli import Script, dataclass_loader, run
from cat.terrain import Scene, SceneError
from cat.terrain.scene import check_scene


@dataclass
class MeshToSceneCfg:
    mesh: str = ""  # OBJ / PLY / STL / GLB file of the obstacles (z up, floor at z = 0, metres)
    start: str = ""  # x,y[,z]
    goal: str = ""  # x,y[,z] or several joined by ';'
    out: str = ""  # scene folder to write (must not exist)
    kind: str = "user"
    check: bool = True


def _points(text: str, key: str) -> list[list[float]]:
    try:
        pts = [[float(v) for v in p.split(",")] for p in text.split(";") if p.strip()]
    except ValueError:
        raise SceneError(f"{key}={text!r}: expected x,y[,z] numbers") from None
    if not pts or any(len(p) not in (2, 3) for p in pts):
        raise SceneError(f"{key}={text!r}: expected x,y[,z] (several joined by ';')")
    return pts


def _job(cfg: MeshToSceneCfg) -> int:
    out = Path(cfg.out)
    if out.exists():
        raise SceneError(f"{out} already exists")
    (start,) = _points(cfg.start, "start")
    goals = _points(cfg.goal, "goal")
    scene = Scene.from_mesh(cfg.mesh, start, goals, kind=cfg.kind)
    if cfg.check:
        check_scene(scene)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        scene.save(Path(tmp) / "scene")
        shutil.move(str(Path(tmp) / "scene"), out)
    print(f"scene folder: {out} ({len(goals)} goal(s))")
    return 0


SCRIPT = Script(
    name="mesh_to_scene",
    doc=__doc__,
    load=dataclass_loader(MeshToSceneCfg, required=("mesh", "start", "goal", "out")),
    job=_job,
    keys=list(MeshToSceneCfg.__dataclass_fields__),
    errors=(SceneError,),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
