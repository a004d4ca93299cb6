"""What drives the robot: a checkpoint (torch, deterministic), an exported ``.onnx`` file (onnxruntime) or
``hold`` (zero actions), all behind one callable: ``policy(obs) -> actions`` and ``policy.reset()``.

A checkpoint comes with the ``config.yaml`` of its run beside it (``cat.learning.runs.load_run_config``); its
policy network is ``cat.run.config.policy_model`` of the run (PPO's actor or the distilled student). An ONNX
file carries the same facts in its metadata (``cat.deploy.metadata``), and is refused when they differ from the
layout the runtime builds. Either way the demo builds the observation the policy was trained on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict

from cat.checkpoint_io import resolve_checkpoint
from cat.deploy.metadata import PolicyFileError, PolicyMetadata, layout_mismatches, read_metadata
from cat.envs.config import EnvCfg, FieldObsCfg, ObsGroupCfg
from cat.run.config import TrainCfg, policy_model
from cat.run.config_file import load_run_config
from cat.run.policy import load_policy_network

HOLD = "hold"


@dataclass
class PolicySpec:
    """A policy source and the task config its observations follow."""

    checkpoint: str
    task: EnvCfg
    run: TrainCfg | None = None  # torch checkpoints: the run's config
    kind: str = HOLD  # hold | torch | onnx
    obs_groups: list[str] = field(default_factory=lambda: ["actor"])  # env groups the policy reads, in order
    metadata: PolicyMetadata | None = None  # onnx

    @property
    def is_hold(self) -> bool:
        return self.kind == HOLD


def is_onnx(checkpoint: str) -> bool:
    return Path(checkpoint).suffix.lower() == ".onnx"


def policy_spec(checkpoint: str) -> PolicySpec:
    """Resolve ``checkpoint=``: ``hold``, an exported ``.onnx`` file, a ``model_*.pt`` with its run's
    ``config.yaml`` beside it, or a run folder (its latest checkpoint)."""
    if checkpoint == HOLD:
        return PolicySpec(HOLD, EnvCfg())
    if is_onnx(checkpoint):
        meta = read_metadata(checkpoint)  # PolicyFileError: missing, not ONNX, not a CAT export
        return PolicySpec(checkpoint, task_from_metadata(meta), None, "onnx", list(meta.obs_groups), meta)
    path = resolve_checkpoint(checkpoint)
    run = load_run_config(path)  # CheckpointError when the file or its config.yaml is missing
    return PolicySpec(str(path), run.task, run, "torch", list(policy_model(run.algo).obs_groups))


def task_from_metadata(meta: PolicyMetadata) -> EnvCfg:
    """The task settings the runtime reads, from an exported policy's metadata (the rest keep their defaults)."""
    fo = meta.field_obs
    return EnvCfg(
        task=meta.task.get("name", "flat"),
        scene_kind=meta.task.get("scene_kind"),
        scene_groups=list(meta.task.get("scene_groups") or []),
        scene_dir=meta.task.get("scene_dir"),
        action_clip=float(meta.action["clip"]),
        gait_freq=tuple(meta.gait["freq_range_hz"]),
        observations={
            g: ObsGroupCfg(terms=[t["name"] for t in o["terms"]], history=int(o["history"]))
            for g, o in meta.observation.items()
        },
        field_obs=FieldObsCfg(enabled=fo["enabled"], refresh_hz=fo["refresh_hz"], sdf_clip=fo["sdf_clip"]),
    )


def _concat(obs: TensorDict, groups: list[str]) -> torch.Tensor:
    return torch.cat([obs[g] for g in groups], dim=-1)


class HoldPolicy:
    """Zero actions: the incremental PD targets stay at the default standing pose."""

    def __init__(self, num_actions: int):
        self.num_actions = num_actions

    def __call__(self, obs: TensorDict) -> torch.Tensor:
        return torch.zeros(obs.batch_size[0], self.num_actions)

    def reset(self) -> None:
        pass


class TorchPolicy:
    """An rsl_rl model's deterministic output; a recurrent model carries its state until ``reset()``."""

    def __init__(self, model, obs_groups: list[str]):
        self.model, self.obs_groups = model.eval(), list(obs_groups)

    def __call__(self, obs: TensorDict) -> torch.Tensor:
        with torch.inference_mode():
            return self.model(obs)

    def reset(self) -> None:
        self.model.reset()


class OnnxPolicy:
    """An exported policy in onnxruntime: the groups concatenated into ``obs``; h / c carried until ``reset()``."""

    def __init__(self, session, meta: PolicyMetadata):
        self.session, self.meta = session, meta
        self.obs_groups = list(meta.obs_groups)
        self.state: dict[str, np.ndarray] = {}
        self.reset()

    def reset(self, batch: int = 1) -> None:
        self.state = {
            k: np.zeros((s[0], batch, *s[2:]), dtype=np.float32) for k, s in self.meta.recurrent_state.items()
        }

    def __call__(self, obs: TensorDict) -> torch.Tensor:
        x = _concat(obs, self.obs_groups).detach().cpu().numpy().astype(np.float32, copy=False)
        names = list(self.state)
        if self.state and next(iter(self.state.values())).shape[1] != len(x):
            self.reset(len(x))
        feeds = {"obs": x, **{f"{k}_in": v for k, v in self.state.items()}}
        result = self.session.run(["actions", *(f"{k}_out" for k in names)], feeds)
        self.state = dict(zip(names, result[1:], strict=True))
        return torch.from_numpy(result[0])


def _onnx_session(path: str):
    import onnxruntime

    opts = onnxruntime.SessionOptions()
    opts.intra_op_num_threads = 1  # a batch of one: threads only contend with perception
    opts.inter_op_num_threads = 1
    try:
        return onnxruntime.InferenceSession(path, opts, providers=["CPUExecutionProvider"])
    except Exception as err:  # ORT's InvalidGraph / Fail of a damaged file
        raise PolicyFileError(f"{path}: onnxruntime cannot load it ({str(err).splitlines()[0]})") from None


def check_session(session, meta: PolicyMetadata, source: str) -> None:
    """The graph's inputs / outputs are the ones the metadata declares (``obs`` width = ``obs_dim``)."""
    inputs = {i.name: i.shape for i in session.get_inputs()}
    outputs = {o.name: o.shape for o in session.get_outputs()}
    if list(inputs) != meta.inputs or list(outputs) != meta.outputs:
        raise PolicyFileError(
            f"{source}: graph inputs {list(inputs)} / outputs {list(outputs)} differ from its metadata "
            f"({meta.inputs} / {meta.outputs})"
        )
    if inputs["obs"][-1] != meta.obs_dim or outputs["actions"][-1] != meta.num_actions:
        raise PolicyFileError(
            f"{source}: graph maps obs {inputs['obs'][-1]} -> actions {outputs['actions'][-1]}, its metadata says "
            f"{meta.obs_dim} -> {meta.num_actions}"
        )


def load_policy(spec: PolicySpec, obs: TensorDict, num_actions: int, layout: PolicyMetadata | None = None):
    """The policy of ``spec`` as a callable for observations shaped like ``obs``; ``layout`` is the runtime's
    own description (``cat.deploy.metadata.layout_metadata``) that an ONNX file's metadata must match.

    Raises ``CheckpointError`` (``PolicyFileError`` for ONNX) naming the file and the mismatch."""
    if spec.is_hold:
        return HoldPolicy(num_actions)
    if spec.kind == "onnx":
        meta = spec.metadata
        if layout is not None:
            diff = layout_mismatches(meta, layout)
            if diff:
                more = f" (+{len(diff) - 3} more)" if len(diff) > 3 else ""
                raise PolicyFileError(f"{spec.checkpoint} was exported for another layout: {'; '.join(diff[:3])}{more}")
        session = _onnx_session(spec.checkpoint)
        check_session(session, meta, spec.checkpoint)
        return OnnxPolicy(session, meta)
    return TorchPolicy(load_policy_network(spec.checkpoint, spec.run, obs, num_actions), spec.obs_groups)
