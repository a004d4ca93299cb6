"""``scripts/bench.py train --scenes N --obstacles physical|field``: PPO training throughput on a scene set.

Runs ``iterations`` PPO iterations (after one warm-up iteration) of the ``task`` recipe on ``N`` scenes with
``sim.obstacles`` = ``physical`` (obstacle geometry; per-world scene models unless ``sim.per_world_scenes=false``
is passed) or ``field`` (floor-only worlds, contact judged from the SDF: ``cat.envs.field_contact``), and
compares with raw MuJoCo stepping the same robot on flat ground with random actions in the same process.
The scenes come from ``--scene-dir`` (its first N scene folders) or, by default, from the embedded typical
generator (the eight typical kinds in turn, difficulties spread over [0, 1]).

Prints ``case=train scenes=<n> obstacles=<mode> num_envs=<n> env_steps_per_s=<x> raw_flat_env_steps_per_s=<y>
ratio=<x/y> field_storage=<s> bank_mb=<b> peak_rss_mb=<m> rss_mb=start:<a>,scenes:<b>,bank:<c>,env:<d>,train:<e>``
(the process's peak resident memory: the whole training setup, bank, models, env and learner; then the resident
memory after imports, after loading the scenes, after filling the bank, after building the env and after the
iterations, which says where memory outside the bank goes). ``sim.field_storage=compact`` (an override) is the
paper-scale bank in 10.4 GiB for 355 scenes x 12 goals.
"""

from __future__ import annotations

import argparse
import logging
import os
import resource
import time
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout

from cat.bench.train import ppo_rate
from cat.envs.field_contact import OBSTACLE_MODES
from cat.envs.robot import RobotCfg
from cat.envs.scene import build_env_model
from cat.envs.scene_set import SceneSet, scene_fields, scene_folders
from cat.envs.traversal_env import TraversalEnv
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import set_torch_threads
from cat.run.config import TrainCfg
from cat.terrain import TYPICAL_KINDS, Scene, make_typical

log = logging.getLogger(__name__)
RAW_EPISODE_STEPS = 50
"""Control steps after which the raw worlds restart from the home pose (random actions fell them within ~1 s;
the env resets fallen robots too)."""


def typical_scenes(n: int, seed: int = 0) -> list[Scene]:
    """``n`` typical scenes: the kinds in turn, difficulties spread over [0, 1] within each kind."""
    per_kind = -(-n // len(TYPICAL_KINDS))
    out = []
    for i in range(n):
        kind, j = TYPICAL_KINDS[i % len(TYPICAL_KINDS)], i // len(TYPICAL_KINDS)
        out.append(make_typical(kind, j / max(per_kind - 1, 1), seed=seed + j))
    return out


def rss_mb() -> float:
    """The process's resident memory now [MiB] (Linux ``/proc/self/statm``)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def scene_set(args: argparse.Namespace, cfg: TrainCfg, num_envs: int, rss: dict[str, float]) -> SceneSet:
    """The bench's scene set; ``rss`` gets the resident memory after the scenes are loaded."""
    kw = dict(per_world=cfg.sim.per_world_scenes, dtype=cfg.sim.field_storage)
    if args.scene_dir:
        folders = scene_folders(Path(args.scene_dir))[: args.scenes]
        if len(folders) < args.scenes:
            raise SystemExit(f"--scene-dir {args.scene_dir} holds {len(folders)} scene folders, --scenes {args.scenes}")
        scenes = [Scene.load(f) for f in folders]
        fields = lambda i: scene_fields(scenes[i], folders[i], None)  # noqa: E731  (read one scene at a time)
    else:
        scenes = typical_scenes(args.scenes)
        fields = lambda i: scene_fields(scenes[i], None, None)  # noqa: E731  (built one scene at a time)
    rss["scenes"] = rss_mb()
    return SceneSet(scenes, fields, num_envs, cfg.sim.device, **kw)


def raw_flat_rate(robot: RobotCfg, num_envs: int, seconds: float, seed: int = 0) -> float:
    """Env steps/s of plain ``mujoco.rollout`` stepping G1 on flat ground (the env's model without obstacles)
    with random PD targets (home pose + uniform ±``action_scale``), ``decimation`` physics steps per env step."""
    model, dec = build_env_model(robot), robot.decimation
    nthread = os.cpu_count() or 1
    runner, datas = rollout.Rollout(nthread=nthread), [mujoco.MjData(model) for _ in range(nthread)]
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    home = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, d, home, spec)
    state = np.tile(home, (num_envs, 1))
    out_s = np.zeros((num_envs, dec, state.shape[1]))
    out_d = np.zeros((num_envs, dec, model.nsensordata))
    rng = np.random.default_rng(seed)
    models = [model] * num_envs
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        ctrl = d.ctrl + robot.action_scale * rng.uniform(-1.0, 1.0, (num_envs, 1, model.nu))
        ctrl = np.repeat(ctrl, dec, axis=1)
        runner.rollout(models, datas, state, ctrl, skip_checks=True, nstep=dec, state=out_s, sensordata=out_d)
        calls += 1
        state[:] = home if calls % RAW_EPISODE_STEPS == 0 else out_s[:, -1]
    return calls * num_envs / (time.perf_counter() - start)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="bench.py train --scenes N --obstacles MODE", description=__doc__)
    parser.add_argument("--scenes", type=int, default=16, help="scenes in the set (default 16: small)")
    parser.add_argument("--obstacles", choices=OBSTACLE_MODES, default="field")
    parser.add_argument("--scene-dir", default="", help="take the first N scene folders here (default: generated)")
    parser.add_argument("--num-envs", type=int, default=1024)
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=5.0, help="duration of the raw MuJoCo measurement")
    parser.add_argument("--task", default="hurdle_crouch", help="the recipe (configs/task); its scenes are replaced")
    parser.add_argument("overrides", nargs="*", help="train.py overrides, e.g. algo.mixed_precision=true")
    args = parser.parse_args(argv)
    if args.scenes < 1:
        parser.error(f"--scenes must be >= 1, got {args.scenes}")
    logging.basicConfig(level=logging.WARNING)
    overrides = [f"task={args.task}", f"num_envs={args.num_envs}", "sim.per_world_scenes=true", *args.overrides]
    cfg = load_config([*overrides, f"sim.obstacles={args.obstacles}"])
    set_torch_threads(cfg.torch_threads)
    n = args.num_envs
    rss = {"start": rss_mb()}
    sset = scene_set(args, cfg, n, rss)
    rss["bank"] = rss_mb()
    task = replace(cfg.task, num_envs=n, warmup_variants=0)
    sim, fc = cfg.sim, cfg.sim.field_contact
    mode = sim.obstacles
    env = TraversalEnv(task, sim.backend, sim.device, scenes=sset, seed=cfg.seed, obstacles=mode, field_contact=fc)
    rss["env"] = rss_mb()
    x = ppo_rate(env, cfg, args.iterations)
    rss["train"] = rss_mb()
    y = raw_flat_rate(env.robot, env.num_envs, args.seconds, cfg.seed)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
    print(
        f"case=train scenes={len(sset.scenes)} obstacles={env.obstacles} num_envs={env.num_envs} "
        f"env_steps_per_s={x:.0f} raw_flat_env_steps_per_s={y:.0f} ratio={x / y:.2f} "
        f"field_storage={sim.field_storage} bank_mb={sset.bank.nbytes / 2**20:.0f} peak_rss_mb={peak_mb:.0f} "
        f"rss_mb={','.join(f'{k}:{v:.0f}' for k, v in rss.items())}"
    )
