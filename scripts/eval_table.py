"""Tables I / II from checkpoints: ``python scripts/eval_table.py manifest=<yaml> out=<dir> [trials_per_scene=<k>]``.

Other keys: ``sim=mujoco|warp``, ``device=``, ``seed=`` (start poses), ``max_envs=``. Writes ``<dir>/trials.csv``,
``table1.md/.tex``, ``table2.md/.tex`` (the tables the manifest asks for) and prints the Markdown. The manifest
format is in ``cat/eval/manifest.py`` and docs/evaluation.md.
"""

from __future__ import annotations

import logging
import sys

from omegaconf import OmegaConf

from cat.envs.scene_set import SceneSetError
from cat.eval.evaluate import EvalTableCfg, evaluate, write_atomically
from cat.eval.manifest import ManifestError
from cat.learning.runs import CheckpointError


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    log = logging.getLogger("eval_table")
    valid = ", ".join(EvalTableCfg.__dataclass_fields__)
    for item in argv:
        if "=" not in item or item.split("=", 1)[0] not in EvalTableCfg.__dataclass_fields__:
            log.error("bad argument %r: expected key=value with key in: %s", item, valid)
            return 2
    try:
        cfg = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(EvalTableCfg), OmegaConf.from_dotlist(argv)))
    except Exception as err:
        log.error("bad arguments %s: %s (valid keys: %s)", argv, err, valid)
        return 2
    for key in ("manifest", "out"):
        if getattr(cfg, key) == "???":
            log.error("missing %s=<%s>", key, "manifest.yaml" if key == "manifest" else "output folder")
            return 2
    try:
        _, files = evaluate(cfg)
    except (ManifestError, CheckpointError, SceneSetError, ValueError) as err:
        log.error("%s", err)
        return 2
    write_atomically(cfg.out, files)
    for name in sorted(files):
        if name.endswith(".md"):
            print(files[name])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
