"""Build a scene dataset: ``python scripts/gen_scenes.py out=<dir> typical_variants=1 procedural=2 indoor=2 seed=0``.

Typical types × variants, procedural scenes over [difficulty_min, difficulty_max], indoor crops (embedded
procedural houses, or 3D-FRONT with ``front3d_dir=... future_dir=...``); one folder per scene, resumable,
fields precomputed per goal when ``cat.fields`` is available. Keys: ``cat.terrain.dataset.GenScenesCfg``.
"""

from __future__ import annotations

import logging
import sys
import time

from cat.cli import Script, run
from cat.learning.hydra_cfg import load_config
from cat.terrain.dataset import GenScenesCfg, build_dataset
from cat.terrain.scene import SceneError

log = logging.getLogger("gen_scenes")


def _job(cfg: GenScenesCfg) -> int:
    t0 = time.perf_counter()
    index = build_dataset(cfg)
    log.info("wrote %d scene folders under %s in %.1f s", len(index), cfg.out, time.perf_counter() - t0)
    return 0


SCRIPT = Script(
    name="gen_scenes",
    doc=__doc__,
    load=lambda overrides: load_config(overrides, config_name="gen_scenes", schema=GenScenesCfg),
    job=_job,
    run_dir_key="out",
    keys=list(GenScenesCfg.__dataclass_fields__),
    errors=(ValueError, SceneError),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
