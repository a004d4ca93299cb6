"""Tables I / II from checkpoints: ``python scripts/eval_table.py manifest=<yaml> out=<dir> [trials_per_scene=<k>]``.

Other keys: ``sim=mujoco|warp``, ``device=``, ``seed=`` (start poses), ``max_envs=``, ``perception=ground_truth|lidar``
(lidar: every trial through the simulated LiDAR -> map -> observation pipeline of the click demo, one robot at a
time) with ``perception_setting=default|harsh|<yaml>`` (``configs/eval/perception/``), ``clearance=true`` (also
``clearance.md``: each column's SR if contacts shallower than 1 / 2 / 4 cm were ignored). Writes ``<dir>/trials.csv``,
``table1.md/.tex``, ``table2.md/.tex`` (the tables the manifest asks for) and prints the Markdown. The manifest
format is in ``cat/eval/manifest.py`` and docs/evaluation.md.
"""

from __future__ import annotations

import sys

from cat.cli import Script, dataclass_loader, run
from cat.envs.scene_set import SceneSetError
from cat.eval.evaluate import EvalTableCfg, evaluate, write_atomically
from cat.eval.manifest import ManifestError
from cat.learning.runs import CheckpointError


def _job(cfg: EvalTableCfg) -> int:
    live = None
    if cfg.perception == "lidar":
        from cat.deploy.live_eval import LiveTrials

        live = LiveTrials(cfg.perception_setting, cfg.live_workers)
    _, files = evaluate(cfg, live)
    write_atomically(cfg.out, files)
    for name in sorted(files):
        if name.endswith(".md"):
            print(files[name])
    return 0


SCRIPT = Script(
    name="eval_table",
    doc=__doc__,
    load=dataclass_loader(EvalTableCfg, required=("manifest", "out")),
    job=_job,
    run_dir_key="out",
    keys=list(EvalTableCfg.__dataclass_fields__),
    errors=(ManifestError, CheckpointError, SceneSetError, ValueError),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
