"""Top-level run configuration (hydra structured schema) and its conversion to rsl_rl's runner dict."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from cat.envs.config import EnvCfg
from cat.envs.field_contact import FieldContactCfg, check_obstacles
from cat.fields.bank import STORAGES


@dataclass
class SimCfg:
    backend: str = "mujoco"  # mujoco | warp
    device: str = "cpu"  # torch device of the env tensors (cuda:0 needs sim=warp)
    per_world_scenes: bool = False  # each world holds only its own scene (docs/scenes.md); else tiles
    # physical: obstacle geometry in the worlds; field: floor only, contact judged from the scene SDF
    # (cat/envs/field_contact.py, docs/training.md "Obstacles as fields"). Evaluation is always physical.
    obstacles: str = "physical"
    field_contact: FieldContactCfg = field(default_factory=FieldContactCfg)  # margin and spacing of field contact
    # the training field bank's storage (cat.fields.bank.STORAGES): float32 | float16 | compact (d, ∇d float16, F
    # as int8 mantissas with a shared exponent: 56 instead of 160 bytes per voxel with 12 goals; docs/fields.md).
    # Evaluation and the demo build float32 banks whatever a run trained with.
    field_storage: str = "float32"

    def __post_init__(self) -> None:
        check_obstacles(self.obstacles)  # a typo fails at load, before any scene is built
        if self.field_storage not in STORAGES:
            raise ValueError(f"sim.field_storage={self.field_storage!r}; valid: {', '.join(STORAGES)}")


ALGOS = ("ppo", "distill")
STUDENT_MODELS = ("mlp", "lstm")


@dataclass
class DistillCfg:
    """Multi-teacher DAgger (``algo=distill``, rsl_rl ``Distillation``): the student acts, each env's specialist
    labels. The student reads the env groups ``student_groups``; teachers read ``teacher_groups`` (each
    teacher checkpoint's actor layout must match them), routed by ``route_group`` (``scene_group`` term)."""

    student: str = "mlp"  # mlp (history in the observation) | lstm (rsl_rl RNNModel)
    hidden_dims: list[int] = field(default_factory=lambda: [256, 128, 64])
    rnn_type: str = "lstm"
    rnn_hidden_dim: int = 256
    rnn_num_layers: int = 1
    init_noise_std: float = 0.1  # the acting student's exploration noise: DAgger visits the student's own states
    learning_rate: float = 1.0e-3
    num_learning_epochs: int = 1
    gradient_length: int = 24  # steps of truncated backprop per gradient step (divides epochs x num_steps_per_env)
    loss_type: str = "mse"  # mse | huber
    max_grad_norm: float = 1.0
    # DAgger's mixing (beta): each episode is driven by its teacher with this probability (drawn per env at every
    # reset), by the student otherwise; every step is labelled and learned from either way. Teacher-driven
    # episodes reach the states behind a hard passage that a still-failing student ends its episodes before.
    teacher_drive_prob: float = 0.0
    student_groups: list[str] = field(default_factory=lambda: ["student"])
    teacher_groups: list[str] = field(default_factory=lambda: ["teacher"])
    route_group: str = "route"


@dataclass
class RehearsalCfg:
    """PPO that rehearses its teachers (``learning_rate`` > 0 with ``teachers=[...]``; cat/learning/rehearsal.py):
    after each PPO update the actor imitates, on the rollout's own states, the specialist of each scene group that
    has one (DAgger's labels, read from ``algo.distill.teacher_groups`` and routed by ``algo.distill.route_group``),
    with its own Adam; groups without a teacher learn from PPO alone. A fine-tune on new scenes keeps the skills
    its teachers hold while PPO works on what they cannot teach (issue 28)."""

    learning_rate: float = 0.0  # the imitation phase's Adam rate; 0: off (plain PPO)
    num_learning_epochs: int = 1  # passes over the rollout's labelled states per PPO update
    num_mini_batches: int = 4
    max_grad_norm: float = 1.0


@dataclass
class AlgoCfg:
    """PPO (rsl_rl) settings; defaults follow the authors' release where known. ``name=distill`` trains a
    student by DAgger instead (``distill``; PPO's policy settings then describe nothing)."""

    name: str = "ppo"  # ppo | distill
    distill: DistillCfg = field(default_factory=DistillCfg)
    rehearsal: RehearsalCfg = field(default_factory=RehearsalCfg)  # PPO only: imitate teachers beside PPO
    num_steps_per_env: int = 24
    learning_rate: float = 3.0e-4
    gamma: float = 0.97
    lam: float = 0.95
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    clip_param: float = 0.2
    entropy_coef: float = 0.005
    value_loss_coef: float = 1.0
    max_grad_norm: float = 1.0
    desired_kl: float = 0.01
    schedule: str = "adaptive"
    actor_hidden_dims: list[int] = field(default_factory=lambda: [256, 128, 64])
    critic_hidden_dims: list[int] = field(default_factory=lambda: [512, 256, 128])
    activation: str = "elu"
    init_noise_std: float = 0.3  # actions are increments of PD targets (0.5 rad per unit): keep early noise small
    # > 0: the learned action std is clamped to at most this (rsl_rl's std_range); 0: unbounded, as every run before
    # 2026-12-04. The hybrid teacher's ankle stds had grown to 2-5.6 (1-2.8 rad of target noise per step)
    max_noise_std: float = 0.0
    obs_normalization: bool = True
    # iterations at the start of the run in which PPO trains the critic only (actor frozen, fixed rate): a new
    # critic under a trained actor (init= a distilled student, cat/learning/finetune.py) first learns its values
    critic_warmup_iterations: int = 0
    # the warm-up's rate, with PPO's value clipping off: the clip keeps each value within clip_param of its
    # rollout-time estimate per update, so a new critic at the fine-tuning rate crawls (docs/distillation.md)
    critic_warmup_learning_rate: float = 1.0e-3
    save_interval: int = 50
    # rsl_rl's use_mixed_precision: the PPO update's forward passes under bf16 autocast (the rollout stays fp32).
    # About halves the update's matmul time on CPUs with AVX512-BF16 (docs/benchmarks.md); off by default
    mixed_precision: bool = False
    symmetry_augment: bool = False  # add left/right mirrored samples to every PPO mini-batch (cat.envs.symmetry)
    mirror_loss_coeff: float = 0.0  # > 0: also penalise disagreement between the policy and its mirror image
    # rsl_rl observation sets -> the env's observation groups (task.observations) each network reads, concatenated
    obs_groups: dict[str, list[str]] = field(default_factory=lambda: {"actor": ["actor"], "critic": ["critic"]})


@dataclass
class TrainCfg:
    method: str = "ours"  # the configs/method/<name>.yaml applied to task (recorded; docs/baselines.md)
    task: EnvCfg = field(default_factory=EnvCfg)
    sim: SimCfg = field(default_factory=SimCfg)
    algo: AlgoCfg = field(default_factory=AlgoCfg)
    num_envs: int | None = None  # overrides task.num_envs when set
    max_iterations: int = 1500  # total PPO iterations of the run (a resumed run continues up to this count)
    max_minutes: float = 0.0  # > 0: stop cleanly after this much wall-clock, save, and resume later
    deadline: float = 0.0  # > 0: also stop so at this Unix time (a sitting's end, shared by jobs a launcher queues)
    seed: int = 0
    verbose: bool = False  # rsl_rl's per-iteration console block and network printout instead of one log line
    torch_threads: int = 0  # torch intra-op threads (0: torch's default); 1 when other work shares the cores
    init: str | None = None  # checkpoint whose policy/critic weights initialise this run
    resume: str | None = None  # checkpoint to continue, in its own run folder (optimiser, iteration, RNG, curriculum)
    run_root: str = "runs"  # runs go to <run_root>/<task>/<time>[_<run_name>]
    run_name: str = ""
    run_dir: str | None = None  # exact run folder instead (hydra.run.dir=...; must not exist or be empty)
    teachers: list[str] = field(default_factory=list)  # algo=distill: specialist checkpoints, one per scene group


def _symmetry_cfg(algo: AlgoCfg) -> dict[str, Any] | None:
    if not algo.symmetry_augment and algo.mirror_loss_coeff <= 0:
        return None
    return {
        "use_data_augmentation": algo.symmetry_augment,
        "use_mirror_loss": algo.mirror_loss_coeff > 0,
        "mirror_loss_coeff": algo.mirror_loss_coeff,
        "data_augmentation_func": "cat.envs.symmetry:mirror_augment",
    }


PPO_OBS_SETS = ("actor", "critic")


def check_obs_groups(obs_groups: dict[str, list[str]], env_groups: Iterable[str]) -> None:
    """``algo.obs_groups`` must map PPO's sets to groups the env builds (one-line ``ValueError`` naming the entry)."""
    env_groups = list(env_groups)
    for obs_set, groups in obs_groups.items():
        if obs_set not in PPO_OBS_SETS:
            raise ValueError(f"algo.obs_groups has unknown set {obs_set!r}; valid: {', '.join(PPO_OBS_SETS)}")
        if not groups:
            raise ValueError(f"algo.obs_groups.{obs_set} lists no observation group")
        for g in groups:
            if g not in env_groups:
                raise ValueError(
                    f"algo.obs_groups.{obs_set} names observation group {g!r} that the env does not build; "
                    f"groups (task.observations): {', '.join(env_groups)}"
                )


def runner_cfg(
    algo: AlgoCfg, env_groups: Iterable[str] | None = None, rehearsal: dict[str, Any] | None = None
) -> dict[str, Any]:
    """rsl_rl 5.5 ``OnPolicyRunner`` config dict; with ``env_groups`` the observation sets are checked against
    the groups the env builds; ``rehearsal`` (the teachers' files and the env's scene groups,
    ``cat.learning.rehearsal.rehearsal_cfg``) makes the algorithm ``RehearsalPPO``."""
    obs_groups = {k: list(v) for k, v in algo.obs_groups.items()}
    if env_groups is not None:
        check_obs_groups(obs_groups, env_groups)
    return {
        "num_steps_per_env": algo.num_steps_per_env,
        "save_interval": algo.save_interval,
        "check_for_nan": False,
        "obs_groups": obs_groups,
        "logger": {"class_name": "cat.learning.rerun_writer:RerunLogWriter"},
        "algorithm": {
            "class_name": "PPO",
            "learning_rate": algo.learning_rate,
            "gamma": algo.gamma,
            "lam": algo.lam,
            "num_learning_epochs": algo.num_learning_epochs,
            "num_mini_batches": algo.num_mini_batches,
            "clip_param": algo.clip_param,
            "entropy_coef": algo.entropy_coef,
            "value_loss_coef": algo.value_loss_coef,
            "max_grad_norm": algo.max_grad_norm,
            "desired_kl": algo.desired_kl,
            "schedule": algo.schedule,
            "symmetry_cfg": _symmetry_cfg(algo),
            "use_mixed_precision": algo.mixed_precision,
            **_critic_warmup(algo),
            **({"class_name": "cat.learning.rehearsal:RehearsalPPO", "rehearsal": rehearsal} if rehearsal else {}),
        },
        "actor": {
            "class_name": "MLPModel",
            "hidden_dims": list(algo.actor_hidden_dims),
            "activation": algo.activation,
            "obs_normalization": algo.obs_normalization,
            "distribution_cfg": _distribution_cfg(algo),
        },
        "critic": {
            "class_name": "MLPModel",
            "hidden_dims": list(algo.critic_hidden_dims),
            "activation": algo.activation,
            "obs_normalization": algo.obs_normalization,
        },
    }


def _distribution_cfg(algo: AlgoCfg) -> dict[str, Any]:
    """The actor's Gaussian: its initial std and, with ``max_noise_std`` > 0, the clamp on the learned std
    (``validate_train_cfg`` refuses a negative one)."""
    cfg: dict[str, Any] = {"class_name": "GaussianDistribution", "init_std": algo.init_noise_std}
    if algo.max_noise_std > 0:
        cfg["std_range"] = (1e-6, algo.max_noise_std)
    return cfg


def _critic_warmup(algo: AlgoCfg) -> dict[str, Any]:
    """A fine-tuned student's critic warm-up: PPO extended by subclass (``cat.learning.finetune``), named here."""
    if algo.critic_warmup_iterations <= 0:
        return {}
    return {
        "class_name": "cat.learning.finetune:CriticWarmupPPO",
        "critic_warmup_iterations": algo.critic_warmup_iterations,
        "critic_warmup_learning_rate": algo.critic_warmup_learning_rate,
    }


def student_model_cfg(d: DistillCfg, activation: str = "elu", obs_normalization: bool = True) -> dict[str, Any]:
    """rsl_rl class config of the distilled student (``MLPModel`` or ``RNNModel``)."""
    if d.student not in STUDENT_MODELS:
        raise ValueError(f"algo.distill.student={d.student!r}; valid: {', '.join(STUDENT_MODELS)}")
    cfg: dict[str, Any] = {
        "class_name": "MLPModel" if d.student == "mlp" else "RNNModel",
        "hidden_dims": list(d.hidden_dims),
        "activation": activation,
        "obs_normalization": obs_normalization,
        "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": d.init_noise_std},
    }
    if d.student == "lstm":
        cfg.update(rnn_type=d.rnn_type, rnn_hidden_dim=d.rnn_hidden_dim, rnn_num_layers=d.rnn_num_layers)
    return cfg


@dataclass
class PolicyModel:
    """The network that acts at deployment: PPO's actor or the distilled student."""

    class_cfg: dict[str, Any]  # rsl_rl resolve_class config (class_name + kwargs)
    obs_set: str  # "actor" | "student"
    obs_groups: list[str]  # env observation groups it reads, concatenated in order
    state_key: str  # its entry in the checkpoint dict

    def build(self, obs, num_actions: int):
        """An untrained instance for observations shaped like ``obs`` (a TensorDict of the env's groups)."""
        from rsl_rl.utils import resolve_class

        cls, kwargs = resolve_class(dict(self.class_cfg))
        return cls(obs, {self.obs_set: list(self.obs_groups)}, self.obs_set, num_actions, **kwargs)


def policy_model(algo: AlgoCfg) -> PolicyModel:
    """Which network of a run's checkpoint is its policy, how to build it, and what it reads."""
    if algo.name == "ppo":
        return PolicyModel(runner_cfg(algo)["actor"], "actor", list(algo.obs_groups["actor"]), "actor_state_dict")
    if algo.name == "distill":
        d = algo.distill
        cfg = student_model_cfg(d, algo.activation, algo.obs_normalization)
        return PolicyModel(cfg, "student", list(d.student_groups), "student_state_dict")
    raise ValueError(f"algo.name={algo.name!r}; valid: {', '.join(ALGOS)}")
