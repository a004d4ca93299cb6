"""ONNX export (scripts/export.py) and the deploy policy loader: onnxruntime = torch within 1e-5 on 1,000
observations of a real rollout (the shipped MLP actor; an LSTM student with its state carried over all 1,000
steps; an MLP student reading a 5-step history group), the metadata round trip, the shipped checkpoint's ONNX
driving the click demo's runtime, history stacked by the runtime as by the env, and bad input as one clear
error. (The runtime's actor observation = the env's for the same MuJoCo state is
tests/test_deploy.py::test_observation_matches_env_actor_group.)"""

from __future__ import annotations

import importlib.util
import logging
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from cat.deploy.export import ExportCfg, export, soft_limits
from cat.deploy.metadata import LAYOUT_KEYS, PolicyFileError, PolicyMetadata, layout_metadata, read_metadata
from cat.deploy.policy import load_policy, policy_spec
from cat.envs.config import ACTOR_TERMS, EnvCfg, ObsGroupCfg, default_obs_groups
from cat.fields import FieldCfg
from cat.learning.runs import load_run_config, save_config
from cat.run.config import AlgoCfg, DistillCfg, TrainCfg, policy_model

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "checkpoints" / "flat" / "model_501.pt"
STEPS = 1000
TOL = 1e-5


PROPRIO = ["gyro", "projected_gravity", "joint_pos", "joint_vel", "last_action", "leg_targets", "gait_phase"]
HISTORY = 5


def _task() -> EnvCfg:
    """The default task plus distillation-style student groups: ``student`` (the actor's terms, noise-free) and,
    as task=generalist has them, ``student_proprio`` (proprioception, 5-step history) + ``student_field``."""
    groups = {
        **default_obs_groups(),
        "student": ObsGroupCfg(terms=list(ACTOR_TERMS)),
        "student_proprio": ObsGroupCfg(terms=PROPRIO, noise=True, history=HISTORY),
        "student_field": ObsGroupCfg(terms=["goal_command", "field_block"], noise=True),
    }
    return EnvCfg(num_envs=1, observations=groups)


def _student_run(folder: Path, rollout_obs: TensorDict, distill: DistillCfg) -> tuple[Path, Path]:
    """A distillation-style run folder: config.yaml (algo.name=distill) and model_0.pt holding an untrained student
    whose normaliser has the rollout's statistics (so the baked normaliser matters) and whose actions reach ~1
    (a trained policy's range; untrained: ~0.1). Returns (folder, its exported ONNX file)."""
    cfg = TrainCfg(task=_task(), algo=AlgoCfg(name="distill", distill=distill))
    save_config(cfg, folder)
    torch.manual_seed(0)
    pm = policy_model(cfg.algo)
    model = pm.build(rollout_obs[:1], 12)
    x = torch.cat([rollout_obs[g] for g in pm.obs_groups], dim=-1)
    with torch.no_grad():
        model.obs_normalizer._mean.copy_(x.mean(0, keepdim=True))
        model.obs_normalizer._std.copy_(x.std(0, keepdim=True))
        model.mlp[-1].weight.mul_(10.0)
    torch.save({"student_state_dict": model.state_dict(), "iter": 0}, folder / "model_0.pt")
    return folder, export(ExportCfg(checkpoint=str(folder), out=str(folder / "student.onnx"))).path


@pytest.fixture(scope="module")
def rollout():
    """(env, 1,000 observations): one G1 on flat ground driven by the shipped policy, noise and resets as trained."""
    from cat.envs.traversal_env import TraversalEnv

    torch.manual_seed(0)  # the observation noise draws from torch's global generator
    env = TraversalEnv(_task(), seed=0)
    actor = load_policy(policy_spec(str(SHIPPED)), env.get_observations(), env.num_actions)
    obs = [env.get_observations().clone()]
    for _ in range(STEPS - 1):
        obs.append(env.step(actor(obs[-1]))[0].clone())
    return env, torch.cat(obs)


@pytest.fixture(scope="module")
def shipped_onnx(tmp_path_factory):
    out = tmp_path_factory.mktemp("onnx") / "flat.onnx"
    return export(ExportCfg(checkpoint=str(SHIPPED), out=str(out))).path


@pytest.fixture(scope="module")
def lstm_run(tmp_path_factory, rollout):
    """An LSTM student reading the ``student`` group."""
    return _student_run(tmp_path_factory.mktemp("lstm_run"), rollout[1], DistillCfg(student="lstm"))


@pytest.fixture(scope="module")
def history_run(tmp_path_factory, rollout):
    """An MLP student reading ``student_proprio`` (5-step history) + ``student_field``, as task=generalist's."""
    groups = ["student_proprio", "student_field"]
    return _student_run(tmp_path_factory.mktemp("history_run"), rollout[1], DistillCfg(student_groups=groups))


def test_mlp_parity_on_rollout(rollout, shipped_onnx):
    """The shipped actor: onnxruntime vs torch on the 1,000 recorded observations (one batch)."""
    _, obs = rollout
    ort = load_policy(policy_spec(str(shipped_onnx)), obs[:1], 12)
    ref = load_policy(policy_spec(str(SHIPPED)), obs[:1], 12)
    diff = float((ort(obs) - ref(obs)).abs().max())
    print(f"MLP parity: max|d action|={diff:.2e} over {len(obs)} observations")
    assert diff <= TOL
    assert float(ref(obs).abs().max()) > 0.1  # a trained policy acting, not a zero net


def test_lstm_parity_state_carried(rollout, lstm_run):
    """An LSTM student step by step over the 1,000 observations, its state carried (torch's inside the model,
    onnxruntime's through h_in/c_in -> h_out/c_out); reset() starts both from zeros again."""
    folder, onnx = lstm_run
    _, obs = rollout
    ort = load_policy(policy_spec(str(onnx)), obs[:1], 12)
    ref = load_policy(policy_spec(str(folder)), obs[:1], 12)
    assert ort.obs_groups == ref.obs_groups == ["student"]
    diffs, first, amax = [], None, 0.0
    for t in range(STEPS):
        a, b = ort(obs[t : t + 1]), ref(obs[t : t + 1])
        diffs.append(float((a - b).abs().max()))
        amax = max(amax, float(b.abs().max()))
        first = a if first is None else first
    print(f"LSTM parity: max|d action|={max(diffs):.2e} over {STEPS} steps, state carried; |a| <= {amax:.2f}")
    assert max(diffs) <= TOL
    assert float(first.abs().max()) > 0.3
    assert float(np.abs(ort.state["h"]).max()) > 0.01  # the state really is carried
    again = ort(obs[:1])
    assert not torch.allclose(again, first, atol=1e-4)  # with 1,000 steps of state the same input acts differently
    ort.reset()
    ref.reset()
    assert torch.allclose(ort(obs[:1]), first, atol=TOL) and torch.allclose(ref(obs[:1]), first, atol=TOL)


def test_metadata_round_trip(shipped_onnx, lstm_run, robot_cfg):
    meta = read_metadata(shipped_onnx)
    assert PolicyMetadata.from_props(meta.to_props(), "x") == meta
    run = load_run_config(SHIPPED)
    want = layout_metadata(robot_cfg, FieldCfg(), run.task, ["actor"], soft_limits(robot_cfg))
    for key in (*LAYOUT_KEYS, "observation", "gait", "torque_limit", "physics_dt"):
        assert getattr(meta, key) == getattr(want, key), key
    assert meta.joint_names == robot_cfg.joint_names and meta.kp == robot_cfg.kp.tolist()
    assert meta.default_joint_pos == robot_cfg.default_joint_pos.tolist()
    assert meta.action["scale"] == 0.5 and meta.control_dt == pytest.approx(0.02)
    assert [t.name for t in meta.terms("actor")] == list(ACTOR_TERMS)
    assert sum(t.size for t in meta.terms("actor")) == meta.obs_dim == 184
    assert meta.terms("actor")[-1].clip == run.task.field_obs.sdf_clip
    assert meta.field_constants == FieldCfg().to_dict() and meta.field_obs["free_space_sdf"] == 1.0
    assert (meta.policy_kind, meta.inputs, meta.outputs, meta.recurrent_state) == ("mlp", ["obs"], ["actions"], {})
    assert re.fullmatch(r"[0-9a-f]{7,40}|unknown", meta.producer["git"]["commit"])
    assert meta.producer["iteration"] == 501 and meta.task["algo"] == "ppo"
    assert meta.robot_model["name"] == "unitree_g1" and meta.robot_model["package_version"]
    lstm = read_metadata(lstm_run[1])
    assert (lstm.policy_kind, lstm.obs_set, lstm.obs_groups) == ("lstm", "student", ["student"])
    assert lstm.inputs == ["obs", "h_in", "c_in"] and lstm.outputs == ["actions", "h_out", "c_out"]
    assert lstm.recurrent_state == {"h": [1, 1, 256], "c": [1, 1, 256]}


def test_term_sizes_equal_the_env(rollout, robot_cfg):
    """The exporter sizes terms from the config; every term of every env group has that size in the env."""
    from cat.deploy.metadata import term_info
    from cat.envs.mdp import observations as obs_terms

    env, _ = rollout
    for terms in env.obs_groups.values():
        for name in terms:
            assert term_info(name, env.cfg, robot_cfg).size == getattr(obs_terms, name)(env).shape[-1], name


def test_shipped_onnx_drives_the_runtime(shipped_onnx):
    """The click demo's runtime on the ONNX file: on each of its observations while walking to a goal 2 m away,
    the torch checkpoint gives the same actions within 1e-5; both specs build the same observation."""
    import threading

    from cat.deploy.runtime import DeployCfg, Runtime
    from cat.deploy.scenes import load_scene

    onnx_spec, torch_spec = policy_spec(str(shipped_onnx)), policy_spec(str(SHIPPED))
    assert onnx_spec.obs_groups == torch_spec.obs_groups == ["actor"]
    for key in ("action_clip", "gait_freq", "field_obs", "scene_kind", "scene_dir"):
        a, b = getattr(onnx_spec.task, key), getattr(torch_spec.task, key)
        assert (list(a) == list(b)) if key == "gait_freq" else a == b, key
    rt = Runtime(load_scene("flat"), onnx_spec, DeployCfg(realtime=False))
    ref = load_policy(torch_spec, rt.observation(), 12)
    ort, diffs = rt.policy, []

    class Both:
        def __call__(self, obs):
            a = ort(obs)
            diffs.append(float((a - ref(obs)).abs().max()))
            return a

        def reset(self):
            ort.reset()
            ref.reset()

    rt.policy = Both()
    rt.set_goal((2.0, 0.0))
    rt.run(threading.Event(), lambda r: r.step_count >= 100)
    print(f"runtime parity: max|d action|={max(diffs):.2e} over {len(diffs)} control steps")
    assert len(diffs) > 50 and max(diffs) <= TOL
    assert rt.outcome.distance < 1.9  # it walked


def test_runtime_builds_the_groups_the_policy_reads(lstm_run):
    from cat.deploy.runtime import DeployCfg, Runtime
    from cat.deploy.scenes import load_scene

    rt = Runtime(load_scene("flat"), policy_spec(str(lstm_run[1])), DeployCfg(realtime=False))
    obs = rt.observation()
    assert list(obs.keys()) == ["student"] and obs["student"].shape == (1, 184)
    assert rt.layout.obs_groups == ["student"]


# --- bad input -------------------------------------------------------------------------------------------------
def _export_script():
    spec = importlib.util.spec_from_file_location("export_script", REPO / "scripts" / "export.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def _one_error(caplog, code: int, needle: str) -> None:
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert code == 2 and len(errors) == 1 and needle in errors[0] and "\n" not in errors[0], errors


@pytest.mark.parametrize(
    "args, needle",
    [
        (["checkpoint=/no/such/model_1.pt", "out={d}/a.onnx"], "checkpoint not found"),
        (["checkpoint={ckpt}", "out={d}/no/such/folder/a.onnx"], "does not exist"),
        (["checkpoint={ckpt}", "out={d}/a.pt"], "must end in .onnx"),
        (["checkpoint={ckpt}", "out={d}/old.onnx"], "exists (force=true replaces it)"),
        (["checkpoint={ckpt}"], "missing out="),
    ],
)
def test_export_refuses_in_one_line(tmp_path, caplog, args, needle):
    (tmp_path / "old.onnx").write_bytes(b"keep me")
    mod = _export_script()
    with caplog.at_level(logging.ERROR):
        code = mod.main([a.format(d=tmp_path, ckpt=SHIPPED) for a in args])
    _one_error(caplog, code, needle)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.onnx"]
    assert (tmp_path / "old.onnx").read_bytes() == b"keep me"


def test_export_force_replaces_and_failure_leaves_nothing(tmp_path, monkeypatch, capsys):
    out = tmp_path / "p.onnx"
    out.write_bytes(b"old")
    mod = _export_script()
    assert mod.main([f"checkpoint={SHIPPED.parent}", f"out={out}", "force=true"]) == 0
    assert "onnxruntime vs torch" in capsys.readouterr().out and read_metadata(out).obs_dim == 184
    before = out.read_bytes()
    import cat.deploy.export as exp

    monkeypatch.setattr(exp, "parity", lambda *a: 1.0)  # the export's own check fails after the temp file is written
    with pytest.raises(PolicyFileError, match="differs from torch"):
        export(ExportCfg(checkpoint=str(SHIPPED), out=str(out), force=True))
    assert [p.name for p in tmp_path.iterdir()] == ["p.onnx"] and out.read_bytes() == before


def _foreign_onnx(path: Path) -> Path:
    """A valid ONNX file that is not a CAT export (no metadata)."""
    torch.onnx.export(torch.nn.Linear(184, 12), (torch.zeros(1, 184),), str(path), dynamo=False)
    return path


def _edited(src: Path, dst: Path, **changes) -> Path:
    """A copy of an export with metadata values replaced (JSON-encoded)."""
    import json

    import onnx

    model = onnx.load(str(src))
    for p in model.metadata_props:
        if p.key in changes:
            p.value = json.dumps(changes[p.key])
    onnx.save(model, str(dst))
    return dst


def test_bad_policy_files_are_one_clear_line(tmp_path, caplog, shipped_onnx):
    from cat.deploy.cli import main

    meta = read_metadata(shipped_onnx)
    swapped = list(meta.joint_names)
    swapped[0], swapped[6] = swapped[6], swapped[0]
    obs = meta.observation
    fewer = {"actor": {**obs["actor"], "terms": [dict(t) for t in obs["actor"]["terms"]]}}
    fewer["actor"]["terms"][2]["size"] = 23
    (tmp_path / "junk.onnx").write_bytes(b"not a model at all")
    cases = [
        ("missing.onnx", "policy file not found"),
        ("junk.onnx", "not an ONNX"),
        (_foreign_onnx(tmp_path / "foreign.onnx").name, "no CAT policy metadata"),
        (_edited(shipped_onnx, tmp_path / "joints.onnx", joint_names=swapped).name, "another layout: joint_names"),
        (
            _edited(shipped_onnx, tmp_path / "terms.onnx", observation=fewer).name,
            "group 'actor' terms (name, size) differ: ('joint_pos', 23) vs runtime ('joint_pos', 29)",
        ),
        (_edited(shipped_onnx, tmp_path / "dim.onnx", obs_dim=185).name, "obs_dim 185 (runtime 184)"),
    ]
    for name, needle in cases:
        caplog.clear()
        with caplog.at_level(logging.ERROR):
            code = main(["scene=flat", f"checkpoint={tmp_path / name}", "goal=1,0", "realtime=false"])
        _one_error(caplog, code, needle)


def _assert_stacked(seq: list[torch.Tensor], h: int) -> None:
    """``seq[t]`` (H * D,) is the last H vectors at step t, oldest first, the first step's repeated before it."""
    blocks = [s.view(h, -1) for s in seq]
    for t, b in enumerate(blocks):
        for k in range(h):
            assert torch.equal(b[k], blocks[max(t - (h - 1 - k), 0)][-1]), (t, k)
    assert not torch.equal(blocks[-1][0], blocks[-1][-1])  # the history really moves


def test_history_student_in_env_export_and_runtime(rollout, history_run):
    """A 5-step history group: the env stacks it (oldest first, filled at reset); the export sizes it 5x; ONNX =
    torch on the 1,000 observations; the click demo's runtime stacks the same way and its ONNX = torch."""
    import threading

    from cat.deploy.runtime import DeployCfg, Runtime
    from cat.deploy.scenes import load_scene

    folder, onnx = history_run
    _, obs = rollout
    _assert_stacked(list(obs["student_proprio"][:40]), HISTORY)  # the env (no reset in the first 40 steps)
    meta = read_metadata(onnx)
    assert meta.obs_groups == ["student_proprio", "student_field"]
    assert meta.observation["student_proprio"]["history"] == HISTORY
    assert meta.obs_dim == HISTORY * (3 + 3 + 29 + 29 + 12 + 12 + 2) + 3 + 91 == obs["student_proprio"].shape[1] + 94
    ort = load_policy(policy_spec(str(onnx)), obs[:1], 12)
    ref = load_policy(policy_spec(str(folder)), obs[:1], 12)
    diff = float((ort(obs) - ref(obs)).abs().max())
    print(f"history student parity: max|d action|={diff:.2e} over {len(obs)} observations")
    assert diff <= TOL

    rt = Runtime(load_scene("flat"), policy_spec(str(onnx)), DeployCfg(realtime=False))
    assert rt.observation()["student_proprio"].shape == (1, HISTORY * 90)
    seen, diffs = [], []
    inner = rt.policy

    class Both:
        def __call__(self, o):
            seen.append(o["student_proprio"][0].clone())
            a = inner(o)
            b = ref(o)  # the untrained student falls and its raw actions grow to ~15: float32 spacing ~1e-6 there
            diffs.append(float(((a - b).abs() / b.abs().clamp_min(1.0)).max()))
            return a

        def reset(self):
            inner.reset()

    rt.policy = Both()
    rt.set_goal((2.0, 0.0))
    rt.run(threading.Event(), lambda r: r.step_count >= 30)
    print(f"history runtime parity: max|d action|/max(1,|a|)={max(diffs):.2e} over {len(diffs)} control steps")
    assert len(seen) >= 2 * HISTORY and max(diffs) <= TOL  # an untrained student: it falls after ~13 steps
    _assert_stacked(seen, HISTORY)  # the runtime


def test_batch_of_observations_through_onnx(shipped_onnx):
    """The MLP export has a dynamic batch axis (one call for many robots or a recorded log)."""
    ort = load_policy(policy_spec(str(shipped_onnx)), None, 12)
    x = TensorDict({"actor": torch.zeros(7, 184)}, batch_size=[7])
    assert ort(x).shape == (7, 12) and np.isfinite(ort(x).numpy()).all()
