"""Benchmarks: ``python scripts/bench.py sim|fields|field_contact|train|learner|eval|gen|scale|soak|live|live_eval``
(extra args go to the case)."""

from __future__ import annotations

import importlib
import sys

COMMANDS = {
    "sim": "cat.bench.sim",
    "fields": "cat.bench.fields",
    "field_contact": "cat.bench.field_contact",
    "learner": "cat.bench.learner",
    "train": "cat.bench.train",
    "eval": "cat.bench.eval",
    "gen": "cat.bench.gen",
    "scale": "cat.bench.scale",
    "soak": "cat.bench.soak",
    "live": "cat.bench.live",
    "live_eval": "cat.bench.live_eval",
}
SCENE_TRAIN_FLAGS = ("--scenes", "--obstacles", "--scene-dir")
"""``train`` with any of these measures a scene set (``cat.bench.train_obstacles``) instead of flat ground."""


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in COMMANDS:
        print(f"usage: bench.py {{{'|'.join(COMMANDS)}}} [args]", file=sys.stderr)
        return 2
    name = COMMANDS[argv[0]]
    if argv[0] == "train" and any(a.split("=")[0] in SCENE_TRAIN_FLAGS for a in argv[1:]):
        name = "cat.bench.train_obstacles"  # training on a scene set, physical or field obstacles
    try:
        module = importlib.import_module(name)
    except ImportError as err:
        print(f"benchmark {argv[0]!r} unavailable: {err}", file=sys.stderr)
        return 2
    module.main(argv[1:])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
