"""``scripts/bench.py eval``: trials per second of the evaluation protocol (Table I workload by default).

One policy on the 8 typical types × ``--variants`` scenes × ``--starts`` start poses (default 80 × 10 = 800
trials of 5 s), each type in its own env of up to ``--max-envs`` parallel trials, as ``scripts/eval_table.py``
runs it. The policy is ``--checkpoint`` or, without one, a freshly initialised actor of the default layout
(same inference cost). Prints ``case=eval trials=<n> trials_per_s=<x>`` plus the wall time split into setup
(scenes, fields, envs, policy loads) and stepping.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import time

from rsl_rl.runners import OnPolicyRunner

from cat.eval.runner import EvalCfg, SceneGroup, make_eval_env, run_trials
from cat.eval.trials import scene_trials
from cat.learning.runs import load_run_config
from cat.run.config import TrainCfg, runner_cfg
from cat.run.policy import load_policy
from cat.terrain import TYPICAL_KINDS


def _policy(env, checkpoint: str | None, cfg: TrainCfg):
    with contextlib.redirect_stdout(io.StringIO()):
        if checkpoint:
            return load_policy(checkpoint, env, cfg)
        runner = OnPolicyRunner(env, runner_cfg(cfg.algo), log_dir=None, device=str(env.device))
        return runner.get_inference_policy(device=str(env.device))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="bench.py eval", description=__doc__)
    parser.add_argument("--checkpoint", default=None)
    parser.add_argument("--variants", type=int, default=10)
    parser.add_argument("--starts", type=int, default=10)
    parser.add_argument("--max-envs", type=int, default=256)
    parser.add_argument("--sim", default="mujoco")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    cfg = load_run_config(args.checkpoint) if args.checkpoint else TrainCfg()
    opts = EvalCfg(starts=args.starts, max_envs=args.max_envs)
    t0 = time.perf_counter()
    setup = stepping = 0.0
    total = 0
    for kind in TYPICAL_KINDS:
        s0 = time.perf_counter()
        group = SceneGroup.typical(kind, args.variants, 0)
        trials = scene_trials(group.scenes, opts.starts, opts.seed, opts.start_yaw_range)
        env = make_eval_env(cfg.task, group, min(len(trials), opts.max_envs), opts, sim=args.sim)
        policy = _policy(env, args.checkpoint, cfg)
        s1 = time.perf_counter()
        run_trials(env, policy, trials, seed=opts.seed)
        s2 = time.perf_counter()
        setup, stepping, total = setup + s1 - s0, stepping + s2 - s1, total + len(trials)
    wall = time.perf_counter() - t0
    print(
        f"case=eval trials={total} trials_per_s={total / wall:.2f} wall_s={wall:.1f} setup_s={setup:.1f} "
        f"stepping_s={stepping:.1f} sim={args.sim} policy={'checkpoint' if args.checkpoint else 'untrained'}"
    )
