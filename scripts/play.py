"""Evaluate a checkpoint on the trial protocol: ``python scripts/play.py checkpoint=<model.pt> episodes=20``.

Optional: ``record=rollout.rrd`` (rerun replay of world 0), ``seed=`` (start poses), ``scene_seed=`` /
``scene_dir=`` (other scenes than the run's), ``scene_variants=`` (how many typical variants: Table I's 10 for a
run trained on more), ``mirror=true`` (their left/right mirror images), ``sim=``,
``num_envs=``, ``by_scene=true`` (first one line per scene: ``scene=<i> kind=<k> difficulty=<d> episodes=...``),
``contacts=true`` (then a line naming the body that touched first: ``first_contact=<body>:<trials>,...``),
``clearance=true`` (then the success rate if contacts shallower than 1 / 2 / 4 cm were ignored:
``tolerant_success=1cm:<x>,2cm:<x>,4cm:<x> deepest_mm_median=<x> contact_trials=<n>``),
``falls=true`` (then ``falls=<n>/<N> fall_time_s=<q25>/<median>/<q75> fall_progress_median=<x>
falls_without_contact=<k>``: when the falls came, how far along the way, how many before any contact),
``paths=<file.csv>`` (each trial's root path in its scene's frame, step by step: ``cat.eval.paths.COLUMNS``),
``warmup=true`` (the run's training-only warm-up scenes instead of the paper's: where its curriculum stands;
``warmup_pitch=true|false`` / ``warmup_slit=offset|narrow|tight|none`` play another grading of them than the run's).
With ``by_scene=true`` and ``contacts=true`` each scene's line also names its first-contact bodies.
Prints one line: ``episodes=<n> success_rate=<x> distance_error=<m> collision_rate=<x> fall_rate=<x>``.
"""

from __future__ import annotations

import sys

from cat.cli import Script, dataclass_loader, run
from cat.envs.scene_set import SceneSetError
from cat.envs.trial_metrics import summarize
from cat.eval.contacts import clearance_line, contact_line
from cat.eval.falls import falls_line
from cat.learning.play import PlayCfg, play_trials, scene_lines
from cat.learning.runs import CheckpointError


def _job(cfg: PlayCfg) -> int:
    played = play_trials(cfg)
    if cfg.by_scene:
        print("\n".join(scene_lines(played.trials, played.results, played.scenes, played.first_contacts)))
    if played.first_contacts is not None:
        print(contact_line(played.first_contacts))
    if played.clearance is not None:
        print(clearance_line(played.results, played.clearance))
    if played.falls is not None:
        print(falls_line(played.results, played.falls))
    print(summarize(played.results).line())
    return 0


SCRIPT = Script(
    name="play",
    doc=__doc__,
    load=dataclass_loader(PlayCfg, required=("checkpoint",)),
    job=_job,
    keys=list(PlayCfg.__dataclass_fields__),
    errors=(CheckpointError, SceneSetError, ValueError),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
