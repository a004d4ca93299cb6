"""Multi-teacher DAgger (paper §III-B) on rsl_rl's ``Distillation``: the student acts, and every env is labelled
by the specialist of its scene group.

``MultiTeacher`` is the teacher model rsl_rl builds by class name: it loads K PPO specialist checkpoints, checks
that each one's actor read the same observation layout as the env's teacher groups, freezes them, and routes each
env to the specialist of its scene group (the ``scene_group`` term in the route group). A teacher's group is the
scene kind its run trained on (``task.scene_kind``, or its single ``task.scene_groups`` entry; ``flat`` without
scenes). ``MultiTeacherDistillation`` keeps the teachers out of the student checkpoints: they are reloaded from
their own files (named in the run's ``config.yaml``), so a student checkpoint stays small.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn
from rsl_rl.algorithms import Distillation
from tensordict import TensorDict

from cat.checkpoint_io import CheckpointError, read_checkpoint, resolve_checkpoint
from cat.envs.obs_groups import groups_layout
from cat.envs.scene_set import scene_folders
from cat.run.config import TrainCfg, policy_model
from cat.run.config_file import load_run_config
from cat.terrain.data_groups import select

log = logging.getLogger(__name__)


class TeacherError(ValueError):
    """A teacher checkpoint that cannot label this env (missing, another layout, no or duplicate group)."""


def teacher_groups(cfg: TrainCfg, checkpoint: str) -> list[str]:
    """The scene groups a specialist run was trained on (scene kinds), or ``TeacherError``. A run on a scene folder
    teaches every kind it trained on there (after ``task.scene_kind`` and ``task.data``), e.g. indoor + procedural."""
    task = cfg.task
    if task.scene_groups:
        if len(task.scene_groups) != 1:
            raise TeacherError(
                f"teacher {checkpoint} trained on several scene groups {task.scene_groups}: not a specialist"
            )
        return [task.scene_groups[0]]
    if task.scene_kind:
        return [task.scene_kind]
    if task.scene_dir:
        return folder_kinds(task.scene_dir, task.data, checkpoint)
    return ["flat"]


def folder_kinds(scene_dir: str, data: str | None, checkpoint: str) -> list[str]:
    """Scene kinds of a scene folder (in the order ``SceneSet.from_dir`` meets them), as data group ``data``
    selects them; read from the ``scene.json`` files only."""
    folders = scene_folders(Path(scene_dir)) if Path(scene_dir).is_dir() else []
    if not folders:
        raise TeacherError(f"teacher {checkpoint} trained on {scene_dir}, which holds no scenes here (regenerate it)")
    meta = [json.loads((f / "scene.json").read_text()) for f in folders]
    kinds = [m.get("kind", "user") for m in meta]
    keep = np.ones(len(meta), dtype=bool)
    if data is not None:
        keep = select(kinds, [float(m.get("difficulty", 0.0)) for m in meta], [m.get("seed") for m in meta], data)
    return list(dict.fromkeys(k for k, ok in zip(kinds, keep, strict=True) if ok))


@dataclass
class Specialist:
    checkpoint: str
    groups: list[str]
    run: TrainCfg


def load_specialists(checkpoints: list[str]) -> list[Specialist]:
    """Each checkpoint with its run config and scene group; ``TeacherError`` names a missing or unusable one."""
    if not checkpoints:
        raise TeacherError("algo=distill needs teachers=[<specialist checkpoint>, ...]")
    out: list[Specialist] = []
    for ckpt in checkpoints:
        try:
            path = str(resolve_checkpoint(ckpt))
            run = load_run_config(path)
            read_checkpoint(path)  # the safe loader refuses an unsafe file here, before any runner is built
        except CheckpointError as err:
            raise TeacherError(f"teacher {ckpt}: {err}") from None
        if run.algo.name != "ppo":
            raise TeacherError(f"teacher {ckpt} is a {run.algo.name} run, not a PPO specialist")
        groups = teacher_groups(run, ckpt)
        for s in out:
            both = sorted(set(s.groups) & set(groups))
            if both:
                raise TeacherError(f"teachers {s.checkpoint} and {ckpt} both teach scene group {both[0]!r}")
        out.append(Specialist(path, groups, run))
    return out


def check_teachers(
    specialists: list[Specialist], cfg: TrainCfg, group_names: list[str], every_group: bool = True
) -> None:
    """Every scene group of the env has a teacher (``every_group``; else at least one has: a PPO run rehearsing
    some groups' teachers), and each teacher's actor layout is the env's teacher groups."""
    own = {g for s in specialists for g in s.groups}
    missing = [g for g in group_names if g not in own]
    if missing and not every_group and len(missing) == len(group_names):
        raise TeacherError(
            f"no scene group of the env ({', '.join(group_names)}) has a teacher; teachers cover: "
            f"{', '.join(sorted(own)) or 'nothing'}"
        )
    if missing and every_group:
        raise TeacherError(
            f"scene group {missing[0]!r} has no teacher; teachers cover: {', '.join(sorted(own)) or 'nothing'}"
        )
    want = groups_layout(cfg.task, list(cfg.algo.distill.teacher_groups))
    for s in specialists:
        have = groups_layout(s.run.task, list(s.run.algo.obs_groups["actor"]))
        if have != want:
            raise TeacherError(
                f"teacher {s.checkpoint} observed {have} but the env's teacher groups "
                f"{cfg.algo.distill.teacher_groups} give {want}"
            )


class MultiTeacher(nn.Module):
    """K frozen specialist actors; ``forward`` labels each env with the actor of its scene group, clipped to
    ``action_clip`` as the env clips every action. Unclipped, a specialist's mean reaches |a| = 7-12 in hurdle
    and side-pass scenes (a third of its entries beyond the clip): an MSE on those spends the student's
    capacity on differences the robot never feels (docs/distillation.md)."""

    is_recurrent = False

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        checkpoints: list[str] | None = None,
        group_names: list[str] | None = None,
        route_group: str = "route",
        action_clip: float | None = None,
    ) -> None:
        super().__init__()
        specialists = load_specialists(list(checkpoints or []))
        self.group_names = list(group_names or [])
        self.route_group = route_group
        if route_group not in obs.keys():
            raise TeacherError(f"the env builds no observation group {route_group!r} (the scene_group term)")
        self.teachers = nn.ModuleList()
        route = torch.full((max(len(self.group_names), 1),), -1, dtype=torch.long)  # scene group -> teacher index
        for k, s in enumerate(specialists):
            model = policy_model(s.run.algo)  # the specialist's actor, reading the env's teacher groups
            actor = replace(model, obs_set=obs_set, obs_groups=list(obs_groups[obs_set])).build(obs, output_dim)
            state = read_checkpoint(s.checkpoint)[model.state_key]
            try:
                actor.load_state_dict(state, strict=True)
            except RuntimeError as err:
                raise TeacherError(f"teacher {s.checkpoint} does not fit the env's teacher groups: {err}") from None
            actor.eval()
            for p in actor.parameters():
                p.requires_grad_(False)
            self.teachers.append(actor)
            for g in s.groups:
                if g in self.group_names:
                    route[self.group_names.index(g)] = k
        self.register_buffer("route", route, persistent=False)
        self.output_dim = output_dim
        self.read_groups = [route_group, *obs_groups[obs_set]]  # what label() indexes per teacher (not the rest)
        self.checkpoints = [s.checkpoint for s in specialists]
        if action_clip is not None and action_clip <= 0:
            raise ValueError(f"action_clip must be positive, got {action_clip}")
        self.action_clip = action_clip

    def label(self, obs: TensorDict) -> tuple[torch.Tensor, torch.Tensor]:
        """Each env's specialist action (clipped) and whether its scene group has a specialist (zeros where not)."""
        obs = obs.select(*self.read_groups)  # a view: the per-teacher masks then copy only the groups teachers read
        group = obs[self.route_group][:, 0].round().long()
        inside = (group >= 0) & (group < len(self.route))
        teacher = torch.where(inside, self.route[group.clamp(0, len(self.route) - 1)], -1)
        out = torch.zeros(group.shape[0], self.output_dim, device=group.device)
        for k, actor in enumerate(self.teachers):
            mask = teacher == k
            if mask.any():
                out[mask] = actor(obs[mask]).to(out.dtype)
        if self.action_clip is not None:  # the label is what the env executes (it clips every action)
            out = out.clamp(-self.action_clip, self.action_clip)
        return out, teacher >= 0

    def forward(self, obs: TensorDict, **unused) -> torch.Tensor:
        out, labelled = self.label(obs)
        if not bool(labelled.all()):
            group = obs[self.route_group][:, 0].round().long()
            bad = sorted(set(group[~labelled].tolist()))
            names = [self.group_names[b] if 0 <= b < len(self.group_names) else str(b) for b in bad]
            raise TeacherError(f"envs of scene group(s) {names} have no teacher")
        return out

    # rsl_rl's recurrent-model interface (the specialists are MLPs: nothing to carry)
    def reset(self, dones: torch.Tensor | None = None, hidden_state=None) -> None:
        pass

    def get_hidden_state(self):
        return None

    def detach_hidden_state(self, dones: torch.Tensor | None = None) -> None:
        pass


class MultiTeacherDistillation(Distillation):
    """rsl_rl ``Distillation`` whose checkpoints hold the student (and optimiser) only, with DAgger's mixing:
    an episode is driven by the teacher with probability ``teacher_drive_prob`` (drawn per env at each reset);
    every step, whoever drove it, is stored with the teacher's label."""

    def __init__(self, *args, teacher_drive_prob: float = 0.0, **kwargs):
        super().__init__(*args, **kwargs)
        if not 0.0 <= teacher_drive_prob <= 1.0:
            raise ValueError(f"algo.distill.teacher_drive_prob must be in [0, 1], got {teacher_drive_prob}")
        self.teacher_drive_prob = teacher_drive_prob
        self.teacher_drives: torch.Tensor | None = None  # (num_envs,) bool, drawn at the first step and each reset

    def _draw_drivers(self, n: int) -> torch.Tensor:
        return torch.rand(n, device=self.device) < self.teacher_drive_prob

    def act(self, obs: TensorDict) -> torch.Tensor:
        actions = super().act(obs)
        if self.teacher_drive_prob <= 0.0:
            return actions
        if self.teacher_drives is None:
            self.teacher_drives = self._draw_drivers(actions.shape[0])
        return torch.where(self.teacher_drives[:, None], self.transition.privileged_actions, actions)

    def process_env_step(self, obs: TensorDict, rewards, dones, extras) -> None:
        super().process_env_step(obs, rewards, dones, extras)
        if self.teacher_drives is not None:
            done = dones.bool().view(-1)
            self.teacher_drives[done] = self._draw_drivers(int(done.sum()))

    def save(self) -> dict:
        return {
            "student_state_dict": self._raw_student.state_dict(),
            "optimizer_state_dict": self.optimizer.state_dict(),
            "teachers": list(getattr(self._raw_teacher, "checkpoints", [])),
        }

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        load_cfg = load_cfg or {"student": True, "optimizer": True, "iteration": True}
        if load_cfg.get("student"):
            self._raw_student.load_state_dict(loaded_dict["student_state_dict"], strict=strict)
        if load_cfg.get("optimizer") and "optimizer_state_dict" in loaded_dict:
            self.optimizer.load_state_dict(loaded_dict["optimizer_state_dict"])
        return bool(load_cfg.get("iteration", False))


def check_student_init(cfg: TrainCfg, init_cfg: TrainCfg, path: str) -> None:
    """``init=`` of a distillation must be an earlier student of the same network on the same input layout, so a
    generalist can grow by scene groups as specialists land (one-line ``ValueError`` naming the mismatch)."""
    if init_cfg.algo.name != "distill":
        raise ValueError(f"init={path}: a distillation starts from an earlier student, not a {init_cfg.algo.name} run")
    have, need = init_cfg.algo.distill, cfg.algo.distill
    wanted = {
        "algo.distill.student": (need.student, have.student),
        "algo.distill.hidden_dims": (list(need.hidden_dims), list(have.hidden_dims)),
        "algo.activation": (cfg.algo.activation, init_cfg.algo.activation),
        "algo.obs_normalization": (cfg.algo.obs_normalization, init_cfg.algo.obs_normalization),
    }
    if need.student == "lstm":
        wanted["algo.distill.rnn_hidden_dim"] = (need.rnn_hidden_dim, have.rnn_hidden_dim)
        wanted["algo.distill.rnn_num_layers"] = (need.rnn_num_layers, have.rnn_num_layers)
    for key, (now, then) in wanted.items():
        if now != then:
            raise ValueError(f"init={path}: its student has {key}={then}, this run {now}")
    then = groups_layout(init_cfg.task, list(have.student_groups))
    now = groups_layout(cfg.task, list(need.student_groups))
    if then != now:
        raise ValueError(f"init={path}: its student read {then}, this run's student groups give {now}")


def load_student_init(alg: Distillation, ckpt: dict, path: str) -> None:
    """The student's weights (normaliser included) from ``ckpt``; the optimiser and iteration start fresh."""
    try:
        alg.load(ckpt, load_cfg={"student": True}, strict=True)
    except RuntimeError as err:
        first = str(err).splitlines()[0]
        raise ValueError(f"init={path}: the student does not fit this run's ({first})") from err
    log.info("init: the student starts from %s", os.path.basename(path))


def distill_runner_cfg(cfg: TrainCfg, group_names: list[str]) -> dict:
    """rsl_rl ``DistillationRunner`` config of a distillation run (student, multi-teacher, algorithm)."""
    from cat.run.config import student_model_cfg

    algo, d = cfg.algo, cfg.algo.distill
    return {
        "num_steps_per_env": algo.num_steps_per_env,
        "save_interval": algo.save_interval,
        "check_for_nan": False,
        "obs_groups": {"student": list(d.student_groups), "teacher": list(d.teacher_groups)},
        "logger": {"class_name": "cat.learning.rerun_writer:RerunLogWriter"},
        "algorithm": {
            "class_name": "cat.learning.distill:MultiTeacherDistillation",
            "num_learning_epochs": d.num_learning_epochs,
            "gradient_length": d.gradient_length,
            "learning_rate": d.learning_rate,
            "max_grad_norm": d.max_grad_norm,
            "loss_type": d.loss_type,
            "teacher_drive_prob": d.teacher_drive_prob,
        },
        "student": student_model_cfg(d, algo.activation, algo.obs_normalization),
        "teacher": {
            "class_name": "cat.learning.distill:MultiTeacher",
            "checkpoints": [os.fspath(c) for c in cfg.teachers],
            "group_names": list(group_names),
            "route_group": d.route_group,
            "action_clip": cfg.task.action_clip,
        },
    }
