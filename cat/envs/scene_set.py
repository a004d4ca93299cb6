"""A set of obstacle scenes for the env: tiled into one MuJoCo model, with a HumanoidPF bank per (scene, goal).

Scenes may differ in grid shape (typical, procedural and indoor in one set): the bank stores d and ∇d once
per scene and F once per goal.

Two layouts of the physics worlds (``per_world``, the run's ``sim.per_world_scenes``):

* tiles (default): all scenes live in every world, side by side on a grid of tiles (``tile_spacing`` apart); one
  compiled model serves both backends and obstacles of other tiles are never reached;
* per world: each world holds only its own scene, in the scene's frame (every offset is zero); one compiled model
  per scene (``cat.envs.scene_models``), swapped per world when an env changes scene at reset (``sim=warp``: a
  slot model, ``cat.envs.sim.warp_slots``).

Env ``i`` starts in scene ``i % num_scenes``. Fields come from the scene folders (``fields/humanoid_pf.npz``,
written by ``scripts/gen_scenes.py``) or are built on load; their grid origins are shifted by the scene's offset
into the world frame.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path

import mujoco
import numpy as np
import torch
from tqdm import tqdm

from cat.envs.episodes import EpisodeCfg, EpisodeSampler
from cat.envs.field_source import FieldSample
from cat.fields import Field, FieldBank, FieldCfg, Grid, SceneFields, SceneLayout, StaleFieldError, build_fields
from cat.fields.store import STORE_FILE
from cat.terrain import NOT_GRADED, Graded, Scene, typical_variants, warmup_variants
from cat.terrain.data_groups import select
from cat.terrain.mujoco_export import add_obstacles_to_spec

log = logging.getLogger(__name__)


class SceneSetError(ValueError):
    """Scenes that cannot be used together (none found, mismatched grids, unknown kind)."""


class BankField:
    """Field source over a ``FieldBank``: each env samples the field it was assigned at reset."""

    def __init__(self, bank: FieldBank, num_envs: int):
        self.bank = bank
        self.field_idx = torch.zeros(num_envs, dtype=torch.long, device=bank.device)

    def assign(self, env_ids: torch.Tensor, field_ids: torch.Tensor) -> None:
        self.field_idx[env_ids.to(self.field_idx.device)] = field_ids.to(self.field_idx.device)

    def sample(self, points: torch.Tensor, goals: torch.Tensor, env_ids: torch.Tensor | None = None) -> FieldSample:
        """Fields at ``points`` (n, K, 3) of all envs, or of ``env_ids`` (goals are baked into the bank)."""
        idx = self.field_idx if env_ids is None else self.field_idx[env_ids.to(self.field_idx.device)]
        s = self.bank.query(idx, points)
        return FieldSample(force=s.force, sdf=s.sdf, grad_sdf=s.grad_sdf, outside=self.outside(idx, points))

    def outside(self, field_idx: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
        """(n,) largest distance (m) of an env's ``points`` outside its field's grid, sideways or above."""
        lo, hi = self.bank.field_bounds(field_idx)
        p = points.to(lo)
        gap = torch.maximum(lo[:, None] - p, p - hi[:, None]).clamp_min(0.0)
        gap[..., 2] = (p[..., 2] - hi[:, None, 2]).clamp_min(0.0)  # below the grid is the floor
        return gap.norm(dim=-1).amax(dim=-1)


class SceneSet:
    """Scenes + field bank + per-env episode sampling (start in the scene's start region, one of its goals)."""

    def __init__(
        self,
        scenes: list[Scene],
        fields: Sequence[SceneFields | list[Field]] | Callable[[int], SceneFields | list[Field]],
        num_envs: int,
        device: str = "cpu",
        tile_margin: float = 2.0,
        dtype: str = "float32",
        per_world: bool = False,
        episodes: EpisodeCfg | None = None,
    ):
        """``fields[s]`` (or ``fields(s)``, called once per scene while the bank fills) are scene ``s``'s goal
        fields on its own grid; scenes may have different grid shapes. ``dtype`` is the bank storage.
        ``per_world``: each world holds only its own scene, at zero offset (else all scenes on tiles)."""
        if not scenes:
            raise SceneSetError("no scenes given")
        self.scenes, self.num_envs, self.device = scenes, num_envs, torch.device(device)
        self.per_world = bool(per_world)
        self.episodes: EpisodeSampler | None = None  # free start/goal sampling (set_episodes); None: start regions
        self.episode_cfg: EpisodeCfg | None = None
        if episodes is not None:
            self.set_episodes(episodes)  # before the bank: a goal range no scene serves fails before anything is built
        extent = max(float(np.max(s.bounds[1, :2] - s.bounds[0, :2])) for s in scenes)
        self.tile_spacing = extent + tile_margin
        cols = math.ceil(math.sqrt(len(scenes)))
        # tile offset chosen so each scene's own frame is kept, shifted to its tile; none per world
        self.offsets = np.array(
            [[(i % cols) * self.tile_spacing, (i // cols) * self.tile_spacing, 0.0] for i in range(len(scenes))]
        )
        if self.per_world:
            self.offsets[:] = 0.0
        layouts = []
        for s in scenes:
            g = s.grid()
            layouts.append(SceneLayout(Grid(g.origin, g.voxel, g.shape), len(s.goals)))
        load = fields if callable(fields) else fields.__getitem__
        if not callable(fields) and len(fields) != len(scenes):
            raise SceneSetError(f"{len(scenes)} scenes but {len(fields)} field sets")

        def checked(i: int) -> SceneFields | list[Field]:
            f = load(i)
            n = f.num_goals if isinstance(f, SceneFields) else len(f)
            if n != len(scenes[i].goals):
                raise SceneSetError(f"scene {i} ({scenes[i].kind!r}) has {len(scenes[i].goals)} goals but {n} fields")
            return f

        self.bank = FieldBank.build(layouts, checked, self.offsets, dtype=dtype, device=self.device)
        return_freed_heap()  # the per-scene temporaries of the fill
        self.scene_of_env = torch.arange(num_envs) % len(scenes)
        # scene groups: one per scene kind, in order of first appearance (distillation routes envs by group)
        self.group_names = list(dict.fromkeys(s.kind for s in scenes))
        self.group_of_scene = torch.tensor([self.group_names.index(s.kind) for s in scenes])
        self._goal_idx = torch.zeros(num_envs, dtype=torch.long)

    # --- construction -------------------------------------------------------------------------------------
    @classmethod
    def from_dir(
        cls,
        path: str | Path,
        num_envs: int,
        device: str = "cpu",
        kind: str | None = None,
        field_cfg: FieldCfg | None = None,
        dtype: str = "float32",
        on_stale: str = "rebuild",
        per_world: bool = False,
        mirror: bool = False,
        data: str | None = None,
        episodes: EpisodeCfg | None = None,
    ) -> SceneSet:
        """Every scene folder (with ``scene.json``) under ``path`` (symbolic links followed, so a folder of links
        composes scene sets), optionally only those of ``kind`` and of data group ``data``
        (``cat.terrain.data_groups``); grid shapes may differ. Fields are read (or built) one scene at a time while
        the bank fills; saved fields that do not match ``field_cfg`` (or the scene) are rebuilt
        (``on_stale="rebuild"``) or refused (``"error"``: raises :class:`cat.fields.StaleFieldError`). ``mirror`` adds
        each scene's mirror image (its fields built anew)."""
        if on_stale not in ("rebuild", "error"):
            raise SceneSetError(f"on_stale must be 'rebuild' or 'error', got {on_stale!r}")
        root = Path(path)
        if not root.is_dir():
            raise SceneSetError(f"scene folder not found: {root}")
        folders = scene_folders(root)
        scenes = [Scene.load(f) for f in folders]
        keep = [i for i, s in enumerate(scenes) if kind is None or s.kind == kind]
        if data is not None:
            sel = select([s.kind for s in scenes], [s.difficulty for s in scenes], [s.seed for s in scenes], data)
            keep = [i for i in keep if sel[i]]
        if not keep:
            kinds = sorted({s.kind for s in scenes})
            what = (" of kind " + repr(kind) if kind else "") + (f" in data group {data!r}" if data else "")
            raise SceneSetError(f"no scenes{what} under {root}; found: {kinds or 'no scene folder'}")
        scenes, folders = [scenes[i] for i in keep], [folders[i] for i in keep]
        if mirror:
            scenes, folders = with_mirrors(scenes), [x for f in folders for x in (f, None)]
        bar = tqdm(total=len(scenes), desc="fields")

        def load(i: int) -> SceneFields | list[Field]:
            bar.update()
            return scene_fields(scenes[i], folders[i], field_cfg, on_stale)

        try:
            return cls(scenes, load, num_envs, device, dtype=dtype, per_world=per_world, episodes=episodes)
        finally:
            bar.close()

    @classmethod
    def typical(
        cls,
        kind: str | Sequence[str],
        num_envs: int,
        variants: int = 10,
        seed: int = 0,
        device: str = "cpu",
        field_cfg: FieldCfg | None = None,
        per_world: bool = False,
        warmup: int = 0,
        mirror: bool = False,
        episodes: EpisodeCfg | None = None,
        dtype: str = "float32",
        warmup_graded: Graded = NOT_GRADED,
    ) -> SceneSet:
        """The paper's typical scenes of ``kind`` (or of each of several kinds: one scene group per kind)
        built on the fly (no dataset needed), plus ``warmup`` training-only easier scenes per kind, and with
        ``mirror`` the mirror image of each (``warmup_graded``: how the warm-ups grade each type, ``Graded``)."""
        kinds = [kind] if isinstance(kind, str) else list(kind)
        scenes = [
            s
            for k in kinds
            for s in warmup_variants(k, warmup, seed, warmup_graded) + typical_variants(k, variants, seed)
        ]
        scenes = with_mirrors(scenes) if mirror else scenes
        load = lambda i: scene_fields(scenes[i], None, field_cfg)  # noqa: E731
        return cls(scenes, load, num_envs, device, dtype=dtype, per_world=per_world, episodes=episodes)

    # --- env hooks ----------------------------------------------------------------------------------------
    def add_to_spec(self, spec: mujoco.MjSpec) -> None:
        """Add every scene's obstacles (convex parts, or voxel height fields and boxes), shifted to its tile,
        under the ``obstacles`` body (tiles only: per world, each scene has its own model)."""
        if self.per_world:
            raise SceneSetError("a per-world scene set has one model per scene (cat.envs.scene_models), no tiles")
        for scene, off in zip(self.scenes, self.offsets, strict=True):
            add_obstacles_to_spec(spec, scene, offset=off)

    @property
    def difficulties(self) -> torch.Tensor:
        """(num_scenes,) difficulty in [0, 1] of each scene (for the curriculum)."""
        return torch.tensor([float(s.difficulty) for s in self.scenes])

    def assign_scenes(self, env_ids: torch.Tensor, scene_ids: torch.Tensor) -> None:
        """Move envs to other scenes (takes effect at their next ``sample_episode``)."""
        self.scene_of_env[env_ids.cpu()] = scene_ids.cpu()

    def place(self, env_ids: torch.Tensor, scene_ids: torch.Tensor, goal_ids: torch.Tensor) -> None:
        """Put envs in given scenes with given goals (evaluation trials; ``field_ids`` follows)."""
        ids, scene_ids, goal_ids = env_ids.cpu(), scene_ids.cpu().long(), goal_ids.cpu().long()
        n_goals = torch.tensor([len(s.goals) for s in self.scenes])
        if ((scene_ids < 0) | (scene_ids >= len(self.scenes))).any() or (
            (goal_ids < 0) | (goal_ids >= n_goals[scene_ids])
        ).any():
            raise IndexError(f"scene/goal ids out of range for {len(self.scenes)} scenes with {n_goals.tolist()} goals")
        self.scene_of_env[ids] = scene_ids
        self._goal_idx[ids] = goal_ids

    def to_world(self, scene_ids: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
        """Scene-frame points (k, 2|3) of scenes ``scene_ids`` (k,) in the shared world frame (tile offset added)."""
        off = torch.as_tensor(self.offsets, dtype=points.dtype)[scene_ids.cpu().long()]
        return points + off[:, : points.shape[-1]].to(points.device)

    def field_source(self, device) -> BankField:
        return BankField(self.bank, self.num_envs)

    def set_episodes(self, cfg: EpisodeCfg) -> None:
        """Sample starts and goals per ``cfg`` (``cat.envs.episodes``); ``mode="scene"`` keeps the start regions.
        Raises ``EpisodeError`` when the goal range fits no scene of the free kinds."""
        if cfg == self.episode_cfg:
            return
        self.episodes = EpisodeSampler(self.scenes, cfg, self.scenes[0].grid().voxel) if cfg.mode == "free" else None
        self.episode_cfg = cfg

    def sample_episode(self, env_ids: torch.Tensor, gen: torch.Generator, progress: torch.Tensor | None = None):
        """(start (k, 3), goal (k, 3), heading to the goal (k,)) in world coordinates for ``env_ids``;
        ``progress`` (k,) in (0, 1]: each env's curriculum progress (free episodes' goal distance)."""
        ids = env_ids.cpu()
        k = len(ids)
        start, goal = torch.zeros(k, 3), torch.zeros(k, 3)
        for j, i in enumerate(ids.tolist()):
            s_idx = int(self.scene_of_env[i])
            scene, off = self.scenes[s_idx], self.offsets[s_idx]
            if self.episodes is not None and self.episodes.is_free(s_idx):
                p = 1.0 if progress is None else float(progress[j])
                xy, g = self.episodes.sample(s_idx, p, gen)
                start[j, :2] = torch.from_numpy(xy + off[:2])
            else:
                lo, hi = scene.start_region
                u = torch.rand(2, generator=gen).numpy()
                start[j, :2] = torch.from_numpy(lo + u * (hi - lo) + off[:2])
                g = int(torch.randint(len(scene.goals), (1,), generator=gen))
            self._goal_idx[i] = g
            goal[j] = torch.from_numpy(scene.goals[g] + off)
        delta = goal[:, :2] - start[:, :2]
        return start, goal, torch.atan2(delta[:, 1], delta[:, 0])

    def groups_of_envs(self) -> torch.Tensor:
        """(num_envs,) scene-group index of each env's current scene (index into ``group_names``)."""
        return self.group_of_scene[self.scene_of_env]

    def field_ids(self, env_ids: torch.Tensor) -> torch.Tensor:
        ids = env_ids.cpu()
        starts = torch.as_tensor(self.bank.field_start[:-1])[self.scene_of_env[ids]]
        return starts + self._goal_idx[ids]

    def mesh_for_env(self, env_id: int):
        s_idx = int(self.scene_of_env[env_id])
        return self.scenes[s_idx].mesh.copy().apply_translation(self.offsets[s_idx])


def return_freed_heap() -> None:
    """Give the heap that glibc keeps after freeing back to the OS (``malloc_trim``; elsewhere a no-op).

    Filling a bank frees each scene's temporaries (fields read or built, sampling grids) before the next; glibc
    keeps most of that memory for reuse, ~2.6 MiB per scene (211 MiB at 80 scenes, docs/benchmarks.md), which a
    355-scene set would carry through training. One trim after the fill costs milliseconds, and unlike a fixed
    ``M_MMAP_THRESHOLD`` it leaves the training loop's allocations as they are."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):  # not glibc
        return
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    trim(0)


def scene_folders(root: Path) -> list[Path]:
    """Every folder holding a ``scene.json`` under ``root``, following symbolic links, sorted."""
    found = []
    for dirpath, _, files in os.walk(root, followlinks=True):
        if "scene.json" in files:
            found.append(Path(dirpath))
    return sorted(found)


def with_mirrors(scenes: list[Scene]) -> list[Scene]:
    """Each scene followed by its left/right mirror image (``Scene.mirrored``)."""
    return [m for s in scenes for m in (s, s.mirrored())]


def scene_fields(
    scene: Scene, folder: Path | None, cfg: FieldCfg | None, on_stale: str = "rebuild"
) -> SceneFields | list[Field]:
    """Precomputed fields of a scene folder when present and current, else built from its occupancy now.

    Saved fields built under other build constants of ``cfg``, on another grid or for other goals are
    stale: rebuilt here with a warning (``on_stale="rebuild"``) or refused (``"error"``)."""
    cfg = cfg or FieldCfg()
    g = scene.grid()
    grid = Grid(g.origin, g.voxel, g.shape)
    if folder is not None:
        fdir = Scene.fields_dir(folder)
        try:
            if (fdir / STORE_FILE).is_file():
                return SceneFields.load(fdir / STORE_FILE, cfg, grid, scene.goals)
            files = [fdir / f"goal_{i:02d}.npz" for i in range(len(scene.goals))]  # the older per-goal layout
            if all(f.is_file() for f in files):
                return _legacy_fields(files, cfg, grid, scene.goals)
        except StaleFieldError as err:
            if on_stale == "error":
                raise
            log.warning("%s; rebuilding in memory (re-run scripts/gen_scenes.py to refresh the folder)", err)
        else:
            log.info("%s: building %d goal fields (not precomputed)", folder, len(scene.goals))
    return build_fields(scene.occupancy(), grid, scene.goals, cfg)


def _legacy_fields(files: list[Path], cfg: FieldCfg, grid: Grid, goals: np.ndarray) -> list[Field]:
    fields = [Field.load(f, cfg) for f in files]
    for f, path, goal in zip(fields, files, goals, strict=True):
        if f.grid.shape != grid.shape or not np.allclose(f.goal, goal, atol=1e-6):
            raise StaleFieldError(f"{path}: built for another grid or goal")
    return fields
