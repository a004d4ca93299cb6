"""Per-iteration hook on rsl_rl's logger: one quiet progress line, and the ``max_minutes`` budget.

rsl_rl prints an 80-column block with ANSI codes every iteration; by default it goes nowhere and a single log
line per iteration takes its place (``verbose=true`` restores the block). The hook runs after the update and the
iteration count are final, so a budget stop leaves a complete iteration to save.
"""

from __future__ import annotations

import logging
import statistics
import time

from rsl_rl.runners import OnPolicyRunner

from cat.run.policy import quiet_constructor

log = logging.getLogger("cat.train")


class BudgetReached(Exception):
    """Raised after the iteration that passes ``max_minutes``."""


def install_iteration_hook(runner: OnPolicyRunner, total: int, minutes: float = 0.0, verbose: bool = False) -> None:
    """Wrap ``runner.logger.log``: progress line (or rsl_rl's block if ``verbose``) and the time budget."""
    logger = runner.logger
    log_iteration = logger.log
    deadline = time.monotonic() + 60.0 * minutes if minutes > 0 else None

    def hooked(*args, **kwargs):
        it = kwargs.get("it", args[0] if args else 0)
        success = [float(e["Metrics/success_rate"]) for e in logger.ep_extras if "Metrics/success_rate" in e]
        collect, learn = kwargs.get("collect_time", 0.0), kwargs.get("learn_time", 0.0)
        with quiet_constructor(verbose):
            log_iteration(*args, **kwargs)
        if not verbose:
            steps = runner.cfg["num_steps_per_env"] * runner.env.num_envs
            rew = statistics.mean(logger.rewbuffer) if logger.rewbuffer else float("nan")
            length = statistics.mean(logger.lenbuffer) if logger.lenbuffer else float("nan")
            sr = statistics.mean(success) if success else float("nan")
            log.info(
                "it %d/%d  %.0f steps/s (collect %.1fs, learn %.1fs)  return %.2f  ep_len %.0f  success %.2f",
                it + 1, total, steps / max(collect + learn, 1e-9), collect, learn, rew, length, sr,
            )  # fmt: skip
        if deadline is not None and time.monotonic() >= deadline:
            raise BudgetReached

    logger.log = hooked
