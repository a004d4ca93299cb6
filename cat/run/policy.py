"""The policy network a checkpoint holds: built from its run's ``policy_model`` and loaded strictly.

One loader for every consumer: evaluation, play and teachers (``load_policy``, for an env), the deploy runtime
and the ONNX export (``cat.deploy.policy``).
"""

from __future__ import annotations

import contextlib
import io
import os

import torch
from tensordict import TensorDict

from cat.checkpoint_io import CheckpointError, read_checkpoint
from cat.envs.symmetry import mirror_augment
from cat.envs.traversal_env import TraversalEnv
from cat.run.config import TrainCfg, policy_model


def quiet_constructor(verbose: bool):
    """Context that swallows rsl_rl's model printout unless ``verbose``."""
    return contextlib.nullcontext() if verbose else contextlib.redirect_stdout(io.StringIO())


def load_policy_network(
    checkpoint: str | os.PathLike, run: TrainCfg, obs: TensorDict, num_actions: int, state: dict | None = None
):
    """The run's policy network (PPO actor or distilled student; deterministic, eval mode) for observations
    shaped like ``obs``, loaded strictly from ``checkpoint`` (or its already read dict ``state``).

    Raises ``CheckpointError`` naming the file when it lacks the run's weights or they do not fit the network."""
    pm = policy_model(run.algo)
    state = state if state is not None else read_checkpoint(checkpoint)
    if pm.state_key not in state:
        raise CheckpointError(
            f"{checkpoint}: no {pm.state_key} (its run is algo.name={run.algo.name}; keys: {', '.join(state)})"
        )
    with quiet_constructor(False):
        model = pm.build(obs, num_actions)
    try:
        model.load_state_dict(state[pm.state_key], strict=True)
    except (RuntimeError, KeyError) as err:
        lines = str(err).splitlines()
        first = lines[1].strip() if len(lines) > 1 else str(err)
        raise CheckpointError(
            f"checkpoint {checkpoint} does not match the observation layout / network: {first}"
        ) from None
    return model.eval()


def load_policy(checkpoint: str | os.PathLike, env: TraversalEnv, cfg: TrainCfg):
    """Deterministic inference policy of a checkpoint (PPO actor or distilled student) for ``env``: called on the
    env's observation ``TensorDict``; ``reset()`` clears a recurrent student's memory."""
    missing = [g for g in policy_model(cfg.algo).obs_groups if g not in env.obs_groups]
    if missing:
        raise CheckpointError(
            f"checkpoint {checkpoint} reads observation group {missing[0]!r} that this env does not build "
            f"(groups: {', '.join(env.obs_groups)})"
        )
    return load_policy_network(checkpoint, cfg, env.get_observations(), env.num_actions).to(env.device)


class MirrorAveraged(torch.nn.Module):
    """``pi_sym(o) = (pi(o) + M_a pi(M_o o)) / 2``: a policy made exactly left/right equivariant at inference
    (``cat.envs.symmetry``: the mirror of an observation gives the mirror of the action). A lateralised policy
    (one that leads with the left foot) plays both sides alike; a symmetric one is unchanged."""

    def __init__(self, policy: torch.nn.Module, env: TraversalEnv):
        super().__init__()
        if getattr(policy, "is_recurrent", False):
            raise CheckpointError("symmetric=true needs a feed-forward policy (a recurrent one keeps one memory)")
        self.policy, self.env = policy, env

    def forward(self, obs: TensorDict) -> torch.Tensor:
        both, _ = mirror_augment(self.env, obs)  # originals, then their mirror images: one forward pass
        a, b = self.policy(both).split(obs.batch_size[0])
        return 0.5 * (a + self.env.mirror_map.mirror_actions(b))
