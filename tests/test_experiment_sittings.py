"""A sitting's budget (``max_minutes=``): a stage's runs go in waves as wide as the launcher runs at once on this
machine (the sequential launcher: one; joblib: ``n_jobs``), each wave given what the sitting has left when it
starts, so one sitting of experiment=table1 (ten runs in one stage) stops on time instead of giving every run the
whole budget."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import yaml

from cat.launcher import load_script

REPO = Path(__file__).resolve().parents[1]
COMMON = ["sim=mujoco", "num_envs=4", "algo.num_steps_per_env=4", "algo.save_interval=1"]


def _given(caplog, by_seed: bool = False) -> dict[str, float]:
    """The sitting budget each stage-0 run was launched with, by cell (or ``cell@seed``), from the runner's log."""
    return {
        (m.group(1) if by_seed else m.group(1).split("@")[0]): float(m.group(2))
        for r in caplog.records
        if (m := re.match(r"stage 0: (\w+@\d): .* max_minutes=([\d.]+)", r.getMessage()))
    }


def test_each_sequential_run_gets_what_the_sitting_has_left(tmp_path, caplog):
    exp = tmp_path / "sit.yaml"
    cells = {"a": {"task": "flat", "iterations": 1}, "b": {"task": "flat", "iterations": 1, "seeds": [1]}}
    exp.write_text(yaml.safe_dump({"common": COMMON, "cells": cells}))
    mod = load_script(REPO / "scripts" / "experiment.py")
    with caplog.at_level(logging.INFO):
        code = mod.main([f"experiment={exp}", f"root={tmp_path / 'exps'}", "max_minutes=30"])
    assert code == 0
    given = _given(caplog)
    assert set(given) == {"a", "b"}
    assert given["a"] <= 30 and given["b"] < given["a"]  # b started after a ran: less of the sitting was left
    assert (tmp_path / "exps/sit/runs/a/seed0/model_0.pt").is_file()
    assert (tmp_path / "exps/sit/runs/b/seed1/model_0.pt").is_file()


def test_joblib_waves_of_n_jobs_each_get_what_is_left(tmp_path, caplog):
    """Waves are seed-major: seed 0 of every cell before any seed 1 (a sitting cut short leaves a whole column)."""
    exp = tmp_path / "wave.yaml"
    cells = {"a": {"task": "flat", "iterations": 1, "seeds": [0, 1]}, "b": {"task": "flat", "iterations": 1}}
    exp.write_text(yaml.safe_dump({"common": COMMON, "cells": cells}))
    mod = load_script(REPO / "scripts" / "experiment.py")
    args = [f"experiment={exp}", f"root={tmp_path / 'exps'}", "max_minutes=30", "hydra/launcher=joblib"]
    with caplog.at_level(logging.INFO):
        code = mod.main([*args, "hydra.launcher.n_jobs=2"])
    assert code == 0
    given = _given(caplog, by_seed=True)
    assert set(given) == {"a@0", "a@1", "b@0"}
    assert given["a@0"] == given["b@0"] <= 30  # the first wave: seed 0 of both cells, launched together
    assert given["a@1"] < given["a@0"]  # the second wave started after the first ran
    assert all((tmp_path / f"exps/wave/runs/{u}/model_0.pt").is_file() for u in ("a/seed0", "a/seed1", "b/seed0"))
