"""Scene dataset builder behind ``scripts/gen_scenes.py``: one folder per scene, resumable.

Layout: ``<out>/typical/<kind>_<v>``, ``<out>/procedural/proc_<i>``, ``<out>/indoor/indoor_<i>``, each a
``Scene`` folder (``scene.json`` + ``mesh.ply``) plus ``fields/humanoid_pf.npz`` when ``cat.fields`` is
available, and a ``done`` marker written last. Folders with ``done`` are skipped on a re-run; a folder with
a ``scene.json`` but no ``done`` (e.g. fields not yet available) is loaded and only its missing fields are
computed. ``index.json`` lists
all complete scenes.
"""

from __future__ import annotations

import functools
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from cat.terrain.data_groups import select
from cat.terrain.front3d import load_front3d
from cat.terrain.furniture import House
from cat.terrain.indoor import make_indoor
from cat.terrain.procedural import make_procedural
from cat.terrain.scene import SCENE_FILE, Scene
from cat.terrain.typical import SHAPES as TYPICAL_SHAPES
from cat.terrain.typical import TYPICAL_KINDS, make_typical

log = logging.getLogger(__name__)
DONE_FILE = "done"


@dataclass
class GenScenesCfg:
    """``scripts/gen_scenes.py`` options (hydra ``key=value`` overrides of ``configs/gen_scenes.yaml``)."""

    out: str = "data/scenes"
    seed: int = 0
    typical_variants: int = 10  # per typical type; difficulties spread over [0, 1]
    typical_kinds: list[str] = field(default_factory=lambda: list(TYPICAL_KINDS))
    # paper: the paper's building blocks; unseen: the same layouts from obstacle shapes no training scene has
    # (cat.terrain.typical; for evaluation, never for training)
    typical_shapes: str = "paper"
    procedural: int = 20
    # a training data group of the paper (cat.terrain.data_groups): only the procedural scenes it selects from the
    # `procedural` ones spread over [difficulty_min, difficulty_max]; "all" or None: every one
    data: str | None = None
    difficulty_min: float = 0.0
    difficulty_max: float = 1.0
    indoor: int = 20
    front3d_dir: str | None = None  # 3D-FRONT house JSON or folder of them; None -> embedded procedural houses
    future_dir: str | None = None  # 3D-FUTURE model folder (<jid>/raw_model.obj)
    fields: bool = True  # precompute HumanoidPF per goal when cat.fields is available
    field_source: str = "occupancy"  # "occupancy" (the scene's voxels) or "mesh"
    max_field_goals: int = -1  # fields for the first N goals only (-1: all)
    field_dtype: str = "float32"  # storage of fields/humanoid_pf.npz: float32 or float16 (half the disk)
    convex_parts: bool = False  # warm the coacd cache for the MuJoCo export
    render: bool = False  # write preview.png per scene


@dataclass
class Job:
    folder: Path
    make: Callable[[], Scene]


FIELD_SOURCES = ("occupancy", "mesh")  # what HumanoidPF is computed from: the scene's voxels, or its mesh


def check_cfg(cfg: GenScenesCfg) -> None:
    """Refuse counts and choices that would silently build something else, before any scene is built."""
    for key in ("typical_variants", "procedural", "indoor"):
        if getattr(cfg, key) < 0:
            raise ValueError(f"{key}={getattr(cfg, key)}: must be >= 0 (0 = none)")
    if cfg.max_field_goals < -1:
        raise ValueError(f"max_field_goals={cfg.max_field_goals}: must be >= 0, or -1 for every goal")
    _check_field_source(cfg.field_source)
    if cfg.field_dtype not in ("float32", "float16"):
        raise ValueError(f"field_dtype must be 'float32' or 'float16', got {cfg.field_dtype!r}")


def _check_field_source(source: str) -> None:
    if source not in FIELD_SOURCES:
        raise ValueError(f"field_source must be {' or '.join(map(repr, FIELD_SOURCES))}, got {source!r}")


def jobs(cfg: GenScenesCfg) -> list[Job]:
    """Every scene the config asks for, in a fixed order with fixed seeds."""
    check_cfg(cfg)
    out = Path(cfg.out)
    todo: list[Job] = []
    if cfg.typical_shapes not in TYPICAL_SHAPES:
        raise ValueError(f"unknown typical_shapes {cfg.typical_shapes!r}; valid: {', '.join(TYPICAL_SHAPES)}")
    for kind in cfg.typical_kinds:
        if kind not in TYPICAL_KINDS:
            raise ValueError(f"unknown typical kind {kind!r}; valid: {', '.join(TYPICAL_KINDS)}")
        n = cfg.typical_variants
        for v, d in enumerate(_spread(0.0, 1.0, n, single=0.5)):
            seed = cfg.seed * 1000 + v
            make = _bind(make_typical, kind, float(d), seed, cfg.typical_shapes)
            todo.append(Job(out / "typical" / f"{kind}_{v:02d}", make))
    n = cfg.procedural
    if not 0.0 <= cfg.difficulty_min <= cfg.difficulty_max <= 1.0:
        lo, hi = cfg.difficulty_min, cfg.difficulty_max
        raise ValueError(f"need 0 <= difficulty_min <= difficulty_max <= 1, got {lo}, {hi}")
    diffs = _spread(cfg.difficulty_min, cfg.difficulty_max, n, single=cfg.difficulty_min)
    seeds = [cfg.seed * 1000 + i for i in range(n)]
    keep = np.ones(n, dtype=bool)
    if cfg.data not in (None, "all"):
        keep = select(["procedural"] * n, diffs, seeds, cfg.data)
    for i, d in enumerate(diffs):
        if keep[i]:
            todo.append(Job(out / "procedural" / f"proc_{i:03d}", _bind(make_procedural, float(d), seeds[i])))
    houses = _front3d_houses(cfg)
    for i in range(cfg.indoor):
        house = houses[i % len(houses)] if houses else None
        todo.append(Job(out / "indoor" / f"indoor_{i:03d}", _bind(make_indoor, cfg.seed * 1000 + i, house)))
    return todo


def _spread(lo: float, hi: float, n: int, single: float) -> list[float]:
    """``n`` difficulties evenly over [lo, hi] (``single`` when n == 1, none when n <= 0)."""
    if n <= 0:
        return []
    return [float(single)] if n == 1 else [float(d) for d in np.linspace(lo, hi, n)]


def _bind(fn: Callable, *args) -> Callable[[], Scene]:
    return lambda: fn(*args)


def _front3d_houses(cfg: GenScenesCfg) -> list[House]:
    if not cfg.front3d_dir:
        return []
    if not cfg.future_dir:
        raise ValueError("front3d_dir needs future_dir (the 3D-FUTURE model folder)")
    src = Path(cfg.front3d_dir)
    files = [src] if src.is_file() else sorted(src.glob("*.json"))
    if not files:
        raise ValueError(f"{cfg.front3d_dir}: no 3D-FRONT house JSON files")
    return [load_front3d(f, cfg.future_dir, missing_models="skip") for f in files]


@functools.lru_cache(maxsize=1)
def _field_api():
    """``cat.fields`` (and its store module), or None when it cannot be imported."""
    try:
        import cat.fields as fields_api
        from cat.fields import store
    except ImportError as err:
        log.warning("cat.fields not available (%s): fields are not precomputed", err)
        return None
    return SimpleNamespace(api=fields_api, store_file=store.STORE_FILE)


def build_fields(
    scene: Scene, folder: Path, source: str = "occupancy", max_goals: int = -1, dtype: str = "float32"
) -> bool:
    """Precompute HumanoidPF for the scene's goals (or the first ``max_goals``) into
    ``folder/fields/humanoid_pf.npz`` (d, ∇d once, F per goal, the FieldCfg); True when it is there and
    current. A file built under other field constants, grid or goals is rebuilt."""
    ns = _field_api()
    if ns is None:
        return False
    fa = ns.api
    _check_field_source(source)
    g = scene.grid()
    grid = fa.Grid(g.origin, g.voxel, g.shape)
    goals = scene.goals if max_goals < 0 else scene.goals[:max_goals]
    out = Scene.fields_dir(folder)
    path = out / ns.store_file
    cfg = fa.FieldCfg()
    if path.is_file():
        try:
            fa.SceneFields.check(path, cfg, grid, goals)
            return True
        except (fa.StaleFieldError, OSError, KeyError) as err:
            log.warning("%s; rebuilding", err)
    out.mkdir(exist_ok=True)
    obstacles = scene.occupancy() if source == "occupancy" else scene.mesh
    try:
        fa.SceneFields.from_fields(fa.build_fields(obstacles, grid, goals, cfg)).save(path, dtype)
    except Exception as err:  # another team's package: never lose the scene over it
        log.warning("%s: fields failed (%s: %s); skipping fields", folder, type(err).__name__, err)
        return False
    return True


def fields_current(folder: Path, max_goals: int = -1) -> bool:
    """True when ``folder/fields/humanoid_pf.npz`` matches the current FieldCfg, the scene's grid and goals
    (reads only the scene JSON and the file's header entries, not the arrays)."""
    ns = _field_api()
    if ns is None:
        return True  # nothing to compare against: leave the folder alone
    fa = ns.api
    raw = json.loads((folder / SCENE_FILE).read_text())
    goals = np.asarray(raw["goals"], dtype=np.float64)
    goals = goals if max_goals < 0 else goals[:max_goals]
    g = raw["grid"]
    grid = fa.Grid(tuple(g["origin"]), float(g["voxel"]), tuple(g["shape"]))
    try:
        fa.SceneFields.check(Scene.fields_dir(folder) / ns.store_file, fa.FieldCfg(), grid, goals)
    except (fa.StaleFieldError, OSError, KeyError) as err:
        log.warning("%s; rebuilding", err)
        return False
    return True


def build_one(job: Job, cfg: GenScenesCfg) -> dict:
    """Make (or finish) one scene folder and return its index entry."""
    folder = job.folder
    if (folder / SCENE_FILE).is_file():
        scene = Scene.load(folder)
    else:
        scene = job.make()
        scene.save(folder)
    complete = (
        build_fields(scene, folder, cfg.field_source, cfg.max_field_goals, cfg.field_dtype) if cfg.fields else True
    )
    if cfg.convex_parts:
        from cat.terrain.mujoco_export import convex_parts, uses_voxels

        if not uses_voxels(scene):  # voxel scenes need no decomposition (height fields + boxes on load)
            convex_parts(scene.mesh)
    if cfg.render:
        from cat.terrain.render import render_scene

        render_scene(scene, folder / "preview.png")
    if complete:  # without it a re-run retries the fields (the scene itself is kept)
        (folder / DONE_FILE).write_text("ok\n")
    return _entry(folder, scene)


def _entry(folder: Path, scene: Scene) -> dict:
    return {"folder": str(folder), "kind": scene.kind, "difficulty": scene.difficulty, "goals": len(scene.goals)}


def build_dataset(cfg: GenScenesCfg, progress: bool = True) -> list[dict]:
    """Build every scene of ``cfg`` (skipping complete folders) and write ``<out>/index.json``."""
    from tqdm import tqdm

    todo = jobs(cfg)
    index = []
    skipped = 0
    for job in tqdm(todo, desc="scenes", unit="scene", disable=not progress):
        if (job.folder / DONE_FILE).is_file() and cfg.fields and not fields_current(job.folder, cfg.max_field_goals):
            (job.folder / DONE_FILE).unlink()  # stale or missing fields: rebuilt by build_one below
        if (job.folder / DONE_FILE).is_file():
            skipped += 1
            raw = json.loads((job.folder / SCENE_FILE).read_text())
            index.append({"folder": str(job.folder), "kind": raw["kind"], "difficulty": raw["difficulty"],
                          "goals": len(raw["goals"])})  # fmt: skip
            continue
        index.append(build_one(job, cfg))
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "index.json").write_text(json.dumps(index, indent=1))
    log.info("%d scenes in %s (%d already complete)", len(index), out, skipped)
    return index
