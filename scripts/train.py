"""Train a PPO policy: ``python scripts/train.py task=flat sim=mujoco num_envs=16 max_iterations=2``.

Keys are hydra overrides of ``configs/train.yaml`` (``task=``, ``sim=``, ``num_envs=``, ``max_iterations=``,
``seed=``, ``init=<checkpoint>``, ``resume=<checkpoint>``, any ``task.*`` / ``algo.*`` field).
"""

from __future__ import annotations

import logging
import sys

from cat.learning.hydra_cfg import ConfigError, load_config
from cat.learning.runs import CheckpointError, resume_config, train


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        cfg = load_config(argv)
        if cfg.resume:
            cfg = resume_config(cfg.resume, argv)
        run_dir = train(cfg)
    except (ConfigError, CheckpointError, ValueError) as err:
        logging.getLogger("train").error("%s", err)
        return 2
    print(f"run folder: {run_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
