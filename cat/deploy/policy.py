"""What drives the robot: an rsl_rl PPO checkpoint (its actor, deterministic) or ``hold`` (zero actions).

A checkpoint comes with the ``config.yaml`` of its run beside it (``cat.learning.runs.load_run_config``): the
actor's observation terms, the field-observation settings and the network shape are read from there, so the
demo builds the same observation the policy was trained on.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from rsl_rl.utils import resolve_class
from tensordict import TensorDict

from cat.envs.config import EnvCfg
from cat.learning.config import TrainCfg, runner_cfg
from cat.learning.runs import CheckpointError, load_run_config, read_checkpoint, resolve_checkpoint

HOLD = "hold"


@dataclass
class PolicySpec:
    """A checkpoint path (or ``hold``) and the task config its observations follow."""

    checkpoint: str
    task: EnvCfg
    run: TrainCfg | None  # None for hold

    @property
    def is_hold(self) -> bool:
        return self.run is None


def policy_spec(checkpoint: str) -> PolicySpec:
    """Resolve ``checkpoint=``: ``hold``, a ``model_*.pt`` with its run's ``config.yaml`` beside it, or a run
    folder (its latest checkpoint)."""
    if checkpoint == HOLD:
        return PolicySpec(HOLD, EnvCfg(), None)
    path = resolve_checkpoint(checkpoint)
    run = load_run_config(path)  # CheckpointError when the file or its config.yaml is missing
    return PolicySpec(str(path), run.task, run)


class HoldPolicy:
    """Zero actions: the incremental PD targets stay at the default standing pose."""

    def __init__(self, num_actions: int):
        self.num_actions = num_actions

    def __call__(self, obs: TensorDict) -> torch.Tensor:
        return torch.zeros(obs.batch_size[0], self.num_actions)


def load_actor(spec: PolicySpec, obs: TensorDict, num_actions: int):
    """The checkpoint's actor as a deterministic callable ``obs -> actions`` for observations shaped like ``obs``.

    Built from the run's network config and loaded strictly: a checkpoint of another observation layout or
    a file that is not an rsl_rl checkpoint raises ``CheckpointError`` with the reason."""
    if spec.is_hold:
        return HoldPolicy(num_actions)
    path = spec.checkpoint
    state = read_checkpoint(path)  # CheckpointError: missing, corrupt, not an rsl_rl checkpoint
    actor_class, actor_cfg = resolve_class(runner_cfg(spec.run.algo)["actor"])
    actor = actor_class(obs, {"actor": ["actor"]}, "actor", num_actions, **actor_cfg)
    try:
        actor.load_state_dict(state["actor_state_dict"], strict=True)
    except (RuntimeError, KeyError) as err:
        raise CheckpointError(f"checkpoint {path} does not match the demo's observation/policy: {err}") from err
    actor.eval()
    return actor
