"""scripts/ship.py: a compact copy of a checkpoint that resumes (Adam moments in bfloat16), refusals leave out as is."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import torch

from cat.cli import run
from cat.learning.runs import CheckpointError, validate_train_cfg
from cat.learning.ship import SCRIPT, ShipCfg, ship
from cat.run.config import TrainCfg


def _run(tmp_path: Path, it: int = 40) -> Path:
    """A run folder with a distillation-style checkpoint of a real Adam after a few steps."""
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(64, 256), torch.nn.ELU(), torch.nn.Linear(256, 12))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    for _ in range(3):
        opt.zero_grad()
        net(torch.randn(32, 64)).square().mean().backward()
        opt.step()
    run = tmp_path / "run"
    run.mkdir()
    ckpt = {"student_state_dict": net.state_dict(), "optimizer_state_dict": opt.state_dict(), "iter": it, "infos": {}}
    ckpt["rehearsal_optimizer_state_dict"] = copy.deepcopy(
        opt.state_dict()
    )  # a second optimiser (algo.rehearsal's) is one too
    torch.save(ckpt, run / f"model_{it}.pt")
    torch.save({"snapshot": torch.zeros(3)}, run / f"env_{it}.pt")
    (run / "config.yaml").write_text("task:\n  task: flat\n")
    (run / "metrics.csv").write_text("iteration,tag,value\n0,Loss/behavior,1.0\n")
    return run / f"model_{it}.pt"


def shipped_dtype(path: Path, key: str) -> torch.dtype:
    """The dtype of the first moment of the first parameter in optimiser state ``key`` of a shipped file."""
    return torch.load(path, weights_only=False)[key]["state"][0]["exp_avg"].dtype


def test_ship_compacts_and_the_optimizer_loads_back(tmp_path):
    src = _run(tmp_path)
    out = tmp_path / "checkpoints" / "student"
    written = ship(ShipCfg(checkpoint=str(src), out=str(out)))
    assert sorted(p.name for p in written) == ["config.yaml", "env_40.pt", "metrics.csv", "model_40.pt"]
    assert (out / "model_40.pt").stat().st_size < 0.7 * src.stat().st_size  # (1 + 4 × ½) / 5 of the float32 bytes
    assert shipped_dtype(out / "model_40.pt", "rehearsal_optimizer_state_dict") == torch.bfloat16
    shipped, orig = torch.load(out / "model_40.pt", weights_only=False), torch.load(src, weights_only=False)
    torch.testing.assert_close(shipped["student_state_dict"], orig["student_state_dict"], rtol=0, atol=0)
    net = torch.nn.Sequential(torch.nn.Linear(64, 256), torch.nn.ELU(), torch.nn.Linear(256, 12))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    opt.load_state_dict(shipped["optimizer_state_dict"])  # cast back to the parameters' float32
    for k, state in opt.state_dict()["state"].items():
        ref = orig["optimizer_state_dict"]["state"][k]
        assert state["exp_avg"].dtype == torch.float32 and state["step"] == ref["step"]
        torch.testing.assert_close(state["exp_avg"], ref["exp_avg"], rtol=1e-2, atol=1e-12)
        torch.testing.assert_close(state["exp_avg_sq"], ref["exp_avg_sq"], rtol=1e-2, atol=1e-20)


def test_ship_refusals_leave_out_unchanged(tmp_path, capsys):
    src = _run(tmp_path)
    out = tmp_path / "shipped"
    out.mkdir()
    (out / "model_9000.pt").write_bytes(b"older")
    with pytest.raises(FileExistsError, match="model_9000.pt"):
        ship(ShipCfg(checkpoint=str(src), out=str(out)))
    with pytest.raises(ValueError, match="max_mb"):
        ship(ShipCfg(checkpoint=str(src), out=str(out), max_mb=0.01, force=True))
    assert [p.name for p in out.iterdir()] == ["model_9000.pt"]
    with pytest.raises(CheckpointError, match="not found"):
        ship(ShipCfg(checkpoint=str(tmp_path / "run" / "model_1.pt"), out=str(out)))
    assert run(SCRIPT, [f"checkpoint={src.parent}", f"out={out}", "force=true"]) == 0  # the run folder's latest model
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "env_40.pt", "metrics.csv", "model_40.pt"]
    assert "wrote" in capsys.readouterr().out


def test_weights_only_ships_the_networks_and_refuses_a_resume(tmp_path):
    src = _run(tmp_path)
    out = tmp_path / "checkpoints" / "student"
    written = ship(ShipCfg(checkpoint=str(src), out=str(out), weights_only=True))
    assert sorted(p.name for p in written) == ["config.yaml", "metrics.csv", "model_40.pt"]  # no env snapshot
    shipped = torch.load(out / "model_40.pt", weights_only=False)
    assert "optimizer_state_dict" not in shipped and "rehearsal_optimizer_state_dict" not in shipped
    assert shipped["iter"] == 40
    assert (out / "model_40.pt").stat().st_size < 0.25 * src.stat().st_size  # 1 of the 5 float32 copies
    torch.testing.assert_close(shipped["student_state_dict"], torch.load(src, weights_only=False)["student_state_dict"])
    with pytest.raises(CheckpointError, match="init= instead"):
        validate_train_cfg(TrainCfg(resume=str(out / "model_40.pt")))
