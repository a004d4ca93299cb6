"""Robustness sweep through the simulated LiDAR: ``python scripts/perception_sweep.py manifest=<yaml> out=<dir>``.

Keys: ``sweep=`` (default ``configs/eval/perception_sweep.yaml``: a base perception setting and the axes raised one
at a time), ``trials_per_scene=``, ``seed=``, ``time_s=``, ``radius=``, ``live_workers=``. For each axis and level
the manifest is scored with ``eval_table.py perception=lidar`` (same trials at every level); writes
``<dir>/sweep.csv`` and ``<dir>/perception_sweep.png`` (SR against the level, a panel per axis) and prints the
CSV. Finished levels are kept in ``<dir>/levels/``: rerun the same command to resume a sweep cut short.
"""

from __future__ import annotations

import sys
from pathlib import Path

from cat.cli import Script, dataclass_loader, run
from cat.deploy.sweep import SweepCfg, plot, run_sweep
from cat.envs.scene_set import SceneSetError
from cat.eval.evaluate import write_atomically
from cat.eval.manifest import ManifestError
from cat.learning.runs import CheckpointError


def _job(cfg: SweepCfg) -> int:
    rows, files = run_sweep(cfg)
    write_atomically(cfg.out, files)
    plot(rows, Path(cfg.out) / "perception_sweep.png", f"{Path(cfg.manifest).name}, sweep {Path(cfg.sweep).name}")
    print(files["sweep.csv"], end="")
    return 0


SCRIPT = Script(
    name="perception_sweep",
    doc=__doc__,
    load=dataclass_loader(SweepCfg, required=("manifest", "out")),
    job=_job,
    run_dir_key="out",
    keys=list(SweepCfg.__dataclass_fields__),
    errors=(ManifestError, CheckpointError, SceneSetError, ValueError),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
