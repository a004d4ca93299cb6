"""Copy a run's checkpoint into a folder that is committed (``checkpoints/<name>/``), small enough for git.

``python scripts/ship.py checkpoint=<run>/model_<it>.pt out=checkpoints/<name> [max_mb=5] [force=true]`` copies
``model_<it>.pt``, its env snapshot ``env_<it>.pt`` (when present), the run's ``config.yaml`` and
``metrics.csv``. The optimiser's moment tensors are stored in bfloat16: a student of 512-256-128 units has a
1.8 MB model and 3.6 MB of Adam moments in float32. ``torch.optim.Optimizer.load_state_dict`` casts them back to
the parameters' dtype, so ``resume=`` works from the shipped file (moments rounded to 8 mantissa bits, a negligible
change next to one update). Any other ``model_*.pt`` / ``env_*.pt`` in ``out`` is removed, so ``out`` names one
checkpoint (``checkpoint=checkpoints/<name>`` picks the highest iteration). Files are written to a temporary
folder first: a refused or failed ship leaves ``out`` as it was.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import torch

from cat.checkpoint_io import CheckpointError, env_snapshot_path, read_checkpoint, read_env_snapshot, resolve_checkpoint
from cat.cli import Script, dataclass_loader


@dataclass
class ShipCfg:
    checkpoint: str = "???"  # model_<it>.pt (its run's config.yaml beside it) or a run folder (latest model)
    out: str = "???"  # folder to write, e.g. checkpoints/generalist
    max_mb: float = 5.0  # refuse a model file larger than this after compaction (MiB)
    force: bool = False  # replace the checkpoint files already in out
    # the networks only (no optimiser state, no env snapshot), for a checkpoint too large to ship whole: it plays,
    # exports and starts new runs (init=), but cannot be resumed
    weights_only: bool = False


def is_optimizer_state(key: str) -> bool:
    """A checkpoint entry that holds an optimiser's state: rsl_rl's ``optimizer_state_dict`` (and its RND one's),
    ``cat.learning.rehearsal``'s ``rehearsal_optimizer_state_dict``."""
    return key.startswith("optimizer") or key.endswith("optimizer_state_dict")


def compact_optimizer_state(ckpt: dict) -> dict:
    """``ckpt`` with every floating-point tensor of its optimiser state(s) in bfloat16 (``step`` counts kept)."""

    def shrink(value):
        if isinstance(value, torch.Tensor) and value.is_floating_point() and value.ndim > 0:
            return value.to(torch.bfloat16)
        if isinstance(value, dict):
            return {k: shrink(v) for k, v in value.items()}
        if isinstance(value, list):
            return [shrink(v) for v in value]
        return value

    return {k: shrink(v) if is_optimizer_state(k) else v for k, v in ckpt.items()}


def ship(cfg: ShipCfg) -> list[Path]:
    """Write the compact checkpoint and its companions into ``cfg.out``; returns the files written."""
    src = resolve_checkpoint(cfg.checkpoint)
    ckpt = read_checkpoint(src)
    run_dir = src.parent
    config = run_dir / "config.yaml"
    if not config.is_file():
        raise CheckpointError(f"{src}: no config.yaml beside it (a checkpoint is shipped with its run's config)")
    out = Path(cfg.out)
    old = sorted(out.glob("model_*.pt")) + sorted(out.glob("env_*.pt")) if out.is_dir() else []
    others = [p.name for p in old if p.name not in (src.name, env_snapshot_path(src).name)]
    if others and not cfg.force:
        raise FileExistsError(f"{out} already holds {others}: pass force=true to replace them")
    with tempfile.TemporaryDirectory(dir=out.parent if out.parent.is_dir() else None) as tmp:
        stage = Path(tmp)
        if cfg.weights_only:
            ckpt = {k: v for k, v in ckpt.items() if not is_optimizer_state(k)}
        torch.save(compact_optimizer_state(ckpt), stage / src.name)
        size_mb = (stage / src.name).stat().st_size / 2**20
        if size_mb > cfg.max_mb:
            raise ValueError(
                f"{src.name} is {size_mb:.2f} MB after compaction, above max_mb={cfg.max_mb}"
                + ("" if cfg.weights_only else " (weights_only=true drops the optimiser state)")
            )
        companions = [config, run_dir / "metrics.csv"] + ([] if cfg.weights_only else [env_snapshot_path(src)])
        if not cfg.weights_only and env_snapshot_path(src).is_file():
            read_env_snapshot(env_snapshot_path(src), map_location="cpu")  # ship only what the safe loader reads
        for path in companions:
            if path.is_file():
                shutil.copy2(path, stage / path.name)
        out.mkdir(parents=True, exist_ok=True)
        for path in old:
            path.unlink()
        written = []
        for path in sorted(stage.iterdir()):
            shutil.move(str(path), out / path.name)
            written.append(out / path.name)
    return written


def _job(cfg: ShipCfg) -> int:
    for path in ship(cfg):
        print(f"wrote {path} ({path.stat().st_size / 2**20:.2f} MB)")
    return 0


SCRIPT = Script(
    name="ship",
    doc=__doc__.split("\n\n")[0] + "\n\n  python scripts/ship.py checkpoint=<model_*.pt|run folder> out=<folder>",
    load=dataclass_loader(ShipCfg, required=("checkpoint", "out")),
    job=_job,
    keys=list(ShipCfg.__dataclass_fields__),
    errors=(CheckpointError, FileExistsError, OSError, ValueError),
)
