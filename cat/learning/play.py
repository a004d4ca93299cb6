"""Roll out a checkpoint on the evaluation protocol (``cat.eval``) and report SR / DE / collision / fall rates.

``episodes`` trials are the first ones of the run's trial list (start-major: spread over its scenes and
goals), each run for ``success.time_s`` from its own reset with no auto-reset, scored by ``cat.envs.trial_metrics``.
The scenes are the run's own (its ``task.scene_seed`` / ``task.scene_dir``) unless ``scene_seed`` or
``scene_dir`` say otherwise.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

from tqdm import tqdm

from cat.envs.trial_metrics import Summary, TrialResult, summarize
from cat.eval.contacts import Clearance, FirstContacts, contact_counts
from cat.eval.falls import Falls
from cat.eval.paths import Paths, write_paths
from cat.eval.runner import EvalCfg, make_eval_env, run_scene_group, run_trials
from cat.eval.trials import Trial, first_trials, flat_trials, scene_trials
from cat.learning.runs import load_run_config, resolve_checkpoint
from cat.run.policy import MirrorAveraged, load_policy
from cat.terrain.graded import GRADED_BY, SLIT_GRADINGS
from cat.terrain.scene import Scene, layout_text

log = logging.getLogger(__name__)


@dataclass
class PlayCfg:
    checkpoint: str = "???"  # model_<it>.pt, or a run folder (its latest checkpoint)
    episodes: int = 10  # trials
    num_envs: int | None = None  # parallel trials; default min(episodes, 64)
    sim: str = ""  # override the run's backend
    seed: int = 0  # start-pose seed of the trials (not the run's RL seed)
    scene_seed: int | None = None  # typical scenes: override the run's task.scene_seed
    scene_variants: int | None = None  # typical scenes: override the run's task.scene_variants (Table I: 10)
    scene_dir: str = ""  # evaluate on these scene folders instead of the run's scenes
    scene_kind: str = ""  # evaluate on this typical kind's variants (a generalist: one of its task.scene_groups)
    mirror: bool = False  # evaluate on the left/right mirror images of the scenes (a lateralised policy shows)
    time_s: float = 5.0  # trial length (paper: 5 s); e.g. 20 to measure falls over a whole flat episode
    record: str = ""  # .rrd path: record world 0 of the rollout for rerun replay (`rerun <file>`)
    by_scene: bool = False  # scripts/play.py also prints one line per evaluated scene (where a policy fails)
    warmup: bool = False  # the run's training-only warm-up scenes (d < 0) instead: curriculum progress, diagnostic
    warmup_pitch: bool | None = None  # with warmup: multi-hurdle's graded-pitch warm-ups (None: as the run trained)
    # with warmup: the side types' warm-up slit grading to play (cat.terrain.graded.SLIT_GRADINGS without ``slit_``:
    # offset | narrow | tight; none: the default ramp; "": as the run trained), e.g. a cell on a ladder it never saw
    warmup_slit: str = ""
    contacts: bool = False  # scripts/play.py also prints which body touched first (cat.eval.contacts)
    clearance: bool = False  # ... and the success rate at contact-depth tolerances (cat.eval.contacts.Clearance)
    falls: bool = False  # scripts/play.py also prints when the falls came and how far along (cat.eval.falls)
    symmetric: bool = False  # play the policy averaged with its mirror image (cat.run.policy.MirrorAveraged)
    paths: str = ""  # .csv path: each trial's root path in its scene's frame, step by step (cat.eval.paths)


class Played(NamedTuple):
    """What ``play_trials`` returns: the trials, their results in order, the evaluated scenes (``None`` on flat
    ground), and with the options each trial's first-contact bodies, its clearance [m] and its fall record
    (``cat.eval.falls.Falls.records``; else ``None``)."""

    trials: list[Trial]
    results: list[TrialResult]
    scenes: list[Scene] | None
    first_contacts: list[str | None] | None = None
    clearance: list[float] | None = None
    falls: list[tuple[float, float, bool]] | None = None


def play(cfg: PlayCfg) -> Summary:
    """``cfg.checkpoint`` may be a run folder: its latest checkpoint plays."""
    return summarize(play_trials(cfg).results)


def scene_lines(
    trials: list[Trial],
    results: list[TrialResult],
    scenes: list[Scene] | None,
    first_contacts: list[str | None] | None = None,
) -> list[str]:
    """One line per evaluated scene: ``scene=<i> kind=<k> difficulty=<d>``, its trials' summary, for a typical
    scene its layout (``layout=slit_gap:0.49,slit_y:-0.30,bar_top:0.18,x:0.67/1.15``; cat.terrain.typical) and,
    given each trial's first-contact bodies, the scene's (``first_contact=left_wrist_yaw_link:4,...``)."""
    lines = []
    for i in sorted({t.scene for t in trials}):
        own = [k for k, t in enumerate(trials) if t.scene == i]
        kind, d = (scenes[i].kind, float(scenes[i].difficulty)) if scenes is not None else ("flat", 0.0)
        line = f"scene={i} kind={kind} difficulty={d:.2f} {summarize([results[k] for k in own]).line()}"
        layout = scenes[i].meta.get("layout") if scenes is not None else None
        if layout:
            line += f" layout={layout_text(layout)}"
        if first_contacts is not None:
            line += f" first_contact={contact_counts([first_contacts[k] for k in own])}"
        lines.append(line)
    return lines


def slit_grading_keys(name: str) -> dict[str, bool]:
    """The task keys that turn on the slit grading ``name`` (``offset``, ``narrow``, ``tight``; ``none``: all off)."""
    names = [f.removeprefix("slit_") for f in SLIT_GRADINGS]
    if name not in (*names, "none"):
        raise ValueError(f"warmup_slit={name!r}: valid: {', '.join(names)}, none")
    return {GRADED_BY[f][1].removeprefix("task."): f == f"slit_{name}" for f in SLIT_GRADINGS}


def play_trials(cfg: PlayCfg) -> Played:
    """The trials of ``play`` and what they gave (``Played``; ``cfg.contacts`` / ``cfg.clearance``:
    ``cat.eval.contacts``)."""
    cfg = replace(cfg, checkpoint=str(resolve_checkpoint(cfg.checkpoint)))
    run_cfg = load_run_config(cfg.checkpoint)
    task = run_cfg.task
    if cfg.episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {cfg.episodes}")
    if cfg.warmup_pitch is not None:
        if not cfg.warmup:
            raise ValueError("warmup_pitch= chooses the warm-up layout: it needs warmup=true")
        task = replace(task, warmup_bar_pitch=cfg.warmup_pitch)
    if cfg.warmup_slit:
        if not cfg.warmup:
            raise ValueError("warmup_slit= chooses the warm-up layout: it needs warmup=true")
        task = replace(task, **slit_grading_keys(cfg.warmup_slit))
    if cfg.scene_variants is not None:
        if cfg.scene_variants < 1:
            raise ValueError(f"scene_variants must be >= 1, got {cfg.scene_variants}")
        if cfg.scene_dir or task.scene_dir or not (task.scene_kind or task.scene_groups):
            raise ValueError("scene_variants= counts typical variants: these trials play no typical scenes")
        task = replace(task, scene_variants=cfg.scene_variants)
    group = run_scene_group(task, cfg.scene_seed, cfg.scene_dir, cfg.scene_kind, cfg.warmup)
    for option in ("mirror", "contacts", "clearance"):
        if getattr(cfg, option) and group is None:
            raise ValueError(f"{option}=true needs obstacle scenes; this run trained on flat ground")
    if cfg.mirror:
        group = group.mirrored()
    if cfg.time_s <= 0:
        raise ValueError(f"time_s must be > 0, got {cfg.time_s}")
    if cfg.num_envs is not None and cfg.num_envs < 1:
        raise ValueError(f"num_envs must be >= 1 (or left out for min(episodes, 64)), got {cfg.num_envs}")
    for key in ("record", "paths"):  # output files: their folder must exist before anything is built
        out = getattr(cfg, key)
        if out and not Path(out).resolve().parent.is_dir():
            raise ValueError(f"{key}={out}: folder {Path(out).resolve().parent} does not exist")
    opts = EvalCfg(seed=cfg.seed, success=replace(EvalCfg().success, time_s=cfg.time_s))
    yaw = opts.start_yaw_range
    if group is None:
        trials = first_trials(lambda k: flat_trials(k, cfg.seed, yaw, radius=2.0), cfg.episodes, 8)
    else:
        pairs = sum(len(s.goals) for s in group.scenes)
        trials = first_trials(lambda k: scene_trials(group.scenes, k, cfg.seed, yaw), cfg.episodes, pairs)
    n = cfg.num_envs if cfg.num_envs is not None else min(cfg.episodes, 64)
    sim, device, trained = cfg.sim or run_cfg.sim.backend, run_cfg.sim.device, run_cfg.sim.obstacles
    env = make_eval_env(task, group, n, opts, sim=sim, device=device, trained_obstacles=trained)  # physical
    policy = load_policy(cfg.checkpoint, env, run_cfg)
    if cfg.symmetric:
        policy = MirrorAveraged(policy, env)
    hooks = []
    if cfg.contacts:
        contacts = FirstContacts(env)
        hooks.append(contacts.on_step)
    if cfg.clearance:
        clearance = Clearance(env)
        hooks.append(clearance.on_step)
    if cfg.falls:
        falls = Falls(env)
        hooks.append(falls.on_step)
    if cfg.paths:
        paths = Paths(env)
        hooks.append(paths.on_step)
    if cfg.record:
        from cat.viz.record import RolloutRecorder

        recorder = RolloutRecorder(cfg.record, env)

        def record(e):  # re-log the obstacles when world 0 starts a trial in another scene
            if e.step_count[0] == 0:
                recorder.log_obstacles()
            recorder.log_step(e)

        hooks.append(record)

    def on_step(e):
        for hook in hooks:
            hook(e)

    with tqdm(total=len(trials), desc="trials", unit="trial") as bar:
        results = run_trials(env, policy, trials, seed=cfg.seed, progress=bar, on_step=on_step if hooks else None)
    if cfg.record:
        recorder.close()
    if cfg.paths:
        out = write_paths(cfg.paths, trials, results, paths.paths(len(trials)), env.dt)
        log.info("wrote each trial's path to %s", out)
    first = contacts.first_bodies(len(trials)) if cfg.contacts else None
    depth = clearance.clearances(len(trials)) if cfg.clearance else None
    fell = falls.records(len(trials)) if cfg.falls else None
    return Played(trials, results, list(group.scenes) if group is not None else None, first, depth, fell)
