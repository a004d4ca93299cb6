"""The fall metric broken down: when each trial fell, how far along its way, and whether it had touched first.

A policy that collapses at its first step (observations it never saw, e.g. a floor obstacle in a field block
trained on empty ones) and one that trips on the last bar have the same fall rate; the fall time and the progress
at the fall tell them apart (``scripts/play.py falls=true``). Read from the trial metrics the env already keeps
(``cat.envs.trial_metrics``): the fall rule, the contact flag and the root-goal distance.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from cat.envs.trial_metrics import TrialResult
from cat.eval.contacts import first_trials_of

_KEYS = ("time", "progress", "touched")


class Falls:
    """``on_step`` hook for ``cat.eval.runner.run_trials``: per trial, the time of the fall [s] (``inf``: none in
    the window), the progress at it (1 − root-goal distance then / at the start: 0 where it started, 1 at the
    goal, negative when it walked away) and whether it had touched an obstacle by then."""

    def __init__(self, env):
        self._batches: list[dict[str, torch.Tensor]] = []

    def on_step(self, env) -> None:
        tr = env.trial
        if int(env.step_count[0]) == 0:  # run_trials placed a new batch (world 0 is in every batch)
            n = env.num_envs
            self._batches.append(
                {
                    "start": env.goal_distance.detach().cpu().clone(),
                    "time": torch.full((n,), math.inf),
                    "progress": torch.full((n,), math.nan),
                    "touched": torch.zeros(n, dtype=torch.bool),
                }
            )
        b = self._batches[-1]
        new = tr.fell.cpu() & torch.isinf(b["time"])
        if not new.any():
            return
        b["time"][new] = env.step_count.cpu()[new].float() * env.dt
        b["progress"][new] = 1.0 - env.goal_distance.cpu()[new] / b["start"][new].clamp_min(1e-6)
        b["touched"][new] = tr.collided.cpu()[new]

    def records(self, num_trials: int) -> list[tuple[float, float, bool]]:
        """``(fall time [s], progress, touched)`` of the first ``num_trials`` trials in order (``inf``, ``nan``,
        False: no fall)."""
        cols = [torch.cat([b[k] for b in self._batches]).tolist() if self._batches else [] for k in _KEYS]
        return first_trials_of(list(zip(*cols, strict=True)), num_trials)


def falls_line(results: list[TrialResult], records: list[tuple[float, float, bool]]) -> str:
    """``falls=<n>/<N> fall_time_s=<q25>/<median>/<q75> fall_progress_median=<x> falls_without_contact=<k>``."""
    fell = [rec for r, rec in zip(results, records, strict=True) if r.fell]
    if not fell:
        return f"falls=0/{len(results)}"
    times = np.array([t for t, _, _ in fell])
    q25, q50, q75 = (float(np.percentile(times, q)) for q in (25, 50, 75))
    progress = float(np.median([p for _, p, _ in fell]))
    untouched = sum(not touched for _, _, touched in fell)
    return (
        f"falls={len(fell)}/{len(results)} fall_time_s={q25:.2f}/{q50:.2f}/{q75:.2f} "
        f"fall_progress_median={progress:.2f} falls_without_contact={untouched}"
    )
