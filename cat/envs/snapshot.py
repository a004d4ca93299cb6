"""Env snapshots: everything that makes the next step of every env what it would have been (physics, episode
bookkeeping, scene / goal / model assignment, observations and their history), for an exact training resume
(``env_<it>.pt`` beside a checkpoint, ``cat.learning.runs``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch
from tensordict import TensorDict

from cat.envs.mdp import events

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv

FIELDS = (
    "targets", "actions", "prev_actions", "goals", "phase", "gait_freq", "episode_length_buf", "step_count",
    "push_timer", "field_obs_buf", "kp", "kd", "dr_scales",
)  # fmt: skip

FORMAT = 2  # bump when get_state's content changes


def get_state(env: TraversalEnv) -> dict:
    """Everything that makes the next step of every env what it would have been: physics, episode
    bookkeeping, scene/goal assignment and the current observations (an exact training resume)."""
    snap = {name: getattr(env, name).clone() for name in FIELDS}
    snap["format"] = FORMAT
    snap["episode_sums"] = {k: v.clone() for k, v in env.episode_sums.items()}
    snap["trial"] = env.trial.state_dict()
    snap["common_step"] = env.common_step
    snap["sim"] = env.sim.get_state()
    snap["obs"] = {k: v.clone() for k, v in env.obs_buf.items()}  # plain dict: the safe loader reads it back
    if env.observation_groups.buffers:  # groups with history (absent otherwise: older snapshots stay valid)
        snap["obs_history"] = env.observation_groups.state_dict()
    if env.scenes is not None:
        snap["scene_of_env"] = env.scenes.scene_of_env.clone()
        snap["goal_idx"] = env.scenes._goal_idx.clone()
        snap["field_idx"] = env.field_source.field_idx.clone()
    if env.world_models is not None:  # per-world scenes (which model each world steps: snap["sim"])
        snap["world_model_scales"] = env.world_models.scales.clone()
    if env.odometry is not None:  # odometry drift (absent otherwise: older snapshots stay valid)
        snap["odometry_error"] = env.odometry.error.clone()
        snap["field_obs_odom_buf"] = env.field_obs_odom_buf.clone()
    return snap


def _shape_mismatches(snap: dict, current: dict, prefix: str = ""):
    """(key, snapshot shape, env shape) of every tensor, nested dicts included, whose shapes differ."""
    for key, want in current.items():
        have = snap.get(key)
        if isinstance(want, dict) and isinstance(have, dict):
            yield from _shape_mismatches(have, want, f"{prefix}{key}.")
        elif isinstance(want, torch.Tensor) and isinstance(have, torch.Tensor) and have.shape != want.shape:
            yield f"{prefix}{key}", tuple(have.shape), tuple(want.shape)


def set_state(env: TraversalEnv, snap: dict) -> None:
    """Restore ``get_state``'s snapshot (same task and number of envs); checked before anything changes."""
    if snap.get("format") != FORMAT:
        raise ValueError(f"env snapshot format {snap.get('format')} is not this code's {FORMAT}")
    current = get_state(env)
    missing = sorted(set(current) - set(snap))
    if missing:
        raise ValueError(f"env snapshot lacks {', '.join(missing)}")
    if snap["targets"].shape != env.targets.shape:
        raise ValueError(f"env snapshot of {snap['targets'].shape[0]} envs cannot restore {env.num_envs} envs")
    if set(snap["episode_sums"]) != set(env.episode_sums):
        raise ValueError("env snapshot has other reward terms than this env")
    if "world_model_scales" in snap and env.world_models is None:
        raise ValueError("env snapshot of per-world scenes (sim.per_world_scenes=true) cannot restore tiles")
    if "odometry_error" in snap and env.odometry is None:
        raise ValueError("env snapshot has odometry drift (field_block_odometry with noise on); this env has none")
    if env.world_models is not None and snap["world_model_scales"].shape != env.world_models.scales.shape:
        raise ValueError("env snapshot has another per-world model pool (scenes x domain_rand.pool_size)")
    for key, have, want in _shape_mismatches(snap, current):
        raise ValueError(f"env snapshot's {key} has shape {have}, this env's {want} (another model or task)")
    for name in FIELDS:
        getattr(env, name).copy_(snap[name])
    for k, v in snap["episode_sums"].items():
        env.episode_sums[k].copy_(v)
    env.trial.load_state_dict(snap["trial"])
    if env.odometry is not None:
        env.odometry.error.copy_(snap["odometry_error"])
        env.field_obs_odom_buf.copy_(snap["field_obs_odom_buf"])
    env.common_step = snap["common_step"]
    if env.world_models is not None:
        env.world_models.set_scales(snap["world_model_scales"])
    elif env.cfg.domain_rand.enabled:
        events.apply_physics_scales(env, torch.arange(env.num_envs), env.dr_scales)
    env.sim.set_state(snap["sim"])
    if env.scenes is not None:
        env.scenes.scene_of_env.copy_(snap["scene_of_env"])
        env.scenes._goal_idx.copy_(snap["goal_idx"])
        env.field_source.field_idx.copy_(snap["field_idx"])
    env._update_state()
    env._update_field()
    obs = snap["obs"]  # a plain dict of groups (a TensorDict in snapshots from before the safe loader)
    env.obs_buf = TensorDict({k: v.clone() for k, v in obs.items()}, batch_size=[env.num_envs], device=env.device)
    if "obs_history" in snap:
        env.observation_groups.load_state_dict(snap["obs_history"])
