"""``scripts/bench.py field_contact``: cost of the ``sim.obstacles=field`` contact judgement per env step.

Builds a ``field``-mode env of ``--envs`` worlds over ``--scenes`` typical scenes, steps it with random actions
(``--warmup`` control steps, robots fall near their starts) and keeps the sensor rows of the last ``--steps``
steps. Two pose sets are timed: ``start`` (those rows as they are: robots near their episode starts, most
collision geoms culled) and ``anywhere`` (each robot moved rigidly to a uniform spot of its scene's grid box:
many bodies in or near obstacles, the expensive case). For each, ``FieldContact.judge`` runs with the torch
reference (``impl=torch``: torch transforms + ``FieldBank.query`` per point) and the fused Warp kernel
(``impl=fused``).

Prints one line per (placement, impl): ``case=field_contact impl=<torch|fused> placement=<start|anywhere>
envs=<n> scenes=<n> points=<n> contact_frac=<x> ms_per_step=<x> cpu_ms_per_step=<x>`` (medians over steps ×
``--repeat``; wall clock, and the process's CPU time, which a busy machine inflates less).
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np
import torch

from cat.bench.train_obstacles import typical_scenes
from cat.envs.config import EnvCfg
from cat.envs.field_contact import FieldContact
from cat.envs.scene_set import SceneSet, scene_fields
from cat.envs.traversal_env import TraversalEnv

log = logging.getLogger(__name__)
IMPLS = ("torch", "fused")
PLACEMENTS = ("start", "anywhere")
EDGE = 0.3
"""m: robots placed ``anywhere`` keep their root this far inside the grid box (in x and y)."""


def snapshots(env: TraversalEnv, warmup: int, steps: int, seed: int) -> list[torch.Tensor]:
    """Sensor rows (n, nsensordata) of the last ``steps`` of ``warmup + steps`` random-action control steps."""
    g = torch.Generator().manual_seed(seed)
    out = []
    for i in range(warmup + steps):
        env.step(0.5 * torch.randn(env.num_envs, env.num_actions, generator=g))
        if i >= warmup:
            out.append(env.sim.sensordata.to(torch.float32).clone())
    return out


def moved_anywhere(fc: FieldContact, sens: torch.Tensor, bank, idx: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    """``sens`` with every robot's body positions shifted by one xy offset per world, to a uniform root spot in
    its field's grid box (a rigid move: the pose stays a real one)."""
    cols = fc.pose_columns[:, :3]
    pos = sens[:, cols]  # (n, B, 3)
    lo, hi = bank.field_bounds(idx)
    target = lo[:, :2] + EDGE + torch.rand(len(idx), 2, generator=g) * (hi[:, :2] - lo[:, :2] - 2 * EDGE)
    shift = torch.zeros(len(idx), 1, 3)
    shift[:, 0, :2] = target - pos[:, 0, :2]
    out = sens.clone()
    out[:, cols] = pos + shift
    return out


def time_judge(fc: FieldContact, rows: list[torch.Tensor], bank, idx: torch.Tensor, repeat: int) -> tuple[float, ...]:
    """(median wall ms, median process CPU ms per ``judge`` call, fraction of worlds in contact) over ``rows`` ×
    ``repeat``. CPU time counts every thread's work and not the time other processes hold the cores."""
    fc.judge(rows[0], bank, idx)  # warm-up: kernel load, allocations
    wall, cpu, hits = [], [], []
    for _ in range(repeat):
        for sens in rows:
            t0, c0 = time.perf_counter(), time.process_time()
            collision, _ = fc.judge(sens, bank, idx)
            wall.append((time.perf_counter() - t0) * 1e3)
            cpu.append((time.process_time() - c0) * 1e3)
            hits.append(float(collision.float().mean()))
    return float(np.median(wall)), float(np.median(cpu)), float(np.mean(hits))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="bench.py field_contact", description=__doc__)
    parser.add_argument("--envs", type=int, default=1024)
    parser.add_argument("--scenes", type=int, default=16, help="typical scenes (the eight kinds in turn)")
    parser.add_argument("--warmup", type=int, default=20, help="random-action control steps before the snapshots")
    parser.add_argument("--steps", type=int, default=5, help="snapshots timed")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--impl", choices=(*IMPLS, "both"), default="both")
    parser.add_argument("--placement", choices=(*PLACEMENTS, "both"), default="both")
    parser.add_argument("--torch-threads", type=int, default=1)
    parser.add_argument("--bank-threads", type=int, default=None, help="concurrent CPU launches (bank default)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(args.torch_threads)
    scenes = typical_scenes(args.scenes, args.seed)
    sset = SceneSet(scenes, lambda i: scene_fields(scenes[i], None, None), args.envs, per_world=True)
    env = TraversalEnv(EnvCfg(num_envs=args.envs), scenes=sset, seed=args.seed, obstacles="field")
    fc, bank, idx = env.field_contact, env.field_source.bank, env.field_source.field_idx
    if args.bank_threads is not None:
        bank.num_threads = max(1, args.bank_threads)
    rows = snapshots(env, args.warmup, args.steps, args.seed)
    g = torch.Generator().manual_seed(args.seed + 1)
    sets = {"start": rows, "anywhere": [moved_anywhere(fc, r, bank, idx, g) for r in rows]}
    for placement in PLACEMENTS if args.placement == "both" else (args.placement,):
        for impl in IMPLS if args.impl == "both" else (args.impl,):
            fc.fused = impl == "fused"
            ms, cpu_ms, frac = time_judge(fc, sets[placement], bank, idx, args.repeat)
            print(
                f"case=field_contact impl={impl} placement={placement} envs={args.envs} scenes={len(scenes)} "
                f"points={fc.num_points} contact_frac={frac:.3f} ms_per_step={ms:.2f} cpu_ms_per_step={cpu_ms:.2f}",
                flush=True,
            )
    fc.fused = True
