"""``scripts/bench.py field_contact``: cost of the ``sim.obstacles=field`` contact judgement per env step.

Builds a ``field``-mode env of ``--envs`` worlds over ``--scenes`` typical scenes (the eight kinds in turn, or
``--kind``'s), steps it with random actions (``--warmup`` control steps, robots fall near their starts) and keeps
the sensor rows of the last ``--steps`` steps. Three pose sets are timed, each robot moved rigidly (its pose
stays a real one): ``start`` (the rows as they are: robots near their episode starts, most collision geoms
culled), ``anywhere`` (root at a uniform spot of its scene's grid box) and ``course`` (root x 0.1-1.9 m past the
typical start line, |y| <= 0.3 m: among the obstacles, most robots in contact, the worst case). For each,
``FieldContact.judge`` runs with the torch reference (``impl=torch``: torch transforms + ``FieldBank.query`` per
point) and the fused Warp kernel (``impl=fused``), both on the fields' d, and the fused kernel on the contact SDF
(``impl=contact``, the default ``sim.field_contact.sdf=mesh``), one instant per call, and the default judgement of a
control step (``impl=substeps``: the contact SDF at the 4 substeps' poses), taking turns call by call.
The contact SDF's one-time cost (computed when the env is built) is printed as ``case=contact_sdf``.

Prints one line per (placement, impl): ``case=field_contact impl=<torch|fused|contact|substeps> placement=<...>
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
from cat.envs.field_contact import FieldContact, FieldContactCfg, fill_contact_sdf
from cat.envs.scene_set import SceneSet, scene_fields
from cat.envs.traversal_env import TraversalEnv
from cat.terrain import TYPICAL_KINDS, make_typical

log = logging.getLogger(__name__)
IMPLS = ("torch", "fused", "contact", "substeps")
PLACEMENTS = ("start", "anywhere", "course")
EDGE = 0.3
"""m: robots placed ``anywhere`` keep their root this far inside the grid box (in x and y)."""
COURSE_X = (0.6, 2.4)
"""m past the grid box's low x (-0.5 m in a typical scene): root x 0.1-1.9 m, among the obstacles."""


Rows = tuple[torch.Tensor, torch.Tensor]
"""A control step's sensor rows (n, nsensordata) and substep pose rows (n, decimation, k)."""


def snapshots(env: TraversalEnv, warmup: int, steps: int, seed: int) -> list[Rows]:
    """The rows of the last ``steps`` of ``warmup + steps`` random-action control steps."""
    g = torch.Generator().manual_seed(seed)
    out = []
    for i in range(warmup + steps):
        env.step(0.5 * torch.randn(env.num_envs, env.num_actions, generator=g))
        if i >= warmup:
            out.append((env.sim.sensordata.float().clone(), env.sim.substep_sensordata.float().clone()))
    return out


def moved(fc: FieldContact, rows: Rows, bank, idx: torch.Tensor, placement: str, g: torch.Generator) -> Rows:
    """``rows`` with every robot's body positions shifted by one xy offset per world (a rigid move, the same at
    every substep), its root to a uniform spot of ``placement`` (``anywhere`` / ``course``, see the module
    docstring) in its field's grid box."""
    if placement == "start":
        return rows
    sens, sub = rows
    cols = fc.pose_columns[:, :3]
    pos = sens[:, cols]  # (n, B, 3)
    lo, hi = bank.field_bounds(idx)
    u = torch.rand(len(idx), 2, generator=g)
    if placement == "anywhere":
        target = lo[:, :2] + EDGE + u * (hi[:, :2] - lo[:, :2] - 2 * EDGE)
    else:
        x = lo[:, 0] + COURSE_X[0] + u[:, 0] * (COURSE_X[1] - COURSE_X[0])
        target = torch.stack((x, 0.5 * (lo[:, 1] + hi[:, 1]) + 0.6 * (u[:, 1] - 0.5)), dim=1)
    shift = torch.zeros(len(idx), 1, 3)
    shift[:, 0, :2] = target - pos[:, 0, :2]
    out, out_sub = sens.clone(), sub.clone()
    out[:, cols] = pos + shift
    sub_cols = fc._sub_cols[:, :3]
    out_sub[:, :, sub_cols] = sub[:, :, sub_cols] + shift[:, None]
    return out, out_sub


def time_judge(
    fc: FieldContact, rows: list[Rows], bank, idx: torch.Tensor, impls: tuple[str, ...], repeat: int
) -> dict[str, tuple[float, float, float]]:
    """Per impl: (median wall ms, median process CPU ms per ``judge`` call, fraction of worlds in contact) over
    ``rows`` × ``repeat``. The impls take turns call by call, so a load that varies (a busy machine) falls on both
    alike; CPU time counts every thread's work and not the time other processes hold the cores."""
    wall, cpu, hits = ({i: [] for i in impls} for _ in range(3))

    def judge(impl: str, r: Rows) -> torch.Tensor:
        fc.fused, fc.cfg.sdf = impl != "torch", "mesh" if impl in ("contact", "substeps") else "field"
        return fc.judge(r[0], bank, idx, r[1] if impl == "substeps" else None)[0]

    for i in impls:  # warm-up: kernel load, allocations
        judge(i, rows[0])
    for _ in range(repeat):
        for r in rows:
            for i in impls:
                t0, c0 = time.perf_counter(), time.process_time()
                collision = judge(i, r)
                wall[i].append((time.perf_counter() - t0) * 1e3)
                cpu[i].append((time.process_time() - c0) * 1e3)
                hits[i].append(float(collision.float().mean()))
    fc.fused, fc.cfg.sdf = True, "mesh"
    return {i: (float(np.median(wall[i])), float(np.median(cpu[i])), float(np.mean(hits[i]))) for i in impls}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="bench.py field_contact", description=__doc__)
    parser.add_argument("--envs", type=int, default=1024)
    parser.add_argument("--scenes", type=int, default=16, help="typical scenes (the eight kinds in turn)")
    parser.add_argument("--kind", choices=TYPICAL_KINDS, default=None, help="only this typical kind")
    parser.add_argument("--warmup", type=int, default=20, help="random-action control steps before the snapshots")
    parser.add_argument("--steps", type=int, default=5, help="snapshots timed")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--impl", choices=(*IMPLS, "all"), default="all")
    parser.add_argument("--placement", choices=(*PLACEMENTS, "all"), default="all")
    parser.add_argument("--torch-threads", type=int, default=1)
    parser.add_argument("--bank-threads", type=int, default=None, help="concurrent CPU launches (bank default)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(args.torch_threads)
    if args.kind is None:
        scenes = typical_scenes(args.scenes, args.seed)
    else:  # difficulties spread over [0, 1]
        scenes = [make_typical(args.kind, i / max(args.scenes - 1, 1), args.seed + i) for i in range(args.scenes)]
    sset = SceneSet(scenes, lambda i: scene_fields(scenes[i], None, None), args.envs, per_world=True)
    t0 = time.perf_counter()
    env = TraversalEnv(EnvCfg(num_envs=args.envs), scenes=sset, seed=args.seed, obstacles="field")
    t1 = time.perf_counter()
    fill_contact_sdf(sset, FieldContactCfg(band=env.field_contact.cfg.band + 1e-9))  # timed again, alone
    print(
        f"case=contact_sdf scenes={len(scenes)} env_build_s={t1 - t0:.1f} "
        f"contact_sdf_s_per_scene={(time.perf_counter() - t1) / len(scenes):.3f}",
        flush=True,
    )
    fc, bank, idx = env.field_contact, env.field_source.bank, env.field_source.field_idx
    if args.bank_threads is not None:
        bank.num_threads = max(1, args.bank_threads)
    rows = snapshots(env, args.warmup, args.steps, args.seed)
    g = torch.Generator().manual_seed(args.seed + 1)
    places = PLACEMENTS if args.placement == "all" else (args.placement,)
    sets = {p: [moved(fc, r, bank, idx, p, g) for r in rows] for p in places}
    impls = IMPLS if args.impl == "all" else (args.impl,)
    for placement in places:
        for impl, (ms, cpu_ms, frac) in time_judge(fc, sets[placement], bank, idx, impls, args.repeat).items():
            print(
                f"case=field_contact impl={impl} placement={placement} envs={args.envs} scenes={len(scenes)} "
                f"points={fc.num_points} contact_frac={frac:.3f} ms_per_step={ms:.2f} cpu_ms_per_step={cpu_ms:.2f}",
                flush=True,
            )
