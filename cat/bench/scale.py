"""``scripts/bench.py scale``: a paper-scale scene set — 355 scenes of the three kinds × 12 goals — in one field
bank: its memory (float16 and float32), load time, the 4096-env × 13-link query, and env steps/s at 1024 envs
against the flat task in the same run.

Scenes repeat to reach the count (a few unique ones are generated once into ``--data``), but every scene of
the set has its own storage in the bank, so memory and the query's memory traffic are those of the full set.
Each scene gets 12 goal fields (a scene with fewer reachable goals repeats them; typical scenes get goals
across the far end). The env measurement uses the bank of the whole set for fields, observations, rewards and
episode sampling; its physics worlds hold no obstacles, or with ``--per-world`` each world its own scene's
(``sim.per_world_scenes``: one compiled model per scene).

``case=scale_physics`` (``--physics-scenes``, a moderate set of the three kinds) compares the two physics
layouts with obstacles, built and measured in the same run: tiles (every world holds every scene) against
per-world scene models — env steps/s (and the flat task's), model memory, build time, reset cost per env;
``--sim warp`` runs both on mujoco_warp (per-world scenes as geom slots, ``cat.envs.sim.warp_slots``).
``case=scale_dr`` gives domain randomisation's model memory: per-world pools (scenes x ``--pool`` copies,
built) against the tiles' per-env copy of the whole tiled model (projected from one copy).

``--device cuda:0`` puts the bank (and, with ``--sim warp``, the envs) on that device; query timings synchronise
it. ``--no-env`` stops after the bank's memory, load and query figures (``env_steps_per_s`` and the ratio are then
not printed).
"""

from __future__ import annotations

import argparse
import copy
import logging
import time
from pathlib import Path

import numpy as np
import torch

from cat.bench.fields import bench_device, median_ms, with_goals
from cat.bench.sim import env_rate
from cat.envs.config import EnvCfg
from cat.envs.scene_models import WorldModels
from cat.envs.scene_set import SceneSet
from cat.envs.traversal_env import TraversalEnv
from cat.fields import FieldBank, FieldCfg, Grid, SceneFields, SceneLayout, StaleFieldError, bank_bytes, build_fields
from cat.fields.bank import STORAGES
from cat.fields.store import STORE_FILE
from cat.terrain import Scene, make_indoor, make_procedural, make_typical

log = logging.getLogger(__name__)
GOALS = 12
UNIQUE = {"typical": 2, "procedural": 2, "indoor": 2}


def unique_scenes(data: Path, dtype: str) -> dict[str, list[Path]]:
    """Scene folders (with ``fields/humanoid_pf.npz`` in ``dtype``) of the unique scenes, made once."""
    makers = {
        "typical": lambda i: make_typical(["hurdle-crouch", "side-pass"][i % 2], 0.5, i),
        "procedural": lambda i: make_procedural([0.4, 0.9][i % 2], 100 + i),
        "indoor": lambda i: make_indoor(200 + i),
    }
    out: dict[str, list[Path]] = {}
    for kind, count in UNIQUE.items():
        out[kind] = []
        for i in range(count):
            folder = data / f"{kind}_{i}_{dtype}"
            path = Scene.fields_dir(folder) / STORE_FILE
            try:
                Scene.load(folder)
                SceneFields.check(path, FieldCfg())
            except (OSError, ValueError, StaleFieldError):
                scene = with_goals(makers[kind](i), GOALS)
                scene.save(folder)
                g = scene.grid()
                fields = build_fields(scene.occupancy(), Grid(g.origin, g.voxel, g.shape), scene.goals)
                Scene.fields_dir(folder).mkdir(exist_ok=True)
                SceneFields.from_fields(fields).save(path, dtype)
            out[kind].append(folder)
    return out


def scene_list(folders: dict[str, list[Path]], counts: dict[str, int]) -> list[Path]:
    """``counts[kind]`` scenes of each kind, cycling through that kind's unique folders."""
    return [folders[k][i % len(folders[k])] for k, n in counts.items() for i in range(n)]


def query_ms(bank: FieldBank, envs: int, repeat: int, seed: int = 0) -> float:
    """Median ms of ``bank.query`` for ``envs`` × 13 links: each env on a random field, its links within
    ±0.35 m (±0.7 m in z) of a pelvis placed at random in the field's grid (points made on the CPU, queried
    on the bank's device)."""
    rng = np.random.default_rng(seed)
    idx = torch.as_tensor(rng.integers(0, bank.num_fields, envs), dtype=torch.int32)
    lo, hi = (b.cpu() for b in bank.field_bounds(idx.to(bank.device)))
    root = lo + torch.as_tensor(rng.uniform(0.1, 0.9, (envs, 3)), dtype=torch.float32) * (hi - lo)
    root[:, 2] = 0.75
    off = torch.as_tensor(rng.uniform(-0.35, 0.35, (envs, 13, 3)), dtype=torch.float32) * torch.tensor([1, 1, 2.0])
    idx, pts = idx.to(bank.device), (root[:, None] + off).to(bank.device)
    out = bank.query(idx, pts)
    return median_ms(lambda: bank.query(idx, pts, out), repeat, bank.device)


class _FieldsOnly(SceneSet):
    """The scene set without obstacle geoms in the physics (see the module docstring)."""

    def add_to_spec(self, spec) -> None:
        return None


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="bench.py scale", description=__doc__)
    p.add_argument("--typical", type=int, default=80)
    p.add_argument("--procedural", type=int, default=167)
    p.add_argument("--indoor", type=int, default=108)
    p.add_argument(
        "--dtype", default="float16", choices=list(STORAGES), help="bank storage (files: float16 for compact)"
    )
    p.add_argument("--data", default="/tmp/cat_scale_bench", help="where the unique scenes are cached")
    p.add_argument("--envs", type=int, default=1024, help="envs for the env steps/s comparison")
    p.add_argument("--query-envs", type=int, default=4096)
    p.add_argument("--seconds", type=float, default=12.0, help="per env, split over --rounds interleaved runs")
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--repeat", type=int, default=21)
    p.add_argument("--mem-limit-gb", type=float, default=None, help="refuse a bank above this (default: RAM - 4 GB)")
    p.add_argument("--per-world", action="store_true", help="case=scale with per-world scene models (obstacles)")
    p.add_argument("--sim", choices=("mujoco", "warp"), default="mujoco", help="physics backend of every env")
    p.add_argument("--physics-scenes", type=int, default=24, help="case=scale_physics set size (0: skip)")
    p.add_argument("--pool", type=int, default=8, help="domain randomisation pool per scene (case=scale_dr)")
    p.add_argument("--only-physics", action="store_true", help="run case=scale_physics / scale_dr only")
    p.add_argument("--device", default="cpu", help="cpu or cuda[:i]: the bank's device (and the envs', sim=warp)")
    p.add_argument("--no-env", action="store_true", help="case=scale: bank memory, load and query only")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # keep stdout to result lines
    args.device = bench_device(args.device)
    if args.device != "cpu" and args.sim == "mujoco" and not (args.no_env and args.physics_scenes == 0):
        raise SystemExit(f"--device {args.device}: MuJoCo C envs run on the CPU; add --sim warp (or --no-env)")

    unique = unique_scenes(Path(args.data), "float32" if args.dtype == "float32" else "float16")
    torch.set_num_threads(1)
    if args.physics_scenes > 0:
        physics_case(unique, args)
    if not args.only_physics:
        scale_case(unique, args)


def scale_case(unique: dict[str, list[Path]], args: argparse.Namespace) -> None:
    counts = {"typical": args.typical, "procedural": args.procedural, "indoor": args.indoor}
    folders = scene_list(unique, counts)
    scenes_u = {f: Scene.load(f) for f in set(folders)}
    layouts = []
    for f in folders:
        g = scenes_u[f].grid()
        layouts.append(SceneLayout(Grid(g.origin, g.voxel, g.shape), len(scenes_u[f].goals)))
    mb = {d: bank_bytes(layouts, d) / 2**20 for d in STORAGES}
    print(
        f"case=scale_memory scenes={len(folders)} goals={GOALS} fp16_mb={mb['float16']:.0f} fp32_mb={mb['float32']:.0f}"
        f" compact_mb={mb['compact']:.0f} fits_24gib_fp16={mb['float16'] < 24 * 1024}"
        f" fits_24gib_fp32={mb['float32'] < 24 * 1024} fits_12gib_compact={mb['compact'] < 12 * 1024}",
        flush=True,
    )
    limit = args.mem_limit_gb if args.mem_limit_gb is not None else _mem_available_gb() - 4.0
    if mb[args.dtype] / 1024 > limit:
        raise SystemExit(f"bank of {mb[args.dtype] / 1024:.1f} GB exceeds --mem-limit-gb {limit:.1f}")

    def load(i: int) -> SceneFields:  # every entry reads its file, as a set of distinct scenes would
        return SceneFields.load(Scene.fields_dir(folders[i]) / STORE_FILE, FieldCfg())

    t = time.perf_counter()
    kw = dict(dtype=args.dtype, device=args.device)
    if args.per_world:
        sset = SceneSet([Scene.load(f) for f in folders], load, args.envs, per_world=True, **kw)
    else:
        sset = _FieldsOnly([scenes_u[f] for f in folders], load, args.envs, **kw)
    load_s = time.perf_counter() - t
    q = query_ms(sset.bank, args.query_envs, args.repeat)
    if args.no_env:
        print(
            f"case=scale scenes={len(folders)} goals={GOALS} bank_mb={sset.bank.nbytes / 2**20:.0f}"
            f" load_s={load_s:.1f} query_ms={q:.2f} device={args.device}",
            flush=True,
        )
        return
    env = TraversalEnv(EnvCfg(num_envs=args.envs), sim=args.sim, device=args.device, scenes=sset, seed=0)
    flat = TraversalEnv(EnvCfg(num_envs=args.envs), sim=args.sim, device=args.device, seed=0)
    rates: dict[str, list[float]] = {"set": [], "flat": []}
    for _ in range(args.rounds):  # interleaved: both see the same machine load
        rates["set"].append(env_rate(env, args.seconds / args.rounds))
        rates["flat"].append(env_rate(flat, args.seconds / args.rounds))
    rate, flat_rate = (float(np.median(rates[k])) for k in ("set", "flat"))
    per_round = np.array(rates["set"]) / np.array(rates["flat"])  # the spread a single ratio hides
    print(
        f"case=scale scenes={len(folders)} goals={GOALS} bank_mb={sset.bank.nbytes / 2**20:.0f} load_s={load_s:.1f}"
        f" query_ms={q:.2f} env_steps_per_s={rate:.0f} flat_env_steps_per_s={flat_rate:.0f}"
        f" ratio={rate / flat_rate:.2f} round_ratios={per_round.min():.2f}-{per_round.max():.2f}"
        f" physics={'per_world' if args.per_world else 'none'} sim={args.sim} device={args.device}",
        flush=True,
    )


def physics_case(unique: dict[str, list[Path]], args: argparse.Namespace) -> None:
    """Tiles against per-world scene models on ``--physics-scenes`` scenes (a third of each kind)."""
    k = max(1, args.physics_scenes // len(UNIQUE))
    folders = scene_list(unique, {kind: k for kind in UNIQUE})
    scenes = [Scene.load(f) for f in folders]  # one object per entry, as distinct scenes

    def load(i: int) -> SceneFields:
        return SceneFields.load(Scene.fields_dir(folders[i]) / STORE_FILE, FieldCfg())

    envs, build_s = {}, {}
    for mode in ("tiles", "per_world"):
        t = time.perf_counter()
        sset = SceneSet(scenes, load, args.envs, args.device, dtype=args.dtype, per_world=mode == "per_world")
        envs[mode] = TraversalEnv(EnvCfg(num_envs=args.envs), sim=args.sim, device=args.device, scenes=sset, seed=0)
        build_s[mode] = time.perf_counter() - t
    envs["flat"] = TraversalEnv(EnvCfg(num_envs=args.envs), sim=args.sim, device=args.device, seed=0)
    rates: dict[str, list[float]] = {m: [] for m in envs}
    for _ in range(args.rounds):  # interleaved: both see the same machine load
        for m, env in envs.items():
            rates[m].append(env_rate(env, args.seconds / args.rounds))
    rate = {m: float(np.median(r)) for m, r in rates.items()}
    reset = {m: reset_us(env) for m, env in envs.items() if m != "flat"}
    tiles, wm = envs["tiles"], envs["per_world"].world_models
    tile_mb, scene_mb = tiles.sim.model.nbuffer / 2**20, wm.nbytes / 2**20
    layouts = getattr(envs["per_world"].sim, "num_layouts", 1)  # MjData layout classes (MuJoCo C)
    print(
        f"case=scale_physics sim={args.sim} device={args.device} scenes={len(scenes)} envs={args.envs}"
        f" layouts={layouts}"
        f" tiles_env_steps_per_s={rate['tiles']:.0f} per_world_env_steps_per_s={rate['per_world']:.0f}"
        f" ratio={rate['per_world'] / rate['tiles']:.2f} flat_env_steps_per_s={rate['flat']:.0f}"
        f" tile_model_mb={tile_mb:.1f} per_world_models_mb={scene_mb:.1f}"
        f" build_s_tiles={build_s['tiles']:.1f} build_s_per_world={build_s['per_world']:.1f}"
        f" reset_us_tiles={reset['tiles']:.0f} reset_us_per_world={reset['per_world']:.0f}",
        flush=True,
    )
    # domain randomisation: a pool of --pool copies per scene, against a per-env copy of the tiled model
    t = time.perf_counter()
    pool = WorldModels([copy.deepcopy(m) for m in wm.models], tiles.robot, pool=args.pool)
    pool.set_scales(0.75 + 0.5 * torch.rand(len(scenes), args.pool, 3))
    pool_s = time.perf_counter() - t
    t = time.perf_counter()
    copy.deepcopy(tiles.sim.model)
    tile_copy_s = time.perf_counter() - t
    print(
        f"case=scale_dr scenes={len(scenes)} envs={args.envs} pool={args.pool} pool_models={len(pool.models)}"
        f" pool_mb={pool.nbytes / 2**20:.0f} pool_build_s={pool_s:.2f}"
        f" tiles_dr_mb={args.envs * tile_mb:.0f} tiles_dr_copy_s={args.envs * tile_copy_s:.1f}",
        flush=True,
    )


def reset_us(env: TraversalEnv, batch: int = 64, repeat: int = 8) -> float:
    """Median µs per env of ``reset_idx`` on ``batch`` random envs (scene pick, model swap, forward, field)."""
    gen = torch.Generator().manual_seed(1)
    times = []
    for _ in range(repeat):
        ids = torch.randperm(env.num_envs, generator=gen)[:batch]
        t = time.perf_counter()
        env.reset_idx(ids)
        times.append((time.perf_counter() - t) / len(ids))
    return 1e6 * float(np.median(times))


def _mem_available_gb() -> float:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 2**20
    except OSError:
        pass
    return float("inf")
