"""What an exported policy needs beside its weights: robot, action, observation layout, field constants, origin.

One ``PolicyMetadata`` describes a policy file. The exporter (``cat.deploy.export``) writes it into the ONNX
file's ``metadata_props`` (one key per field, each value a JSON string); :func:`read_metadata` gives it back,
typed. The deploy runtime builds the same description of itself (:func:`layout_metadata`) and refuses a policy
whose layout differs (:func:`layout_mismatches`), naming the first differences.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import subprocess
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np

from cat.envs.config import EnvCfg
from cat.envs.mdp.registry import OBS_TERMS
from cat.envs.obs_groups import resolve_groups
from cat.envs.robot import RobotCfg
from cat.fields import FieldCfg
from cat.learning.runs import CheckpointError

FORMAT = "cat-policy/1"


class PolicyFileError(CheckpointError):
    """A policy file that is missing, not ONNX, not a CAT export, or of another layout (one line)."""


@dataclass
class TermInfo:
    """One observation term as the network reads it (noise-free): ``size`` values, each ``scale * clip(raw)``."""

    name: str
    size: int | None  # None: a term this version cannot size statically
    scale: float = 1.0  # multiplies the value (every term is unscaled today)
    clip: float | None = None  # the term's own clip (see ``note`` for what is clipped)
    note: str = ""


def term_info(name: str, task: EnvCfg, robot: RobotCfg, size: int | None = None) -> TermInfo:
    """A term's layout from its declaration (``cat.envs.mdp.registry``) and the task and robot (``size`` given:
    measured, e.g. by the runtime); a term this version does not know has no size."""
    term = OBS_TERMS.get(name)
    if term is None:
        return TermInfo(name, size, 1.0, None, "unknown to this version")
    clip = term.clip(task) if term.clip is not None else None
    return TermInfo(name, size if size is not None else term.size(task, robot), 1.0, clip, term.note)


@dataclass
class PolicyMetadata:
    """Everything a runtime needs to feed and drive the policy; one ONNX ``metadata_props`` key per field."""

    format: str = FORMAT
    policy_kind: str = "mlp"  # mlp | lstm | gru
    inputs: list[str] = field(default_factory=lambda: ["obs"])  # ONNX input names (obs, then h_in, c_in)
    outputs: list[str] = field(default_factory=lambda: ["actions"])
    recurrent_state: dict[str, list[int]] = field(default_factory=dict)  # h / c: [layers, 1, hidden] (zeros at reset)
    obs_set: str = "actor"  # rsl_rl observation set of the network (actor | student)
    obs_groups: list[str] = field(default_factory=list)  # env groups concatenated, in order, into "obs"
    observation: dict[str, dict] = field(default_factory=dict)  # group -> {"history": H, "terms": [TermInfo]}
    obs_dim: int = 0
    num_actions: int = 0
    joint_names: list[str] = field(default_factory=list)  # all actuated joints, MuJoCo actuator order
    policy_joints: list[str] = field(default_factory=list)  # the joints the actions command, in action order
    default_joint_pos: list[float] = field(default_factory=list)  # joint_names order [rad]
    kp: list[float] = field(default_factory=list)
    kd: list[float] = field(default_factory=list)
    torque_limit: list[float] = field(default_factory=list)
    soft_joint_limits: list[list[float]] = field(default_factory=list)  # [lower, upper] per joint [rad]
    action: dict = field(default_factory=dict)  # scale, clip, rule
    control_dt: float = 0.0
    physics_dt: float = 0.0
    gait: dict = field(default_factory=dict)  # freq_range_hz (training), freq_hz (deployed)
    field_constants: dict = field(default_factory=dict)  # cat.fields.FieldCfg
    field_obs: dict = field(default_factory=dict)  # task.field_obs + the free-space convention
    query_links: list[str] = field(default_factory=list)  # field_block link order
    task: dict = field(default_factory=dict)  # training task: name, scene_kind / scene_groups / scene_dir, method, algo
    robot_model: dict = field(default_factory=dict)  # menagerie source and version
    producer: dict = field(default_factory=dict)  # git commit, checkpoint, iteration, library versions

    def terms(self, group: str) -> list[TermInfo]:
        return [TermInfo(**t) for t in self.observation[group]["terms"]]

    def to_props(self) -> dict[str, str]:
        return {f.name: json.dumps(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_props(cls, props: dict[str, str], source: str) -> PolicyMetadata:
        if props.get("format") is None:
            raise PolicyFileError(f"{source}: no CAT policy metadata (not written by scripts/export.py)")
        values = {}
        for f in fields(cls):
            if f.name not in props:
                raise PolicyFileError(f"{source}: metadata key {f.name!r} missing")
            try:
                values[f.name] = json.loads(props[f.name])
            except json.JSONDecodeError:
                raise PolicyFileError(f"{source}: metadata key {f.name!r} is not JSON") from None
        if values["format"] != FORMAT:
            raise PolicyFileError(f"{source}: metadata format {values['format']!r}, this version reads {FORMAT!r}")
        return cls(**values)


def free_space_sdf(task: EnvCfg) -> float | None:
    """The flat task's field convention: free space reads d = sdf_clip and grad d = 0 (None: field as built)."""
    flat = not (task.scene_dir or task.scene_kind or task.scene_groups)
    return task.field_obs.sdf_clip if flat else None


def layout_metadata(
    robot: RobotCfg,
    field_cfg: FieldCfg,
    task: EnvCfg,
    obs_groups: list[str],
    soft_limits: np.ndarray,
    sizes: dict[str, int] | None = None,
) -> PolicyMetadata:
    """The layout part of the metadata (robot, action, observation, field) for a policy reading ``obs_groups``.

    ``soft_limits`` (nj, 2) are the target clips; ``sizes`` measured term sizes (default: from the config)."""
    groups = resolve_groups(task.observations)
    missing = [g for g in obs_groups if g not in groups]
    if missing:
        raise ValueError(f"the policy reads observation group {missing[0]!r}, the task builds {', '.join(groups)}")
    observation, dim = {}, 0
    for g in obs_groups:
        history = int(task.observations[g].history)
        terms = [term_info(t, task, robot, (sizes or {}).get(t)) for t in groups[g]]
        observation[g] = {"history": history, "terms": [asdict(t) for t in terms]}
        if all(t.size is not None for t in terms):
            dim += history * sum(t.size for t in terms)
    free = free_space_sdf(task)
    return PolicyMetadata(
        obs_groups=list(obs_groups),
        observation=observation,
        obs_dim=dim,
        num_actions=len(robot.policy_joints),
        joint_names=list(robot.joint_names),
        policy_joints=list(robot.policy_joints),
        default_joint_pos=[float(v) for v in robot.default_joint_pos],
        kp=[float(v) for v in robot.kp],
        kd=[float(v) for v in robot.kd],
        torque_limit=[float(v) for v in robot.torque_limit],
        soft_joint_limits=[[float(lo), float(hi)] for lo, hi in np.asarray(soft_limits)],
        action={
            "scale": float(robot.action_scale),
            "clip": float(task.action_clip),
            "rule": "targets[policy_joints] = clip(targets + scale * clip(a, -clip, clip), soft_joint_limits); "
            "targets start at default_joint_pos; other joints hold their defaults",
        },
        control_dt=float(robot.control_dt),
        physics_dt=float(robot.timestep),
        gait={"freq_range_hz": [float(v) for v in task.gait_freq], "freq_hz": float(np.mean(task.gait_freq))},
        field_constants=field_cfg.to_dict(),
        field_obs={
            "enabled": bool(task.field_obs.enabled),
            "refresh_hz": float(task.field_obs.refresh_hz),
            "sdf_clip": float(task.field_obs.sdf_clip),
            "free_space_sdf": free,  # not None: free space reads d = this and grad d = 0 (the flat task's field)
        },
        query_links=[q.name for q in robot.query_links],
        task={
            "name": task.task,
            "scene_kind": task.scene_kind,
            "scene_groups": list(task.scene_groups),
            "scene_dir": task.scene_dir,
        },
    )


# Fields a runtime must agree on with the policy file (the rest describe where the file came from).
LAYOUT_KEYS = (
    "obs_groups", "obs_dim", "num_actions", "joint_names", "policy_joints", "default_joint_pos", "kp", "kd",
    "soft_joint_limits", "action", "control_dt", "field_constants", "field_obs", "query_links",
)  # fmt: skip


def _differs(a, b) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() != b.keys() or any(_differs(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) != len(b) or any(_differs(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float | int) and isinstance(b, float | int) and not isinstance(a, bool):
        return not np.isclose(float(a), float(b), rtol=1e-9, atol=1e-9)
    return a != b


def _short(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def layout_mismatches(policy: PolicyMetadata, runtime: PolicyMetadata) -> list[str]:
    """Human-readable differences between a policy file's layout and the runtime's (empty: compatible)."""
    out = []
    for g in policy.obs_groups:
        if g not in runtime.observation:
            continue
        theirs, ours = policy.observation[g], runtime.observation[g]
        if theirs["history"] != ours["history"]:
            out.append(f"group {g!r} history {theirs['history']} (runtime {ours['history']})")
        t_terms = [(t["name"], t["size"]) for t in theirs["terms"]]
        o_terms = [(t["name"], t["size"]) for t in ours["terms"]]
        if t_terms != o_terms:
            diff = next((f"{a} vs runtime {b}" for a, b in zip(t_terms, o_terms, strict=False) if a != b), "")
            out.append(f"group {g!r} terms (name, size) differ{': ' + diff if diff else ' in count'}")
    for key in LAYOUT_KEYS:
        a, b = getattr(policy, key), getattr(runtime, key)
        if _differs(a, b):
            out.append(f"{key} {_short(a)} (runtime {_short(b)})")
    return out


def git_version(path: str | os.PathLike | None = None) -> dict:
    """Short commit and dirty flag of the checkout holding ``path`` (this package); ``unknown`` outside git."""
    root = Path(path) if path is not None else Path(__file__).resolve().parents[2]

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30, check=True
        ).stdout.strip()

    try:
        commit = git("rev-parse", "--short", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return {"commit": "unknown", "dirty": None}
    return {"commit": commit, "dirty": dirty}


def robot_model_source(robot: RobotCfg) -> dict:
    """Where the robot model comes from: menagerie robot, entry, package version, model oid and file hash."""
    import hashlib

    from cat.envs.robot import menagerie_model_path

    src: dict = {"source": "mujoco_menagerie", "name": robot.model_name, "entry": robot.model_entry}
    try:
        src["package_version"] = importlib.metadata.version("mujoco-menagerie")
    except importlib.metadata.PackageNotFoundError:
        src["package_version"] = "unknown"
    try:
        import mujoco_menagerie

        src["oid"] = getattr(mujoco_menagerie.get(robot.model_name), "oid", None)
        path = menagerie_model_path(robot)
        src["file"] = path.name
        src["file_sha256"] = hashlib.sha256(path.read_bytes()).hexdigest()
    except Exception:  # registry without that robot, no model files here: the version fields above still say it
        src.setdefault("oid", None)
    return src


def library_versions() -> dict:
    out = {}
    for pkg in ("torch", "rsl-rl-lib", "onnx", "onnxruntime"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def read_metadata(path: str | os.PathLike) -> PolicyMetadata:
    """The metadata of an exported policy file (``PolicyFileError``: missing, not ONNX, not a CAT export)."""
    import onnx

    path = Path(path)
    if not path.is_file():
        raise PolicyFileError(f"policy file not found: {path}")
    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception as err:  # protobuf decode errors of a file that is not ONNX
        raise PolicyFileError(f"{path}: not an ONNX file ({type(err).__name__})") from None
    if not model.graph.node:
        raise PolicyFileError(f"{path}: not an ONNX model (no graph)")
    return PolicyMetadata.from_props({p.key: p.value for p in model.metadata_props}, str(path))
