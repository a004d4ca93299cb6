"""A trial file's success rate by how wide a way its trials offer (the widest body radius connecting start and goal).

``python scripts/corridors.py trials=<table>_trials.csv.gz scene_root=data/test_unseen [method=...] [out=...]``;
see cat/eval/corridors.py.
"""

from __future__ import annotations

import sys

from cat.cli import run
from cat.eval.corridors import SCRIPT


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
