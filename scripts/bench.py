"""Benchmarks: ``python scripts/bench.py sim|fields|train|eval|gen|scale|soak`` (extra args go to the case)."""

from __future__ import annotations

import importlib
import sys

COMMANDS = {
    "sim": "cat.bench.sim",
    "fields": "cat.bench.fields",
    "train": "cat.bench.train",
    "eval": "cat.bench.eval",
    "gen": "cat.bench.gen",
    "scale": "cat.bench.scale",
    "soak": "cat.bench.soak",
    "live": "cat.bench.live",
}


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in COMMANDS:
        print(f"usage: bench.py {{{'|'.join(COMMANDS)}}} [args]", file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(COMMANDS[argv[0]])
    except ImportError as err:
        print(f"benchmark {argv[0]!r} unavailable: {err}", file=sys.stderr)
        return 2
    module.main(argv[1:])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
