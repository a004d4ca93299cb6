"""Click-and-Traverse (paper §III-C) in simulation with live perception.

Browser: ``python scripts/click_and_traverse.py scene=hurdle-crouch checkpoint=<model_*.pt|run folder|x.onnx|hold>``
prints the URL; click the floor to send the G1 there.
Headless: add ``goal=2,0 [time_limit=20] [record=run.rrd]``; prints
``success=<0|1> time_s=<t> distance_error=<m> collisions=<n> field_updates_hz=<f>``. See docs/demo.md.
"""

from __future__ import annotations

import sys

from cat.cli import run
from cat.deploy.cli import SCRIPT


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
