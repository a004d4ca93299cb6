"""How wide a way each trial offers: the widest body radius at which its start still connects to its goal.

A test trial is *reachable* when the floor eroded by 0.1 m (``ReachCfg.body_radius``, the paper's rule) connects
start and goal; the G1 is ~0.45 m across the shoulders and ~0.25 m deep, so a 0.2 m gap is reachable by that rule
and impassable for the robot. :func:`widest_radius` measures, per trial, the largest radius of ``RADII`` at which
the start still connects to the goal, in two floor models:

* ``walk``: the scene generators' 2.5-D model (``cat.terrain.voxel.walkable``: low obstacles may be stepped over,
  high ones crouched under), eroded by the radius;
* ``upright``: only columns free from the floor to ``height`` (no hurdle, no crouch), eroded by the radius: the
  start rule's ``standing_mask`` at that radius.

The goal counts as reached when the start's component comes within ``goal_window`` of it: a goal next to
furniture (its own column eroded away at larger radii) is the goal's standing radius, measured apart
(``cat.envs.episodes.goal_stand_radii``). ``scripts/corridors.py`` tabulates a trial file's success by class.
"""

from __future__ import annotations

import csv
import gzip
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage
from tqdm import tqdm

from cat.cli import Script, dataclass_loader
from cat.terrain import Scene
from cat.terrain.voxel import ReachCfg, standing_mask, walkable

RADII = (0.10, 0.14, 0.18, 0.22, 0.26, 0.30)
"""m: the body radii tried (0.10: the reachability rule's; 0.30: a 0.6 m corridor, room for the G1 walking)."""


@dataclass
class CorridorCfg:
    """What :func:`widest_radius` tries and what counts as at the goal."""

    radii: tuple[float, ...] = RADII
    goal_window: float = 0.3  # m: the start's component must come within this of the goal
    height: float = 1.35  # m: the free height of an ``upright`` column (the G1 upright: ~1.32 m)


class SceneCorridors:
    """The eroded floor masks of one scene at every radius, in both floor models (built once, queried per trial)."""

    def __init__(self, scene: Scene, cfg: CorridorCfg | None = None):
        self.cfg = cfg or CorridorCfg()
        occ, self.grid = scene.occupancy(), scene.grid()
        eight = np.ones((3, 3), dtype=bool)
        self.labels = {}
        for r in self.cfg.radii:
            walk = walkable(occ, self.grid, ReachCfg(body_radius=r))
            upright = standing_mask(occ, self.grid.voxel, self.cfg.height, r)
            self.labels[("walk", r)] = ndimage.label(walk, structure=eight)[0]
            self.labels[("upright", r)] = ndimage.label(upright, structure=eight)[0]

    def widest_radius(self, start_xy, goal_xy, model: str = "walk") -> float:
        """The largest radius at which ``start_xy`` connects to within ``goal_window`` of ``goal_xy`` in ``model``
        (``walk`` | ``upright``); 0.0 when none does (the start itself blocked at the smallest)."""
        if model not in ("walk", "upright"):
            raise ValueError(f"floor model {model!r}; valid: walk, upright")
        pts = np.array([[start_xy[0], start_xy[1], 0.0], [goal_xy[0], goal_xy[1], 0.0]])
        (si, sj), (gi, gj) = self.grid.index(pts)[:, :2]
        shape = self.labels[(model, self.cfg.radii[0])].shape
        if not (0 <= si < shape[0] and 0 <= sj < shape[1]):
            raise ValueError(f"start ({start_xy[0]:.2f}, {start_xy[1]:.2f}) lies outside the scene's grid")
        w = int(np.ceil(self.cfg.goal_window / self.grid.voxel))
        ii, jj = np.mgrid[max(gi - w, 0) : min(gi + w + 1, shape[0]), max(gj - w, 0) : min(gj + w + 1, shape[1])]
        near = (ii - gi) ** 2 + (jj - gj) ** 2 <= w * w
        best = 0.0
        for r in self.cfg.radii:
            lab = self.labels[(model, r)]
            if lab[si, sj] and (lab[ii[near], jj[near]] == lab[si, sj]).any():
                best = r
        return best


@dataclass
class CorridorsScriptCfg:
    """``scripts/corridors.py``: a trial file's success rate by how wide a way its trials offer."""

    trials: str = ""  # a trial file of eval_table.py (<table>_trials.csv[.gz])
    scene_root: str = ""  # the folder whose <group>/<scene> folders the trials were played on (data/test_unseen)
    table: str = "table2"  # which table's trials of the file
    method: str = ""  # one method of the file ("": every method, pooled)
    out: str = ""  # optional: the trials with their widest radii (CSV)


def read_trials(path: str | Path, table: str, method: str = "") -> list[dict]:
    """The rows of a trial file (``.csv`` or ``.csv.gz``) for ``table`` (and ``method``); refuses an empty pick."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"trials={p}: no such file")
    opener = gzip.open if p.suffix == ".gz" else open
    with opener(p, "rt", newline="") as f:
        rows = list(csv.DictReader(f))
    need = {"table", "group", "scene", "start_x", "start_y", "goal_x", "goal_y", "success", "collided"}
    if rows and not need <= set(rows[0]):
        raise ValueError(f"trials={p}: not a trial file of eval_table.py (missing {sorted(need - set(rows[0]))})")
    picked = [r for r in rows if r["table"] == table and (not method or r["method"] == method)]
    if not picked:
        methods = sorted({r["method"] for r in rows})
        raise ValueError(f"trials={p}: no trials of table={table!r} method={method!r}; methods: {methods}")
    return picked


def classify(rows: list[dict], scene_root: str | Path, cfg: CorridorCfg | None = None) -> list[dict]:
    """Each trial row with ``widest_walk`` and ``widest_upright`` added (scenes loaded once each)."""
    root = Path(scene_root)
    scenes: dict[tuple[str, str], SceneCorridors] = {}
    out = []
    for r in tqdm(rows, desc="trials", unit="trial"):
        key = (r["group"], r["scene"])
        if key not in scenes:
            folder = root / key[0] / key[1]
            if not folder.is_dir():
                raise FileNotFoundError(f"scene_root={root}: no scene folder {key[0]}/{key[1]} for the trials")
            scenes[key] = SceneCorridors(Scene.load(folder), cfg)
        sc = scenes[key]
        start, goal = (float(r["start_x"]), float(r["start_y"])), (float(r["goal_x"]), float(r["goal_y"]))
        out.append(r | {m: sc.widest_radius(start, goal, m.split("_")[1]) for m in ("widest_walk", "widest_upright")})
    return out


def summary(rows: list[dict]) -> list[str]:
    """One line per (floor model, group, widest radius): trials, SR and contact share."""
    lines = []
    for model in ("widest_walk", "widest_upright"):
        for group in sorted({r["group"] for r in rows}):
            sub = [r for r in rows if r["group"] == group]
            for radius in sorted({r[model] for r in sub}):
                cls = [r for r in sub if r[model] == radius]
                sr = 100.0 * sum(int(r["success"]) for r in cls) / len(cls)
                touch = 100.0 * sum(int(r["collided"]) for r in cls) / len(cls)
                lines.append(
                    f"{model[7:]:8s} {group:6s} widest radius {radius:.2f} m: {len(cls):5d} trials "
                    f"({100.0 * len(cls) / len(sub):5.1f} %)  SR {sr:5.1f} %  contact {touch:5.1f} %"
                )
    return lines


def _job(cfg: CorridorsScriptCfg) -> int:
    rows = classify(read_trials(cfg.trials, cfg.table, cfg.method), cfg.scene_root)
    for line in summary(rows):
        print(line)
    if cfg.out:
        out = Path(cfg.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + ".tmp")
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        tmp.replace(out)
        print(f"wrote {out} ({len(rows)} trials)")
    return 0


SCRIPT = Script(
    name="corridors",
    doc=__doc__.split("\n\n")[0]
    + "\n\n  python scripts/corridors.py trials=docs/tables/<name>_trials.csv.gz scene_root=data/test_unseen"
    + " [method=...] [out=...]",
    load=dataclass_loader(CorridorsScriptCfg, required=("trials", "scene_root")),
    job=_job,
    keys=list(CorridorsScriptCfg.__dataclass_fields__),
    errors=(FileNotFoundError, ValueError, OSError),
)
