"""One scene source: the scenes a task config names, checked once, for training, evaluation and the demo.

A task names its scenes with ``scene_dir`` / ``scene_kind`` / ``scene_groups`` / ``data`` / ``scene_variants`` /
``scene_seed`` / ``warmup_variants`` / ``mirror_scenes`` (``cat.envs.config.EnvCfg``). :func:`scene_source`
checks those keys (one-line ``ValueError`` naming the key) and returns a :class:`SceneSource`, the plain
description every consumer builds from:

* training (``cat.learning.runs.make_env``): :func:`scene_set_for`, a ``SceneSet`` with warm-up variants, mirrors
  and the task's episode sampling;
* evaluation (``cat.eval.runner.run_scene_group``): :func:`eval_scene_source`, the run's scenes with play's
  overrides (another seed, folder or typical kind, the warm-up scenes), built into a ``SceneGroup``;
* the demo (``cat.deploy.scenes.load_scene``): :func:`typical_kind_or_none` for a scene spelt as a typical kind.

The paper tables (``cat.eval.evaluate``) build their own fixed scene sets and do not read a run's task.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from cat.envs.config import EnvCfg
from cat.envs.episodes import EpisodeCfg, check_episode_cfg
from cat.envs.scene_set import SceneSet
from cat.terrain import NOT_GRADED, TYPICAL_KINDS, Graded, kind_name
from cat.terrain.data_groups import data_group
from cat.terrain.graded import GRADED_BARS, graded_kinds, kinds_text


@dataclass(frozen=True)
class SceneSource:
    """Typical kinds built from a seed (``typical``), or the scene folders under ``scene_dir``."""

    typical: tuple[str, ...] = ()  # typical kinds, one scene group each; empty: the scenes of scene_dir
    scene_dir: str | None = None
    kind: str | None = None  # scene_dir: only scenes of this kind
    data: str | None = None  # scene_dir: only scenes of this data group (cat.terrain.data_groups)
    variants: int = 10  # typical: the paper's variants per kind (difficulties spread over [0, 1])
    seed: int = 0  # typical: seeds seed..seed+variants-1 (the scene seed, not the RL seed)
    warmup: int = 0  # typical: training-only warm-up variants per kind (difficulty in [-1, 0))
    warmup_graded: Graded = NOT_GRADED  # typical: how the warm-ups grade each type's hard part (graded(task))
    mirror: bool = False  # each scene followed by its left/right mirror image
    episodes: EpisodeCfg | None = None  # start / goal sampling (None: the scenes' start regions)

    def scene_set(
        self, num_envs: int, device: str = "cpu", per_world: bool = False, storage: str = "float32"
    ) -> SceneSet:
        """The training ``SceneSet`` of these scenes (``per_world``: one scene per physics world; ``storage``:
        the field bank's, ``cat.fields.bank.STORAGES``)."""
        kw = dict(device=device, per_world=per_world, mirror=self.mirror, episodes=self.episodes, dtype=storage)
        if self.scene_dir:
            return SceneSet.from_dir(self.scene_dir, num_envs=num_envs, kind=self.kind, data=self.data, **kw)
        return SceneSet.typical(
            list(self.typical),
            num_envs,
            self.variants,
            self.seed,
            warmup=self.warmup,
            warmup_graded=self.warmup_graded,
            **kw,
        )


def typical_kind_or_none(name: str) -> str | None:
    """``name`` spelt canonically (``hurdle_crouch`` -> ``hurdle-crouch``) when it is a typical kind, else None."""
    kind = kind_name(name)
    return kind if kind in TYPICAL_KINDS else None


def typical_kind(name: str, key: str) -> str:
    """The canonical typical kind ``name``, or a one-line ``ValueError`` naming ``key`` and the valid kinds."""
    kind = typical_kind_or_none(name)
    if kind is None:
        raise ValueError(f"{key}={name!r} is not a typical kind; valid: {', '.join(TYPICAL_KINDS)}")
    return kind


def check_scene_task(task: EnvCfg) -> tuple[str | None, list[str]]:
    """Refuse scene keys that would silently do something else; returns the canonical
    (``scene_kind``, ``scene_groups``). Pure: ``task`` is not changed."""
    scene_kind = kind_name(task.scene_kind) if task.scene_kind else task.scene_kind
    if scene_kind and not task.scene_dir:
        typical_kind(scene_kind, "task.scene_kind (without task.scene_dir)")
    groups = [kind_name(k) for k in task.scene_groups]
    if groups and task.scene_dir:
        raise ValueError("task.scene_groups builds typical scenes: it cannot be used with task.scene_dir")
    for kind in groups:
        typical_kind(kind, "task.scene_groups entry")
    if task.warmup_variants < 0:
        raise ValueError(f"task.warmup_variants={task.warmup_variants}: must be >= 0")
    if task.data is not None:
        if not task.scene_dir:
            raise ValueError(f"task.data={task.data!r} selects from a hybrid scene folder: set task.scene_dir")
        data_group(task.data)  # unknown name -> DataGroupError (a ValueError) naming the valid ones
    check_episode_cfg(task.episodes)
    if task.warmup_variants and task.scene_dir:
        raise ValueError("task.warmup_variants builds typical scenes: it cannot be used with task.scene_dir")
    bars = [b for b in GRADED_BARS if b]  # 0 is "not graded": the config says that with warmup_bar_pitch=false
    if task.warmup_bars not in bars:
        raise ValueError(f"task.warmup_bars={task.warmup_bars}: a graded warm-up holds 2 bars, or 3 where they fit")
    if task.warmup_bars != 2 and not task.warmup_bar_pitch:
        raise ValueError("task.warmup_bars counts the bars of the graded warm-ups: it needs task.warmup_bar_pitch=true")
    for key, kinds in graded_kinds(graded(task)).items():
        if not set(kinds) & {scene_kind, *groups} or not task.warmup_variants:
            either = kinds_text(kinds)
            raise ValueError(f"{key} grades {either}'s warm-ups: needs task.scene_kind (or scene_groups) with "
                             f"{either} and task.warmup_variants > 0")  # fmt: skip
    return scene_kind, groups


def graded(task: EnvCfg) -> Graded:
    """How ``task``'s warm-ups grade their types (``cat.terrain.graded.Graded``): ``task.warmup_bar_pitch`` with
    ``task.warmup_bars``, ``task.warmup_slit_offset``, ``task.warmup_slit_narrow``, ``task.warmup_slit_tight``."""
    return Graded(
        bars=task.warmup_bars if task.warmup_bar_pitch else 0,
        slit_offset=task.warmup_slit_offset,
        slit_narrow=task.warmup_slit_narrow,
        slit_tight=task.warmup_slit_tight,
    )


def scene_source(task: EnvCfg) -> SceneSource | None:
    """The scenes ``task`` trains on (checked by :func:`check_scene_task`); ``None``: flat ground.

    ``scene_dir`` reads its scene folders (only ``scene_kind`` / ``data`` when set); otherwise ``scene_groups``
    (or the one ``scene_kind``) are built as typical variants from ``scene_seed``, with ``warmup_variants``."""
    kind, groups = check_scene_task(task)
    common = dict(mirror=task.mirror_scenes, episodes=task.episodes)
    if task.scene_dir:
        return SceneSource(scene_dir=task.scene_dir, kind=kind or None, data=task.data, **common)
    if not (groups or kind):
        return None
    typical = tuple(groups) if groups else (kind,)
    return SceneSource(
        typical,
        variants=task.scene_variants,
        seed=task.scene_seed,
        warmup=task.warmup_variants,
        warmup_graded=graded(task),
        **common,
    )


def scene_set_for(
    task: EnvCfg, num_envs: int, device: str = "cpu", per_world: bool = False, storage: str = "float32"
) -> SceneSet | None:
    """The training scene set of ``task`` (``None``: flat ground): ``scene_source(task).scene_set(...)``."""
    source = scene_source(task)
    return None if source is None else source.scene_set(num_envs, device, per_world, storage)


def eval_scene_source(
    task: EnvCfg, scene_seed: int | None = None, scene_dir: str = "", scene_kind: str = "", warmup: bool = False
) -> SceneSource | None:
    """The scenes a run is evaluated on (``None``: flat ground), unless ``scene_seed`` / ``scene_dir`` /
    ``scene_kind`` override them; no mirrors, no warm-up scenes and no episode sampling (trials place the robot).

    Typical tasks rebuild their variants from ``task.scene_seed`` (not the RL seed); dataset tasks read
    ``task.scene_dir`` filtered to ``task.scene_kind`` (every data group: ``task.data`` is not applied). A run
    over several typical groups (a generalist's ``task.scene_groups``) is evaluated one group at a time:
    ``scene_kind`` names it. ``warmup``: the kind's ``task.warmup_variants`` training-only warm-up scenes instead
    of the paper's variants (``variants=0``; typical kinds only).
    """
    if warmup and (scene_dir or task.scene_dir):
        raise ValueError("warmup=true evaluates a typical kind's warm-up scenes; it cannot read scene_dir scenes")
    if scene_kind:
        task = copy.copy(task)
        task.scene_kind, task.scene_groups = typical_kind(scene_kind, "scene_kind"), []
    elif task.scene_groups and not (scene_dir or task.scene_dir):
        raise ValueError(
            f"the run trained on several scene groups {list(task.scene_groups)}: evaluate one at a time "
            f"with scene_kind=<group>"
        )
    if scene_dir or task.scene_dir:
        kind = task.scene_kind if task.scene_kind and not scene_dir else None
        return SceneSource(scene_dir=scene_dir or task.scene_dir, kind=kind)
    if task.scene_kind:
        seed = task.scene_seed if scene_seed is None else scene_seed
        if warmup:
            if task.warmup_variants < 1:
                raise ValueError(f"warmup=true: the run's task {task.scene_kind!r} has no warm-up scenes")
            for key, kinds in graded_kinds(graded(task)).items():
                if kind_name(task.scene_kind) not in kinds:
                    raise ValueError(f"{key} grades {kinds_text(kinds)}'s warm-ups, not {task.scene_kind!r}'s")
            return SceneSource(
                (task.scene_kind,),
                variants=0,
                seed=seed,
                warmup=task.warmup_variants,
                warmup_graded=graded(task),
            )
        return SceneSource((task.scene_kind,), variants=task.scene_variants, seed=seed)
    if warmup:
        raise ValueError("warmup=true needs a typical scene kind; this run trained on flat ground")
    return None
