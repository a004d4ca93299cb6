"""Evaluate a checkpoint on the trial protocol: ``python scripts/play.py checkpoint=<model.pt> episodes=20``.

Optional: ``record=rollout.rrd`` (rerun replay of world 0), ``seed=`` (start poses), ``scene_seed=`` /
``scene_dir=`` (other scenes than the run's), ``sim=``, ``num_envs=``. Prints one line:
``episodes=<n> success_rate=<x> distance_error=<m> collision_rate=<x> fall_rate=<x>``.
"""

from __future__ import annotations

import logging
import sys

from omegaconf import OmegaConf

from cat.envs.scene_set import SceneSetError
from cat.learning.play import PlayCfg, play
from cat.learning.runs import CheckpointError


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    log = logging.getLogger("play")
    try:
        cfg = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(PlayCfg), OmegaConf.from_dotlist(argv)))
    except Exception as err:
        valid = ", ".join(PlayCfg.__dataclass_fields__)
        log.error("bad arguments %s: %s (valid keys: %s)", argv, err, valid)
        return 2
    if cfg.checkpoint == "???":
        log.error("missing checkpoint=<path to model_*.pt>")
        return 2
    try:
        res = play(cfg)
    except (CheckpointError, SceneSetError, ValueError) as err:
        log.error("%s", err)
        return 2
    print(res.line())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
