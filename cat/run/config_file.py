"""A run's saved configuration: the ``config.yaml`` beside its checkpoints, read back (old runs upgraded) and
merged with a resume's command line. Pure config, no env or runner, so ``distill`` and ``eval`` read run configs
without importing the training loop (``cat.learning.runs``)."""

from __future__ import annotations

import os
from pathlib import Path

import yaml
from omegaconf import OmegaConf

from cat.checkpoint_io import CheckpointError, resolve_checkpoint
from cat.envs.obs_groups import upgrade_legacy_observations
from cat.run.config import TrainCfg


def save_config(cfg: TrainCfg, run_dir: Path) -> None:
    """``<run_dir>/config.yaml``: the resolved config, read back by ``load_run_config``."""
    (run_dir / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.structured(cfg)))


def load_run_config(checkpoint: str | os.PathLike) -> TrainCfg:
    """The resolved config saved beside a checkpoint."""
    ckpt = resolve_checkpoint(checkpoint)
    if not ckpt.is_file():
        raise CheckpointError(f"checkpoint not found: {ckpt}")
    cfg_file = ckpt.parent / "config.yaml"
    if not cfg_file.is_file():
        raise CheckpointError(f"no config.yaml beside checkpoint {ckpt} (expected {cfg_file})")
    raw = yaml.safe_load(cfg_file.read_text()) or {}
    task = raw.get("task") or {}
    if "scene_seed" not in task and task.get("scene_kind"):
        # runs from before task.scene_seed built their typical scenes from the RL seed: keep their scenes
        raw.setdefault("task", {})["scene_seed"] = raw.get("seed", 0)
    if raw.get("task"):
        raw["task"] = upgrade_legacy_observations(raw["task"])  # runs from before named observation groups
    schema = OmegaConf.structured(TrainCfg)
    return OmegaConf.to_object(OmegaConf.merge(schema, raw))


def resume_config(checkpoint: str | os.PathLike, overrides: list[str]) -> TrainCfg:
    """The config of the run being resumed, with only the keys given on the command line changed.

    Config-group choices (``task=``, ``sim=``, ``algo=``, ``method=``) cannot change on resume: the run keeps its
    own. The wall-clock budgets (``max_minutes``, ``deadline``) were the earlier sitting's and are not carried
    over: a budget holds only when given again.
    """
    base = OmegaConf.structured(load_run_config(checkpoint))
    # an earlier sitting's end (long past) and its minutes: a resumed run kept stopping after the old sitting's
    # max_minutes, whatever the new sitting had left (found 2026-12-05: a run resumed by the deadline runner
    # stopped after 26 of its 44 minutes)
    base.deadline, base.max_minutes = 0.0, 0.0
    dotlist = []
    for item in overrides:
        key, value = item.split("=", 1)
        if key in ("task", "sim", "algo", "method"):
            if key == "task" and value != base.task.task:
                raise ValueError(f"resume={checkpoint} continues task {base.task.task!r}; drop task={value}")
            if key == "method" and value != base.method:
                raise ValueError(f"resume={checkpoint} continues method {base.method!r}; drop method={value}")
            continue
        dotlist.append(item)
    merged = OmegaConf.merge(base, OmegaConf.from_dotlist(dotlist))
    merged.resume = str(checkpoint)
    return OmegaConf.to_object(merged)
