"""PPO that rehearses its teachers: after each PPO update the actor imitates, on the rollout's own states, the
specialist of each scene group that has one; groups without a teacher learn from PPO alone."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import torch

from cat.learning.distill import MultiTeacher, TeacherError
from cat.learning.rehearsal import RehearsalPPO
from cat.learning.runs import make_env, make_runner, train, validate_train_cfg
from cat.run.config import AlgoCfg, RehearsalCfg, TrainCfg, runner_cfg
from tests.test_distill import KINDS, _generalist_cfg, _teacher

STUDENT_GROUPS = ["student_proprio", "student"]


@pytest.fixture(scope="module")
def teacher(tmp_path_factory) -> str:
    """A hurdle-crouch specialist whose every action is 0.3; side-pass has no teacher."""
    env = make_env(_generalist_cfg([]))
    return _teacher(tmp_path_factory.mktemp("teachers") / "hc", "hurdle-crouch", 0.3, env)


def _cfg(teachers: list[str], run_dir: Path | None = None, rate: float = 1e-2, warmup: int = 1) -> TrainCfg:
    cfg = _generalist_cfg(teachers)
    cfg.algo = AlgoCfg(
        actor_hidden_dims=[32, 32],
        critic_hidden_dims=[32],
        obs_groups={"actor": list(STUDENT_GROUPS), "critic": ["critic"]},
        learning_rate=1e-6,  # PPO barely moves the actor: what it learns here is the rehearsal's
        schedule="fixed",
        num_steps_per_env=8,
        num_mini_batches=2,
        save_interval=1,
        critic_warmup_iterations=warmup,
        rehearsal=RehearsalCfg(learning_rate=rate, num_learning_epochs=4, num_mini_batches=2),
    )
    cfg.algo.distill = _generalist_cfg([]).algo.distill  # teacher and route groups as DAgger's
    cfg.max_iterations = 5
    cfg.run_dir = str(run_dir) if run_dir else None
    return cfg


def _actor_error(run: Path, it: int, obs, groups: torch.Tensor, group: int) -> float:
    """Mean squared distance of the checkpoint's actor mean from 0.3 on the envs of scene group ``group``."""
    cfg = _cfg([], rate=0.0)
    env = make_env(cfg)
    actor = make_runner(cfg, env, None).alg.actor
    actor.load_state_dict(torch.load(run / f"model_{it}.pt", weights_only=False)["actor_state_dict"])
    with torch.no_grad():
        return float((actor(obs)[groups == group] - 0.3).pow(2).mean())


def test_the_actor_learns_the_teachers_actions_on_their_groups_only_after_the_warm_up(teacher, tmp_path):
    run = train(_cfg([teacher], tmp_path / "run"))
    env = make_env(_cfg([], rate=0.0))
    obs = env.get_observations()
    groups = obs["route"][:, 0].round().long()
    hc, sp = KINDS.index("hurdle-crouch"), KINDS.index("side-pass")
    assert {hc, sp} <= set(groups.tolist())
    taught = [_actor_error(run, it, obs, groups, hc) for it in (0, 4)]
    untaught = [_actor_error(run, it, obs, groups, sp) for it in (0, 4)]
    assert taught[1] < 0.2 * taught[0]  # the hurdle-crouch envs' actions went to their teacher's 0.3
    assert untaught[1] > 0.5 * untaught[0]  # side-pass has no teacher: the tiny PPO rate leaves it where it was
    rows = list(csv.DictReader(open(run / "metrics.csv")))
    rehearsal = {int(r["iteration"]): float(r["value"]) for r in rows if r["tag"] == "Loss/rehearsal"}
    assert sorted(rehearsal) == [1, 2, 3, 4]  # none while the critic warms up (iteration 0: the actor is frozen)
    assert rehearsal[4] < rehearsal[1]
    ckpt = torch.load(run / "model_4.pt", weights_only=False)
    assert ckpt["rehearsal_optimizer_state_dict"]["state"]  # a resume continues the imitation's Adam exactly


def test_labels_cover_only_the_taught_groups_and_a_distillation_still_needs_every_group(teacher):
    cfg = _cfg([teacher])
    env = make_env(cfg)
    obs = env.get_observations()
    mt = MultiTeacher(obs, {"teacher": ["teacher"]}, "teacher", env.num_actions, [teacher], list(KINDS), "route")
    labels, labelled = mt.label(obs)
    hc = obs["route"][:, 0].round().long() == KINDS.index("hurdle-crouch")
    assert torch.equal(labelled, hc)
    assert torch.allclose(labels[hc], torch.full_like(labels[hc], 0.3)) and not labels[~hc].any()
    with pytest.raises(TeacherError, match=r"scene group\(s\) \['side-pass'\] have no teacher"):
        mt(obs)
    runner = make_runner(cfg, env, None)
    assert isinstance(runner.alg, RehearsalPPO)
    cfg.algo.rehearsal.learning_rate = 0.0
    assert not runner_cfg(cfg.algo)["algorithm"]["class_name"].endswith("RehearsalPPO")


def test_bad_rehearsal_settings_are_refused_before_any_env_is_built(teacher, tmp_path):
    with pytest.raises(ValueError, match="needs teachers="):
        validate_train_cfg(_cfg([]))
    with pytest.raises(ValueError, match="teachers= is for algo=distill, or PPO with algo.rehearsal"):
        validate_train_cfg(_cfg([teacher], rate=0.0))
    cfg = _cfg([teacher])
    cfg.algo.rehearsal.num_mini_batches = 0
    with pytest.raises(ValueError, match="algo.rehearsal.num_mini_batches=0"):
        validate_train_cfg(cfg)
    cfg = _cfg([teacher])
    cfg.algo.distill.route_group = "critic"
    with pytest.raises(ValueError, match="route_group='critic'"):
        validate_train_cfg(cfg)
    cfg = _cfg([teacher], tmp_path / "none")  # a teacher of a group this env does not have
    cfg.task.scene_groups = ["side-pass"]
    with pytest.raises(TeacherError, match="no scene group of the env \\(side-pass\\) has a teacher"):
        train(cfg)
    assert not (tmp_path / "none").exists()


def test_a_rank_without_labelled_states_still_takes_every_averaged_step(teacher, monkeypatch):
    """Multi-GPU: each rank's gradients are all-reduced before every imitation step, so every rank must take the
    same number of steps; one whose rollout holds no taught scene takes them on empty mini-batches (zero
    gradient, finite loss). Exercised on a one-process gloo group."""
    import torch.distributed as dist

    cfg = _cfg([teacher])
    env = make_env(cfg)
    alg = make_runner(cfg, env, None).alg
    obs, labels = alg._labelled_states()
    empty_obs, empty_labels = obs[:0], labels[:0]
    before = [p.detach().clone() for p in alg.actor.parameters()]
    dist.init_process_group("gloo", init_method="tcp://127.0.0.1:29517", rank=0, world_size=1)
    try:
        monkeypatch.setattr(alg, "is_multi_gpu", True)
        steps, step = [], alg.rehearsal_optimizer.step
        monkeypatch.setattr(alg.rehearsal_optimizer, "step", lambda: steps.append(1) or step())  # counted, then run
        assert alg._rehearse(empty_obs, empty_labels) == 0.0
    finally:
        dist.destroy_process_group()
    assert len(steps) == 4 * 2  # num_learning_epochs x num_mini_batches, as every other rank
    assert all(torch.equal(a, b) for a, b in zip(before, alg.actor.parameters(), strict=True))
    grads = [p.grad for p in alg.actor.parameters() if p.grad is not None]
    assert grads and all(not g.any() for g in grads)
