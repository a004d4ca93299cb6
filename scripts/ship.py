"""Ship a run's checkpoint into a committed folder, its optimiser moments in bfloat16 (under 5 MB).

``python scripts/ship.py checkpoint=<model_<it>.pt | run folder> out=checkpoints/<name> [max_mb=5] [force=true]``;
see cat/learning/ship.py.
"""

from __future__ import annotations

import sys

from cat.cli import run
from cat.learning.ship import SCRIPT


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
