"""Export a run's policy to one self-contained ONNX file (observation normaliser baked in, deployment metadata).

``python scripts/export.py checkpoint=<model_<it>.pt | run folder> out=policy.onnx [force=true]`` prints one line:
``wrote <out> (<mlp|lstm>, obs <n> -> actions <m>, <size> KB); onnxruntime vs torch max|d action|/max(1,|a|)=<x> ...``.
The file drives ``scripts/click_and_traverse.py checkpoint=policy.onnx``. See docs/export.md.
"""

from __future__ import annotations

import sys

from cat.cli import run
from cat.deploy.export import SCRIPT


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
