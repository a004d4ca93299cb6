"""Where each trial went: the root's path through its scene, step by step, beside the summary metrics.

The summary says a policy fails an offset slit; the path says how: where the root stood and which way it faced
when it reached the wall, when it first touched, when it fell (``scripts/play.py paths=<file.csv>``; the side-hurdle
diagnosis in docs/results.md reads it). Poses are in the scene's own frame (the frame of its mesh, start and goal),
so paths of one scene overlay whichever world played them.
"""

from __future__ import annotations

import csv
from pathlib import Path

import torch

from cat.envs.math_utils import yaw_from_quat
from cat.envs.trial_metrics import TrialResult
from cat.eval.contacts import first_trials_of
from cat.eval.trials import Trial

COLUMNS = ("trial", "scene", "goal", "step", "time_s", "x", "y", "z", "yaw", "touched", "fell", "success")
"""The CSV's columns: one row per trial and control step (step 0: the placed start). ``touched`` / ``fell``: the
trial had touched an obstacle / fallen by that step; ``success``: the trial's outcome, repeated on each row."""


class Paths:
    """``on_step`` hook for ``cat.eval.runner.run_trials``: per trial and control step, the root's ``x, y, z`` [m]
    and yaw [rad] in the scene's frame, and whether the trial had touched an obstacle or fallen by then."""

    def __init__(self, env):
        offsets = env.scenes.offsets if env.scenes is not None else None
        self._offsets = None if offsets is None else torch.as_tensor(offsets, dtype=torch.float32)
        self._batches: list[list[torch.Tensor]] = []

    def on_step(self, env) -> None:
        if int(env.step_count[0]) == 0:  # run_trials placed a new batch (world 0 is in every batch)
            self._batches.append([])
        q = env.sim.qpos[:, :7].detach().float().cpu()
        pos = q[:, :3].clone()
        if self._offsets is not None:
            pos -= self._offsets[env.scenes.scene_of_env.cpu().long()]
        tr = env.trial
        row = torch.cat(
            [
                pos,
                yaw_from_quat(q[:, 3:7])[:, None],
                tr.collided.cpu()[:, None].float(),
                tr.fell.cpu()[:, None].float(),
            ],
            dim=1,
        )
        self._batches[-1].append(row)

    def paths(self, num_trials: int) -> list[torch.Tensor]:
        """Each trial's (steps + 1, 6) path ``x, y, z, yaw, touched, fell``, in trial order."""
        flat = [path for batch in self._batches for path in torch.stack(batch, dim=1)]
        return first_trials_of(flat, num_trials)


def write_paths(
    out: str | Path, trials: list[Trial], results: list[TrialResult], paths: list[torch.Tensor], dt: float
) -> Path:
    """Write ``COLUMNS`` to ``out`` (a temporary file renamed into place: never half a file); returns the path."""
    out = Path(out)
    if not out.resolve().parent.is_dir():
        raise ValueError(f"paths={out}: folder {out.resolve().parent} does not exist")
    if not len(trials) == len(results) == len(paths):
        raise ValueError(f"{len(trials)} trials, {len(results)} results and {len(paths)} paths: must be equal")
    tmp = out.with_name(out.name + ".part")
    with tmp.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for k, (t, r, p) in enumerate(zip(trials, results, paths, strict=True)):
            for step, (x, y, z, yaw, touched, fell) in enumerate(p.tolist()):
                w.writerow([k, t.scene, t.goal, step, f"{step * dt:.3f}", f"{x:.4f}", f"{y:.4f}", f"{z:.4f}",
                            f"{yaw:.4f}", int(touched), int(fell), int(r.success)])  # fmt: skip
    tmp.replace(out)
    return out
