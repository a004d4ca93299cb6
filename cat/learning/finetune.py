"""PPO fine-tuning of a distilled student (``algo=ppo_student init=<distillation checkpoint>``).

DAgger copies its teachers only where the student's own states resemble theirs: contact ends an episode, so a
student that touches the first wall of a hard passage is never taught what lies behind it (docs/distillation.md).
PPO on the student's own observations optimises the task itself. The student's network becomes PPO's actor
(same rsl_rl ``MLPModel``, same observation groups); the critic is new, reads the privileged groups, and learns
alone for ``algo.critic_warmup_iterations`` first: advantages from an untrained critic are noise, and a PPO step
on noise moves a trained actor away from what it learned.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import torch
from rsl_rl.algorithms import PPO
from rsl_rl.runners import OnPolicyRunner

from cat.run.config import TrainCfg

log = logging.getLogger(__name__)


def is_student_checkpoint(ckpt: dict) -> bool:
    """A distillation checkpoint: it holds a student and no PPO actor."""
    return "student_state_dict" in ckpt and "actor_state_dict" not in ckpt


def check_actor_matches_student(cfg: TrainCfg, student_cfg: TrainCfg, path: str) -> None:
    """PPO's actor must be the student's network on the student's groups (one-line ``ValueError`` saying which
    override makes it so)."""
    d = student_cfg.algo.distill
    if d.student != "mlp":
        raise ValueError(f"init={path}: a {d.student} student cannot initialise PPO's actor (an MLPModel)")
    actor = cfg.algo
    wanted = {
        "algo.actor_hidden_dims": (list(actor.actor_hidden_dims), list(d.hidden_dims)),
        "algo.obs_groups.actor": (list(actor.obs_groups.get("actor", [])), list(d.student_groups)),
        "algo.activation": (actor.activation, student_cfg.algo.activation),
        "algo.obs_normalization": (actor.obs_normalization, student_cfg.algo.obs_normalization),
    }
    for key, (have, need) in wanted.items():
        if have != need:
            raise ValueError(f"init={path} is a distilled student: PPO's actor needs {key}={need} (got {have})")


def load_student_as_actor(runner: OnPolicyRunner, ckpt: dict, path: str, noise_std: float) -> None:
    """Copy the student's weights (normaliser, MLP) into PPO's actor, with action noise ``noise_std``; the critic
    stays untrained. The student's own std is DAgger's fixed acting noise (``algo.distill.init_noise_std``), never
    learned, so PPO's exploration is set here (``algo.init_noise_std``)."""
    actor = runner.alg.actor
    try:
        actor.load_state_dict(ckpt["student_state_dict"], strict=True)
    except RuntimeError as err:
        first = str(err).splitlines()[0]
        raise ValueError(f"init={path}: the student does not fit PPO's actor ({first})") from err
    dist = actor.distribution
    with torch.no_grad():
        if dist.std_type == "log":
            dist.log_std_param.fill_(math.log(noise_std))
        else:
            dist.std_param.fill_(noise_std)
    log.info(
        "init: PPO's actor is the distilled student of %s (action std %g); the critic starts untrained",
        Path(path).name,
        noise_std,
    )


class CriticWarmupPPO(PPO):
    """rsl_rl's PPO whose updates, for the run's iterations below ``critic_warmup_iterations``, train the critic
    only, at the fixed ``critic_warmup_learning_rate`` and without value clipping; from then on the actor learns
    too, from the configured learning rate, schedule and clipping. Named by ``cat.run.config.runner_cfg`` through
    the algorithm's ``class_name`` when ``algo.critic_warmup_iterations`` > 0; ``start_at`` tells it the run's
    iteration before learning (a resumed run past the warm-up is plain PPO).

    Why each: the adaptive schedule reads the actor's KL, ~0 while it is frozen, and would raise the rate to its
    ceiling; PPO's clipped value loss keeps every value within ``clip_param`` of its rollout-time estimate per
    update, a brake that suits a trained critic and leaves a new one hundreds of updates from its targets."""

    def __init__(self, *args, critic_warmup_iterations: int = 0, critic_warmup_learning_rate: float = 1e-3, **kw):
        super().__init__(*args, **kw)
        self.warmup_iterations, self.warmup_rate = critic_warmup_iterations, critic_warmup_learning_rate
        self.configured_rate, self.iteration = self.learning_rate, 0

    def start_at(self, iteration: int) -> None:
        """The run's iteration at which learning (re)starts."""
        self.iteration = iteration
        if iteration < self.warmup_iterations:
            log.info(
                "critic warm-up: the actor is frozen for iterations %d-%d (critic rate %g, no value clipping)",
                iteration,
                self.warmup_iterations - 1,
                self.warmup_rate,
            )

    @property
    def actor_frozen(self) -> bool:
        """Whether the next update is a warm-up one (the critic alone)."""
        return self.iteration < self.warmup_iterations

    def _set_rate(self, lr: float) -> None:
        self.learning_rate = lr
        for group in self.optimizer.param_groups:
            group["lr"] = lr

    def update(self) -> dict[str, float]:
        warm = self.actor_frozen
        self.iteration += 1
        if not warm:
            return super().update()
        trainable = [p for p in self.actor.parameters() if p.requires_grad]
        for p in trainable:
            p.requires_grad_(False)  # Adam skips parameters without gradients: the actor is untouched
        schedule, clipped = self.schedule, self.use_clipped_value_loss
        self.schedule, self.use_clipped_value_loss = "fixed", False
        self._set_rate(self.warmup_rate)
        try:
            return super().update()
        finally:
            for p in trainable:
                p.requires_grad_(True)
            self.schedule, self.use_clipped_value_loss = schedule, clipped
            if self.iteration == self.warmup_iterations:
                self._set_rate(self.configured_rate)
                log.info("critic warm-up done after %d iterations: the actor learns from now on", self.iteration)
