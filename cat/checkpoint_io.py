"""Checkpoint I/O a stranger can trust: every ``model_<it>.pt`` and ``env_<it>.pt`` is read with torch's safe
loader (``weights_only=True``), which rebuilds tensors and plain data (dict, list, tuple, str, int, float, bool,
None) and refuses anything else *without executing it*, so playing a downloaded checkpoint cannot run code
hidden in its pickle. What CAT writes is tensors and plain data (``plain``). Env snapshots written before held a
``TensorDict``: they still load (tensordict allow-lists its own rebuild function) and
``scripts/convert_checkpoints.py`` rewrites them once into plain dicts.

This module depends on torch and tensordict only, so every layer (eval, learning, deploy, scripts) reads
checkpoints through this one definition.
"""

from __future__ import annotations

import os
import pickle
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from tensordict import is_tensor_collection  # importing tensordict allow-lists its TensorDict rebuild

CONVERT_HINT = "python scripts/convert_checkpoints.py path="


class CheckpointError(FileNotFoundError):
    """A checkpoint or its run folder is missing or unreadable."""


class UnsafeCheckpointError(CheckpointError):
    """A checkpoint needs more than tensors and plain data to load (an arbitrary pickled object): refused."""


def _unsupported_global(err: Exception) -> str:
    """The global the safe unpickler refused (``module.name``), or ``''`` when it refused something else."""
    m = re.search(r"GLOBAL (\S+)", str(err))
    return m.group(1) if m else ""


def safe_load(path: str | os.PathLike, map_location: str | torch.device | None = "cpu") -> Any:
    """``torch.load(path, weights_only=True)``: tensors and plain data, or a one-line error naming the file.

    ``UnsafeCheckpointError`` when the file needs an arbitrary pickled object (not executed); ``CheckpointError``
    when it is missing or not a torch file at all.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint not found: {path}")
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as err:
        what = _unsupported_global(err)
        if not what:  # a byte stream the safe unpickler cannot parse: damaged or not a torch file
            raise CheckpointError(f"{path}: not a readable checkpoint ({str(err).splitlines()[0]})") from None
        raise UnsafeCheckpointError(
            f"{path}: refused: loading it would unpickle {what} beyond tensors and plain data (not executed); "
            f"an old-format CAT file is rewritten safely by `{CONVERT_HINT}{path}`"
        ) from None
    except Exception as err:  # zip / EOF / magic-number errors of a damaged or foreign file
        first = str(err).splitlines()[0] if str(err) else ""
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(err).__name__}: {first})") from None


def read_checkpoint(path: str | os.PathLike, map_location: str | torch.device | None = "cpu") -> dict:
    """A PPO or distillation checkpoint's dict (safe loader), or ``CheckpointError`` naming the file (missing,
    corrupt, unsafe, not rsl_rl's)."""
    ckpt = safe_load(path, map_location)
    if not isinstance(ckpt, dict) or not ({"actor_state_dict", "student_state_dict"} & set(ckpt)):
        raise CheckpointError(f"{path}: not an rsl_rl checkpoint (no actor_state_dict or student_state_dict)")
    return ckpt


def read_env_snapshot(path: str | os.PathLike, map_location: str | torch.device | None = None) -> dict:
    """An env snapshot (``env_<it>.pt``) through the safe loader; ``map_location=None`` keeps the saved device
    (a resumed CUDA run restores CUDA buffers, as before)."""
    snap = safe_load(path, map_location)
    if not isinstance(snap, dict):
        raise CheckpointError(f"{path}: not an env snapshot (a {type(snap).__name__}, not a dict)")
    return snap


def resolve_checkpoint(path: str | os.PathLike) -> Path:
    """A checkpoint file, or a run folder's latest ``model_<it>.pt`` (highest iteration)."""
    path = Path(path)
    if path.is_dir():
        models = sorted(
            path.glob("model_*.pt"), key=lambda p: int(p.stem.split("_")[1]) if p.stem[6:].isdigit() else -1
        )
        if not models:
            raise CheckpointError(f"run folder {path} holds no model_<iteration>.pt")
        return models[-1]
    return path


def env_snapshot_path(checkpoint: str | os.PathLike) -> Path:
    """``model_<it>.pt`` -> ``env_<it>.pt``: the env snapshot saved with it (not needed to play)."""
    ckpt = Path(checkpoint)
    return ckpt.with_name(ckpt.name.replace("model_", "env_", 1))


def plain(value: Any) -> Any:
    """``value`` with every mapping (a ``TensorDict`` included) turned into a plain ``dict`` and tuples/lists kept,
    recursively: what the safe loader can read back. Tensors and scalars pass unchanged (same storage)."""
    if isinstance(value, torch.Tensor):
        return value
    if isinstance(value, Mapping) or is_tensor_collection(value):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [plain(v) for v in value]
    if isinstance(value, tuple):
        return tuple(plain(v) for v in value)
    return value
