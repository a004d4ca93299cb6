"""``scripts/bench.py sim``: full env steps/s per backend vs raw ``mujoco.rollout`` of the same model.

Env steps include observations, rewards, terminations and auto-resets (the policy is excluded: actions are
uniform noise). Raw is MuJoCo C ``rollout`` on all cores, same model, same decimation, measured in the same run.
"""

from __future__ import annotations

import argparse
import logging
import os
import time

import mujoco
import numpy as np
import torch
from mujoco import rollout

from cat.envs.config import EnvCfg
from cat.envs.traversal_env import TraversalEnv

SIZES = {"mujoco": (64, 256, 1024), "warp": (64, 256)}


def env_rate(env: TraversalEnv, seconds: float) -> float:
    gen = torch.Generator().manual_seed(0)
    for _ in range(3):  # warm-up (and Warp compile)
        env.step(2 * torch.rand(env.num_envs, env.num_actions, generator=gen) - 1)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.step(0.3 * (2 * torch.rand(env.num_envs, env.num_actions, generator=gen) - 1))
        steps += 1
    return steps * env.num_envs / (time.perf_counter() - start)


def raw_rate(model: mujoco.MjModel, num_envs: int, decimation: int, seconds: float) -> float:
    """Raw MuJoCo: rollout of ``decimation`` steps per call from the home keyframe, no env logic."""
    nthread = os.cpu_count() or 1
    runner = rollout.Rollout(nthread=nthread)
    datas = [mujoco.MjData(model) for _ in range(nthread)]
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.zeros((num_envs, mujoco.mj_stateSize(model, spec)))
    mujoco.mj_getState(model, d, state0[0], spec)
    state0[:] = state0[0]
    ctrl = np.tile(d.ctrl, (num_envs, decimation, 1))
    out_s = np.zeros((num_envs, decimation, state0.shape[1]))
    out_d = np.zeros((num_envs, decimation, model.nsensordata))
    models = [model] * num_envs
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        runner.rollout(models, datas, state0, ctrl, skip_checks=True, nstep=decimation, state=out_s, sensordata=out_d)
        state0[:] = out_s[:, -1]
        calls += 1
    return calls * num_envs / (time.perf_counter() - start)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="bench.py sim", description=__doc__)
    parser.add_argument("--backends", nargs="+", default=["mujoco", "warp"])
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    for backend in args.backends:
        for n in SIZES[backend]:
            env = TraversalEnv(EnvCfg(num_envs=n), sim=backend)
            x = env_rate(env, args.seconds)
            y = raw_rate(env.sim.model, n, env.robot.decimation, args.seconds)
            print(f"sim={backend} num_envs={n} env_steps_per_s={x:.0f} raw_env_steps_per_s={y:.0f} ratio={x / y:.2f}")
            del env
