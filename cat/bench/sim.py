"""``scripts/bench.py sim``: full env steps/s per backend vs raw ``mujoco.rollout`` of the same model.

Env steps include observations, rewards, terminations and auto-resets (the policy is excluded: actions are
uniform noise). Raw is MuJoCo C ``rollout`` on all cores, same model, same decimation, measured in the same run.
``--device cuda:0`` runs the warp backend there (MuJoCo C always runs on the CPU); ``--envs`` replaces the default
sizes, e.g. ``--backends warp --device cuda:0 --envs 1024 4096 16384`` on a GPU.
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

from cat.bench.fields import bench_device, device_sync
from cat.envs.config import EnvCfg
from cat.envs.traversal_env import TraversalEnv

SIZES = {"mujoco": (64, 256, 1024), "warp": (64, 256)}


def env_rate(env: TraversalEnv, seconds: float) -> float:
    """Env steps/s under uniform random actions (drawn on the CPU, moved to the env's device); CUDA is
    synchronised before the clock stops."""
    gen = torch.Generator().manual_seed(0)
    sync = device_sync(env.device)

    def act(scale: float) -> torch.Tensor:
        return (scale * (2 * torch.rand(env.num_envs, env.num_actions, generator=gen) - 1)).to(env.device)

    for _ in range(3):  # warm-up (and Warp compile)
        env.step(act(1.0))
    sync()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.step(act(0.3))
        steps += 1
    sync()
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
    parser.add_argument("--envs", type=int, nargs="+", default=None, help="env counts (default: per backend)")
    parser.add_argument("--device", default="cpu", help="cpu or cuda[:i], for sim=warp")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    device = bench_device(args.device)
    if device != "cpu" and "mujoco" in args.backends:
        raise SystemExit(f"--device {args.device}: MuJoCo C runs on the CPU; use --backends warp")
    for backend in args.backends:
        for n in args.envs or SIZES[backend]:
            env = TraversalEnv(EnvCfg(num_envs=n), sim=backend, device=device)
            x = env_rate(env, args.seconds)
            y = raw_rate(env.sim.model, n, env.robot.decimation, args.seconds)
            print(
                f"sim={backend} num_envs={n} env_steps_per_s={x:.0f} raw_env_steps_per_s={y:.0f} ratio={x / y:.2f}"
                f" device={device}",
                flush=True,
            )
            del env
