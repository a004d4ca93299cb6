"""Run a checkpoint: ``python scripts/play.py checkpoint=<model.pt> episodes=2 [record=rollout.rrd]``."""

from __future__ import annotations

import logging
import sys

from omegaconf import OmegaConf

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
    except CheckpointError as err:
        log.error("%s", err)
        return 2
    print(
        f"episodes={res.episodes} success_rate={res.success_rate:.3f} mean_return={res.mean_return:.3f} "
        f"distance_error={res.distance_error:.3f} collision_rate={res.collision_rate:.3f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
