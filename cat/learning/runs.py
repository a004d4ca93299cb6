"""Run folders: build env + runner from a ``TrainCfg``, train, save, reload for play/eval."""

from __future__ import annotations

import logging
import os
import time
from dataclasses import replace
from pathlib import Path

import torch
import yaml
from omegaconf import OmegaConf
from rsl_rl.runners import OnPolicyRunner

from cat.envs.sim import BACKENDS
from cat.envs.traversal_env import TraversalEnv
from cat.learning.config import TrainCfg, runner_cfg

log = logging.getLogger(__name__)


class CheckpointError(FileNotFoundError):
    """A checkpoint or its run folder is missing or unreadable."""


def make_env(cfg: TrainCfg, num_envs: int | None = None) -> TraversalEnv:
    """The env of a run config (``num_envs`` overrides both the task's and the run's)."""
    n = num_envs or cfg.num_envs or cfg.task.num_envs
    task = replace(cfg.task, num_envs=n)
    scenes = None
    if task.scene_dir or task.scene_kind:
        from cat.envs.scene_set import SceneSet

        if task.scene_dir:
            scenes = SceneSet.from_dir(task.scene_dir, num_envs=n, device=cfg.sim.device, kind=task.scene_kind)
        else:
            scenes = SceneSet.typical(task.scene_kind, n, task.scene_variants, cfg.seed, device=cfg.sim.device)
    return TraversalEnv(task, sim=cfg.sim.backend, device=cfg.sim.device, scenes=scenes, seed=cfg.seed)


def new_run_dir(cfg: TrainCfg) -> Path:
    stamp = time.strftime("%Y-%m-%d_%H-%M-%S")
    name = f"{stamp}_{cfg.run_name}" if cfg.run_name else stamp
    path = Path(cfg.run_root) / cfg.task.task / name
    path.mkdir(parents=True, exist_ok=False)
    return path


def save_config(cfg: TrainCfg, run_dir: Path) -> None:
    (run_dir / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.structured(cfg)))


def load_run_config(checkpoint: str | os.PathLike) -> TrainCfg:
    """The resolved config saved beside a checkpoint."""
    ckpt = Path(checkpoint)
    if not ckpt.is_file():
        raise CheckpointError(f"checkpoint not found: {ckpt}")
    cfg_file = ckpt.parent / "config.yaml"
    if not cfg_file.is_file():
        raise CheckpointError(f"no config.yaml beside checkpoint {ckpt} (expected {cfg_file})")
    schema = OmegaConf.structured(TrainCfg)
    return OmegaConf.to_object(OmegaConf.merge(schema, yaml.safe_load(cfg_file.read_text())))


def train(cfg: TrainCfg) -> Path:
    """Train PPO per ``cfg``; returns the run folder (config.yaml, model_*.pt, metrics.rrd)."""
    torch.manual_seed(cfg.seed)
    if cfg.sim.backend not in BACKENDS:
        raise ValueError(f"unknown sim backend {cfg.sim.backend!r}; valid: {', '.join(BACKENDS)}")
    for path in (cfg.init, cfg.resume):
        if path and not Path(path).is_file():
            raise CheckpointError(f"checkpoint not found: {path}")
    run_dir = new_run_dir(cfg)
    save_config(cfg, run_dir)
    log.info("run folder: %s", run_dir)
    env = make_env(cfg)
    runner = OnPolicyRunner(env, runner_cfg(cfg.algo), log_dir=str(run_dir), device=str(env.device))
    if cfg.resume:
        runner.load(cfg.resume)
        log.info("resumed from %s at iteration %d", cfg.resume, runner.current_learning_iteration)
    elif cfg.init:
        runner.load(cfg.init, load_cfg={"actor": True, "critic": True}, strict=True)
        runner.current_learning_iteration = 0
        log.info("initialised weights from %s", cfg.init)
    runner.learn(cfg.max_iterations, init_at_random_ep_len=True)
    return run_dir


def load_policy(checkpoint: str | os.PathLike, env: TraversalEnv, cfg: TrainCfg):
    """Deterministic inference policy of a PPO checkpoint for ``env``."""
    runner = OnPolicyRunner(env, runner_cfg(cfg.algo), log_dir=None, device=str(env.device))
    try:
        runner.load(str(checkpoint), load_cfg={"actor": True}, strict=True)
    except (RuntimeError, KeyError) as err:
        raise CheckpointError(f"checkpoint {checkpoint} does not match this env/policy: {err}") from err
    return runner.get_inference_policy(device=str(env.device))
