"""Train a PPO policy: ``python scripts/train.py task=flat sim=mujoco num_envs=16 max_iterations=2``.

Keys are hydra overrides of ``configs/train.yaml``: task=, sim=, algo=, method=, num_envs=, max_iterations=,
max_minutes=, seed=, init=<checkpoint>, resume=<checkpoint>, run_root= / run_name= / run_dir=, and any task.* /
algo.* field. ``resume=`` continues that run with its own config; other keys given change only themselves.
"""

from __future__ import annotations

import sys

from cat.cli import Script, run
from cat.learning.hydra_cfg import _options, load_config
from cat.learning.runs import CheckpointError, resume_config, train, validate_train_cfg


def _load(overrides: list[str]):
    # a resume starts from the run's own config, so keys only its task has (e.g. a distillation's teacher group)
    # can be changed; composing the defaults first would refuse them
    resume = next((o.split("=", 1)[1] for o in overrides if o.startswith("resume=")), "")
    cfg = resume_config(resume, overrides) if resume not in ("", "null") else load_config(overrides)
    validate_train_cfg(cfg)  # every job of a multirun is checked before the first starts
    return cfg


def _job(cfg) -> int:
    run_dir = train(cfg)
    print(f"run folder: {run_dir}" if run_dir else "nothing run: the deadline passed or a stop signal came first")
    return 0


SCRIPT = Script(
    name="train",
    doc=__doc__,
    load=_load,
    job=_job,
    run_dir_key="run_dir",
    groups={g: _options(g) for g in ("task", "sim", "algo", "method")},
    keys=["num_envs", "max_iterations", "max_minutes", "seed", "init", "resume", "teachers", "run_name", "verbose"],
    errors=(CheckpointError, ValueError),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
