"""Build the unseen Table II test set: ``python scripts/gen_test_set.py [out=data/test_unseen]``.

30 indoor crops from a random stream no training run uses, split 15 easy / 15 hard by obstacle density,
fields precomputed (see ``cat/eval/test_set.py`` and docs/evaluation.md). Deterministic: the same command
rebuilds the same scenes. Keys: ``out``, ``num_scenes``, ``goals_per_scene``, ``max_seeds``, ``fields``.
"""

from __future__ import annotations

import logging
import sys
import time

from omegaconf import OmegaConf

from cat.eval.test_set import UnseenSetCfg, build_test_set
from cat.terrain import SceneError


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    log = logging.getLogger("gen_test_set")
    valid = ", ".join(UnseenSetCfg.__dataclass_fields__)
    for item in argv:
        if "=" not in item or item.split("=", 1)[0] not in UnseenSetCfg.__dataclass_fields__:
            log.error("bad argument %r: expected key=value with key in: %s", item, valid)
            return 2
    try:
        cfg = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(UnseenSetCfg), OmegaConf.from_dotlist(argv)))
        t0 = time.perf_counter()
        index = build_test_set(cfg)
    except (ValueError, SceneError) as err:
        log.error("%s", err)
        return 2
    easy = sum(e["split"] == "easy" for e in index)
    log.info("wrote %d scenes (%d easy, %d hard) under %s in %.0f s", len(index), easy, len(index) - easy, cfg.out,
             time.perf_counter() - t0)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
