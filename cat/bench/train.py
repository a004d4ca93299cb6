"""``scripts/bench.py train``: PPO training throughput (env steps/s including learning) vs raw MuJoCo.

Runs ``iterations`` PPO iterations of the flat task (after one warm-up iteration) exactly as ``train`` does,
without writing a run folder, and compares with raw ``mujoco.rollout`` of the same model in the same process.
"""

from __future__ import annotations

import argparse
import logging
import time

from rsl_rl.runners import OnPolicyRunner

from cat.bench.sim import raw_rate
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import make_env, set_torch_threads
from cat.run.config import runner_cfg


def ppo_rate(env, cfg, iterations: int) -> float:
    """Env steps/s of ``iterations`` PPO iterations (rollout + update) on ``env``, after one warm-up iteration."""
    runner = OnPolicyRunner(env, runner_cfg(cfg.algo), log_dir=None, device=str(env.device))
    runner.learn(1, init_at_random_ep_len=True)  # warm-up
    start = time.perf_counter()
    runner.learn(iterations)
    return iterations * cfg.algo.num_steps_per_env * env.num_envs / (time.perf_counter() - start)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="bench.py train", description=__doc__)
    parser.add_argument("--num-envs", type=int, default=1024)
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=5.0, help="duration of the raw MuJoCo measurement")
    parser.add_argument("overrides", nargs="*", help="train.py overrides, e.g. algo.symmetry_augment=true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    cfg = load_config(["task=flat", f"num_envs={args.num_envs}", *args.overrides])
    set_torch_threads(cfg.torch_threads)
    env = make_env(cfg)
    x = ppo_rate(env, cfg, args.iterations)
    y = raw_rate(env.sim.model, env.num_envs, env.robot.decimation, args.seconds)
    print(f"case=train num_envs={env.num_envs} env_steps_per_s={x:.0f} raw_env_steps_per_s={y:.0f} ratio={x / y:.2f}")
