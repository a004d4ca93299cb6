"""Named observation groups: the default actor / critic layout is pinned (trained checkpoints keep loading), old
run configs load to the same groups and their checkpoints play, any number of groups with their own noise, the
runner's observation sets follow the groups, and bad names are one clear error."""

from __future__ import annotations

import pytest
import torch
import yaml

from cat.envs.config import EnvCfg, NoiseCfg, ObsGroupCfg
from cat.envs.obs_groups import resolve_groups, upgrade_legacy_observations
from cat.envs.traversal_env import TraversalEnv
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import load_run_config, make_env, train, validate_train_cfg
from cat.run.config import AlgoCfg, runner_cfg
from cat.run.policy import load_policy

ACTOR = [
    ("gyro", 3, 0.2),
    ("projected_gravity", 3, 0.05),
    ("joint_pos", 29, 0.01),
    ("joint_vel", 29, 1.5),
    ("last_action", 12, 0.0),
    ("leg_targets", 12, 0.0),
    ("goal_command", 3, 0.0),
    ("gait_phase", 2, 0.0),
    ("field_block", 91, 0.05),
]
PRIVILEGED = [("base_lin_vel", 3), ("base_height", 1), ("link_positions", 39), ("foot_contacts", 2), ("dr_scales", 3)]


def test_default_layout_is_pinned():
    """The layout every checkpoint so far was trained on: same terms, order, widths (184 / 232) and noise."""
    cfg = EnvCfg(num_envs=3)
    groups = resolve_groups(cfg.observations)
    assert list(groups) == ["actor", "critic"]
    assert groups["actor"] == [t for t, _, _ in ACTOR]
    assert groups["critic"] == [t for t, _, _ in ACTOR] + [t for t, _ in PRIVILEGED]
    for term, _, scale in ACTOR:
        assert getattr(cfg.noise, term, 0.0) == scale, term
    env = TraversalEnv(cfg, sim="mujoco", seed=0)
    obs = env.get_observations()
    assert obs["actor"].shape == (3, 184) and obs["critic"].shape == (3, 232)
    # the critic holds the actor terms without noise: the difference per term is within its noise scale, and zero
    # for terms without noise
    diff = (obs["actor"] - obs["critic"][:, :184]).abs()
    col = 0
    for term, width, scale in ACTOR:
        d = diff[:, col : col + width]
        assert d.max() <= scale + 1e-6, term
        assert (d.max() > 0) == (scale > 0), term
        col += width


def _legacy(raw: dict) -> dict:
    """A run config in the format written before named groups (observations.actor / .privileged lists)."""
    raw = yaml.safe_load(yaml.safe_dump(raw))
    raw["task"]["observations"] = {
        "actor": [t for t, _, _ in ACTOR],
        "privileged": [t for t, _ in PRIVILEGED],
    }
    return raw


def test_old_run_config_loads_and_its_checkpoint_plays(tmp_path):
    """A checkpoint whose config.yaml has the old observation format builds the same env and loads strictly."""
    cfg = load_config(
        ["task=flat", "num_envs=4", "max_iterations=1", f"run_root={tmp_path}", "algo.num_steps_per_env=4"]
    )
    run = train(cfg)
    ckpt = sorted(run.glob("model_*.pt"))[-1]
    raw = yaml.safe_load((run / "config.yaml").read_text())
    (run / "config.yaml").write_text(yaml.safe_dump(_legacy(raw)))
    old = load_run_config(ckpt)
    assert resolve_groups(old.task.observations) == resolve_groups(EnvCfg().observations)
    assert {k: v.noise for k, v in old.task.observations.items()} == {"actor": True, "critic": False}
    env = make_env(old, num_envs=2)
    policy = load_policy(ckpt, env, old)
    actions = policy(env.get_observations())
    assert actions.shape == (2, 12) and torch.isfinite(actions).all()


def test_legacy_upgrade_keeps_edited_lists_and_rejects_unknown_keys():
    task = {"observations": {"actor": ["gyro", "gait_phase"], "privileged": ["base_height"]}}
    up = upgrade_legacy_observations(task)
    groups = {k: ObsGroupCfg(**v) for k, v in up["observations"].items()}
    assert resolve_groups(groups) == {"actor": ["gyro", "gait_phase"], "critic": ["gyro", "gait_phase", "base_height"]}
    assert task["observations"]["actor"] == ["gyro", "gait_phase"]  # input untouched
    assert upgrade_legacy_observations(up) == up  # new format passes through
    with pytest.raises(ValueError, match="unknown key 'teacher'; valid: actor, privileged"):
        upgrade_legacy_observations({"observations": {"actor": ["gyro"], "teacher": ["gyro"]}})


def test_any_number_of_groups_each_with_its_own_noise_switch():
    cfg = EnvCfg(num_envs=2)
    cfg.observations["teacher"] = ObsGroupCfg(terms=["elevation_map"], extends="critic")
    cfg.observations["student"] = ObsGroupCfg(terms=["gyro", "joint_vel", "goal_command"], noise=True)
    env = TraversalEnv(cfg, sim="mujoco", seed=0)
    obs = env.get_observations()
    assert list(obs.keys()) == ["actor", "critic", "teacher", "student"]
    assert env.obs_groups["teacher"] == env.obs_groups["critic"] + ["elevation_map"]
    assert obs["teacher"].shape == (2, 232 + 2 * 17 * 13)
    torch.testing.assert_close(obs["teacher"][:, :232], obs["critic"])  # both clean
    clean_gyro = obs["critic"][:, :3]
    assert 0 < (obs["student"][:, :3] - clean_gyro).abs().max() <= cfg.noise.gyro
    # one reading per term and step: every noisy group sees the same noisy gyro and joint_vel (a teacher with
    # noise on labels from what the student observes), while the clean groups see the clean value
    torch.testing.assert_close(obs["student"][:, :3], obs["actor"][:, :3], rtol=0, atol=0)
    torch.testing.assert_close(obs["student"][:, 3:32], obs["actor"][:, 35:64], rtol=0, atol=0)
    assert not torch.equal(obs["student"][:, 3:32], obs["critic"][:, 35:64])
    m = env.mirror_map
    for group in obs.keys():
        torch.testing.assert_close(m.mirror_obs(m.mirror_obs(obs))[group], obs[group])
    # noise off everywhere with the master switch
    cfg.noise = NoiseCfg(enabled=False)
    obs = TraversalEnv(cfg, sim="mujoco", seed=0).get_observations()
    torch.testing.assert_close(obs["student"][:, :3], obs["critic"][:, :3])


def test_runner_observation_sets_follow_the_groups():
    algo = AlgoCfg()
    assert runner_cfg(algo, ["actor", "critic"])["obs_groups"] == {"actor": ["actor"], "critic": ["critic"]}
    algo.obs_groups = {"actor": ["actor"], "critic": ["critic", "teacher"]}
    assert runner_cfg(algo, ["actor", "critic", "teacher"])["obs_groups"]["critic"] == ["critic", "teacher"]
    with pytest.raises(
        ValueError, match="names observation group 'teacher' that the env does not build; .*actor, critic"
    ):
        runner_cfg(algo, ["actor", "critic"])
    algo.obs_groups = {"actor": ["actor"], "student": ["actor"]}
    with pytest.raises(ValueError, match="unknown set 'student'; valid: actor, critic"):
        runner_cfg(algo, ["actor", "critic"])
    cfg = load_config(["algo.obs_groups.critic=[critc]"])
    with pytest.raises(ValueError, match="observation group 'critc'"):
        validate_train_cfg(cfg)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda o: o["actor"].terms.append("heightmap"),
            "unknown observation term 'heightmap'; valid: .*elevation_map",
        ),
        (lambda o: o.update(teacher=ObsGroupCfg(terms=["gyro"], extends="critc")), "extends unknown group 'critc'"),
        (lambda o: setattr(o["actor"], "extends", "critic"), "cycle: actor -> critic -> actor"),
        (lambda o: o.update(student=ObsGroupCfg()), "observation group 'student' has no terms"),
        (lambda o: o["critic"].terms.append("gyro"), "lists term 'gyro' more than once"),
        (lambda o: o.clear(), "defines no observation group"),
    ],
)
def test_bad_groups_are_one_clear_error(edit, message):
    cfg = EnvCfg(num_envs=1)
    edit(cfg.observations)
    with pytest.raises(ValueError, match=message):
        TraversalEnv(cfg)


def test_bad_command_source_and_heading_gate():
    cfg = EnvCfg(num_envs=1)
    cfg.command.source = "geodesic"
    with pytest.raises(ValueError, match="unknown command source 'geodesic'; valid: field, straight"):
        TraversalEnv(cfg)
    cfg = EnvCfg(num_envs=1)
    cfg.rewards.params.heading_gate = "sdf"
    with pytest.raises(ValueError, match="unknown heading gate 'sdf'; valid: field, none"):
        TraversalEnv(cfg)
