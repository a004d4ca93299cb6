"""Trials scored through the simulated perception (``scripts/eval_table.py perception=lidar``): Table III's setting.

Each trial is the evaluation protocol's trial (``cat.eval.trials``: the same scene, goal, start pose and yaw as
with ``perception=ground_truth``, scored by ``cat.envs.trial_metrics``' rules on the true root) run by the click demo's
runtime (``cat.deploy.runtime.Runtime``, lockstep): LiDAR scans at ``rate_hz`` -> log-odds map -> the policy's
exteroceptive block from that map (HumanoidPF built on the window, or the voxel grid / elevation map tables of
``cat.envs.perception`` read from it), visible ``latency_s`` after each scan, with the setting's LiDAR noise,
dropouts and odometry error. Every policy meets the same setting (``LiveSettingCfg``, a YAML under
``configs/eval/perception/``). One robot per trial, one after another, in a fresh map.

Differences from the ground-truth path, the same for every policy: no training observation noise (the sensor
is the noise), the robot starts in its default pose with the gait clock at 0, and before its first step the
robot has taken one scan after the goal is set (the demo's robot maps while it stands).
"""

from __future__ import annotations

import contextlib
import copy
import io
import logging
import multiprocessing
import threading
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch
import yaml

from cat.deploy.lidar import LidarCfg
from cat.deploy.perception import PerceptionCfg
from cat.deploy.policy import PolicySpec
from cat.deploy.runtime import DeployCfg, Runtime, _check_deployable
from cat.envs.trial_metrics import TrialResult
from cat.eval.manifest import ManifestError, MethodRun
from cat.eval.runner import SceneGroup
from cat.eval.trials import Trial
from cat.run.config import policy_model

log = logging.getLogger(__name__)

SETTINGS_DIR = Path(__file__).resolve().parents[2] / "configs" / "eval" / "perception"
MAP_MARGIN = 0.48  # the map around the scene [m]: 12 voxels, so map and scene voxel lattices coincide


@dataclass
class LiveSettingCfg:
    """One perception setting (sensor, timing, odometry), identical for every policy scored under it."""

    range_noise: float = 0.02
    dropout: float = 0.05
    rays_per_scan: int = 12000
    rate_hz: float = 10.0
    latency_s: float = 0.1
    odom_pos_noise: float = 0.0
    odom_yaw_noise: float = 0.0
    odom_drift_xy: float = 0.0
    odom_drift_yaw: float = 0.0


def load_setting(name: str) -> LiveSettingCfg:
    """``default`` / ``harsh`` (``configs/eval/perception/<name>.yaml``) or a YAML path; unknown keys refused."""
    path = Path(name) if name.endswith((".yaml", ".yml")) else SETTINGS_DIR / f"{name}.yaml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in SETTINGS_DIR.glob("*.yaml")))
        raise ValueError(f"perception setting {name!r}: no {path} (known: {known}, or a .yaml path)")
    raw = yaml.safe_load(path.read_text()) or {}
    valid = {f.name for f in fields(LiveSettingCfg)}
    unknown = sorted(set(raw) - valid)
    if unknown:
        raise ValueError(f"perception setting {path}: unknown key {unknown[0]!r}; valid: {', '.join(sorted(valid))}")
    return LiveSettingCfg(**raw)


def deploy_cfg(setting: LiveSettingCfg, seed: int) -> DeployCfg:
    """The runtime's settings for ``setting`` (lockstep, so a trial is reproducible)."""
    lidar = LidarCfg(range_noise=setting.range_noise, dropout=setting.dropout, rays_per_scan=setting.rays_per_scan)
    return DeployCfg(
        perception=PerceptionCfg(lidar=lidar, rate_hz=setting.rate_hz, latency_s=setting.latency_s),
        realtime=False,
        map_margin=MAP_MARGIN,
        odom_pos_noise=setting.odom_pos_noise,
        odom_yaw_noise=setting.odom_yaw_noise,
        odom_drift_xy=setting.odom_drift_xy,
        odom_drift_yaw=setting.odom_drift_yaw,
        seed=seed,
    )


def policy_of(run: MethodRun) -> PolicySpec:
    """The manifest entry as the runtime's policy source (``hold`` for a hold row)."""
    if run.checkpoint is None:
        return PolicySpec("hold", run.config.task)
    return PolicySpec(
        run.checkpoint, run.config.task, run.config, "torch", list(policy_model(run.config.algo).obs_groups)
    )


def check_live(run: MethodRun) -> None:
    """``ManifestError`` naming the terms when the live pipeline cannot build this policy's observation."""
    spec = policy_of(run)
    try:
        _check_deployable(spec.task, spec.obs_groups)
    except ValueError as err:
        raise ManifestError(f"method {run.method!r}: perception=lidar cannot score it: {err}") from None


class LiveTrials:
    """``evaluate``'s hook for ``perception=lidar``: checks policies and runs a column's trials through perception."""

    def __init__(self, setting: str | LiveSettingCfg = "default", workers: int = 1):
        """``workers`` > 1: scenes are shared out to that many processes (a trial's result does not depend on
        where or after what it runs: every trial starts from a fresh map, pose, policy state and seeded draws)."""
        self.setting = load_setting(setting) if isinstance(setting, str) else setting
        if workers < 1:
            raise ValueError(f"live workers must be >= 1, got {workers}")
        self.workers = workers

    def check(self, run: MethodRun) -> None:
        check_live(run)

    def run(
        self, run: MethodRun, group: SceneGroup, trials: list[Trial], time_s: float, radius: float, seed: int, bar=None
    ) -> list[TrialResult]:
        """Results of ``trials`` (in order) of ``run``'s policy on ``group``'s scenes."""
        spec = policy_of(run)
        spec.task = copy.deepcopy(spec.task)
        spec.task.success.radius, spec.task.success.time_s = radius, time_s
        results: dict[int, TrialResult] = {}
        quiet = logging.getLogger("cat.deploy.runtime")  # one "goal set" line per trial would bury the progress bar
        level = quiet.level
        quiet.setLevel(max(level, logging.WARNING))
        try:
            self._run_scenes(spec, group, trials, time_s, seed, results, bar)
        finally:
            quiet.setLevel(level)
        return [results[i] for i in range(len(trials))]

    def _run_scenes(self, spec, group, trials, time_s, seed, results, bar) -> None:
        jobs = [
            (spec, group.scenes[s], [(i, t) for i, t in enumerate(trials) if t.scene == s], time_s, seed, self.setting)
            for s in sorted({t.scene for t in trials})
        ]
        if self.workers == 1 or len(jobs) == 1:
            for job in jobs:
                results.update(scene_trials_job(*job, bar=bar))
            return
        ctx = multiprocessing.get_context("spawn")  # no fork of a process holding torch / Warp threads
        with ProcessPoolExecutor(max_workers=min(self.workers, len(jobs)), mp_context=ctx) as pool:
            for done in as_completed([pool.submit(scene_trials_job, *job) for job in jobs]):
                part = done.result()
                results.update(part)
                if bar is not None:
                    bar.update(len(part))


def scene_trials_job(spec, scene, items, time_s: float, seed: int, setting: LiveSettingCfg, bar=None) -> dict:
    """{trial index: result} of ``items`` ((index, trial) of one scene) on one runtime (also a worker's job)."""
    torch.set_num_threads(1)
    logging.getLogger("cat.deploy.runtime").setLevel(logging.WARNING)
    with contextlib.redirect_stdout(io.StringIO()):  # rsl_rl prints the network: stdout carries the tables
        rt = Runtime(scene, spec, deploy_cfg(setting, seed))
    out = {}
    for i, t in items:
        out[i] = run_trial(rt, t, time_s, seed)
        if bar is not None:
            bar.update(1)
    return out


def run_trial(rt: Runtime, trial: Trial, time_s: float, seed: int = 0) -> TrialResult:
    """One trial on a fresh map: place the robot, set the goal, one scan, then ``time_s`` of lockstep control."""
    rt.rng = np.random.default_rng([seed, trial.scene, trial.goal, trial.start])  # sensor-independent draws
    rt.perception.lidar.rng = np.random.default_rng([seed, trial.scene, trial.goal, trial.start, 1])
    rt.reset(start_xy=trial.start_xy, yaw=trial.yaw)
    rt.perception.reset_map()
    rt.perception.lidar.scan_index = 0
    rt.deploy.trial_time_s = time_s
    rt.set_goal(trial.goal_xyz, check=False)  # the protocol's goal, as the ground-truth path places it
    rt.perception.cycle(rt.snapshot())
    rt.perception.publish(float("inf"))  # what the standing robot saw before it starts
    steps = rt.trial.window
    with torch.inference_mode():
        rt.run(threading.Event(), lambda r: r._trial_steps >= steps)
    return rt.trial.results(torch.zeros(1, dtype=torch.long))[0]
