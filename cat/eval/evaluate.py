"""``scripts/eval_table.py``: evaluate every manifest row on Tables I / II and write trials.csv + the tables.

For each row × checkpoint × table column: an env on the column's scenes built from the checkpoint's own
``config.yaml`` (its observation layout), the same trials for every method (``cat.eval.trials``), run by
``cat.eval.runner``; with ``perception=lidar`` each trial instead runs through the simulated LiDAR perception of the
deploy runtime (a hook, ``cat.deploy.live_eval.LiveTrials``, handed in by ``scripts/eval_table.py``: the deploy
layer sits above this one). Nothing is written until every trial has run; then all files are written to temporary
names and renamed into place, so an error leaves no half-written output.
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from cat.checkpoint_io import CheckpointError, UnsafeCheckpointError
from cat.envs.config import SuccessCfg
from cat.envs.trial_metrics import TrialResult
from cat.eval.contacts import Clearance, clearance_line
from cat.eval.manifest import Manifest, ManifestError, MethodRun, load_manifest
from cat.eval.runner import EvalCfg, HoldPolicy, SceneGroup, make_eval_env, run_trials
from cat.eval.table import CSV_COLUMNS, render_by_scene, render_latex, render_markdown
from cat.eval.trials import Trial, scene_trials
from cat.run.policy import load_policy
from cat.terrain import TYPICAL_KINDS

log = logging.getLogger(__name__)


@dataclass
class EvalTableCfg:
    """``scripts/eval_table.py key=value`` options."""

    manifest: str = "???"
    out: str = "???"
    trials_per_scene: int = 10  # start poses per (scene, goal); typical scenes have one goal
    sim: str = "mujoco"  # physics backend for every method (mujoco | warp)
    device: str = "cpu"
    seed: int = 0  # start-pose seed
    max_envs: int = 256  # parallel trials per batch
    time_s: float = 5.0  # trial length (paper: 5 s)
    radius: float = 0.1  # success radius (paper: 0.1 m)
    perception: str = "ground_truth"  # ground_truth (the env's terms) | lidar (LiDAR -> map -> block, per trial)
    perception_setting: str = "default"  # with lidar: configs/eval/perception/<name>.yaml (default | harsh) or a path
    live_workers: int = 1  # with lidar: processes running a column's scenes in parallel (one trial each at a time)
    clearance: bool = False  # also each trial's deepest penetration and the SR at depth tolerances (clearance.md/.csv)


def scene_groups(manifest: Manifest) -> dict[str, list[SceneGroup]]:
    """The columns of each requested table, with their scenes and fields (built once, shared by all rows)."""
    out = {}
    if manifest.table1 is not None:
        t1 = manifest.table1
        out["table1"] = [SceneGroup.typical(k, t1["variants"], t1["scene_seed"], t1["shapes"]) for k in TYPICAL_KINDS]
    if manifest.table2:
        out["table2"] = [SceneGroup.from_dir(name, folder) for name, folder in manifest.table2.items()]
    if manifest.table3 is not None:
        t3 = manifest.table3
        out["table3"] = [SceneGroup.typical(k, t3["variants"], t3["scene_seed"], t3["shapes"]) for k in t3["kinds"]]
    return out


def check_policy(run: MethodRun, opts: EvalCfg, sim: str, device: str) -> None:
    """Fail early when a checkpoint does not fit the observation layout of its own config.yaml."""
    if run.checkpoint is None:
        return
    env = make_eval_env(run.config.task, None, 1, opts, sim, device, run.config.sim.obstacles)
    try:
        load_policy(run.checkpoint, env, run.config)
    except UnsafeCheckpointError as err:
        raise ManifestError(f"method {run.method!r}: {err}") from None
    except CheckpointError as err:
        raise ManifestError(
            f"method {run.method!r}: checkpoint {run.checkpoint} does not fit the observation layout of its "
            f"config.yaml ({err})"
        ) from err


def trial_row(run: MethodRun, table: str, group: SceneGroup, t: Trial, r: TrialResult) -> dict[str, str]:
    """One trials.csv row (strings, fixed precision: the tables are recomputed from exactly these)."""
    return {
        "method": run.method,
        "seed": str(run.seed),
        "checkpoint": run.checkpoint or "hold",
        "table": table,
        "group": group.name,
        "scene": group.scene_names[t.scene],
        "goal": str(t.goal),
        "start": str(t.start),
        "start_x": f"{t.start_xy[0]:.4f}",
        "start_y": f"{t.start_xy[1]:.4f}",
        "start_yaw": f"{t.yaw:.4f}",
        "goal_x": f"{t.goal_xyz[0]:.4f}",
        "goal_y": f"{t.goal_xyz[1]:.4f}",
        "success": str(int(r.success)),
        "de": f"{r.de:.4f}",
        "collided": str(int(r.collided)),
        "fell": str(int(r.fell)),
        "reach_time": "" if math.isinf(r.reach_time) else f"{r.reach_time:.2f}",
    }


def evaluate(cfg: EvalTableCfg, live=None) -> tuple[list[dict[str, str]], dict[str, str]]:
    """(trials.csv rows, {file name: content}) for the manifest; writes nothing. ``live``: the perception-in-the-
    loop hook (``check(run)``, ``run(run, group, trials, time_s, radius, seed, bar)``), needed by
    ``perception=lidar``."""
    if cfg.trials_per_scene < 1:
        raise ManifestError(f"trials_per_scene must be >= 1, got {cfg.trials_per_scene}")
    if cfg.perception not in ("ground_truth", "lidar"):
        raise ManifestError(f"perception must be ground_truth or lidar, got {cfg.perception!r}")
    if cfg.perception == "lidar" and live is None:
        raise ManifestError("perception=lidar needs the live perception hook (scripts/eval_table.py hands it in)")
    if cfg.clearance and cfg.perception != "ground_truth":
        raise ManifestError("clearance=true measures the simulated trials: it needs perception=ground_truth")
    live = live if cfg.perception == "lidar" else None
    manifest = load_manifest(cfg.manifest)
    opts = EvalCfg(
        starts=cfg.trials_per_scene, seed=cfg.seed, max_envs=cfg.max_envs, success=SuccessCfg(cfg.radius, cfg.time_s)
    )
    for runs in manifest.methods.values():
        for run in runs:
            check_policy(run, opts, cfg.sim, cfg.device)  # before the scenes: a bad checkpoint fails fast
            if live is not None:
                live.check(run)  # a block the live pipeline cannot build: refused before any trial
    groups = scene_groups(manifest)
    trials = {
        (table, g.name): scene_trials(g.scenes, opts.starts, opts.seed, opts.start_yaw_range)
        for table, gl in groups.items()
        for g in gl
    }
    runs = [run for rs in manifest.methods.values() for run in rs]
    total = sum(len(ts) for run in runs for (table, group), ts in trials.items() if run.plays(table, group))
    rows: list[dict[str, str]] = []
    depth: list[tuple[str, str, str, list[TrialResult], list[float]]] = []  # (method, table, column, results, m)
    with tqdm(total=total, desc="trials", unit="trial") as bar:
        for run in runs:
            for table, gl in groups.items():
                for group in gl:
                    if not run.plays(table, group.name):
                        continue
                    ts = trials[table, group.name]
                    bar.set_postfix_str(f"{run.method}/{run.seed} {table} {group.name}")
                    if live is not None:
                        results = live.run(run, group, ts, cfg.time_s, cfg.radius, opts.seed, bar)
                        rows += [trial_row(run, table, group, t, r) for t, r in zip(ts, results, strict=True)]
                        continue
                    n = min(len(ts), opts.max_envs)
                    trained = run.config.sim.obstacles  # evaluation is physical whatever it says
                    env = make_eval_env(run.config.task, group, n, opts, cfg.sim, cfg.device, trained)
                    if run.checkpoint is None:
                        policy = HoldPolicy(env.num_actions)
                    else:
                        policy = load_policy(run.checkpoint, env, run.config)
                    bar.set_postfix_str(f"{run.method}/{run.seed} {table} {group.name}")
                    hook = Clearance(env) if cfg.clearance else None
                    on_step = hook.on_step if hook is not None else None
                    results = run_trials(env, policy, ts, seed=opts.seed, progress=bar, on_step=on_step)
                    rows += [trial_row(run, table, group, t, r) for t, r in zip(ts, results, strict=True)]
                    if hook is not None:
                        depth.append((run.method, table, group.name, results, hook.clearances(len(ts))))
                    del env
    methods = list(manifest.methods)
    files = {"trials.csv": to_csv(rows)}
    note = (
        f"{opts.starts} start pose(s) per scene goal; success: within {cfg.radius:g} m within {cfg.time_s:g} s, "
        f"no contact, no fall; sim={cfg.sim}."
    )
    if live is not None:
        note += f" Perception in the loop: LiDAR -> log-odds map -> block, setting {cfg.perception_setting!r}."
    per_type = manifest.per_type_methods()
    for table, gl in groups.items():
        names = [g.name for g in gl]
        shown = [m for m in methods if any(r.plays(table, g) for r in manifest.methods[m] for g in names)]
        text = note
        if table == "table1" and per_type:
            text += f" {', '.join(per_type)}: each column played by that type's own checkpoint(s); – = none."
        shapes = (manifest.table1 if table == "table1" else manifest.table3 if table == "table3" else {}) or {}
        if shapes.get("shapes", "paper") != "paper":
            text += (
                f" Scenes: the typical layouts built from {shapes['shapes']} obstacle shapes "
                f"(scene seeds {shapes['scene_seed']}..{shapes['scene_seed'] + shapes['variants'] - 1})."
            )
        files[f"{table}.md"] = render_markdown(rows, table, shown, names, text)
        files[f"{table}.tex"] = render_latex(rows, table, shown, names, text)
        files[f"{table}_by_scene.md"] = render_by_scene(rows, table, shown, names)
    if depth:
        files["clearance.md"] = clearance_report(depth)
    return rows, files


def clearance_report(depth: list[tuple[str, str, str, list[TrialResult], list[float]]]) -> str:
    """One line per (method, table, column), pooled over its trials: the physical SR and ``clearance_line``."""
    head = (
        "**Contact depth** (`clearance=true`, cat.eval.contacts): SR pooled over trials by the physical rule, and if "
        "contacts shallower than 1 / 2 / 4 cm were ignored; deepest penetration of the trials with contact."
    )
    lines = [head, ""]
    for method, table, column, results, clear in depth:
        sr = sum(r.success for r in results) / max(len(results), 1)
        lines.append(f"- {method} / {table} / {column}: success={sr:.3f} {clearance_line(results, clear)}")
    return "\n".join(lines) + "\n"


def to_csv(rows: list[dict[str, str]]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def write_atomically(out: str | os.PathLike, files: dict[str, str]) -> None:
    """Write every file to a temporary name first, then rename them all into place."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    tmp = {name: folder / f".{name}.tmp-{os.getpid()}" for name in files}
    try:
        for name, text in files.items():
            tmp[name].write_text(text)
        for name in files:
            os.replace(tmp[name], folder / name)
    finally:
        for path in tmp.values():
            path.unlink(missing_ok=True)
