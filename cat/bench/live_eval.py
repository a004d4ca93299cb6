"""``scripts/bench.py live_eval``: seconds per trial of ``eval_table.py perception=lidar`` per exteroceptive block,
and what a 200-trial cell would take (the issue 32 target: <= 10 min).

Per block (``field``: HumanoidPF at the odometry pose, ``voxel``: voxel grid, ``elevation``: two-layer elevation
map) a few trials of one typical type, each exactly as ``cat.deploy.live_eval`` runs it (fresh map, 5 s of
lockstep control, LiDAR at the setting's rate). The policy is ``--checkpoint`` for the field block (its run's
layout) or ``hold`` with the block in its observation: perception, not the MLP, is the cost (< 1 ms per step).
Prints per block ``case=live_eval block=<b> setting=<s> trials=<n> wall_s_per_trial=<x> cpu_s_per_trial=<y>
cell200_min=<200 x / 60>``; the first trial (Warp kernel loads) is not timed.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import time

import torch

from cat.deploy.live_eval import deploy_cfg, load_setting, run_trial
from cat.deploy.policy import PolicySpec, policy_spec
from cat.deploy.runtime import Runtime
from cat.envs.config import EnvCfg, ObsGroupCfg
from cat.eval.runner import SceneGroup
from cat.eval.trials import scene_trials

BLOCKS = {"field": "field_block_odometry", "voxel": "voxel_grid", "elevation": "elevation_map"}
PROPRIO = ["gyro", "projected_gravity", "joint_pos", "joint_vel", "last_action", "leg_targets", "gait_phase"]


def _spec(block: str, checkpoint: str | None) -> PolicySpec:
    if block == "field" and checkpoint:
        return policy_spec(checkpoint)
    task = EnvCfg()
    task.observations = {"student": ObsGroupCfg(terms=[*PROPRIO, "goal_command", BLOCKS[block]])}
    return PolicySpec("hold", task, obs_groups=["student"])


def measure(block: str, kind: str, trials: int, setting: str, checkpoint: str | None) -> dict:
    group = SceneGroup.typical(kind, 1, 0)
    ts = scene_trials(group.scenes, trials + 1, 0, 1.5708)[: trials + 1]
    with contextlib.redirect_stdout(io.StringIO()):
        rt = Runtime(group.scenes[0], _spec(block, checkpoint), deploy_cfg(load_setting(setting), 0))
    run_trial(rt, ts[0], 5.0)  # warm-up: kernel loads
    w0, c0 = time.perf_counter(), time.process_time()
    for t in ts[1:]:
        run_trial(rt, t, 5.0)
    wall, cpu = (time.perf_counter() - w0) / trials, (time.process_time() - c0) / trials
    return {"wall": wall, "cpu": cpu, "fields": rt.perception.field_updates}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="bench.py live_eval", description=__doc__)
    p.add_argument("--blocks", default="field,voxel,elevation")
    p.add_argument("--kind", default="hurdle-crouch", help="typical type of the trials")
    p.add_argument("--trials", type=int, default=2, help="timed trials per block (after one warm-up)")
    p.add_argument("--setting", default="default", help="perception setting (configs/eval/perception)")
    p.add_argument("--checkpoint", default="checkpoints/generalist5/model_607.pt", help="field-block policy")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)
    for block in args.blocks.split(","):
        r = measure(block, args.kind, args.trials, args.setting, args.checkpoint)
        print(
            f"case=live_eval block={block} setting={args.setting} kind={args.kind} trials={args.trials} "
            f"wall_s_per_trial={r['wall']:.2f} cpu_s_per_trial={r['cpu']:.2f} cell200_min={200 * r['wall'] / 60:.1f}"
        )
