"""Which robot body touches an obstacle first in each trial: the collision metric broken down by body.

A hurdle policy that lands its feet on the bar and a crouch policy that hits the lintel with its head have the same
collision rate; the first-contact body tells them apart (``scripts/play.py contacts=true``). Read from the
per-body obstacle contact sensors the env model carries (``cat.envs.scene.part_obstacle_sensor``).
"""

from __future__ import annotations

from collections import Counter

import torch

from cat.envs.scene import PART_SENSOR_PREFIX


class FirstContacts:
    """``on_step`` hook for ``cat.eval.runner.run_trials``: records, per trial, the bodies in contact at the
    trial's first step with any robot-obstacle contact ("+"-joined when several touch at once; None: no contact).
    """

    def __init__(self, env):
        sensors = env.sim.sensors
        names = sorted(n for n in sensors if n.startswith(PART_SENSOR_PREFIX))
        if not names:
            raise ValueError("the env model has no per-body obstacle contact sensors (a run on flat ground?)")
        self.bodies = [n.removeprefix(PART_SENSOR_PREFIX) for n in names]
        self._cols = torch.tensor([sensors[n].adr for n in names])
        self._batches: list[list[str | None]] = []

    def on_step(self, env) -> None:
        if int(env.step_count[0]) == 0:  # run_trials placed a new batch (world 0 is in every batch)
            self._batches.append([None] * env.num_envs)
        slot = self._batches[-1]
        touching = (env.sim.sensordata[:, self._cols.to(env.sim.sensordata.device)] > 0).cpu()
        for i in touching.any(dim=1).nonzero().flatten().tolist():
            if slot[i] is None:
                slot[i] = "+".join(b for b, t in zip(self.bodies, touching[i].tolist(), strict=True) if t)

    def first_bodies(self, num_trials: int) -> list[str | None]:
        """The first ``num_trials`` records in trial order (a short last batch leaves its idle envs out)."""
        flat = [b for batch in self._batches for b in batch]
        if len(flat) < num_trials:
            raise ValueError(f"recorded {len(flat)} trial slots, fewer than the {num_trials} trials asked for")
        return flat[:num_trials]


def contact_line(first: list[str | None]) -> str:
    """``first_contact=<body>:<trials>,...`` (most frequent first) over the trials with a contact, e.g.
    ``first_contact=left_ankle_roll_link:53,right_knee_link:2 trials_with_contact=55/60``."""
    hits = [b for b in first if b is not None]
    counts = ",".join(f"{b}:{k}" for b, k in Counter(hits).most_common())
    return f"first_contact={counts or 'none'} trials_with_contact={len(hits)}/{len(first)}"
