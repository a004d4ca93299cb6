"""Multi-teacher DAgger: routing by scene group, a real small distillation run, observation history, bad input."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from cat.envs.config import ACTOR_TERMS, EnvCfg, ObsGroupCfg
from cat.learning.distill import MultiTeacher, TeacherError, check_teachers, distill_runner_cfg, load_specialists
from cat.learning.runs import make_env, make_runner, resume_config, save_config, train, validate_train_cfg
from cat.run.config import AlgoCfg, DistillCfg, TrainCfg, policy_model
from cat.run.policy import load_policy

KINDS = ["hurdle-crouch", "side-pass"]


def _obs_groups(history: int = 3) -> dict[str, ObsGroupCfg]:
    proprio = [t for t in ACTOR_TERMS if t not in ("goal_command", "field_block")]
    return {
        "actor": ObsGroupCfg(terms=list(ACTOR_TERMS), noise=True),
        "critic": ObsGroupCfg(terms=["base_lin_vel"], extends="actor"),
        "teacher": ObsGroupCfg(terms=list(ACTOR_TERMS)),
        "student_proprio": ObsGroupCfg(terms=proprio, noise=True, history=history),
        "student": ObsGroupCfg(terms=["goal_command", "field_block"], noise=True),
        "route": ObsGroupCfg(terms=["scene_group"]),
    }


def _generalist_cfg(teachers: list[str], student: str = "mlp", num_envs: int = 8) -> TrainCfg:
    task = EnvCfg(
        task="generalist",
        num_envs=num_envs,
        episode_length_s=2.0,
        scene_groups=list(KINDS),
        scene_variants=1,
        observations=_obs_groups(),
    )
    task.curriculum.enabled = False
    distill = DistillCfg(
        student=student,
        hidden_dims=[32, 32],
        rnn_hidden_dim=16,
        gradient_length=8,
        learning_rate=5e-3,
        num_learning_epochs=4,
        student_groups=["student_proprio", "student"],
    )
    algo = AlgoCfg(name="distill", distill=distill, num_steps_per_env=8, save_interval=100)
    return TrainCfg(task=task, algo=algo, teachers=teachers, max_iterations=6, seed=0)


@pytest.fixture(scope="module")
def env():
    return make_env(_generalist_cfg([]))


def _teacher(folder: Path, kind: str, value: float, env, terms: list[str] | None = None) -> str:
    """A specialist checkpoint whose actor outputs ``value`` on every action, whatever it observes."""
    task = EnvCfg(task=kind.replace("-", "_"), scene_kind=kind, num_envs=4, scene_variants=1)
    if terms is not None:
        task.observations = {"actor": ObsGroupCfg(terms=terms, noise=True), "critic": ObsGroupCfg(extends="actor")}
    run = TrainCfg(task=task)
    folder.mkdir(parents=True)
    save_config(run, folder)
    model = replace(policy_model(run.algo), obs_groups=["teacher"])
    obs = env.get_observations()
    if terms is not None:  # another layout: an input width the env's teacher group does not have
        obs = obs.clone()
        obs["teacher"] = obs["teacher"][:, : -7 * 13]
    actor = model.build(obs, env.num_actions)
    last = actor.mlp[-1]
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.constant_(last.bias, value)
    path = folder / "model_0.pt"
    torch.save({"actor_state_dict": actor.state_dict(), "iter": 0, "infos": None}, path)
    return str(path)


@pytest.fixture(scope="module")
def teachers(env, tmp_path_factory):
    root = tmp_path_factory.mktemp("teachers")
    return [_teacher(root / "hc", KINDS[0], 0.5, env), _teacher(root / "sp", KINDS[1], -0.5, env)]


def test_scene_groups_and_route_term(env):
    assert env.scene_group_names == KINDS
    group = env.get_observations()["route"][:, 0]
    scene_kind = [env.scenes.scenes[int(s)].kind for s in env.scenes.scene_of_env]
    assert [KINDS[int(g)] for g in group] == scene_kind
    assert set(group.tolist()) == {0.0, 1.0}


def test_routing_labels_each_env_by_its_groups_teacher(env, teachers):
    obs = env.get_observations()
    teacher = MultiTeacher(obs, {"teacher": ["teacher"]}, "teacher", env.num_actions, teachers, KINDS, "route")
    labels = teacher(obs)
    group = obs["route"][:, 0].long()
    expected = torch.where(group == 0, 0.5, -0.5)[:, None].expand_as(labels)
    assert torch.allclose(labels, expected)
    # teachers given in the other order route the same way (routing follows each teacher's own scene kind)
    swapped = MultiTeacher(obs, {"teacher": ["teacher"]}, "teacher", env.num_actions, teachers[::-1], KINDS, "route")
    assert torch.allclose(swapped(obs), expected)
    assert not any(p.requires_grad for p in teacher.parameters())


def test_history_group_stacks_oldest_first_and_restarts_at_reset(env):
    obs0 = env.get_observations()
    width = obs0["student_proprio"].shape[1] // 3
    first = obs0["student_proprio"].view(env.num_envs, 3, width)
    assert torch.equal(first[:, 0], first[:, 2])  # filled with the current value after reset
    obs1, *_ = env.step(torch.zeros(env.num_envs, env.num_actions))
    hist = obs1["student_proprio"].view(env.num_envs, 3, width)
    assert torch.equal(hist[:, 1], first[:, 2])  # shifted by one step
    assert not torch.equal(hist[:, 2], hist[:, 1])
    env.reset_idx(torch.tensor([0]))
    env._compute_obs()
    again = env.get_observations()["student_proprio"].view(env.num_envs, 3, width)
    assert torch.equal(again[0, 0], again[0, 2])  # env 0 restarted
    assert torch.equal(again[1, 1], hist[1, 2])  # env 1 carried on


def test_bad_teachers_give_one_clear_error(env, teachers, tmp_path):
    cfg = _generalist_cfg(teachers)
    with pytest.raises(TeacherError, match="not found"):
        load_specialists([str(tmp_path / "missing" / "model_9.pt")])
    with pytest.raises(TeacherError, match="scene group 'side-pass' has no teacher"):
        check_teachers(load_specialists(teachers[:1]), cfg, env.scene_group_names)
    other = _teacher(tmp_path / "other", KINDS[1], 0.0, env, terms=[t for t in ACTOR_TERMS if t != "field_block"])
    with pytest.raises(TeacherError, match=f"teacher {other} observed"):
        check_teachers(load_specialists([teachers[0], other]), cfg, env.scene_group_names)
    with pytest.raises(TeacherError, match="both teach scene group 'hurdle-crouch'"):
        load_specialists([teachers[0], teachers[0]])


@pytest.mark.parametrize("student", ["mlp", "lstm"])
def test_small_dagger_run_lowers_the_loss_and_the_student_plays(teachers, tmp_path, student):
    cfg = _generalist_cfg(teachers, student=student)
    cfg.run_dir = str(tmp_path / "run")
    run = train(cfg)
    rows = list(csv.DictReader(open(run / "metrics.csv")))
    loss = [float(r["value"]) for r in rows if r["tag"] == "Loss/behavior"]
    assert len(loss) == cfg.max_iterations
    assert loss[-1] < 0.5 * loss[0], loss
    ckpt = torch.load(run / "model_5.pt", weights_only=False)
    assert "student_state_dict" in ckpt and "teacher_state_dict" not in ckpt  # teachers stay in their own files
    play_env = make_env(cfg, num_envs=2)
    policy = load_policy(run / "model_5.pt", play_env, cfg)
    policy.reset()
    obs = play_env.get_observations()
    for _ in range(3):
        actions = policy(obs)
        assert actions.shape == (2, play_env.num_actions) and torch.isfinite(actions).all()
        obs, *_ = play_env.step(actions)


def test_distillation_resumes_in_its_own_folder(teachers, tmp_path):
    cfg = _generalist_cfg(teachers)
    cfg.max_iterations, cfg.run_dir = 2, str(tmp_path / "run")
    run = train(cfg)
    assert (run / "model_1.pt").is_file() and (run / "env_1.pt").is_file()
    resumed = resume_config(run / "model_1.pt", ["max_iterations=4"])
    assert resumed.algo.name == "distill" and resumed.teachers == teachers
    assert train(resumed) == run
    assert (run / "model_3.pt").is_file()
    its = [int(r["iteration"]) for r in csv.DictReader(open(run / "metrics.csv")) if r["tag"] == "Loss/behavior"]
    assert its == [0, 1, 2, 3]  # the iteration count continues
    history = torch.load(run / "env_3.pt", weights_only=False)["obs_history"]
    assert set(history) == {"student_proprio"}  # the student's observation history travels with the snapshot


@pytest.mark.parametrize("prob", [0.0, 0.5, 1.0])
def test_teacher_driven_episodes_act_with_the_teachers_labels(env, teachers, prob):
    """DAgger's mixing: a teacher-driven env acts with its teacher's label (+-0.5 here), a student-driven one with
    the student's own action; the driver is drawn again for exactly the envs that reset."""
    cfg = _generalist_cfg(teachers)
    cfg.algo.distill.teacher_drive_prob = prob
    alg = make_runner(cfg, env, None).alg
    obs = env.get_observations()
    torch.manual_seed(0)
    actions = alg.act(obs)
    drives = alg.teacher_drives if prob > 0 else torch.zeros(env.num_envs, dtype=torch.bool)
    assert torch.equal(actions[drives], alg.transition.privileged_actions[drives])
    assert torch.equal(actions[~drives], alg.transition.actions[~drives])
    assert not torch.allclose(alg.transition.actions, alg.transition.privileged_actions)  # labels != student
    if prob == 1.0:
        assert drives.all()
    if prob == 0.5:
        before = drives.clone()
        dones = torch.zeros(env.num_envs)
        dones[:3] = 1
        draws = [before]
        for _ in range(20):  # envs that do not reset keep their driver; the reset ones are drawn anew
            alg.act(obs)
            alg.process_env_step(obs, torch.zeros(env.num_envs), dones, {})
            alg.storage.clear()
            assert torch.equal(alg.teacher_drives[3:], before[3:])
            draws.append(alg.teacher_drives[:3].clone())
        assert len({tuple(d.tolist()) for d in draws}) > 1


def test_teacher_drive_prob_out_of_range_is_refused(env, teachers):
    cfg = _generalist_cfg(teachers)
    cfg.algo.distill.teacher_drive_prob = 1.5
    with pytest.raises(ValueError, match="teacher_drive_prob must be in"):
        validate_train_cfg(cfg)  # before any env is built
    with pytest.raises(ValueError, match="teacher_drive_prob must be in"):
        make_runner(cfg, env, None)


def test_init_warm_starts_the_student_and_refuses_a_mismatch(teachers, tmp_path):
    """init= of a distillation: a new run (iteration 0, its own optimiser) whose student starts as the earlier
    student, so a generalist can grow by scene groups; another network, layout or a PPO policy is refused."""
    cfg = _generalist_cfg(teachers)
    cfg.max_iterations, cfg.run_dir = 2, str(tmp_path / "first")
    first = train(cfg) / "model_1.pt"
    grown = _generalist_cfg(teachers)
    grown.max_iterations, grown.run_dir, grown.init = 1, str(tmp_path / "grown"), str(first)
    grown.algo.distill.learning_rate = 0.0  # the saved student is then exactly the loaded one
    run = train(grown)
    its = [int(r["iteration"]) for r in csv.DictReader(open(run / "metrics.csv")) if r["tag"] == "Loss/behavior"]
    assert its == [0]
    before = torch.load(first, weights_only=False)["student_state_dict"]
    after = torch.load(run / "model_0.pt", weights_only=False)["student_state_dict"]
    assert before.keys() == after.keys()
    assert all(torch.equal(before[k], after[k]) for k in before if "normalizer" not in k)
    wider = _generalist_cfg(teachers)
    wider.init, wider.algo.distill.hidden_dims = str(first), [64, 32]
    with pytest.raises(ValueError, match=r"its student has algo.distill.hidden_dims=\[32, 32\], this run \[64, 32\]"):
        validate_train_cfg(wider)
    shorter = _generalist_cfg(teachers)
    shorter.init = str(first)
    shorter.task.observations["student_proprio"].history = 2
    with pytest.raises(ValueError, match="its student read"):
        validate_train_cfg(shorter)
    ppo = _generalist_cfg(teachers)
    ppo.init = teachers[0]
    with pytest.raises(ValueError, match="not a PPO policy"):
        validate_train_cfg(ppo)


def test_labels_are_clipped_as_the_env_clips_actions(env, tmp_path):
    """A specialist's mean may leave the action range; the label is the action the env executes."""
    wide = [_teacher(tmp_path / "hc", KINDS[0], 3.0, env), _teacher(tmp_path / "sp", KINDS[1], -0.5, env)]
    obs = env.get_observations()
    group = obs["route"][:, 0].long()
    raw = MultiTeacher(obs, {"teacher": ["teacher"]}, "teacher", env.num_actions, wide, KINDS, "route")
    clipped = MultiTeacher(obs, {"teacher": ["teacher"]}, "teacher", env.num_actions, wide, KINDS, "route", 1.0)
    assert torch.allclose(raw(obs)[group == 0], torch.tensor(3.0))
    assert torch.allclose(clipped(obs)[group == 0], torch.tensor(1.0))
    assert torch.allclose(clipped(obs)[group == 1], torch.tensor(-0.5))  # inside the range: unchanged
    with pytest.raises(ValueError, match="action_clip must be positive"):
        MultiTeacher(obs, {"teacher": ["teacher"]}, "teacher", env.num_actions, wide, KINDS, "route", 0.0)
    runner_teacher = distill_runner_cfg(_generalist_cfg(wide), KINDS)["teacher"]
    assert runner_teacher["action_clip"] == EnvCfg().action_clip  # the run's labels follow task.action_clip
