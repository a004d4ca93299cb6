"""Roll out a checkpoint for N episodes and report success rate / return (optionally record to rerun)."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tqdm import tqdm

from cat.learning.runs import load_policy, load_run_config, make_env


@dataclass
class PlayCfg:
    checkpoint: str = "???"
    episodes: int = 10
    num_envs: int = 0  # 0 = min(episodes, 64)
    sim: str = ""  # override the run's backend
    seed: int = 1
    record: str = ""  # .rrd path: record world 0 of the rollout for rerun replay (`rerun <file>`)


@dataclass
class PlayResult:
    episodes: int
    success_rate: float
    mean_return: float
    distance_error: float
    collision_rate: float


def play(cfg: PlayCfg) -> PlayResult:
    run_cfg = load_run_config(cfg.checkpoint)
    run_cfg.seed = cfg.seed
    if cfg.sim:
        run_cfg.sim.backend = cfg.sim
    n = cfg.num_envs or min(cfg.episodes, 64)
    env = make_env(run_cfg, num_envs=n)
    policy = load_policy(cfg.checkpoint, env, run_cfg)
    recorder = None
    if cfg.record:
        from cat.viz.record import RolloutRecorder

        recorder = RolloutRecorder(cfg.record, env)
    obs = env.get_observations()
    ret = torch.zeros(n, device=env.device)
    returns, success, de, coll = [], [], [], []
    bar = tqdm(total=cfg.episodes, desc="episodes", unit="ep")
    with torch.inference_mode():
        while len(returns) < cfg.episodes:
            obs, rew, dones, extras = env.step(policy(obs))
            ret += rew
            if recorder is not None:
                recorder.log_step(env)
            ids = dones.nonzero(as_tuple=False).flatten()
            if len(ids):
                ended = extras["episode_end"]
                for j, i in enumerate(ids.tolist()):
                    if len(returns) >= cfg.episodes:
                        break
                    returns.append(float(ret[i]))
                    success.append(bool(ended["success"][j]))
                    de.append(float(ended["distance_error"][j]))
                    coll.append(bool(ended["collided"][j]))
                    bar.update(1)
                ret[ids] = 0.0
    bar.close()
    if recorder is not None:
        recorder.close()
    k = len(returns)
    return PlayResult(
        episodes=k,
        success_rate=sum(success) / k,
        mean_return=sum(returns) / k,
        distance_error=sum(de) / k,
        collision_rate=sum(coll) / k,
    )
