"""``init=`` across observation layouts (cat/learning/layout_init.py): a baseline whose observation differs from
the walking prior's starts from the prior's weights where the layouts agree and acts exactly as the prior does."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from cat.checkpoint_io import CheckpointError, read_checkpoint
from cat.learning.hydra_cfg import load_config
from cat.learning.layout_init import Block, blocks, init_from_prior, partial_state, prior_blocks, term_layout
from cat.learning.runs import make_env, make_runner, train

PRIOR = Path(__file__).resolve().parents[1] / "checkpoints" / "flat" / "model_770.pt"
SHARED = ["gyro", "projected_gravity", "joint_pos", "joint_vel", "last_action", "leg_targets", "goal_command",
          "gait_phase"]  # fmt: skip


def _initialised(tmp_path, overrides: list[str]):
    cfg = load_config([*overrides, "num_envs=4", f"run_root={tmp_path}"])
    env = make_env(cfg)
    runner = make_runner(cfg, env, str(tmp_path))
    reports = init_from_prior(runner.alg, env, str(PRIOR))
    return env, runner.alg, reports


def _as_prior_input(x: torch.Tensor, model, new: list[Block], old: list[Block]) -> torch.Tensor:
    """The prior's input for this run's observation ``x``: shared terms moved to the prior's columns, the terms
    this run does not read at the prior's normaliser mean."""
    out = model.obs_normalizer._mean[0].expand(x.shape[0], -1).clone()
    at = {b.term: b for b in new}
    for b in old:
        if b.term in at:
            out[:, list(b.cols)] = x[:, list(at[b.term].cols)]
    return out


@pytest.mark.parametrize(
    ("overrides", "new_terms"),
    [
        (["task=flat", "method=wo_obs_field"], ["elevation_map"]),
        (["task=hurdle_pass", "task.scene_variants=1", "method=astraversal"], ["elevation_map"]),
        (["task=hurdle_pass", "task.scene_variants=1", "method=humanoid_parkour"], ["ground_map", "overhead_map"]),
    ],
)
def test_a_baseline_from_the_flat_prior_acts_as_the_prior(tmp_path, overrides, new_terms):
    torch.manual_seed(0)
    env, alg, reports = _initialised(tmp_path, overrides)
    actor, critic = alg.actor, alg.critic
    assert [b.term for b in reports["actor"].new] == new_terms
    assert [b.term for b in reports["actor"].shared] == SHARED
    assert [b.term for b in reports["actor"].dropped] == ["field_block"]
    assert "mlp.2.weight" in reports["actor"].copied and "distribution.std_param" in reports["actor"].copied
    _, prior, _ = _initialised(tmp_path / "prior", ["task=flat"])  # the prior in its own layout (strict)
    prior_actor, prior_critic = prior.actor.eval(), prior.critic.eval()
    cols = {n: blocks(sum((env.observation_groups.term_columns(env, g) for g in m.obs_groups), []))
            for n, m in (("actor", actor), ("critic", critic))}  # fmt: skip
    old = {
        "actor": prior_blocks([*SHARED, "field_block"], 184, {b.term: b.width for b in cols["actor"]}, "actor"),
        "critic": prior_blocks(
            [*SHARED, "field_block", "base_lin_vel", "base_height", "link_positions", "foot_contacts", "dr_scales"],
            232, {b.term: b.width for b in cols["critic"]}, "critic",
        ),
    }  # fmt: skip
    new_cols = [c for b in cols["actor"] if b.term in new_terms for c in b.cols]
    assert (actor.mlp[0].weight[:, new_cols] == 0).all()
    obs = env.get_observations()
    with torch.inference_mode():
        for _ in range(5):  # real observations along a rollout of the initialised policy
            a = actor(obs)
            x = obs["actor"]
            a_prior = prior_actor(
                TensorDict({"actor": _as_prior_input(x, prior_actor, cols["actor"], old["actor"])}, [x.shape[0]])
            )
            torch.testing.assert_close(a, a_prior, atol=1e-5, rtol=0)
            xc = obs["critic"]
            v_prior = prior_critic(
                TensorDict({"critic": _as_prior_input(xc, prior_critic, cols["critic"], old["critic"])}, [xc.shape[0]])
            )
            torch.testing.assert_close(critic(obs), v_prior, atol=1e-4, rtol=0)
            scrambled = obs.clone()  # whatever the new terms read, the actions do not move
            scrambled["actor"][:, new_cols] = torch.randn(x.shape[0], len(new_cols)) * 3.0
            torch.testing.assert_close(actor(scrambled), a, atol=1e-6, rtol=0)
            obs, _, _, _ = env.step(a)  # fmt: skip


def test_the_same_layout_loads_strictly(tmp_path):
    env, alg, reports = _initialised(tmp_path, ["task=flat"])
    assert reports == {}
    prior = read_checkpoint(PRIOR)["actor_state_dict"]
    for key, value in alg.actor.state_dict().items():
        torch.testing.assert_close(value, prior[key])


def test_train_from_the_prior_with_another_layout(tmp_path, caplog):
    cfg = load_config(["task=flat", "method=wo_obs_field", f"init={PRIOR}", "num_envs=4", "max_iterations=1",
                       "algo.num_steps_per_env=4", f"run_root={tmp_path}"])  # fmt: skip
    with caplog.at_level("INFO", logger="cat.learning.layout_init"):
        run = train(cfg)
    assert (run / "model_0.pt").is_file()
    assert any("new columns zeroed: elevation_map[442]" in r.message for r in caplog.records)


def _state(hidden: int = 8, width: int = 5) -> dict[str, torch.Tensor]:
    return {
        "obs_normalizer._mean": torch.arange(width, dtype=torch.float32)[None],
        "obs_normalizer._var": torch.ones(1, width),
        "obs_normalizer._std": torch.ones(1, width),
        "obs_normalizer.count": torch.tensor(7),
        "mlp.0.weight": torch.arange(hidden * width, dtype=torch.float32).reshape(hidden, width),
        "mlp.0.bias": torch.ones(hidden),
        "mlp.2.weight": torch.ones(2, hidden),
    }


def test_partial_state_columns_by_term():
    prior = _state(width=5)  # a[2] b[3]
    fresh = {k: torch.zeros_like(v) for k, v in _state(width=6).items()}  # b[3] c[3]
    out, report = partial_state(prior, fresh, [Block("a", 0, 2), Block("b", 2, 3)],
                                [Block("b", 0, 3), Block("c", 3, 3)], "t")  # fmt: skip
    torch.testing.assert_close(out["mlp.0.weight"][:, :3], prior["mlp.0.weight"][:, 2:5])
    assert (out["mlp.0.weight"][:, 3:] == 0).all()
    assert out["obs_normalizer._mean"][0].tolist() == [2.0, 3.0, 4.0, 0.0, 0.0, 0.0]
    assert int(out["obs_normalizer.count"]) == 7
    assert [b.term for b in report.shared] == ["b"] and [b.term for b in report.new] == ["c"]
    assert [b.term for b in report.dropped] == ["a"]


def test_bad_combinations_are_one_clear_error():
    fresh = {k: torch.zeros_like(v) for k, v in _state(hidden=16, width=5).items()}
    with pytest.raises(CheckpointError, match="units in the prior"):
        partial_state(_state(), fresh, [Block("a", 0, 5)], [Block("a", 0, 5)], "t")
    with pytest.raises(CheckpointError, match="share no observation term"):
        partial_state(_state(), {k: torch.zeros_like(v) for k, v in _state().items()}, [Block("a", 0, 5)],
                      [Block("z", 0, 5)], "t")  # fmt: skip
    with pytest.raises(CheckpointError, match="term a is 5 wide in the prior and 4 here"):
        partial_state(_state(), {k: torch.zeros_like(v) for k, v in _state(width=4).items()}, [Block("a", 0, 5)],
                      [Block("a", 0, 4)], "t")  # fmt: skip
    with pytest.raises(CheckpointError, match=r"cannot size the prior's terms \['x', 'y'\]"):
        prior_blocks(["a", "x", "y"], 10, {"a": 3}, "t")
    with pytest.raises(CheckpointError, match="do not fit"):
        prior_blocks(["a", "b"], 10, {"a": 3, "b": 3}, "t")
    assert [(b.term, b.start, b.width) for b in prior_blocks(["a", "x", "b"], 10, {"a": 3, "b": 2}, "t")] == [
        ("a", 0, 3), ("x", 3, 5), ("b", 8, 2),
    ]  # fmt: skip


def test_a_map_term_of_another_grid_is_another_layout():
    a = load_config(["task=flat", "method=wo_obs_field"]).task
    b = load_config(["task=flat", "method=wo_obs_field", "task.perception.height_map.resolution=0.2"]).task
    assert term_layout(a, "elevation_map") != term_layout(b, "elevation_map")
    assert term_layout(a, "gyro") == term_layout(b, "gyro")


def test_a_history_model_is_refused_across_layouts(tmp_path):
    cfg = load_config(["task=flat", "method=wo_obs_field", "task.observations.actor.history=2", "num_envs=2",
                       f"run_root={tmp_path}"])  # fmt: skip
    env = make_env(cfg)
    runner = make_runner(cfg, env, str(tmp_path))
    with pytest.raises(CheckpointError, match="history=2"):
        init_from_prior(runner.alg, env, str(PRIOR))


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["task=flat", "algo.actor_hidden_dims=[128,64,32]"], r"does not fit this run's networks"),
        (["task=flat", "method=wo_obs_field", "algo.actor_hidden_dims=[128,64,32]"],
         r"\(actor\): mlp.0.weight has 256 units in the prior, 128 here"),
    ],
)  # fmt: skip
def test_networks_of_other_sizes_are_one_clear_error(tmp_path, overrides, message):
    cfg = load_config([*overrides, "num_envs=2", f"run_root={tmp_path}"])
    env = make_env(cfg)
    runner = make_runner(cfg, env, str(tmp_path))
    with pytest.raises(CheckpointError, match=message):
        init_from_prior(runner.alg, env, str(PRIOR))
