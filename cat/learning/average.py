"""Interpolate two checkpoints of one policy lineage: ``(1 - alpha) * a + alpha * b``, weight by weight.

Two students continued from the same parent (two DAgger legs, say) sit in one basin of the loss, and a point
between them can keep what each leg kept (model soups, Wortsman et al. 2022). Each network's observation
normaliser is part of its input map, so ``b``'s first linear layer is first re-expressed in ``a``'s normaliser
(exactly: ``W_b diag((s_a + eps) / (s_b + eps))`` and ``b_b + W_b (m_a - m_b) / (s_b + eps)``) and the result keeps
``a``'s statistics; every other float tensor is interpolated as is. Refused, naming the difference: checkpoints of
different observation layouts or network shapes. The result is weights only (Adam moments of two runs do not
average into a resumable state), written with ``a``'s ``config.yaml`` and an ``average.yaml`` saying what it is.

Two runs of different kinds (a PPO fine-tune of a student, ``algo=ppo_student``, and the distilled student it
started from: WiSE-FT, Wortsman et al. 2022) are averaged through their deployable networks only (PPO's actor,
the student: ``policy_model``), which must read the same observation groups; ``a``'s other networks are dropped.

``python scripts/average.py a=<model_*.pt> b=<model_*.pt> alpha=0.5 out=checkpoints/<name> [force=true]``
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import torch
import yaml

from cat.checkpoint_io import CheckpointError, read_checkpoint, resolve_checkpoint
from cat.cli import Script, dataclass_loader
from cat.learning.layout_init import NORM_KEYS, first_linear
from cat.run.config import policy_model
from cat.run.config_file import load_run_config

EPS = 1e-2  # rsl_rl's EmpiricalNormalization: (x - mean) / (std + eps)


@dataclass
class AverageCfg:
    a: str = "???"  # model_<it>.pt (or run folder); its config and normaliser are kept
    b: str = "???"  # model_<it>.pt of the same observation layout and network
    alpha: float = 0.5  # weight of b: 0 gives a's weights, 1 b's (in a's normaliser)
    out: str = "???"  # folder to write
    force: bool = False  # replace a model already in out


def model_keys(ckpt: dict) -> list[str]:
    """The checkpoint's network state dicts (``actor_state_dict``, ``student_state_dict``, ...), not the optimiser's."""
    return [k for k in ckpt if k.endswith("_state_dict") and not k.startswith("optimizer")]


def _in_normaliser_of(state_b: dict, state_a: dict) -> dict:
    """``state_b`` with its first linear layer re-expressed for inputs normalised by ``state_a``'s statistics."""
    if not all(k in state_b for k in NORM_KEYS):
        return dict(state_b)
    w_key = first_linear(state_b)
    b_key = w_key[: -len("weight")] + "bias"
    mean_a, mean_b = state_a["obs_normalizer._mean"][0], state_b["obs_normalizer._mean"][0]
    den_a, den_b = state_a["obs_normalizer._std"][0] + EPS, state_b["obs_normalizer._std"][0] + EPS
    w = state_b[w_key]
    out = dict(state_b)
    out[w_key] = w * (den_a / den_b)[None, :]
    out[b_key] = state_b[b_key] + w @ ((mean_a - mean_b) / den_b)
    return out


def average_states(state_a: dict, state_b: dict, alpha: float, what: str = "") -> dict:
    """The interpolated state dict (``a``'s normaliser, every other float tensor mixed)."""
    if set(state_a) != set(state_b):
        diff = sorted(set(state_a) ^ set(state_b))
        raise CheckpointError(f"{what}: the two networks differ in parameters {diff[:4]}")
    for k, v in state_a.items():
        if tuple(v.shape) != tuple(state_b[k].shape):
            raise CheckpointError(f"{what}: {k} is {tuple(v.shape)} in a and {tuple(state_b[k].shape)} in b")
    b = _in_normaliser_of(state_b, state_a)
    out = {}
    for k, v in state_a.items():
        keep = k.startswith("obs_normalizer") or not v.is_floating_point()
        out[k] = v.clone() if keep else torch.lerp(v, b[k].to(v), alpha)
    return out


def _observations(config: Path) -> dict:
    raw = yaml.safe_load(config.read_text()) or {}
    return (raw.get("task") or {}).get("observations") or {}


def network_pairs(src_a: Path, ck_a: dict, src_b: Path, ck_b: dict) -> list[tuple[str, str]]:
    """Which network of ``a`` is mixed with which of ``b``: all of them for runs of one kind, else the deployable
    networks (``policy_model``), which must read the same observation groups."""
    if model_keys(ck_a) == model_keys(ck_b):
        return [(k, k) for k in model_keys(ck_a)]
    pa, pb = policy_model(load_run_config(src_a).algo), policy_model(load_run_config(src_b).algo)
    if pa.obs_groups != pb.obs_groups or pa.state_key not in ck_a or pb.state_key not in ck_b:
        raise CheckpointError(
            f"{src_a} holds {model_keys(ck_a)} (policy reads {pa.obs_groups}), {src_b} {model_keys(ck_b)} "
            f"(policy reads {pb.obs_groups}): not one policy lineage"
        )
    return [(pa.state_key, pb.state_key)]


def average(cfg: AverageCfg) -> Path:
    """Write the interpolated checkpoint into ``cfg.out``; returns the model file."""
    if not 0.0 <= cfg.alpha <= 1.0:
        raise ValueError(f"alpha must lie in [0, 1] (the weight of b), got {cfg.alpha}")
    src_a, src_b = resolve_checkpoint(cfg.a), resolve_checkpoint(cfg.b)
    ck_a, ck_b = read_checkpoint(src_a), read_checkpoint(src_b)
    conf_a, conf_b = src_a.parent / "config.yaml", src_b.parent / "config.yaml"
    for conf in (conf_a, conf_b):
        if not conf.is_file():
            raise CheckpointError(f"{conf.parent}: no config.yaml beside the checkpoint")
    if _observations(conf_a) != _observations(conf_b):
        raise CheckpointError(
            f"{src_a} and {src_b}: different observation layouts (task.observations of their configs)"
        )
    pairs = network_pairs(src_a, ck_a, src_b, ck_b)
    out = Path(cfg.out)
    if out.is_dir() and any(out.glob("model_*.pt")) and not cfg.force:
        raise FileExistsError(f"{out} already holds a model: pass force=true to replace it")
    dropped = set(model_keys(ck_a)) - {ka for ka, _ in pairs}
    mixed = {k: v for k, v in ck_a.items() if not k.startswith("optimizer") and k not in dropped}
    for ka, kb in pairs:
        mixed[ka] = average_states(ck_a[ka], ck_b[kb], cfg.alpha, f"{ka} / {kb} of {src_a.name} / {src_b.name}")
    how = "(1 - alpha) a + alpha b; b's first layer re-expressed in a's normaliser (cat/learning/average.py)"
    note = {"a": str(src_a), "b": str(src_b), "alpha": cfg.alpha, "how": how}
    with tempfile.TemporaryDirectory(dir=out.parent if out.parent.is_dir() else None) as tmp:
        stage = Path(tmp)
        torch.save(mixed, stage / src_a.name)
        shutil.copy2(conf_a, stage / "config.yaml")
        (stage / "average.yaml").write_text(yaml.safe_dump(note, sort_keys=False))
        out.mkdir(parents=True, exist_ok=True)
        for old in out.glob("model_*.pt"):
            old.unlink()
        for old in out.glob("env_*.pt"):
            old.unlink()  # an env snapshot of another checkpoint would make the folder look resumable
        for path in sorted(stage.iterdir()):
            shutil.move(str(path), out / path.name)
    return out / src_a.name


def _job(cfg: AverageCfg) -> int:
    path = average(cfg)
    print(f"wrote {path} ((1 - {cfg.alpha:g}) a + {cfg.alpha:g} b)")
    return 0


SCRIPT = Script(
    name="average",
    doc=__doc__.split("\n\n")[0]
    + "\n\n  python scripts/average.py a=<model_*.pt> b=<model_*.pt> alpha=0.5 out=<folder>",
    load=dataclass_loader(AverageCfg, required=("a", "b", "out")),
    job=_job,
    keys=list(AverageCfg.__dataclass_fields__),
    errors=(CheckpointError, FileExistsError, OSError, ValueError),
)
