"""Shared test set-up: the offline menagerie (MENAGERIE_ROOT) and small, fast defaults."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

_SHARED = Path(__file__).resolve().parents[2] / "shared" / "menagerie"
if "MENAGERIE_ROOT" not in os.environ and _SHARED.is_dir():
    os.environ["MENAGERIE_ROOT"] = str(_SHARED)


@pytest.fixture(scope="session")
def robot_cfg():
    from cat.envs.robot import load_robot_cfg

    return load_robot_cfg()
