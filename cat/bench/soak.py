"""``scripts/bench.py soak steps=<n>``: random actions through every scene kind; counts non-finite observations
and rewards and the episode resets by cause.

Scenes: the eight typical types, two procedural and two indoor scenes (cached in ``--data``), tiled in one
model, or with ``--per-world`` one scene per world (``sim.per_world_scenes``); ``--scene-dir`` takes every scene
folder under a directory instead (e.g. a ≥ 300-scene hybrid set, free start / goal sampling as training on scene
sets does). ``--obstacles field`` steps floor-only worlds with field-judged contact (``sim.obstacles``),
``--field-storage`` picks the bank's storage (``sim.field_storage``), ``--sim warp`` runs mujoco_warp.
Actions are uniform in [-1, 1], pushes on. Reward terms are counted *before* the env's ``nan_to_num`` (the term
functions are wrapped for the run), so a non-finite value cannot hide; the physics state (qpos, qvel) is
checked after every step, and a world MuJoCo reset on its own (``PhysicsBackend.auto_resets``) is counted; each
reset is attributed to the termination terms that fired (the env's ``termination_flags``), or ``time_out``.
Prints ``case=soak steps=<n> nonfinite=<k> nonfinite_state=<k> auto_resets=<k> resets=<r> by_cause=<cause:count,...>``
(``nonfinite``: observations and rewards).
"""

from __future__ import annotations

import argparse
import functools
import logging
import time
from collections import Counter
from pathlib import Path

import torch
from tqdm import tqdm

from cat.envs.config import EnvCfg, PushCfg
from cat.envs.episodes import EpisodeCfg
from cat.envs.mdp import rewards as rew_terms
from cat.envs.scene_set import SceneSet
from cat.envs.traversal_env import TraversalEnv
from cat.fields import FieldCfg, Grid, SceneFields, StaleFieldError, build_fields
from cat.fields.store import STORE_FILE
from cat.terrain import TYPICAL_KINDS, Scene, make_indoor, make_procedural, make_typical

log = logging.getLogger(__name__)


def soak_scenes(data: Path) -> tuple[list[Scene], list[Path]]:
    """Every scene kind (8 typical, 2 procedural, 2 indoor), generated with fields once into ``data``."""
    makers = [(f"typical_{k}", functools.partial(make_typical, k, 0.5, 0)) for k in TYPICAL_KINDS]
    makers += [(f"procedural_{i}", functools.partial(make_procedural, d, 300 + i)) for i, d in enumerate((0.3, 0.9))]
    makers += [(f"indoor_{i}", functools.partial(make_indoor, 400 + i)) for i in range(2)]
    scenes, folders = [], []
    for name, make in makers:
        folder = data / name
        try:
            scene = Scene.load(folder)
            SceneFields.check(Scene.fields_dir(folder) / STORE_FILE, FieldCfg())
        except (OSError, ValueError, StaleFieldError):
            scene = make()
            scene.save(folder)
            g = scene.grid()
            fields = build_fields(scene.occupancy(), Grid(g.origin, g.voxel, g.shape), scene.goals)
            Scene.fields_dir(folder).mkdir(exist_ok=True)
            SceneFields.from_fields(fields).save(Scene.fields_dir(folder) / STORE_FILE)
        scenes.append(scene)
        folders.append(folder)
    return scenes, folders


class _Recorder:
    """Wraps reward term functions of a module for the run and counts their non-finite values."""

    def __init__(self, module, names: list[str]):
        self.module = module
        self.saved = {n: getattr(module, n) for n in names}
        self.nonfinite = 0

    def __enter__(self) -> _Recorder:
        for name, fn in self.saved.items():
            setattr(self.module, name, self._wrap(fn))
        return self

    def __exit__(self, *exc) -> None:
        for name, fn in self.saved.items():
            setattr(self.module, name, fn)

    def _wrap(self, fn):
        def wrapped(env, **params):
            value = fn(env, **params)
            self.nonfinite += int((~torch.isfinite(value)).sum())
            return value

        return wrapped


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="bench.py soak", description=__doc__)
    p.add_argument("steps", nargs="?", default="steps=200000", help="steps=<n>: env steps in total")
    p.add_argument("--envs", type=int, default=256)
    p.add_argument("--data", default="/tmp/cat_soak_bench")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sim", choices=("mujoco", "warp"), default="mujoco")
    p.add_argument("--per-world", action="store_true", help="each world holds only its own scene's obstacles")
    p.add_argument("--scene-dir", default=None, help="every scene folder under this directory (free episodes)")
    p.add_argument("--obstacles", choices=("physical", "field"), default="physical")
    p.add_argument("--field-storage", choices=("float32", "float16", "compact"), default="float32")
    args = p.parse_args(argv)
    if not args.steps.startswith("steps="):
        raise SystemExit(f"expected steps=<n>, got {args.steps!r}")
    total = int(float(args.steps.split("=", 1)[1]))
    logging.basicConfig(level=logging.WARNING)
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # keep stdout to result lines

    cfg = EnvCfg(num_envs=args.envs, push=PushCfg(enabled=True))
    if args.scene_dir is not None:
        cfg.episodes = EpisodeCfg(mode="free")
        sset = SceneSet.from_dir(
            args.scene_dir, args.envs, dtype=args.field_storage, per_world=args.per_world, episodes=cfg.episodes
        )
    else:
        scenes, folders = soak_scenes(Path(args.data))

        def load(i: int) -> SceneFields:
            return SceneFields.load(Scene.fields_dir(folders[i]) / STORE_FILE)

        sset = SceneSet(scenes, load, args.envs, per_world=args.per_world, dtype=args.field_storage)
    env = TraversalEnv(cfg, sim=args.sim, scenes=sset, seed=args.seed, obstacles=args.obstacles)
    gen = torch.Generator().manual_seed(args.seed)
    causes: Counter = Counter()
    nonfinite_obs, nonfinite_state, resets, steps = 0, 0, 0, 0
    rew_names = list(env.reward_names)
    t0 = time.perf_counter()
    bar = tqdm(total=total, desc="soak", unit="step", unit_scale=True, mininterval=30)
    with _Recorder(rew_terms, rew_names) as rew, bar:
        while steps < total:
            obs, reward, done, extras = env.step(2 * torch.rand(args.envs, env.num_actions, generator=gen) - 1)
            steps += args.envs
            bar.update(args.envs)
            nonfinite_obs += sum(int((~torch.isfinite(v)).sum()) for v in obs.values())
            rew.nonfinite += int((~torch.isfinite(reward)).sum())
            nonfinite_state += int((~torch.isfinite(env.sim.qpos)).sum() + (~torch.isfinite(env.sim.qvel)).sum())
            ids = done.nonzero().flatten()
            resets += len(ids)
            for i in ids.tolist():
                named = [n for n, flags in env.termination_flags.items() if bool(flags[i])]
                causes.update(named or ["time_out"])
    by_cause = ",".join(f"{k}:{v}" for k, v in sorted(causes.items()))
    print(
        f"case=soak steps={steps} nonfinite={nonfinite_obs + rew.nonfinite} nonfinite_state={nonfinite_state}"
        f" auto_resets={env.sim.auto_resets} resets={resets} by_cause={by_cause}"
        f" envs={args.envs} sim={args.sim} layout={'per_world' if args.per_world else 'tiles'}"
        f" obstacles={args.obstacles} scenes={len(sset.scenes)} field_storage={args.field_storage}"
        f" seconds={time.perf_counter() - t0:.0f}",
        flush=True,
    )
    if nonfinite_obs + rew.nonfinite + nonfinite_state:
        log.warning(
            "non-finite: %d in observations, %d in rewards, %d in states", nonfinite_obs, rew.nonfinite, nonfinite_state
        )
