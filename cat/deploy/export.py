"""A run's policy as one self-contained ONNX file: normaliser baked in, deployment facts in its metadata.

``python scripts/export.py checkpoint=<model_*.pt | run folder> out=policy.onnx [force=true]``. The network is the
run's policy (``cat.run.config.policy_model``: PPO's actor or the distilled student); the file is written
next to ``out`` under a temporary name, checked against torch with onnxruntime, and only then renamed, so a
failed export leaves nothing behind. See docs/export.md.
"""

from __future__ import annotations

import io
import logging
import os
import tempfile
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict

from cat.checkpoint_io import CheckpointError, read_checkpoint, resolve_checkpoint
from cat.cli import CliError, Script, dataclass_loader
from cat.deploy.metadata import (
    PolicyFileError,
    PolicyMetadata,
    git_version,
    layout_metadata,
    library_versions,
    robot_model_source,
)
from cat.deploy.policy import OnnxPolicy, TorchPolicy
from cat.envs.mdp.actions import soft_joint_limits
from cat.envs.robot import MenagerieModelError, RobotCfg, load_robot_cfg, robot_spec
from cat.fields import FieldCfg
from cat.run.config import policy_model
from cat.run.config_file import load_run_config
from cat.run.policy import load_policy_network

log = logging.getLogger("export")

OPSET = 18
PARITY_TOL = 1e-5  # max |action difference| / max(1, |action|), onnxruntime vs torch, accepted by the export's check


@dataclass
class ExportCfg:
    checkpoint: str = "???"  # model_<it>.pt with its run's config.yaml beside it, or a run folder (latest model)
    out: str = "???"  # .onnx file to write
    force: bool = False  # replace an existing out
    check_samples: int = 256  # observations of the onnxruntime-vs-torch check run before the file is kept


@dataclass
class ExportResult:
    path: Path
    metadata: PolicyMetadata
    max_abs_diff: float  # onnxruntime vs torch on the check's observations: max |d action| / max(1, |action|)
    samples: int

    def line(self) -> str:
        m = self.metadata
        size = self.path.stat().st_size / 1024
        return (
            f"wrote {self.path} ({m.policy_kind}, obs {m.obs_dim} -> actions {m.num_actions}, {size:.0f} KB); "
            f"onnxruntime vs torch max|d action|/max(1,|a|)={self.max_abs_diff:.2e} on {self.samples} observations"
        )


def soft_limits(robot: RobotCfg) -> np.ndarray:
    """(nj, 2) PD-target clips the env applies (central ``soft_limit_factor`` of each joint's range)."""
    model = robot_spec(robot, floor=False).compile()
    lo, hi = soft_joint_limits(torch.tensor(model.jnt_range[1:], dtype=torch.float32), robot.soft_limit_factor)
    return torch.stack((lo, hi), dim=-1).numpy()


def zero_observation(meta: PolicyMetadata) -> TensorDict:
    """A batch-of-one TensorDict shaped like the groups the policy reads."""
    widths = {}
    for g in meta.obs_groups:
        o = meta.observation[g]
        sizes = [t["size"] for t in o["terms"]]
        if None in sizes:
            unknown = [t["name"] for t in o["terms"] if t["size"] is None]
            raise ValueError(f"observation group {g!r}: cannot size term(s) {', '.join(unknown)} in this version")
        widths[g] = o["history"] * sum(sizes)
    return TensorDict({g: torch.zeros(1, w) for g, w in widths.items()}, batch_size=[1])


def _onnx_bytes(model) -> tuple[bytes, str, dict[str, list[int]], list[str], list[str]]:
    """Legacy (TorchScript) export to one protobuf; (bytes, kind, recurrent state shapes, inputs, outputs)."""
    wrapper = model.as_onnx(verbose=False).to("cpu").eval()
    recurrent = getattr(wrapper, "is_recurrent", False)
    kind = wrapper.rnn_type if recurrent else "mlp"
    state = {}
    if recurrent:
        shape = [wrapper.num_layers, 1, wrapper.hidden_size]
        state = {"h": shape, "c": shape} if kind == "lstm" else {"h": shape}
    inputs, outputs = list(wrapper.input_names), list(wrapper.output_names)
    axes = {"obs": {0: "batch"}, "actions": {0: "batch"}}
    for name in inputs[1:] + outputs[1:]:
        axes[name] = {1: "batch"}
    buf = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")  # the legacy exporter's deprecation notice and the LSTM batch note
        torch.onnx.export(
            wrapper,
            wrapper.get_dummy_inputs(),
            buf,
            export_params=True,
            opset_version=OPSET,
            input_names=inputs,
            output_names=outputs,
            dynamic_axes=axes,
            dynamo=False,  # the dynamo exporter writes the weights to a side .onnx.data file
        )
    return buf.getvalue(), kind, state, inputs, outputs


def parity(model, session, meta: PolicyMetadata, obs: torch.Tensor) -> float:
    """Max action difference between ``model`` (torch) and ``session`` (onnxruntime) on ``obs`` (T, obs_dim),
    each |difference| over max(1, |torch action|): absolute for actions within [-1, 1], relative beyond (fp32
    rounding grows with the output's magnitude). One batch for an MLP; for a recurrent policy, T steps of a
    batch of one with the state carried."""
    ort, ref = OnnxPolicy(session, meta), TorchPolicy(model, meta.obs_groups)
    split = _split_groups(obs, meta)

    def diff(a: torch.Tensor, b: torch.Tensor) -> float:
        return float(((a - b).abs() / b.abs().clamp_min(1.0)).max())

    with torch.inference_mode():
        if meta.recurrent_state:
            ref.reset()
            ort.reset()
            return max(diff(ort(s), ref(s)) for s in (split[t : t + 1] for t in range(len(obs))))
        return diff(ort(split), ref(split))


def _split_groups(obs: torch.Tensor, meta: PolicyMetadata) -> TensorDict:
    out, start = {}, 0
    for g in meta.obs_groups:
        o = meta.observation[g]
        w = o["history"] * sum(t["size"] for t in o["terms"])
        out[g] = obs[:, start : start + w]
        start += w
    return TensorDict(out, batch_size=[len(obs)])


def check_observations(model, n: int, seed: int = 0) -> torch.Tensor:
    """``n`` observations spread like the training data: normaliser mean + std * N(0, 1) (or N(0, 1) without one)."""
    g = torch.Generator().manual_seed(seed)
    norm = model.obs_normalizer
    mean = getattr(norm, "_mean", torch.zeros(1, model.obs_dim))
    std = getattr(norm, "_std", torch.ones(1, model.obs_dim))
    return mean + std * torch.randn(n, model.obs_dim, generator=g)


def _check_out(cfg: ExportCfg) -> Path:
    out = Path(cfg.out)
    if out.suffix.lower() != ".onnx":
        raise CliError(f"out={cfg.out}: must end in .onnx")
    if out.is_dir():
        raise CliError(f"out={cfg.out} is a folder")
    if not out.resolve().parent.is_dir():
        raise CliError(f"out={cfg.out}: folder {out.resolve().parent} does not exist")
    if not os.access(out.resolve().parent, os.W_OK):
        raise CliError(f"out={cfg.out}: folder {out.resolve().parent} is not writable")
    if out.exists() and not cfg.force:
        raise CliError(f"out={cfg.out} exists (force=true replaces it)")
    if cfg.check_samples < 1:
        raise CliError(f"check_samples must be >= 1, got {cfg.check_samples}")
    return out


def export(cfg: ExportCfg, robot: RobotCfg | None = None, field_cfg: FieldCfg | None = None) -> ExportResult:
    """Write ``cfg.checkpoint``'s policy to ``cfg.out`` (see the module docstring)."""
    import onnx
    import onnxruntime

    out = _check_out(cfg)
    ckpt = resolve_checkpoint(cfg.checkpoint)
    run = load_run_config(ckpt)  # CheckpointError: missing file or config.yaml
    robot = robot or load_robot_cfg()
    pm = policy_model(run.algo)
    meta = layout_metadata(robot, field_cfg or FieldCfg(), run.task, pm.obs_groups, soft_limits(robot))
    saved = read_checkpoint(ckpt)
    model = load_policy_network(ckpt, run, zero_observation(meta), meta.num_actions, saved)
    data, kind, state, inputs, outputs = _onnx_bytes(model)
    meta = replace(
        meta,
        policy_kind=kind,
        inputs=inputs,
        outputs=outputs,
        recurrent_state=state,
        obs_set=pm.obs_set,
        task={**meta.task, "method": run.method, "algo": run.algo.name},
        robot_model=robot_model_source(robot),
        producer={
            "git": git_version(),
            "checkpoint": str(ckpt),
            "iteration": saved.get("iter"),
            "libraries": library_versions(),
        },
    )
    proto = onnx.load_from_string(data)
    proto.producer_name = "cat"
    proto.doc_string = f"CAT policy ({kind}) of {ckpt}; metadata_props: cat.deploy.metadata.PolicyMetadata"
    for key, value in meta.to_props().items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(proto)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.resolve().parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(proto.SerializeToString())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it private; the policy file is an ordinary one
        session = onnxruntime.InferenceSession(tmp, providers=["CPUExecutionProvider"])
        diff = parity(model, session, meta, check_observations(model, cfg.check_samples))
        if not diff <= PARITY_TOL:
            raise PolicyFileError(f"onnxruntime differs from torch by {diff:.2e} > {PARITY_TOL:g}: not written")
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return ExportResult(out, meta, diff, cfg.check_samples)


def _job(cfg: ExportCfg) -> int:
    print(export(cfg).line(), flush=True)
    return 0


SCRIPT = Script(
    name="export",
    doc=__doc__.split("\n\n")[0] + "\n\n  python scripts/export.py checkpoint=<model_*.pt|run folder> out=<file.onnx>",
    load=dataclass_loader(ExportCfg, required=("checkpoint", "out")),
    job=_job,
    keys=list(ExportCfg.__dataclass_fields__),
    errors=(CheckpointError, MenagerieModelError, OSError, ValueError),
)
