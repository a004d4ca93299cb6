"""Rewrite env snapshots of the old format in place into plain data (``cat.checkpoint_io``).

Old snapshots held the observations as a ``TensorDict``: the safe loader reads it only because tensordict
allow-lists its rebuild function, and a reader without tensordict cannot. Each rewrite is checked before it
replaces the file: the new file loads through the safe loader, holds no TensorDict, and every tensor is
bit-identical to the old one. Files already plain are left untouched (idempotent); a file that needs an arbitrary
pickled object is refused unexecuted, like everywhere else.
"""

from __future__ import annotations

import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from tensordict import is_tensor_collection

from cat.checkpoint_io import CheckpointError, plain, safe_load
from cat.cli import Script, dataclass_loader

log = logging.getLogger("convert_checkpoints")


@dataclass
class ConvertCfg:
    path: str = "checkpoints"  # a .pt file, or a folder searched recursively for *.pt


def _has_tensordict(value: Any) -> bool:
    """Whether a TensorDict sits anywhere inside ``value`` (the one non-plain container of the old format)."""
    if is_tensor_collection(value):
        return True
    if isinstance(value, dict):
        return any(_has_tensordict(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_has_tensordict(v) for v in value)
    return False


def _tensors(value: Any, prefix: str = "") -> dict[str, torch.Tensor]:
    """Every tensor inside ``value`` by its dotted path (mappings, TensorDicts, lists and tuples walked)."""
    if isinstance(value, torch.Tensor):
        return {prefix: value}
    out: dict[str, torch.Tensor] = {}
    if hasattr(value, "items"):
        for k, v in value.items():
            out.update(_tensors(v, f"{prefix}.{k}"))
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            out.update(_tensors(v, f"{prefix}.{i}"))
    return out


def _same_bits(a: torch.Tensor, b: torch.Tensor) -> bool:
    """Equal dtype, shape and bytes (NaNs included, which ``torch.equal`` calls unequal)."""
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    return torch.equal(a.reshape(-1).contiguous().view(torch.uint8), b.reshape(-1).contiguous().view(torch.uint8))


def convert_file(path: Path) -> bool:
    """Rewrite ``path`` as plain data; ``False`` when it already was. ``UnsafeCheckpointError`` (file untouched)
    when it needs an arbitrary pickled object."""
    old = safe_load(path)
    if not _has_tensordict(old):
        return False
    fd, tmp = tempfile.mkstemp(suffix=".pt", dir=path.parent)
    os.close(fd)
    try:
        torch.save(plain(old), tmp)
        new = safe_load(tmp)
        before, after = _tensors(old), _tensors(new)
        same = before.keys() == after.keys() and all(_same_bits(before[k], after[k]) for k in before)
        if _has_tensordict(new) or not same:
            raise CheckpointError(f"{path}: the rewrite does not hold the same tensors; left as it was")
        os.chmod(tmp, path.stat().st_mode & 0o777)  # mkstemp's 0600 would hide the file from other users
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return True


def convert(cfg: ConvertCfg) -> dict[str, list[Path]]:
    """Convert every ``*.pt`` under ``cfg.path``: ``{"converted": [...], "unchanged": [...]}``."""
    root = Path(cfg.path)
    if not root.exists():
        raise CheckpointError(f"path not found: {root}")
    files = [root] if root.is_file() else sorted(root.rglob("*.pt"))
    out: dict[str, list[Path]] = {"converted": [], "unchanged": []}
    for f in files:
        out["converted" if convert_file(f) else "unchanged"].append(f)
    return out


def _job(cfg: ConvertCfg) -> int:
    result = convert(cfg)
    for f in result["converted"]:
        log.info("converted %s", f)
    log.info("%d converted, %d already safe", len(result["converted"]), len(result["unchanged"]))
    return 0


SCRIPT = Script(
    name="convert_checkpoints",
    doc=__doc__.split("\n\n")[0] + "\n\n  python scripts/convert_checkpoints.py [path=checkpoints]",
    load=dataclass_loader(ConvertCfg),
    job=_job,
    keys=list(ConvertCfg.__dataclass_fields__),
    errors=(CheckpointError, OSError),
)
