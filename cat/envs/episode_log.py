"""What an env logs about the episodes that just ended (rsl_rl's ``extras["log"]``, written to metrics.csv)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv


def episode_log(env: TraversalEnv, ids: torch.Tensor) -> dict[str, torch.Tensor]:
    """Means over the ended episodes ``ids``: each reward term per second of episode, the trial metrics
    (``cat.envs.trial_metrics``: success, reached, distance error, collision, fall), the termination causes, and
    with several scene groups the success per group (``Metrics/success_rate/<group>``: a mixed run is watched on
    each kind of scene, e.g. the typical types beside the hybrid scenes)."""
    length_s = (env.step_count[ids].to(torch.float32) * env.dt).clamp_min(env.dt)
    out = {f"Episode_Reward/{k}": (v[ids] / length_s).mean() for k, v in env.episode_sums.items()}
    tr = env.trial
    success = tr.success(ids)
    out["Metrics/success_rate"] = success.float().mean()
    if env.scenes is not None and len(env.scenes.group_names) > 1:
        groups = env.scenes.groups_of_envs()[ids.cpu()]
        for g in groups.unique().tolist():
            out[f"Metrics/success_rate/{env.scenes.group_names[g]}"] = (
                success[(groups == g).to(success.device)].float().mean()
            )
    out["Metrics/reached_rate"] = torch.isfinite(tr.reach_time[ids]).float().mean()
    out["Metrics/distance_error"] = tr.distance_error(ids).mean()
    out["Metrics/collision_rate"] = tr.collided[ids].float().mean()
    out["Metrics/fall_rate"] = tr.fell[ids].float().mean()
    for name, flags in env.termination_flags.items():  # the causes, as fractions of the ended episodes
        out[f"Episode_Termination/{name}"] = flags[ids].float().mean()
    out["Episode_Termination/time_out"] = (env.episode_length_buf[ids] >= env.max_episode_length).float().mean()
    return out
