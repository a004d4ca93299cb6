"""PPO fine-tuning of a distilled student: the student becomes PPO's actor, the new critic warms up alone."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from rsl_rl.algorithms import PPO

from cat.envs.config import ACTOR_TERMS, EnvCfg, ObsGroupCfg
from cat.learning.finetune import CriticWarmupPPO
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import make_env, make_runner, save_config, train, validate_train_cfg
from cat.run.config import AlgoCfg, DistillCfg, TrainCfg, policy_model, runner_cfg

STUDENT_GROUPS = ["student_proprio", "student"]


def _task() -> EnvCfg:
    proprio = [t for t in ACTOR_TERMS if t not in ("goal_command", "field_block")]
    task = EnvCfg(
        task="generalist",
        num_envs=8,
        episode_length_s=2.0,
        scene_groups=["crouch-pass", "side-pass"],
        scene_variants=1,
        observations={
            "actor": ObsGroupCfg(terms=list(ACTOR_TERMS), noise=True),
            "critic": ObsGroupCfg(terms=["base_lin_vel"], extends="actor"),
            "student_proprio": ObsGroupCfg(terms=proprio, noise=True, history=2),
            "student": ObsGroupCfg(terms=["goal_command", "field_block"], noise=True),
            "route": ObsGroupCfg(terms=["scene_group"]),
        },
    )
    task.curriculum.enabled = False
    return task


@pytest.fixture(scope="module")
def student(tmp_path_factory) -> Path:
    """A distillation checkpoint (random student with a confident normaliser) and its config.yaml."""
    folder = tmp_path_factory.mktemp("student")
    algo = AlgoCfg(name="distill", distill=DistillCfg(hidden_dims=[32, 32], student_groups=list(STUDENT_GROUPS)))
    cfg = TrainCfg(task=_task(), algo=algo, teachers=["unused.pt"])
    save_config(cfg, folder)
    env = make_env(cfg, num_envs=2)
    model = policy_model(cfg.algo).build(env.get_observations(), env.num_actions)
    norm = model.obs_normalizer
    with torch.no_grad():
        norm._mean.uniform_(-0.5, 0.5)
        norm._var.fill_(4.0)
        norm._std.fill_(2.0)
        norm.count.fill_(10**9)  # PPO's few rollouts barely move it: its values show that it was loaded
    path = folder / "model_7.pt"
    torch.save({"student_state_dict": model.state_dict(), "iter": 7, "infos": None}, path)
    return path


def _finetune_cfg(student: Path, run_dir: Path) -> TrainCfg:
    algo = AlgoCfg(
        actor_hidden_dims=[32, 32],
        critic_hidden_dims=[32],
        obs_groups={"actor": list(STUDENT_GROUPS), "critic": ["critic"]},
        init_noise_std=0.2,
        critic_warmup_iterations=2,
        num_steps_per_env=8,
        num_mini_batches=2,
        save_interval=1,
    )
    return TrainCfg(task=_task(), algo=algo, init=str(student), max_iterations=4, run_dir=str(run_dir))


def _params(state: dict, prefix: str) -> dict[str, torch.Tensor]:
    return {k: v for k, v in state.items() if k.startswith(prefix)}


def test_the_student_becomes_the_actor_and_only_the_critic_learns_during_warm_up(student, tmp_path):
    run = train(_finetune_cfg(student, tmp_path / "run"))
    src = torch.load(student, weights_only=False)["student_state_dict"]
    ckpts = [torch.load(run / f"model_{it}.pt", weights_only=False) for it in range(4)]
    for it in (0, 1):  # warm-up: the actor's weights are the student's, its noise is algo.init_noise_std
        actor = ckpts[it]["actor_state_dict"]
        for key, value in _params(src, "mlp.").items():
            assert torch.equal(actor[key], value), (it, key)
        assert torch.allclose(actor["distribution.std_param"], torch.full((12,), 0.2))
        assert torch.allclose(actor["obs_normalizer._mean"], src["obs_normalizer._mean"], atol=1e-4)
    critic = [_params(c["critic_state_dict"], "mlp.") for c in ckpts]
    assert any(not torch.equal(critic[0][k], critic[1][k]) for k in critic[0])  # the critic learns meanwhile
    after = ckpts[3]["actor_state_dict"]
    assert any(not torch.equal(after[k], v) for k, v in _params(src, "mlp.").items())  # then the actor does too


def test_the_warm_up_trains_the_critic_unclipped_at_its_own_rate_then_restores_ppo(tmp_path, monkeypatch):
    """The warm-up is PPO extended by subclass, named through the algorithm's class_name; a run resumed past the
    warm-up is plain PPO."""
    cfg = _finetune_cfg(Path("unused"), tmp_path)
    cfg.init = None
    cfg.algo.critic_warmup_learning_rate, cfg.algo.learning_rate = 2e-3, 5e-5
    env = make_env(cfg, num_envs=8)
    runner = make_runner(cfg, env, None)
    alg = runner.alg
    assert isinstance(alg, CriticWarmupPPO) and runner_cfg(cfg.algo)["algorithm"]["class_name"].endswith("WarmupPPO")
    seen: list[tuple[bool, float, str]] = []
    update = PPO.update

    def spy(self) -> dict[str, float]:  # what rsl_rl's update runs with, read as it starts
        seen.append((self.use_clipped_value_loss, self.optimizer.param_groups[0]["lr"], self.schedule))
        return update(self)

    monkeypatch.setattr(PPO, "update", spy)
    alg.start_at(0)
    runner.learn(3)
    assert seen == [(False, 2e-3, "fixed"), (False, 2e-3, "fixed"), (True, 5e-5, "adaptive")]
    seen.clear()
    alg.start_at(2)  # a run resumed at iteration 2: past the warm-up
    runner.learn(1)
    assert len(seen) == 1 and seen[0][0] is True and seen[0][2] == "adaptive"
    cfg.algo.critic_warmup_iterations = 0
    assert runner_cfg(cfg.algo)["algorithm"]["class_name"] == "PPO"


def test_an_actor_unlike_the_student_is_refused_before_any_env_is_built(student, tmp_path):
    cfg = _finetune_cfg(student, tmp_path)
    cfg.algo.actor_hidden_dims = [64]
    with pytest.raises(ValueError, match=r"algo.actor_hidden_dims=\[32, 32\]"):
        validate_train_cfg(cfg)
    cfg = _finetune_cfg(student, tmp_path)
    cfg.algo.obs_groups["actor"] = ["actor"]
    with pytest.raises(ValueError, match="algo.obs_groups.actor=\\['student_proprio', 'student'\\]"):
        validate_train_cfg(cfg)
    cfg = _finetune_cfg(student, tmp_path)
    cfg.algo.critic_warmup_iterations = -1
    with pytest.raises(ValueError, match="algo.critic_warmup_iterations=-1"):
        validate_train_cfg(cfg)
    cfg = _finetune_cfg(student, tmp_path)
    cfg.algo.critic_warmup_learning_rate = 0.0
    with pytest.raises(ValueError, match="algo.critic_warmup_learning_rate=0.0"):
        validate_train_cfg(cfg)


def test_the_shipped_fine_tuning_config_fits_the_shipped_generalist():
    shipped = Path(__file__).resolve().parents[1] / "checkpoints" / "generalist"
    cfg = load_config(["task=generalist", "algo=ppo_student", f"init={shipped}/model_4505.pt"])
    validate_train_cfg(cfg)  # the actor matches the student (check_actor_matches_student)
    assert cfg.algo.critic_warmup_iterations > 0
