"""Warp's start-up banner, kernel-load lines and native CUDA warning stay off the terminal unless asked for."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SNIPPET = (
    "import numpy as np\n"
    "from cat.fields import Grid, build_field\n"
    "occ = np.zeros((12, 12, 6), bool); occ[4:6, 4:6, :3] = True\n"
    "build_field(occ, Grid((0, 0, 0), 0.04, (12, 12, 6)), goal=(0.4, 0.1, 0.1))\n"
    "print('built')\n"
)


def _run(extra_env: dict[str, str]) -> str:
    env = {k: v for k, v in os.environ.items() if k != "CAT_WARP_VERBOSE"}
    env.update(PYTHONPATH=str(REPO), **extra_env)
    out = subprocess.run(
        [sys.executable, "-c", SNIPPET], env=env, capture_output=True, text=True, timeout=300, check=True
    )
    return out.stdout + out.stderr


def test_warp_quiet_by_default():
    text = _run({})
    assert "built" in text
    assert "Warp" not in text and "Module" not in text, text


def test_warp_verbose_opt_in():
    text = _run({"CAT_WARP_VERBOSE": "1"})
    assert "Warp 1." in text and "initialized" in text
