"""The collision metric broken down: which robot body touches an obstacle first, and how deep contacts go.

A hurdle policy that lands its feet on the bar and a crouch policy that hits the lintel with its head have the same
collision rate; the first-contact body tells them apart (``scripts/play.py contacts=true``). Read from the
per-body obstacle contact sensors the env model carries (``cat.envs.scene.part_obstacle_sensor``).

The paper counts a trial with any collision as failed but does not say how a collision is detected; the authors'
release trains with an episode ending only when a body point is 4 cm inside an obstacle. ``Clearance`` measures,
per trial, the deepest penetration of the robot's collision shapes (the field-contact judgement's exact capsule
distances on the contact SDF, ``cat.envs.field_contact``), so the success rate can be read at a depth tolerance
too (``scripts/play.py clearance=true``): how much of the failure is grazing contact.
"""

from __future__ import annotations

import math
from collections import Counter

import mujoco
import numpy as np
import torch

from cat.envs.field_contact import FieldContact, FieldContactCfg, body_poses, fill_contact_sdf
from cat.envs.scene import PART_SENSOR_PREFIX
from cat.envs.trial_metrics import TrialResult

TOLERANCES = (0.01, 0.02, 0.04)
"""m: the depth tolerances ``clearance_line`` reads the success rate at (0.04: the release's training rule)."""


def first_trials_of(flat: list, num_trials: int) -> list:
    """The first ``num_trials`` of an ``on_step`` hook's per-slot records, concatenated over batches in trial order
    (a short last batch leaves its idle envs out); too few slots is an error, never a short list."""
    if len(flat) < num_trials:
        raise ValueError(f"recorded {len(flat)} trial slots, fewer than the {num_trials} trials asked for")
    return flat[:num_trials]


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
        return first_trials_of([b for batch in self._batches for b in batch], num_trials)


def contact_line(first: list[str | None]) -> str:
    """``first_contact=<body>:<trials>,...`` (most frequent first) over the trials with a contact, e.g.
    ``first_contact=left_ankle_roll_link:53,right_knee_link:2 trials_with_contact=55/60``."""
    hits = [b for b in first if b is not None]
    return f"first_contact={contact_counts(first)} trials_with_contact={len(hits)}/{len(first)}"


def contact_counts(first: list[str | None]) -> str:
    """``<body>:<trials>,...`` over the trials with a contact, most frequent first (``none``: no contact)."""
    return ",".join(f"{b}:{k}" for b, k in Counter(b for b in first if b is not None).most_common()) or "none"


class Clearance:
    """``on_step`` hook for ``cat.eval.runner.run_trials``: per trial, the smallest signed distance between the
    robot's collision shapes and the obstacles over the trial's control steps until a fall (negative: the deepest
    penetration), judged as ``sim.obstacles=field`` judges contact (capsule axes and sphere centres at SDF − radius on
    each scene's contact SDF; body poses by MuJoCo's forward kinematics of each world's state)."""

    def __init__(self, env):
        if env.scenes is None:
            raise ValueError("clearance=true needs obstacle scenes; this run plays on flat ground")
        model = env.sim.model
        self.fc = FieldContact(model, env.robot, FieldContactCfg())
        fill_contact_sdf(env.scenes, self.fc.cfg)
        self._model, self._data = model, mujoco.MjData(model)
        self._batches: list[torch.Tensor] = []

    def on_step(self, env) -> None:
        if int(env.step_count[0]) == 0:  # run_trials placed a new batch (world 0 is in every batch)
            self._batches.append(torch.full((env.num_envs,), math.inf))
        tr = env.trial
        active = ((env.step_count <= tr.window) & ~tr.fell).cpu()
        if not active.any():
            return
        ids = active.nonzero().flatten()
        pos, quat = body_poses(self._model, self.fc.bodies, env.sim.qpos[ids].cpu().numpy(), self._data)
        idx = env.field_source.field_idx[ids.to(env.field_source.field_idx.device)]
        sdf = self.fc.body_sdf(env.scenes.bank, idx, pos, quat).amin(-1).cpu()
        slot = self._batches[-1]
        slot[ids] = torch.minimum(slot[ids], sdf)

    def clearances(self, num_trials: int) -> list[float]:
        """Each trial's smallest signed distance [m] (``inf``: never near an obstacle), in trial order."""
        return first_trials_of(torch.cat(self._batches).tolist() if self._batches else [], num_trials)


def tolerant_success(results: list[TrialResult], clearance: list[float], tolerance: float) -> float:
    """Success rate when contacts shallower than ``tolerance`` [m] are ignored: reached within the window, no fall,
    no penetration deeper than ``tolerance``."""
    ok = [
        math.isfinite(r.reach_time) and not r.fell and c > -tolerance for r, c in zip(results, clearance, strict=True)
    ]
    return sum(ok) / max(len(ok), 1)


def clearance_line(results: list[TrialResult], clearance: list[float]) -> str:
    """``tolerant_success=1cm:<x>,2cm:<x>,4cm:<x> deepest_mm_median=<x> (trials with contact)``."""
    rates = ",".join(f"{round(t * 100)}cm:{tolerant_success(results, clearance, t):.3f}" for t in TOLERANCES)
    deep = [-1000.0 * c for r, c in zip(results, clearance, strict=True) if r.collided and math.isfinite(c)]
    median = f"{float(np.median(deep)):.1f}" if deep else "nan"
    return f"tolerant_success={rates} deepest_mm_median={median} contact_trials={len(deep)}"
