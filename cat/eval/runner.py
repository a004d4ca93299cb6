"""Run trials: each env runs exactly one trial at a time, ``success.time_s`` of simulated time, no auto-reset.

A batch of up to N trials is placed with ``TraversalEnv.reset_to`` (env i gets trial i of the batch), the env
steps the trial window (250 control steps for 5 s at 50 Hz) with auto-reset off, and each env's
``TrialMetrics`` (``cat.envs.trial_metrics``, the same object the training log reads) gives the result. Envs left
over in the last batch keep running their previous (finished) trial and are not read.

Evaluation settings (``EvalCfg``): pushes and domain randomisation off (a nominal robot, as the paper's
tables do not say otherwise), observation noise as the policy was trained, the curriculum off. The success
rule (0.1 m, 5 s) and the fall thresholds are the evaluation's, not each run's, so every method is scored by
the same rule. Random
draws at reset (joint offsets, gait phase) and the observation noise come from streams seeded per batch,
so the same trials on the same machine give the same results.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import torch

from cat.envs.config import EnvCfg, SuccessCfg, TerminationCfg
from cat.envs.episodes import EpisodeCfg
from cat.envs.scene_set import SceneSet, SceneSetError, scene_fields, scene_folders
from cat.envs.scene_source import SceneSource, eval_scene_source
from cat.envs.traversal_env import TraversalEnv
from cat.envs.trial_metrics import TrialResult
from cat.eval.trials import Trial
from cat.fields import Field
from cat.terrain import NOT_GRADED, Graded, Scene, typical_variants, warmup_variants

log = logging.getLogger(__name__)


@dataclass
class EvalCfg:
    """How trials are drawn, run and scored (the same for every method)."""

    starts: int = 10  # start poses per (scene, goal)
    seed: int = 0  # start-pose seed (trials) and the per-batch reset / noise streams
    start_yaw_range: float = 1.5708  # start yaw within +-this of the heading to the goal [rad]
    success: SuccessCfg = field(default_factory=SuccessCfg)  # paper: 0.1 m within 5 s
    fall: TerminationCfg = field(default_factory=TerminationCfg)  # fall thresholds (min_base_height, max_tilt)
    max_envs: int = 256  # envs per batch (fewer when there are fewer trials)
    noise: bool = True  # keep the observation noise the policy was trained with
    domain_rand: bool = False
    push: bool = False
    # MuJoCo C: each world holds only its own scene's obstacles (cat/envs/scene_models.py), not every scene in
    # tiles: the same contacts, much faster with many scenes. Warp always uses tiles.
    per_world_scenes: bool = True


@dataclass
class SceneGroup:
    """A named list of scenes evaluated together (a table column), with their per-goal fields."""

    name: str
    scenes: list[Scene]
    scene_names: list[str]
    fields: list[list[Field]] = field(repr=False)

    @classmethod
    def typical(cls, kind: str, variants: int, scene_seed: int, shapes: str = "paper") -> SceneGroup:
        """The typical scenes of ``kind`` (seeds scene_seed..+variants-1), exactly as training builds them
        (``shapes="unseen"``: the same layouts from obstacle shapes no training scene has)."""
        scenes = typical_variants(kind, variants, scene_seed, shapes)
        names = [f"{kind}_{i:02d}" for i in range(variants)]
        return cls(kind, scenes, names, [scene_fields(s, None, None) for s in scenes])

    @classmethod
    def warmup(cls, kind: str, variants: int, scene_seed: int, graded: Graded = NOT_GRADED) -> SceneGroup:
        """The training-only warm-up scenes of ``kind`` (difficulties in [-1, 0)), exactly as training builds them:
        a diagnostic of where a curriculum stands, never a headline figure."""
        scenes = warmup_variants(kind, variants, scene_seed, graded)
        names = [f"{kind}_warmup_{i:02d}" for i in range(variants)]
        return cls(f"{kind}_warmup", scenes, names, [scene_fields(s, None, None) for s in scenes])

    @classmethod
    def from_dir(cls, name: str, path: str | Path) -> SceneGroup:
        """Every scene folder under ``path`` (precomputed fields used when present)."""
        root = Path(path)
        if not root.is_dir():
            raise SceneSetError(f"scene folder not found: {root}")
        folders = scene_folders(root)  # symbolic links followed, as training reads a folder (a folder of links)
        if not folders:
            raise SceneSetError(f"no scenes (scene.json) under {root}")
        scenes = [Scene.load(f) for f in folders]
        names = [str(f.relative_to(root)) for f in folders]
        return cls(name, scenes, names, [scene_fields(s, f, None) for s, f in zip(scenes, folders, strict=True)])

    @classmethod
    def of_source(cls, source: SceneSource) -> SceneGroup:
        """The scenes of ``source`` (``cat.envs.scene_source``): a folder (only ``source.kind`` when set), or one
        typical kind's paper variants, or with ``variants=0`` its warm-up variants."""
        if source.scene_dir:
            group = cls.from_dir("scenes", source.scene_dir)
            if not source.kind:
                return group
            keep = [i for i, s in enumerate(group.scenes) if s.kind == source.kind]
            if not keep:
                raise SceneSetError(f"no scenes of kind {source.kind!r} under {source.scene_dir}")
            pick = (
                [group.scenes[i] for i in keep],
                [group.scene_names[i] for i in keep],
                [group.fields[i] for i in keep],
            )
            return SceneGroup(source.kind, *pick)
        (kind,) = source.typical
        if source.variants == 0:
            return cls.warmup(kind, source.warmup, source.seed, source.warmup_graded)
        return cls.typical(kind, source.variants, source.seed)

    def mirrored(self) -> SceneGroup:
        """The group's scenes reflected left/right (``Scene.mirrored``), their fields built anew."""
        scenes = [s.mirrored() for s in self.scenes]
        names = [f"{n}_mirrored" for n in self.scene_names]
        return SceneGroup(f"{self.name}_mirrored", scenes, names, [scene_fields(s, None, None) for s in scenes])

    def scene_set(self, num_envs: int, device: str, per_world: bool = False) -> SceneSet:
        return SceneSet(self.scenes, self.fields, num_envs, device, per_world=per_world)


def run_scene_group(
    task: EnvCfg, scene_seed: int | None = None, scene_dir: str = "", scene_kind: str = "", warmup: bool = False
) -> SceneGroup | None:
    """The scenes a run trained on (``None``: flat ground), unless ``scene_seed`` / ``scene_dir`` /
    ``scene_kind`` override them; chosen and checked by ``cat.envs.scene_source.eval_scene_source``."""
    source = eval_scene_source(task, scene_seed, scene_dir, scene_kind, warmup)
    return None if source is None else SceneGroup.of_source(source)


def eval_task(task: EnvCfg, num_envs: int, cfg: EvalCfg) -> EnvCfg:
    """The run's task config with the evaluation settings (observation layout and success rule unchanged)."""
    t = copy.deepcopy(task)
    t.num_envs = num_envs
    t.noise.enabled = t.noise.enabled and cfg.noise
    t.domain_rand.enabled = cfg.domain_rand
    t.push.enabled = cfg.push
    t.curriculum.enabled = False
    t.curriculum.group_weights = {}  # how training drew its scenes; trials name theirs
    t.episodes = EpisodeCfg()  # trials place start and goal themselves: no free-episode sampling to build
    t.ghost_obstacles, t.ghost_parts, t.ghost_parts_physical = False, [], 0.0  # training aids: trials are physical
    t.success = copy.deepcopy(cfg.success)
    t.terminations.min_base_height = cfg.fall.min_base_height
    t.terminations.max_tilt = cfg.fall.max_tilt
    t.episode_length_s = max(t.episode_length_s, t.success.time_s + 1.0)  # no time-out inside a trial
    return t


def make_eval_env(
    task: EnvCfg,
    group: SceneGroup | None,
    num_envs: int,
    cfg: EvalCfg,
    sim: str = "mujoco",
    device: str = "cpu",
    trained_obstacles: str = "physical",
) -> TraversalEnv:
    """An env for ``task`` on ``group``'s scenes (``None``: flat ground), auto-reset off.

    Obstacles are always physical (real geometry, real contacts), whatever the run trained with
    (``trained_obstacles``, its ``sim.obstacles``): a field-trained policy is scored like every other."""
    if trained_obstacles != "physical":
        log.info("the run trained with sim.obstacles=%s: evaluation builds physical obstacles", trained_obstacles)
    per_world = cfg.per_world_scenes and sim == "mujoco"
    scenes = group.scene_set(num_envs, device, per_world) if group is not None else None
    t = eval_task(task, num_envs, cfg)
    env = TraversalEnv(t, sim=sim, device=device, scenes=scenes, seed=cfg.seed, obstacles="physical")
    env.auto_reset = False
    return env


class HoldPolicy:
    """The reference policy: zero actions, so the PD targets stay at the default pose."""

    def __init__(self, num_actions: int):
        self.num_actions = num_actions

    def __call__(self, obs) -> torch.Tensor:
        return torch.zeros(obs.batch_size[0], self.num_actions, device=obs.device)


def place(env: TraversalEnv, env_ids: torch.Tensor, trials: Sequence[Trial]) -> None:
    """Reset ``env_ids`` to ``trials`` (scene frame -> the env's world frame)."""
    start = torch.tensor([t.start_xy for t in trials], dtype=torch.float32)
    goal = torch.tensor([t.goal_xyz for t in trials], dtype=torch.float32)
    yaw = torch.tensor([t.yaw for t in trials], dtype=torch.float32)
    if env.scenes is None:
        env.reset_to(env_ids, start, yaw, goal)
        return
    scene_ids = torch.tensor([t.scene for t in trials])
    goal_ids = torch.tensor([t.goal for t in trials])
    ss = env.scenes
    env.reset_to(env_ids, ss.to_world(scene_ids, start), yaw, ss.to_world(scene_ids, goal), scene_ids, goal_ids)


def run_trials(
    env: TraversalEnv,
    policy: Callable,
    trials: Sequence[Trial],
    seed: int = 0,
    progress=None,
    on_step: Callable[[TraversalEnv], None] | None = None,
) -> list[TrialResult]:
    """Results of ``trials`` in order; ``progress`` (tqdm-like) advances per finished trial."""
    if env.auto_reset:
        raise ValueError("run_trials needs an env with auto_reset = False (see make_eval_env)")
    steps = env.trial.window
    results: list[TrialResult] = []
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small per-step tensors: one thread is much faster on a few shared cores
    try:
        with torch.random.fork_rng(), torch.inference_mode():
            _run_batches(env, policy, trials, seed, steps, results, progress, on_step)
    finally:
        torch.set_num_threads(threads)
    return results


def _run_batches(env, policy, trials, seed, steps, results, progress, on_step) -> None:
    n = env.num_envs
    for b, first in enumerate(range(0, len(trials), n)):
        batch = trials[first : first + n]
        ids = torch.arange(len(batch), device=env.device)
        env.generator.manual_seed(seed * 1_000_003 + b)  # reset draws, per batch
        torch.manual_seed(seed * 1_000_003 + b)  # observation noise
        place(env, ids, batch)
        if hasattr(policy, "reset"):
            policy.reset()  # a recurrent policy starts each batch of trials with no memory
        obs = env.get_observations()
        if on_step is not None:
            on_step(env)
        for _ in range(steps):
            obs, _, _, _ = env.step(policy(obs))
            if on_step is not None:
                on_step(env)
        results += env.trial.results(ids)
        if progress is not None:
            progress.update(len(batch))
