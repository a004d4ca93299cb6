"""rsl_rl's runners extended by subclass (issue 29: nothing is patched on a live object).

``CatOnPolicyRunner`` / ``CatDistillationRunner`` are rsl_rl's ``OnPolicyRunner`` / ``DistillationRunner`` with:

* a ``ProgressLogger``: rsl_rl prints an 80-column block with ANSI codes every iteration; by default it goes
  nowhere and a single log line per iteration takes its place (``verbose=true`` restores the block), and the
  ``max_minutes`` budget raises ``BudgetReached`` after the iteration that passes it (the update and the iteration
  count are final then, so a budget stop leaves a complete iteration to save); a stop signal (SIGTERM, SIGUSR1,
  SIGINT: a kill, a scheduler's notice, Ctrl-C) does the same after the iteration it arrives in (``stop_on_signals``;
  a second one stops at once);
* checkpoints that also carry what a resume needs beyond rsl_rl's (RNG streams, curriculum: ``state()``, stored
  in ``infos``) and an env snapshot file beside them.

PPO's own extension, the critic warm-up of a fine-tuned student, is ``cat.learning.finetune.CriticWarmupPPO``,
named through the algorithm config's ``class_name``.
"""

from __future__ import annotations

import logging
import signal
import statistics
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import torch
from rsl_rl.runners import DistillationRunner, OnPolicyRunner
from rsl_rl.utils.logger import Logger

from cat.checkpoint_io import env_snapshot_path, plain
from cat.run.policy import quiet_constructor

log = logging.getLogger("cat.train")


class BudgetReached(Exception):
    """Raised after the iteration that passes ``max_minutes``."""


class StopRequested(BudgetReached):
    """Raised after the iteration in which a stop signal arrived: saved like a budget stop, so the run resumes."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


STOP_SIGNALS = (signal.SIGTERM, signal.SIGUSR1, signal.SIGINT)  # a kill, a scheduler's notice, Ctrl-C
_stopped_by: int | None = None  # the stop signal this process received, if any (process-wide, as signals are)


def stop_signal_received() -> int | None:
    """The stop signal a run of this process received (a later run in the same process does not start), or None."""
    return _stopped_by


def clear_stop_signal() -> None:
    """Forget a received stop signal (for a process that goes on training after one, e.g. a test)."""
    global _stopped_by
    _stopped_by = None


class ProgressLogger(Logger):
    """rsl_rl's ``Logger``: one quiet progress line per iteration (or rsl_rl's block if ``verbose``) and the time
    budget set by ``set_budget`` (none until then)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.total, self.verbose, self.deadline = 0, False, None
        self.steps_per_iteration = self.cfg["num_steps_per_env"] * self.num_envs

    def set_budget(self, total: int, minutes: float = 0.0, verbose: bool = False) -> None:
        """``total`` iterations in the run (for the progress line); ``minutes`` > 0: the budget starts now."""
        self.total, self.verbose = total, verbose
        self.deadline = time.monotonic() + 60.0 * minutes if minutes > 0 else None

    def log(self, *args, **kwargs) -> None:
        it = kwargs.get("it", args[0] if args else 0)
        success = [float(e["Metrics/success_rate"]) for e in self.ep_extras if "Metrics/success_rate" in e]
        collect, learn = kwargs.get("collect_time", 0.0), kwargs.get("learn_time", 0.0)
        with quiet_constructor(self.verbose):
            super().log(*args, **kwargs)
        if not self.verbose:
            rew = statistics.mean(self.rewbuffer) if self.rewbuffer else float("nan")
            length = statistics.mean(self.lenbuffer) if self.lenbuffer else float("nan")
            sr = statistics.mean(success) if success else float("nan")
            log.info(
                "it %d/%d  %.0f steps/s (collect %.1fs, learn %.1fs)  return %.2f  ep_len %.0f  success %.2f",
                it + 1, self.total, self.steps_per_iteration / max(collect + learn, 1e-9), collect, learn, rew,
                length, sr,
            )  # fmt: skip
        if _stopped_by is not None:
            raise StopRequested(_stopped_by)
        if self.deadline is not None and time.monotonic() >= self.deadline:
            raise BudgetReached


def _request_stop(signum: int, frame=None) -> None:
    """Signal handler: the training stops after the current iteration (``StopRequested``, raised by the logger); a
    second signal stops now (KeyboardInterrupt)."""
    global _stopped_by
    name = signal.Signals(signum).name
    if _stopped_by is not None:
        raise KeyboardInterrupt(f"second {name}: stopping without saving")
    _stopped_by = signum
    log.warning("%s received: finishing this iteration, then saving (again: stop now, unsaved)", name)


@contextmanager
def stop_on_signals(signals: tuple[int, ...] = STOP_SIGNALS) -> Iterator[None]:
    """While inside, ``signals`` stop the training after the iteration (and save) instead of killing the process;
    the previous handlers come back on exit. Only the main thread can own handlers: elsewhere (a thread pool's
    worker) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in signals}
    for s in signals:
        signal.signal(s, _request_stop)
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


class _CatRunner:
    """What both runners add (module docstring). ``state``: the training state a checkpoint carries in ``infos``
    (tensors and plain data: the safe loader reads it); ``None``: rsl_rl's checkpoints, no env snapshot."""

    def __init__(self, env, train_cfg: dict, log_dir: str | None = None, device: str = "cpu", *, state=None):
        super().__init__(env, train_cfg, log_dir=log_dir, device=device)
        self.state: Callable[[], dict] | None = state
        self.logger = ProgressLogger(
            log_dir=log_dir,
            cfg=self.cfg,
            env_cfg=self.env.cfg,
            num_envs=self.env.num_envs,
            is_distributed=self.is_distributed,
            gpu_world_size=self.gpu_world_size,
            gpu_global_rank=self.gpu_global_rank,
            device=self.device,
        )

    def save(self, path: str, infos: dict | None = None) -> None:
        if self.state is None:
            return super().save(path, infos=infos)
        super().save(path, infos=plain(self.state()))
        torch.save(plain(self.env.get_state()), env_snapshot_path(path))


class CatOnPolicyRunner(_CatRunner, OnPolicyRunner):
    """rsl_rl's PPO runner with the progress logger and resumable checkpoints."""


class CatDistillationRunner(_CatRunner, DistillationRunner):
    """rsl_rl's distillation runner with the progress logger and resumable checkpoints."""
