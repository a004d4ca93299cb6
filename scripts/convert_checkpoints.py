"""Rewrite old-format checkpoints / env snapshots in place so that torch's safe loader reads them.

``python scripts/convert_checkpoints.py [path=checkpoints]`` (a file or a folder); idempotent, weights
bit-identical; see cat/checkpoint_convert.py.
"""

from __future__ import annotations

import sys

from cat.checkpoint_convert import SCRIPT
from cat.cli import run


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
