"""``scripts/bench.py learner``: wall-clock of one rsl_rl PPO update, without an env, per learner setting.

Builds rsl_rl's PPO exactly as training does (``cat.run.config.runner_cfg`` → ``PPO.construct_algorithm``:
the project's actor and critic MLPs with observation normalisation, adaptive learning rate), fills its rollout
storage with ``--envs`` × ``--steps`` transitions of random observations (actor ``--actor-obs``, critic
``--critic-obs`` wide) and rewards through ``act`` / ``process_env_step`` / ``compute_returns`` (not timed),
then times ``update()``. Each setting (torch threads, epochs, mini-batches, network sizes) runs ``--repeat``
updates after one warm-up; the settings take turns update by update, so a varying load falls on all alike.

Prints one line per setting: ``case=learner threads=<n> epochs=<n> mini_batches=<n> actor=<dims> critic=<dims>
envs=<n> steps=<n> update_ms=<median wall> cpu_ms=<median process CPU>``. A measurement only: nothing here says
whether a setting learns as well (issue 33 asks for equal return and success at equal env steps).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np
import torch
from rsl_rl.algorithms import PPO
from tensordict import TensorDict

from cat.run.config import AlgoCfg, runner_cfg

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LearnerSetting:
    """One learner configuration to time (the rest is ``AlgoCfg``'s defaults)."""

    threads: int = 1
    epochs: int = 5
    mini_batches: int = 4
    actor: tuple[int, ...] = (256, 128, 64)
    critic: tuple[int, ...] = (512, 256, 128)

    def label(self) -> str:
        dims = lambda d: "-".join(map(str, d))  # noqa: E731
        return (
            f"threads={self.threads} epochs={self.epochs} mini_batches={self.mini_batches} "
            f"actor={dims(self.actor)} critic={dims(self.critic)}"
        )


DEFAULT_SETTINGS = (
    LearnerSetting(threads=1),
    LearnerSetting(threads=2),
    LearnerSetting(epochs=3),
    LearnerSetting(epochs=5, mini_batches=2),
    LearnerSetting(epochs=5, mini_batches=8),
    LearnerSetting(critic=(256, 128, 64)),
    LearnerSetting(actor=(128, 64), critic=(256, 128)),
)
"""Today's defaults at 1 and 2 threads, then one change at a time at 1 thread."""


@dataclass
class _Env:
    """What ``PPO.construct_algorithm`` reads of an env."""

    num_envs: int
    num_actions: int
    cfg: dict = field(default_factory=dict)


def build_ppo(s: LearnerSetting, envs: int, steps: int, actor_obs: int, critic_obs: int, actions: int) -> PPO:
    """rsl_rl PPO as training builds it for setting ``s`` (model printouts swallowed)."""
    algo = replace(
        AlgoCfg(),
        num_steps_per_env=steps,
        num_learning_epochs=s.epochs,
        num_mini_batches=s.mini_batches,
        actor_hidden_dims=list(s.actor),
        critic_hidden_dims=list(s.critic),
    )
    cfg = runner_cfg(algo) | {"multi_gpu": None}
    with contextlib.redirect_stdout(io.StringIO()):
        return PPO.construct_algorithm(_obs(envs, actor_obs, critic_obs), _Env(envs, actions), cfg, "cpu")


def _obs(envs: int, actor_obs: int, critic_obs: int, g: torch.Generator | None = None) -> TensorDict:
    return TensorDict(
        {"actor": torch.randn(envs, actor_obs, generator=g), "critic": torch.randn(envs, critic_obs, generator=g)},
        batch_size=[envs],
    )


def fill(ppo: PPO, steps: int, g: torch.Generator) -> None:
    """One rollout of random transitions into the storage, returns computed (as the runner does, untimed)."""
    envs = ppo.storage.num_envs
    a, c = ppo.storage.observations["actor"].shape[-1], ppo.storage.observations["critic"].shape[-1]
    obs = _obs(envs, a, c, g)
    with torch.inference_mode():
        for _ in range(steps):
            ppo.act(obs)
            obs = _obs(envs, a, c, g)
            dones = torch.rand(envs, generator=g) < 0.02
            ppo.process_env_step(obs, torch.randn(envs, generator=g), dones, {})
        ppo.compute_returns(obs)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="bench.py learner", description=__doc__)
    parser.add_argument("--envs", type=int, default=512)
    parser.add_argument("--steps", type=int, default=24)
    parser.add_argument("--actor-obs", type=int, default=184)
    parser.add_argument("--critic-obs", type=int, default=232)
    parser.add_argument("--actions", type=int, default=12)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--only-defaults", action="store_true", help="today's settings at 1 and 2 threads only")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    settings = DEFAULT_SETTINGS[:2] if args.only_defaults else DEFAULT_SETTINGS
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(0)
    ppos = [build_ppo(s, args.envs, args.steps, args.actor_obs, args.critic_obs, args.actions) for s in settings]
    wall: list[list[float]] = [[] for _ in settings]
    cpu: list[list[float]] = [[] for _ in settings]
    for r in range(args.repeat + 1):  # round 0 warms up
        for i, (s, ppo) in enumerate(zip(settings, ppos, strict=True)):
            torch.set_num_threads(s.threads)
            fill(ppo, args.steps, g)
            t0, c0 = time.perf_counter(), time.process_time()
            ppo.update()
            if r > 0:
                wall[i].append((time.perf_counter() - t0) * 1e3)
                cpu[i].append((time.process_time() - c0) * 1e3)
    for s, w, c in zip(settings, wall, cpu, strict=True):
        print(
            f"case=learner {s.label()} envs={args.envs} steps={args.steps} update_ms={np.median(w):.0f} "
            f"cpu_ms={np.median(c):.0f}",
            flush=True,
        )
