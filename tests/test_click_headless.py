"""scripts/click_and_traverse.py without a browser: the one-line result, the rerun recording, a policy checkpoint
driving the robot, and bad input ending in one clear line with exit code 2."""

from __future__ import annotations

import logging
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from cat.deploy.cli import main

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts" / "click_and_traverse.py"
LINE = re.compile(
    r"^success=(?P<success>[01]) time_s=(?P<time>[\d.]+) distance_error=(?P<de>[\d.]+) "
    r"collisions=(?P<coll>\d+) field_updates_hz=(?P<hz>[\d.]+)$"
)


def _script(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO), "RERUN_ANALYTICS": "0"}
    return subprocess.run(
        [sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=timeout, env=env, cwd=REPO
    )


def test_hold_does_not_reach_and_records(tmp_path):
    """Zero actions on flat ground: the goal 2 m ahead is not reached; the line and the .rrd are written."""
    rrd = tmp_path / "hold.rrd"
    out = _script("scene=flat", "checkpoint=hold", "goal=2,0", "time_limit=3", f"record={rrd}")
    assert out.returncode == 0, out.stderr
    m = LINE.match(out.stdout.strip().splitlines()[-1])
    assert m, out.stdout
    assert m["success"] == "0" and float(m["de"]) > 1.0
    assert float(m["hz"]) > 0.0  # the live field was rebuilt while it ran
    assert "Traceback" not in out.stderr and "Warp" not in out.stderr
    printed = subprocess.run(
        ["rerun", "rrd", "print", str(rrd)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    ).stdout
    for entity in ("world/robot/capsules", "world/goal", "world/field/F_H", "world/map/window"):
        assert entity in printed, entity


def _flat_checkpoint() -> Path | None:
    env = os.environ.get("CAT_FLAT_CHECKPOINT")
    if env:
        return Path(env)
    found = sorted((REPO / "checkpoints" / "flat").glob("*.pt"))
    return found[-1] if found else None


def test_trained_flat_policy_reaches_goal():
    """With the shipped flat prior (checkpoints/flat/ or CAT_FLAT_CHECKPOINT) the robot reaches 2 m on flat ground."""
    ckpt = _flat_checkpoint()
    if ckpt is None or not ckpt.is_file():
        pytest.skip("no trained flat checkpoint (checkpoints/flat/*.pt or CAT_FLAT_CHECKPOINT)")
    out = _script("scene=flat", f"checkpoint={ckpt}", "goal=2,0", "time_limit=10", "realtime=false")
    assert out.returncode == 0, out.stderr
    m = LINE.match(out.stdout.strip().splitlines()[-1])
    assert m and m["success"] == "1", out.stdout


def _write_checkpoint(path: Path, actor_state: dict | None) -> Path:
    """A run folder: config.yaml of a flat task, and a checkpoint (``None``: garbage bytes)."""
    from cat.run.config import TrainCfg

    path.mkdir(parents=True, exist_ok=True)
    (path / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.structured(TrainCfg())))
    ckpt = path / "model_1.pt"
    if actor_state is None:
        ckpt.write_bytes(b"this is not a torch checkpoint")
    else:
        torch.save({"actor_state_dict": actor_state, "iter": 1}, ckpt)
    return ckpt


def test_policy_checkpoint_drives_robot(tmp_path, capsys):
    """An rsl_rl actor shaped for the env's actor group loads strictly and acts (the layouts agree)."""
    from rsl_rl.utils import resolve_class

    from cat.envs.config import EnvCfg
    from cat.envs.traversal_env import TraversalEnv
    from cat.run.config import AlgoCfg, runner_cfg

    env = TraversalEnv(EnvCfg(num_envs=1))
    cls, cfg = resolve_class(runner_cfg(AlgoCfg())["actor"])
    actor = cls(env.get_observations(), {"actor": ["actor"]}, "actor", env.num_actions, **cfg)
    ckpt = _write_checkpoint(tmp_path / "run", actor.state_dict())
    code = main(["scene=flat", f"checkpoint={ckpt}", "goal=1.5,0", "time_limit=1", "realtime=false"])
    assert code == 0
    assert LINE.match(capsys.readouterr().out.strip().splitlines()[-1])


@pytest.mark.parametrize(
    "args, message",
    [
        (["scene=/no/such/mesh.obj", "checkpoint=hold", "goal=1,0"], "mesh file not found"),
        (["scene=/no/such/folder", "checkpoint=hold", "goal=1,0"], "not a typical type"),
        (["scene=flat", "checkpoint=/no/such/model_1.pt", "goal=1,0"], "checkpoint not found"),
        (["scene=flat", "checkpoint=hold", "goal=one,0"], "goal must be x,y"),
        (["scene=flat", "checkpoint=hold", "goal=40,0"], "outside the map"),
        (["checkpoint=hold"], "missing scene="),
        (["scene=flat", "checkpoint=hold", "gaol=1,0"], "did you mean goal"),
    ],
)
def test_bad_input_is_one_clear_line(args, message, caplog):
    with caplog.at_level(logging.ERROR):
        assert main(args) == 2
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and message in errors[0], errors
    assert "\n" not in errors[0]


def test_unreadable_checkpoint_is_one_clear_line(tmp_path, caplog):
    ckpt = _write_checkpoint(tmp_path / "run", None)
    with caplog.at_level(logging.ERROR):
        assert main(["scene=flat", f"checkpoint={ckpt}", "goal=1,0"]) == 2
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "not a readable checkpoint" in errors[0], errors


def test_goal_inside_obstacle_from_the_shell(tmp_path):
    """As a user sees it: a mesh scene, a goal inside its box -> one line on stderr, exit 2, no traceback."""
    import trimesh

    mesh = tmp_path / "box.obj"
    trimesh.creation.box(bounds=[[0.8, -0.4, 0.0], [1.4, 0.4, 1.0]]).export(mesh)
    out = _script(f"scene={mesh}", "checkpoint=hold", "goal=1.1,0")
    assert out.returncode == 2
    lines = [ln for ln in out.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "inside an obstacle" in lines[0], out.stderr
    assert "Traceback" not in out.stderr and out.stdout.strip() == ""
