"""Interpolate two checkpoints of one lineage (a model soup).

``python scripts/average.py a=<model_*.pt> b=<model_*.pt> alpha=0.5 out=checkpoints/<name> [force=true]``;
see cat/learning/average.py.
"""

from __future__ import annotations

import sys

from cat.cli import run
from cat.learning.average import SCRIPT


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
