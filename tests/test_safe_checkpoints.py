"""Checkpoints a stranger can open safely (``cat.checkpoint_io``): a checkpoint or env snapshot carrying an
arbitrary pickled object is refused by every entry point (play, eval_table, train ``init=`` / ``resume=``, the
click demo, ship, export) with a line naming the file, and its payload never runs; every shipped file loads with
the safe loader; ``scripts/convert_checkpoints.py`` rewrites the old format bit for bit, idempotently."""

from __future__ import annotations

import importlib.util
import logging
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml
from omegaconf import OmegaConf
from tensordict import TensorDict

from cat.checkpoint_convert import ConvertCfg, convert, convert_file
from cat.checkpoint_io import (
    CheckpointError,
    UnsafeCheckpointError,
    read_checkpoint,
    read_env_snapshot,
    safe_load,
)
from cat.run.config import TrainCfg

REPO = Path(__file__).resolve().parents[1]
SHIPPED = sorted((REPO / "checkpoints").glob("*/*.pt"))


class Payload:
    """Unpickling this runs code: it writes ``marker`` (what a malicious checkpoint would do)."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (exec, (f"open({self.marker!r}, 'w').write('ran')",))


def _evil_run(folder: Path, marker: Path, snapshot_too: bool = False) -> Path:
    """A run folder of a flat task whose ``model_1.pt`` carries a ``Payload`` (and ``env_1.pt`` too if asked)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.structured(TrainCfg())))
    ckpt = folder / "model_1.pt"
    torch.save({"actor_state_dict": {}, "iter": 1, "infos": {"x": Payload(marker)}}, ckpt)
    if snapshot_too:
        torch.save({"format": 2, "obs": Payload(marker)}, folder / "env_1.pt")
    return ckpt


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"{name}_script", REPO / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _run(name: str, args: list[str], caplog) -> tuple[int, str]:
    caplog.clear()
    with caplog.at_level(logging.ERROR):
        code = _script(name).main(args)
    return code, " ".join(r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR)


def test_the_payload_is_live(tmp_path):
    """The test's payload really runs under the unsafe loader (so the refusals below mean something)."""
    marker = tmp_path / "ran"
    ckpt = _evil_run(tmp_path / "run", marker)
    torch.load(ckpt, weights_only=False)
    assert marker.read_text() == "ran"


def test_loader_refuses_a_pickled_object_without_running_it(tmp_path):
    marker = tmp_path / "ran"
    ckpt = _evil_run(tmp_path / "run", marker, snapshot_too=True)
    for load, path in ((read_checkpoint, ckpt), (read_env_snapshot, ckpt.with_name("env_1.pt"))):
        with pytest.raises(UnsafeCheckpointError) as err:
            load(path)
        line = str(err.value)
        assert "\n" not in line and str(path) in line and "convert_checkpoints.py" in line, line
        assert "unpickle exec " in line, line  # names what it would have called
    assert not marker.exists()
    with pytest.raises(CheckpointError, match="not a readable checkpoint"):
        (tmp_path / "junk.pt").write_bytes(b"not a torch file")
        safe_load(tmp_path / "junk.pt")


@pytest.mark.parametrize(
    "script, args",
    [
        ("play", ["checkpoint={ckpt}", "episodes=1", "num_envs=1", "time_s=0.1"]),
        ("eval_table", ["manifest={manifest}", "out={tmp}/out", "trials_per_scene=1", "time_s=0.1"]),
        ("train", ["task=flat", "num_envs=2", "max_iterations=1", "init={ckpt}", "run_root={tmp}/runs"]),
        ("train", ["resume={ckpt}"]),
        ("click_and_traverse", ["scene=flat", "checkpoint={ckpt}", "goal=1,0", "time_limit=0.1", "realtime=false"]),
        ("ship", ["checkpoint={ckpt}", "out={tmp}/shipped"]),
        ("export", ["checkpoint={ckpt}", "out={tmp}/policy.onnx"]),
    ],
)
def test_every_entry_point_refuses_it(tmp_path, caplog, script, args):
    marker = tmp_path / "ran"
    ckpt = _evil_run(tmp_path / "run", marker)
    manifest = tmp_path / "m.yaml"
    manifest.write_text(yaml.safe_dump({"methods": {"A": [str(ckpt)]}, "table1": {}}))
    argv = [a.format(ckpt=ckpt, manifest=manifest, tmp=tmp_path) for a in args]
    code, err = _run(script, argv, caplog)
    assert code == 2 and str(ckpt) in err and "refused" in err, err
    assert not marker.exists()
    assert not any((tmp_path / name).exists() for name in ("out", "shipped", "policy.onnx", "runs"))


def test_distillation_teachers_refuse_it(tmp_path):
    """A teacher named in ``teachers=[...]`` is read by the safe loader when the specialists are listed."""
    from cat.learning.distill import TeacherError, load_specialists

    marker = tmp_path / "ran"
    ckpt = _evil_run(tmp_path / "run", marker)
    with pytest.raises(TeacherError, match=f"teacher {ckpt}: {ckpt}: refused"):
        load_specialists([str(ckpt)])
    assert not marker.exists()


def test_resume_refuses_a_pickled_env_snapshot(tmp_path, caplog):
    """A safe model file beside an unsafe ``env_<it>.pt``: the resume stops before building anything."""
    marker = tmp_path / "ran"
    ckpt = _evil_run(tmp_path / "run", marker, snapshot_too=True)
    torch.save({"actor_state_dict": {}, "optimizer_state_dict": {}, "iter": 1, "infos": None}, ckpt)
    code, err = _run("train", [f"resume={ckpt}"], caplog)
    assert code == 2 and str(ckpt.with_name("env_1.pt")) in err and "refused" in err, err
    assert not marker.exists()


@pytest.mark.parametrize("path", SHIPPED, ids=[f"{p.parent.name}/{p.name}" for p in SHIPPED])
def test_shipped_files_load_with_the_safe_loader(path):
    if path.name.startswith("model_"):
        assert read_checkpoint(path)["iter"] >= 0
    else:
        snap = read_env_snapshot(path, map_location="cpu")
        assert type(snap["obs"]) is dict and snap["format"] == 2  # converted: no TensorDict left


def _bare_torch_loads(paths: list[Path]) -> subprocess.CompletedProcess:
    """Load ``paths`` with ``weights_only=True`` in a process that imports torch only (no tensordict, no cat)."""
    code = "import sys, torch\nfor p in sys.argv[1:]: torch.load(p, map_location='cpu', weights_only=True)"
    return subprocess.run([sys.executable, "-c", code, *map(str, paths)], capture_output=True, text=True, timeout=300)


def test_shipped_files_need_nothing_beyond_torch():
    """Every shipped file is tensors and plain data: it loads where neither tensordict nor cat is imported."""
    out = _bare_torch_loads(SHIPPED)
    assert out.returncode == 0, out.stderr[-2000:]


def test_conversion_is_bit_identical_and_idempotent(tmp_path):
    """An env snapshot of the old format (``obs`` a TensorDict) is rewritten to plain dicts, tensor for tensor."""
    obs = TensorDict({"actor": torch.randn(4, 3), "critic": torch.tensor([[float("nan")]] * 4)}, batch_size=[4])
    old = {"format": 2, "obs": obs, "rng": torch.get_rng_state(), "steps": 7}
    path = tmp_path / "env_3.pt"
    torch.save(old, path)
    assert isinstance(read_env_snapshot(path)["obs"], TensorDict)  # the old format keeps loading
    assert _bare_torch_loads([path]).returncode != 0  # ... but only where tensordict is imported
    path.chmod(0o644)
    assert convert_file(path) is True
    assert path.stat().st_mode & 0o777 == 0o644  # readable as before, not the temporary file's 0600
    new = read_env_snapshot(path)
    assert type(new["obs"]) is dict and new["steps"] == 7
    torch.testing.assert_close(new["obs"]["actor"], obs["actor"], rtol=0, atol=0)
    assert torch.isnan(new["obs"]["critic"]).all() and torch.equal(new["rng"], old["rng"])
    assert _bare_torch_loads([path]).returncode == 0
    data = path.read_bytes()
    assert convert(ConvertCfg(path=str(tmp_path))) == {"converted": [], "unchanged": [path]}
    assert path.read_bytes() == data  # the second pass leaves the file alone


def test_conversion_refuses_an_arbitrary_object(tmp_path):
    marker = tmp_path / "ran"
    ckpt = _evil_run(tmp_path / "run", marker)
    data = ckpt.read_bytes()
    with pytest.raises(UnsafeCheckpointError, match="refused"):
        convert_file(ckpt)
    assert not marker.exists() and ckpt.read_bytes() == data


def test_converted_shipped_snapshot_keeps_the_weights_beside_it(tmp_path):
    """The conversion touches env snapshots only: a shipped model file passes through unchanged."""
    src = next((p for p in SHIPPED if p.name.startswith("model_")), None)
    if src is None:
        pytest.skip("no shipped checkpoints in this tree")
    copy = tmp_path / src.name
    shutil.copy2(src, copy)
    assert convert_file(copy) is False and copy.read_bytes() == src.read_bytes()
