"""docs/extending.md's worked example, run as written: its toy observation term (one declaration) and toy reward
term are registered from outside the package, an env (flat, 4 worlds, sim=mujoco) reads them with the declared
noise and mirror map and scores them, the deploy runtime refuses the undeployable term, and an ONNX policy
exported from a run with the term reads one more input (run in onnxruntime)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import torch

from cat.deploy.export import ExportCfg, export
from cat.deploy.metadata import read_metadata
from cat.deploy.policy import TorchPolicy
from cat.envs.mdp.registry import OBS_TERMS, REWARD_TERMS, register_observation, register_reward
from cat.envs.obs_groups import group_layout
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import make_env, save_config
from cat.run.config import policy_model

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "extending.md"


def _example() -> dict:
    """The python blocks of the doc's "Worked example" section, executed in order (a doc that drifts fails)."""
    text = DOC.read_text()
    section = text.split("## Worked example", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert len(blocks) >= 2, "the worked example lost its code"
    ns: dict = {"__name__": "extending_example"}
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), ns)  # noqa: S102  (our own doc, the point of the test)
    return ns


@pytest.fixture(scope="module")
def example():
    ns = _example()
    yield ns
    OBS_TERMS.pop("time_left", None)  # registration is process-wide: leave other tests the package's terms
    REWARD_TERMS.pop("pelvis_height", None)


def test_the_example_registers_its_terms(example):
    assert OBS_TERMS["time_left"].fn is example["time_left"]
    assert REWARD_TERMS["pelvis_height"].fn is example["pelvis_height"]
    # registering the same term again is harmless; another function under the name is refused
    register_observation("time_left", example["time_left"], size=1, mirror=([0], [1.0]))
    with pytest.raises(ValueError, match="already registered"):
        register_observation("time_left", lambda env: env.state.gyro[:, :1], size=1)
    with pytest.raises(ValueError, match="built in"):
        register_observation("gyro", example["time_left"], size=1)
    with pytest.raises(ValueError, match="built in"):
        register_reward("alive", example["pelvis_height"])


def test_env_reads_and_scores_the_new_terms(example):
    base = make_env(load_config(["task=flat", "sim=mujoco", "num_envs=4"]))
    cfg = load_config(example["OVERRIDES"])
    example["turn_on"](cfg)
    env = make_env(cfg)
    obs = env.get_observations()
    assert obs["actor"].shape[-1] == base.get_observations()["actor"].shape[-1] + 1
    assert "pelvis_height" in env.reward_names and "pelvis_height" not in base.reward_names
    assert "time_left" in group_layout(cfg.task, "actor")[0]
    col = env.observation_groups.term_columns(env, "actor").index("time_left")
    first = obs["critic"][:, col].clone()  # the critic extends the actor: same column, read without noise
    for _ in range(5):
        obs, _, _, _ = env.step(torch.zeros(env.num_envs, env.num_actions))
    assert torch.all(obs["critic"][:, col] < first)  # the episode's time runs out
    noise = obs["actor"][:, col] - obs["critic"][:, col]  # the declared noise at task.noise.extra's scale
    assert torch.all(noise != 0) and torch.all(noise.abs() <= 0.001)
    assert torch.all(env.episode_sums["pelvis_height"] < 0)  # the weight is negative, the error positive
    assert env.reward_terms["pelvis_height"] == (-2.0, {"target": 0.74})  # weight and constant from the config
    perm, sign = env.mirror_map.obs["actor"]  # symmetry reads the declared mirror map
    assert len(perm) == obs["actor"].shape[-1] and perm[col] == col and sign[col] == 1.0
    with pytest.raises(ValueError, match="unknown reward term 'nope'"):
        bad = load_config(["task=flat", "sim=mujoco", "num_envs=4", "+task.rewards.extra.nope=1.0"])
        make_env(bad)
    with pytest.raises(ValueError, match="not an observation term declared with noise"):
        make_env(load_config(["task=flat", "sim=mujoco", "num_envs=4", "+task.noise.extra.last_action=0.1"]))


def test_the_deploy_runtime_refuses_the_undeployable_term(example):
    from cat.deploy.policy import PolicySpec
    from cat.deploy.runtime import DeployCfg, Runtime
    from cat.deploy.scenes import load_scene

    cfg = load_config(example["OVERRIDES"])
    example["turn_on"](cfg)
    with pytest.raises(ValueError, match=r"\['time_left'\], which this deployed robot does not compute"):
        Runtime(load_scene("flat"), PolicySpec("hold", cfg.task, obs_groups=["actor"]), DeployCfg(realtime=False))


def test_onnx_policy_reads_the_new_term(example, tmp_path):
    import onnxruntime

    cfg = load_config(example["OVERRIDES"])
    example["turn_on"](cfg)
    env = make_env(cfg)
    obs = env.get_observations()
    save_config(cfg, tmp_path)
    pm = policy_model(cfg.algo)
    torch.manual_seed(0)
    model = pm.build(obs, env.num_actions)  # an untrained actor: the layout is what is tested
    torch.save({pm.state_key: model.state_dict(), "iter": 0}, tmp_path / "model_0.pt")
    out = export(ExportCfg(checkpoint=str(tmp_path), out=str(tmp_path / "policy.onnx"))).path

    meta = read_metadata(out)
    terms = [t["name"] for t in meta.observation["actor"]["terms"]]
    last = meta.observation["actor"]["terms"][-1]
    assert terms[-1] == "time_left" and (last["size"], last["note"]) == (1, "fraction of the episode left")
    assert meta.obs_dim == obs["actor"].shape[-1]
    session = onnxruntime.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    x = obs["actor"].numpy().astype(np.float32)
    (actions,) = session.run(["actions"], {"obs": x})
    with torch.inference_mode():
        ref = TorchPolicy(model, meta.obs_groups)(obs).numpy()
    np.testing.assert_allclose(actions, ref, atol=1e-5)
    x2 = x.copy()
    x2[:, -1] += 1.0  # the new input moves the actions: the network reads it
    (moved,) = session.run(["actions"], {"obs": x2})
    assert np.abs(moved - actions).max() > 1e-4
