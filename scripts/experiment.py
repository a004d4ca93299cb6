"""Run an experiment: ``python scripts/experiment.py experiment=smoke [only=[a,b]] [dry_run=true] [max_minutes=60]``.

Trains what ``configs/experiment/<name>.yaml`` is missing, stage by stage (prior -> specialists -> distillation
-> fine-tuning), skipping runs already done (checkpoint + config hash), resuming unfinished ones, then builds its
tables (``trials.csv``, ``table*.md``). Each stage's runs go through hydra's launcher: ``hydra/launcher=joblib``
(parallel processes here), ``submitit_local``, ``submitit_slurm`` (a SLURM cluster) with ``hydra.launcher.<key>=``
settings. Its folder: ``<root>/<name>/`` (``state.json``, ``runs/<cell>/seed<k>/``, ``tables/<table>/``).
Format and cluster commands: docs/experiments.md.
"""

from __future__ import annotations

import sys

from cat.cli import Script, dataclass_loader, run
from cat.experiment.runner import ExperimentCfg, run_experiment
from cat.experiment.spec import experiment_names
from cat.learning.runs import CheckpointError

SCRIPT = Script(
    name="experiment",
    doc=__doc__,
    load=dataclass_loader(ExperimentCfg, required=("experiment",)),
    job=run_experiment,
    groups={"experiment": experiment_names()},
    keys=list(ExperimentCfg.__dataclass_fields__),
    errors=(CheckpointError, ValueError),
    uses_launcher=True,
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
