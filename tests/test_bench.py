"""Benchmark plumbing that the speed figures rest on (no timing is asserted): the device check, the bank query
timer on the bank's own device, and the env rate."""

from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from cat.bench.fields import bench_device, median_ms
from cat.bench.scale import query_ms
from cat.bench.sim import env_rate
from cat.envs.config import EnvCfg
from cat.envs.traversal_env import TraversalEnv
from cat.fields import FieldBank, FieldCfg, Grid, SceneFields


def test_a_cuda_device_without_a_gpu_is_one_clear_error():
    if torch.cuda.is_available():
        pytest.skip("a GPU is present")
    with pytest.raises(SystemExit, match=r"--device cuda:0: .*no CUDA device"):
        bench_device("cuda:0")
    assert bench_device("cpu") == "cpu"


def test_query_timer_runs_the_query_it_times():
    rng = np.random.default_rng(0)
    grid = Grid((-1.0, -1.0, 0.0), 0.05, (40, 40, 32))
    sf = SceneFields(grid, np.array([[0.5, 0.0, 0.75]]), rng.normal(size=(*grid.shape, 4)).astype(np.float32),
                     rng.normal(size=(1, *grid.shape, 3)).astype(np.float32), FieldCfg())  # fmt: skip
    bank = FieldBank.from_scenes([sf, sf], "float16")
    calls = []
    query = bank.query
    bank.query = lambda *a, **k: calls.append(a[0].shape) or query(*a, **k)
    ms = query_ms(bank, envs=64, repeat=5)
    assert ms > 0.0 and len(calls) == 1 + 5 and all(c == (64,) for c in calls)
    assert median_ms(lambda: None, 3) >= 0.0


def test_env_rate_counts_env_steps():
    """``env_rate`` = timed steps × envs / the timed window (≥ the asked seconds, ≤ the whole call)."""
    env = TraversalEnv(EnvCfg(num_envs=4), sim="mujoco", seed=0)
    calls = []
    step = env.step
    env.step = lambda a: calls.append(a.shape) or step(a)
    t = time.perf_counter()
    rate = env_rate(env, 0.2)
    total = time.perf_counter() - t
    timed = len(calls) - 3  # after 3 warm-up steps
    assert timed >= 1 and all(c == (4, env.num_actions) for c in calls)
    assert timed * 4 / total <= rate <= timed * 4 / 0.2
