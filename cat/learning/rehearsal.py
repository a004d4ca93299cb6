"""PPO that rehearses its teachers (``algo.rehearsal.learning_rate`` > 0 with ``teachers=[...]``, issue 28).

PPO fine-tuning of a distilled generalist on new scenes gains on them for 50-100 updates and then slowly loses the
skills its typical teachers gave it (docs/results.md, "v4 and its own PPO fine-tune, averaged"). Averaging the
weights back afterwards (WiSE-FT, ``scripts/average.py``) recovers part of it; here the skills are kept during
training instead: after every PPO update the actor imitates, on the rollout's own states, the specialist of each
scene group that has one (DAgger's labels on PPO's visitation), with its own Adam. Groups without a teacher (the
hybrid scenes) learn from PPO alone. The two phases alternate as in phasic policy gradient's auxiliary phase: PPO's
update stays rsl_rl's, unchanged, and the imitation never enters its ratio or KL.
"""

from __future__ import annotations

import logging
import os
from typing import Any

import torch
import torch.nn as nn
from rsl_rl.utils import reduce_gradients_in_buckets
from tensordict import TensorDict

from cat.learning.distill import MultiTeacher
from cat.learning.finetune import CriticWarmupPPO
from cat.run.config import TrainCfg

log = logging.getLogger(__name__)


def rehearsal_cfg(cfg: TrainCfg, group_names: list[str]) -> dict[str, Any] | None:
    """The ``rehearsal`` entry of the algorithm's runner config for a PPO run of ``cfg`` on an env whose scene
    groups are ``group_names`` (None: rehearsal off)."""
    r = cfg.algo.rehearsal
    if cfg.algo.name != "ppo" or r.learning_rate <= 0:
        return None
    d = cfg.algo.distill
    return {
        "checkpoints": [os.fspath(c) for c in cfg.teachers],
        "group_names": list(group_names),
        "teacher_groups": list(d.teacher_groups),
        "route_group": d.route_group,
        "action_clip": cfg.task.action_clip,
        "learning_rate": r.learning_rate,
        "num_learning_epochs": r.num_learning_epochs,
        "num_mini_batches": r.num_mini_batches,
        "max_grad_norm": r.max_grad_norm,
    }


class RehearsalPPO(CriticWarmupPPO):
    """``CriticWarmupPPO`` (a warm-up of 0 iterations is plain PPO) followed, once the actor learns, by an
    imitation phase on the rollout's labelled states; its mean loss is logged as ``Loss/rehearsal``. Named by
    ``cat.run.config.runner_cfg`` when the run rehearses."""

    def __init__(self, *args, rehearsal: dict[str, Any], **kw):
        super().__init__(*args, **kw)
        r = dict(rehearsal)
        sample = self.storage.observations[0]  # a TensorDict of every env group, shaped as one step
        self.teacher = MultiTeacher(
            sample,
            {"teacher": list(r["teacher_groups"])},
            "teacher",
            int(self.storage.actions.shape[-1]),
            checkpoints=list(r["checkpoints"]),
            group_names=list(r["group_names"]),
            route_group=r["route_group"],
            action_clip=r["action_clip"],
        ).to(self.device)
        self.rehearsal_optimizer = torch.optim.Adam(self.actor.parameters(), lr=r["learning_rate"])
        self.rehearsal_epochs, self.rehearsal_batches = int(r["num_learning_epochs"]), int(r["num_mini_batches"])
        self.rehearsal_grad_norm = float(r["max_grad_norm"])
        taught = [g for g, k in zip(r["group_names"], self.teacher.route.tolist(), strict=False) if k >= 0]
        log.info("rehearsal: the actor imitates %d teacher(s) on scene groups %s", len(self.teacher.teachers), taught)

    def update(self) -> dict[str, float]:
        learns = not self.actor_frozen  # read before the warm-up counts this update
        states = self._labelled_states() if learns else None  # before PPO's update recycles the storage
        out = super().update()
        # every rank of a multi-GPU run takes the same steps (their gradients are averaged), labelled states or not
        if states is not None and (len(states[1]) > 0 or self.is_multi_gpu):
            out["rehearsal"] = self._rehearse(*states)
        return out

    @torch.no_grad()
    def _labelled_states(self) -> tuple[TensorDict, torch.Tensor]:
        """The rollout's states whose scene group has a teacher (the actor's groups only) and their labels."""
        obs = self.storage.observations.flatten(0, 1)
        labels, labelled = self.teacher.label(obs)
        index = labelled.nonzero().squeeze(1)
        return obs.select(*self.actor.obs_groups)[index], labels[index]

    def _rehearse(self, obs: TensorDict, labels: torch.Tensor) -> float:
        """``num_learning_epochs`` x ``num_mini_batches`` MSE steps of the actor's mean toward the labels (a
        mini-batch may be empty on a rank with few labelled states: its gradient is zero, and the ranks' gradients
        are averaged before each step as PPO's are); returns the mean loss."""
        n, params = labels.shape[0], list(self.actor.parameters())
        total = 0.0
        for _ in range(self.rehearsal_epochs):
            for chunk in torch.randperm(n, device=labels.device).tensor_split(self.rehearsal_batches):
                loss = (self.actor(obs[chunk]) - labels[chunk]).pow(2).sum() / max(chunk.numel() * labels.shape[1], 1)
                self.rehearsal_optimizer.zero_grad()
                loss.backward()
                if self.is_multi_gpu:
                    reduce_gradients_in_buckets(params, self.gpu_world_size, self.grad_reduce_bucket_mb)
                nn.utils.clip_grad_norm_(params, self.rehearsal_grad_norm)
                self.rehearsal_optimizer.step()
                total += loss.item()
        return total / (self.rehearsal_epochs * self.rehearsal_batches)

    def save(self) -> dict:
        return {**super().save(), "rehearsal_optimizer_state_dict": self.rehearsal_optimizer.state_dict()}

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        resumed = super().load(loaded_dict, load_cfg, strict)
        wants = load_cfg is None or load_cfg.get("optimizer")
        if wants and "rehearsal_optimizer_state_dict" in loaded_dict:
            self.rehearsal_optimizer.load_state_dict(loaded_dict["rehearsal_optimizer_state_dict"])
        return resumed
