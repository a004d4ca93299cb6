"""Build the unseen Table II test set: ``python scripts/gen_test_set.py [out=data/test_unseen]``.

30 indoor crops from a random stream no training run uses, split 15 easy / 15 hard by obstacle density,
fields precomputed (see ``cat/eval/test_set.py`` and docs/evaluation.md). Deterministic: the same command
rebuilds the same scenes. Keys: ``out``, ``split`` (``test``, or ``val``: the validation twin from a third stream,
for choosing checkpoints and arms), ``num_scenes``, ``goals_per_scene``, ``max_seeds``, ``fields``.
"""

from __future__ import annotations

import logging
import sys
import time

from cat.cli import Script, dataclass_loader, run
from cat.eval.test_set import UnseenSetCfg, build_test_set
from cat.terrain import SceneError

log = logging.getLogger("gen_test_set")


def _job(cfg: UnseenSetCfg) -> int:
    t0 = time.perf_counter()
    index = build_test_set(cfg)
    easy = sum(e["split"] == "easy" for e in index)
    log.info("wrote %d scenes (%d easy, %d hard) under %s in %.0f s", len(index), easy, len(index) - easy, cfg.out,
             time.perf_counter() - t0)  # fmt: skip
    return 0


SCRIPT = Script(
    name="gen_test_set",
    doc=__doc__,
    load=dataclass_loader(UnseenSetCfg),
    job=_job,
    run_dir_key="out",
    keys=list(UnseenSetCfg.__dataclass_fields__),
    errors=(ValueError, SceneError),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
