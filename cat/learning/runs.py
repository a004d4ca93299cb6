"""Run folders: build env + runner from a ``TrainCfg``, train, save, reload for play/eval."""

from __future__ import annotations

import functools
import logging
import math
import os
import shutil
import signal
import time
from dataclasses import replace
from pathlib import Path

import torch
from rsl_rl.runners import OnPolicyRunner

import cat
from cat.checkpoint_io import (  # noqa: F401  (re-exported: the checkpoint API as callers know it)
    CheckpointError,
    UnsafeCheckpointError,
    env_snapshot_path,
    plain,
    read_checkpoint,
    read_env_snapshot,
    resolve_checkpoint,
)
from cat.envs.obs_groups import resolve_groups
from cat.envs.scene_source import check_scene_task, scene_set_for
from cat.envs.sim import check_backend
from cat.envs.traversal_env import TraversalEnv
from cat.learning.distill import (
    check_student_init,
    check_teachers,
    distill_runner_cfg,
    load_specialists,
    load_student_init,
)
from cat.learning.finetune import (
    CriticWarmupPPO,
    check_actor_matches_student,
    is_student_checkpoint,
    load_student_as_actor,
)
from cat.learning.layout_init import init_from_prior
from cat.learning.precision import check_mixed_precision
from cat.learning.rehearsal import rehearsal_cfg
from cat.learning.rerun_writer import prune_metrics
from cat.learning.runners import (
    BudgetReached,
    CatDistillationRunner,
    CatOnPolicyRunner,
    StopRequested,
    stop_on_signals,
    stop_signal_received,
)
from cat.learning.warm_start import adapt_to_new_inputs
from cat.run.config import ALGOS, DistillCfg, TrainCfg, check_obs_groups, runner_cfg, student_model_cfg
from cat.run.config_file import load_run_config, resume_config, save_config  # noqa: F401  (re-exported)
from cat.run.policy import quiet_constructor

log = logging.getLogger(__name__)


def set_torch_threads(threads: int) -> None:
    """Torch intra-op threads for the whole run (0: torch's default).

    On an idle machine torch's default is fastest (2-core box: 4.35 k env steps/s incl. learning vs 3.1 k with
    one thread). On cores shared with other work, multi-threaded torch ops spin-wait on descheduled peers: there
    a PPO update took 26-46 s with 2 threads against 5-7 s with one, so pass ``torch_threads=1``.
    """
    if threads > 0:
        torch.set_num_threads(threads)


def for_this_rank(cfg: TrainCfg, environ: dict | None = None) -> TrainCfg:
    """Under ``torchrun`` (``WORLD_SIZE`` > 1: rsl_rl's multi-GPU PPO, one process per GPU), ``sim.device=cuda``
    becomes this process's ``cuda:<LOCAL_RANK>`` (rsl_rl requires exactly that) and the seed is offset by
    ``RANK`` so the processes explore differently. Single-process runs are returned unchanged."""
    env = os.environ if environ is None else environ
    world = int(env.get("WORLD_SIZE", "1"))
    if world <= 1:
        return cfg
    rank, local = int(env.get("RANK", "0")), int(env.get("LOCAL_RANK", "0"))
    device = cfg.sim.device
    if device == "cuda":
        device = f"cuda:{local}"
    if device != f"cuda:{local}":
        raise ValueError(f"torchrun (WORLD_SIZE={world}) needs sim.device=cuda (or cuda:{local}), got {device!r}")
    return replace(cfg, sim=replace(cfg.sim, device=device), seed=cfg.seed + rank)


def make_env(cfg: TrainCfg, num_envs: int | None = None) -> TraversalEnv:
    """The env of a run config (``num_envs`` overrides both the task's and the run's)."""
    n = num_envs or cfg.num_envs or cfg.task.num_envs
    task = replace(cfg.task, num_envs=n)
    sim = cfg.sim
    scenes = scene_set_for(task, n, sim.device, sim.per_world_scenes, sim.field_storage)  # cat.envs.scene_source
    fc = sim.field_contact
    return TraversalEnv(
        task, sim.backend, sim.device, scenes=scenes, seed=cfg.seed, obstacles=sim.obstacles, field_contact=fc
    )


def new_run_dir(cfg: TrainCfg) -> Path:
    """``<run_root>/<task>/<time>[_<run_name>]``, with ``-<k>`` appended if two runs start in the same second;
    or exactly ``cfg.run_dir`` when given (it must not exist, or be empty)."""
    if cfg.run_dir:
        path = Path(cfg.run_dir)
        if path.exists() and any(path.iterdir()):
            raise ValueError(f"run_dir {path} exists and is not empty")
        path.mkdir(parents=True, exist_ok=True)
        return path
    stamp = time.strftime("%Y-%m-%d_%H-%M-%S")
    name = f"{stamp}_{cfg.run_name}" if cfg.run_name else stamp
    base = Path(cfg.run_root) / cfg.task.task
    base.mkdir(parents=True, exist_ok=True)
    for k in range(1000):
        path = base / (name if k == 0 else f"{name}-{k}")
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue
    raise RuntimeError(f"could not create a fresh run folder under {base}")


def validate_train_cfg(cfg: TrainCfg) -> None:
    """Refuse values that would silently do something else (one-line ``ValueError`` naming the key)."""
    counts = {
        "num_envs": cfg.num_envs if cfg.num_envs is not None else 1,
        "task.num_envs": cfg.task.num_envs,
        "max_iterations": cfg.max_iterations,
        "algo.num_steps_per_env": cfg.algo.num_steps_per_env,
        "algo.num_learning_epochs": cfg.algo.num_learning_epochs,
        "algo.num_mini_batches": cfg.algo.num_mini_batches,
        "algo.save_interval": cfg.algo.save_interval,
    }
    for key, value in counts.items():
        if value < 1:
            raise ValueError(f"{key}={value}: must be >= 1")
    nonnegative = {
        "max_minutes": cfg.max_minutes,
        "deadline": cfg.deadline,
        "torch_threads": cfg.torch_threads,
        "algo.critic_warmup_iterations": cfg.algo.critic_warmup_iterations,
        "algo.max_noise_std": cfg.algo.max_noise_std,
    }
    for key, value in nonnegative.items():
        if value < 0:
            raise ValueError(f"{key}={value}: must be >= 0 (0 = off / default)")
    algo = cfg.algo
    # PPO's constants, where a value out of range trains something else without an error
    for key, value in {"algo.gamma": algo.gamma, "algo.lam": algo.lam}.items():
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"{key}={value}: must be in [0, 1]")
    for key in ("learning_rate", "clip_param", "init_noise_std"):
        if not 0.0 < getattr(algo, key) < math.inf:
            raise ValueError(f"algo.{key}={getattr(algo, key)}: must be > 0")
    for key in ("entropy_coef", "value_loss_coef", "max_grad_norm", "mirror_loss_coeff"):
        if getattr(algo, key) < 0:
            raise ValueError(f"algo.{key}={getattr(algo, key)}: must be >= 0")
    cfg.task.scene_kind, cfg.task.scene_groups = check_scene_task(cfg.task)  # canonical kind names
    if cfg.task.episode_length_s <= 0:
        raise ValueError(f"task.episode_length_s={cfg.task.episode_length_s}: must be > 0")
    if cfg.algo.critic_warmup_iterations > 0 and cfg.algo.critic_warmup_learning_rate <= 0:
        raise ValueError(f"algo.critic_warmup_learning_rate={cfg.algo.critic_warmup_learning_rate}: must be > 0")
    env_groups = resolve_groups(cfg.task.observations)
    check_obs_groups(cfg.algo.obs_groups, env_groups)  # names, before any env is built
    if cfg.algo.name not in ALGOS:
        raise ValueError(f"algo.name={cfg.algo.name!r}; valid: {', '.join(ALGOS)}")
    rehearses = cfg.algo.name == "ppo" and cfg.algo.rehearsal.learning_rate > 0
    if cfg.algo.name == "distill" or rehearses:
        _check_teacher_groups(cfg.algo.distill, env_groups, student=not rehearses)
    if rehearses:
        r = cfg.algo.rehearsal
        if not cfg.teachers:
            raise ValueError("algo.rehearsal.learning_rate > 0 needs teachers=[<specialist checkpoint>,...]")
        for key, value in (("num_learning_epochs", r.num_learning_epochs), ("num_mini_batches", r.num_mini_batches)):
            if value < 1:
                raise ValueError(f"algo.rehearsal.{key}={value}: must be >= 1")
    elif cfg.algo.rehearsal.learning_rate < 0:
        raise ValueError(f"algo.rehearsal.learning_rate={cfg.algo.rehearsal.learning_rate}: must be >= 0 (0 = off)")
    if cfg.algo.name == "distill":
        d = cfg.algo.distill
        student_model_cfg(d)  # checks algo.distill.student
        if not 0.0 <= d.teacher_drive_prob <= 1.0:
            raise ValueError(f"algo.distill.teacher_drive_prob must be in [0, 1], got {d.teacher_drive_prob}")
        if not cfg.teachers:
            raise ValueError("algo=distill needs teachers=[<specialist checkpoint>,...]")
        if cfg.algo.symmetry_augment or cfg.algo.mirror_loss_coeff > 0:
            raise ValueError("rsl_rl's Distillation rejects symmetry: set algo.symmetry_augment=false")
    elif cfg.teachers and not rehearses:
        raise ValueError("teachers= is for algo=distill, or PPO with algo.rehearsal.learning_rate > 0")
    check_backend(cfg.sim.backend)
    # a resumed run's init= is history (its weights are in the checkpoint): only the file to read is checked
    path = cfg.resume or cfg.init
    if path:
        ckpt = read_checkpoint(path)
        if cfg.resume and env_snapshot_path(path).is_file():
            read_env_snapshot(env_snapshot_path(path), map_location="cpu")  # an unsafe one: refused before any env
        if cfg.resume and "optimizer_state_dict" not in ckpt:
            raise CheckpointError(
                f"resume={path}: it holds no optimiser state (shipped with weights_only=true), so the run cannot "
                "continue exactly; start a new run from it with init= instead"
            )
        if not cfg.resume and cfg.algo.name == "distill":
            if not is_student_checkpoint(ckpt):
                raise ValueError(
                    f"init={path}: a distillation starts from an earlier student (a distillation checkpoint), "
                    "not a PPO policy; name PPO specialists in teachers=[...]"
                )
            check_student_init(cfg, load_run_config(path), str(path))
        elif not cfg.resume and is_student_checkpoint(ckpt):
            check_actor_matches_student(cfg, load_run_config(path), str(path))


def _check_teacher_groups(d: DistillCfg, env_groups: dict[str, list[str]], student: bool) -> None:
    """The observation groups the teachers (and a student) read, and the route group, are built by the env."""
    keys = (("student_groups", d.student_groups),) if student else ()
    for key, groups in (*keys, ("teacher_groups", d.teacher_groups)):
        for g in groups or [None]:
            if g not in env_groups:
                raise ValueError(
                    f"algo.distill.{key} names observation group {g!r} that the env does not build; "
                    f"groups (task.observations): {', '.join(env_groups)}"
                )
    if d.route_group not in env_groups or env_groups[d.route_group] != ["scene_group"]:
        raise ValueError(
            f"algo.distill.route_group={d.route_group!r} must be an observation group of exactly the "
            "scene_group term (task.observations)"
        )


def make_runner(cfg: TrainCfg, env: TraversalEnv, log_dir: str | None) -> OnPolicyRunner:
    """rsl_rl's PPO runner, or for ``algo=distill`` its ``DistillationRunner`` with the multi-teacher loaded, as
    ``cat.learning.runners`` extends them: checkpoints carry ``_training_state`` and an env snapshot."""
    state = functools.partial(_training_state, env, cfg)
    if cfg.algo.name == "distill":
        train_cfg = distill_runner_cfg(cfg, env.scene_group_names)
        runner = CatDistillationRunner(env, train_cfg, log_dir, str(env.device), state=state)
        runner.alg.teacher_loaded = True  # MultiTeacher loaded and checked every specialist on construction
        return runner
    train_cfg = runner_cfg(cfg.algo, env.obs_groups, rehearsal_cfg(cfg, env.scene_group_names))
    return CatOnPolicyRunner(env, train_cfg, log_dir=log_dir, device=str(env.device), state=state)


def load_into_runner(runner: OnPolicyRunner, path: str, load_cfg: dict | None = None) -> dict | None:
    """rsl_rl's ``runner.load`` (weights, optimiser, iteration per ``load_cfg``; strict) with the file read by the
    safe loader: rsl_rl's own ``load`` unpickles with ``weights_only=False``. Returns the checkpoint's ``infos``."""
    ckpt = read_checkpoint(path, map_location=None)  # tensors where they were saved, as rsl_rl's load
    if runner.alg.load(ckpt, load_cfg, True):
        runner.current_learning_iteration = ckpt["iter"]
    return ckpt.get("infos")


def _training_state(env: TraversalEnv, cfg: TrainCfg) -> dict:
    """What a resumed run needs beyond rsl_rl's checkpoint: RNG streams, the env's curriculum, and the configured
    learning rate (a resume that gives another one replaces the optimiser's)."""
    return {
        "torch_rng": torch.get_rng_state(),
        "env_rng": env.generator.get_state(),
        "configured_lr": configured_learning_rate(cfg),
        **env.training_state(),
    }


def configured_learning_rate(cfg: TrainCfg) -> float:
    """The learning rate the config asks for (PPO's start value, or the distillation student's)."""
    return cfg.algo.distill.learning_rate if cfg.algo.name == "distill" else cfg.algo.learning_rate


def _restore_training_state(
    runner: OnPolicyRunner, env: TraversalEnv, cfg: TrainCfg, infos: dict | None, run_lr: float
) -> None:
    """A learning rate configured other than the run's (``infos``' ``configured_lr``, else ``run_lr`` from the
    run's config.yaml) was given on the resume's command line and replaces the optimiser's; otherwise the
    optimiser (and PPO's adaptive schedule) continues from the rate in use, not the configured start value."""
    checkpoint = cfg.resume
    lr = configured_learning_rate(cfg)
    if lr != (infos or {}).get("configured_lr", run_lr):
        for group in runner.alg.optimizer.param_groups:
            group["lr"] = lr
        log.info("resume: learning rate set to %g (given on the command line)", lr)
    runner.alg.learning_rate = runner.alg.optimizer.param_groups[0]["lr"]
    if not infos:
        log.warning("checkpoint has no training state (RNG, curriculum): continuing from fresh streams")
        return
    env.load_training_state(infos)
    snap = env_snapshot_path(checkpoint)
    if snap.is_file():
        try:
            env.set_state(read_env_snapshot(snap))  # an unsafe snapshot raises: never a silent fresh start
        except (ValueError, KeyError) as err:
            log.warning("env snapshot %s not usable (%s): the resumed run starts fresh episodes", snap, err)
    else:
        log.warning("no env snapshot %s: the resumed run starts fresh episodes", snap)
    torch.set_rng_state(infos["torch_rng"])
    env.generator.set_state(infos["env_rng"])


def budget_minutes(cfg: TrainCfg) -> float:
    """The wall-clock minutes left from now: ``max_minutes`` and what ``deadline`` leaves, the lesser (0: none)."""
    budgets = [cfg.max_minutes] if cfg.max_minutes > 0 else []
    if cfg.deadline > 0:
        budgets.append(max((cfg.deadline - time.time()) / 60.0, 1e-6))
    return min(budgets, default=0.0)


def train(cfg: TrainCfg) -> Path | None:
    """Train PPO per ``cfg``; returns the run folder (config.yaml, model_*.pt, metrics.rrd, metrics.csv).

    ``cfg.resume`` continues that checkpoint's run in its own folder (iteration count, optimiser, normaliser,
    RNG, curriculum) up to ``max_iterations`` in total; ``cfg.max_minutes`` > 0 stops after the iteration that
    passes the budget and saves it, so one training can span several sittings. ``cfg.deadline`` (Unix time) is
    such an end too; a job that starts after it runs and writes nothing and returns None. A stop signal
    (``stop_on_signals``) saves after the iteration in progress; later runs in the same process then return None.
    """
    validate_train_cfg(cfg)
    if cfg.deadline > 0 and time.time() >= cfg.deadline:
        log.info("deadline passed before the run started: nothing run (%s)", cfg.resume or cfg.run_dir or "new run")
        return None
    if (signum := stop_signal_received()) is not None:  # a sweep or sitting in this process was told to stop
        what = cfg.resume or cfg.run_dir or "new run"
        log.info("%s stopped an earlier run in this process: nothing run (%s)", signal.Signals(signum).name, what)
        return None
    cfg = for_this_rank(cfg)
    torch.manual_seed(cfg.seed)
    set_torch_threads(cfg.torch_threads)
    check_mixed_precision(cfg.algo.mixed_precision, cfg.sim.device)
    env = make_env(cfg)  # before any folder exists: a bad scene or model leaves nothing behind
    if cfg.teachers:  # distillation, or PPO that rehearses the teachers of some scene groups
        every = cfg.algo.name == "distill"
        check_teachers(load_specialists(list(cfg.teachers)), cfg, env.scene_group_names, every_group=every)
    run_dir = Path(cfg.resume).parent if cfg.resume else new_run_dir(cfg)
    try:
        return _train_in(cfg, env, run_dir)
    except BaseException:
        if not cfg.resume and not any(run_dir.glob("model_*.pt")):
            shutil.rmtree(run_dir, ignore_errors=True)  # no half-made run folder
        raise


def _train_in(cfg: TrainCfg, env: TraversalEnv, run_dir: Path) -> Path:
    run_lr = configured_learning_rate(load_run_config(cfg.resume)) if cfg.resume else 0.0
    if not cfg.resume:  # a resume rewrites the run's config.yaml only once it stands
        save_config(cfg, run_dir)
    log.info("run folder: %s", run_dir)
    with quiet_constructor(cfg.verbose):
        runner = make_runner(cfg, env, str(run_dir))
    runner.logger.git_status_repos = [cat.__file__]  # record this project's commit and diff in <run>/git/
    if cfg.resume:
        _restore_training_state(runner, env, cfg, load_into_runner(runner, cfg.resume), run_lr)
        save_config(cfg, run_dir)
        runner.current_learning_iteration += 1  # the checkpoint's iteration is complete
        dropped = prune_metrics(run_dir / "metrics.csv", runner.current_learning_iteration)
        if dropped:
            log.info("metrics.csv: dropped %d rows logged after the checkpoint (redone now)", dropped)
        log.info("resumed %s at iteration %d", cfg.resume, runner.current_learning_iteration)
    elif cfg.init and cfg.algo.name == "distill":
        load_student_init(runner.alg, read_checkpoint(cfg.init), cfg.init)  # a generalist grows by scene groups
    elif cfg.init and is_student_checkpoint(ckpt := read_checkpoint(cfg.init)):
        # the student knows its inputs: nothing to adapt (finetune.py)
        load_student_as_actor(runner, ckpt, cfg.init, cfg.algo.init_noise_std)
    elif cfg.init:
        init_from_prior(runner.alg, env, cfg.init)  # strict, or where the layouts agree (layout_init.py)
        runner.current_learning_iteration = 0
        adapt_to_new_inputs(runner.alg, env)  # inputs the prior never saw vary (warm_start.py)
        log.info("initialised weights from %s", cfg.init)
    remaining = cfg.max_iterations - runner.current_learning_iteration
    if remaining <= 0:
        log.info(
            "nothing to do: the run is at iteration %d of %d", runner.current_learning_iteration, cfg.max_iterations
        )
        return run_dir
    if isinstance(runner.alg, CriticWarmupPPO):
        runner.alg.start_at(runner.current_learning_iteration)
    runner.logger.set_budget(cfg.max_iterations, budget_minutes(cfg), cfg.verbose)
    try:
        with quiet_constructor(cfg.verbose), stop_on_signals():  # quiet: rsl_rl's "Storing git diff"
            runner.learn(remaining, init_at_random_ep_len=not cfg.resume)
    except BudgetReached as stop:
        it = runner.current_learning_iteration
        runner.save(str(run_dir / f"model_{it}.pt"))
        runner.logger.stop_logging_writer()
        if isinstance(stop, StopRequested):
            log.info("stopped by %s: saved model_%d.pt; resume=%s continues", stop, it, run_dir / f"model_{it}.pt")
            return run_dir
        end = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(cfg.deadline)) if cfg.deadline > 0 else "none"
        log.info(
            "time budget reached (max_minutes=%g, deadline %s): saved model_%d.pt; resume=%s continues",
            cfg.max_minutes,
            end,
            it,
            run_dir / f"model_{it}.pt",
        )
    return run_dir
