"""End to end with real rsl_rl: train 2 iterations, save, reload, resume, play; bad input gives clear errors."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from cat.learning.hydra_cfg import ConfigError, load_config
from cat.learning.play import PlayCfg, play
from cat.learning.runs import CheckpointError, resume_config, train

REPO = Path(__file__).resolve().parents[1]


def _small(tmp_path, *extra: str):
    return load_config(
        ["task=flat", "num_envs=16", "max_iterations=2", f"run_root={tmp_path}", "algo.num_steps_per_env=8", *extra]
    )


def _train_and_play(tmp_path, sim: str):
    run_dir = train(_small(tmp_path, f"sim={sim}"))
    ckpts = sorted(run_dir.glob("model_*.pt"))
    assert ckpts, "no checkpoint written"
    assert (run_dir / "config.yaml").is_file() and (run_dir / "metrics.rrd").stat().st_size > 0
    play_cfg = PlayCfg(checkpoint=str(ckpts[-1]), episodes=3, num_envs=2)
    res = play(play_cfg)
    assert res == play(play_cfg)  # deterministic: same trials, same seeds, same numbers
    assert res.trials == 3
    # 2 PPO iterations cannot walk 2 m in 5 s; DE includes the start reading, exactly 2 m away on flat ground
    assert res.success_rate == 0.0
    assert 0.0 < res.distance_error <= 2.0 + 1e-5
    return ckpts[-1]


def test_train_save_reload_play_mujoco(tmp_path):
    ckpt = _train_and_play(tmp_path, "mujoco")
    # a recorded rollout replays in rerun: robot shapes, goal and the F_H arrows at the 13 links
    rrd = tmp_path / "rollout.rrd"
    play(PlayCfg(checkpoint=str(ckpt), episodes=1, num_envs=1, record=str(rrd)))
    printed = subprocess.run(
        ["rerun", "rrd", "print", str(rrd)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    ).stdout
    for entity in ("world/robot/capsules", "world/goal", "world/field/F_H"):
        assert entity in printed
    # resume continues the iteration count in the same run folder; init loads only weights
    resumed = train(resume_config(ckpt, ["max_iterations=3"]))
    assert resumed == ckpt.parent and (resumed / "model_2.pt").is_file()
    inited = train(_small(tmp_path, f"init={ckpt}"))
    assert (inited / "model_1.pt").is_file()


def test_train_save_reload_play_warp(tmp_path):
    pytest.importorskip("mujoco_warp")
    _train_and_play(tmp_path, "warp")


def test_scripts_run_as_written(tmp_path):
    out = subprocess.run(
        [
            sys.executable,
            "scripts/train.py",
            "task=flat",
            "sim=mujoco",
            "num_envs=16",
            "max_iterations=2",
            f"run_root={tmp_path}",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    run_dir = Path(out.stdout.strip().splitlines()[-1].removeprefix("run folder: "))
    ckpt = sorted(run_dir.glob("model_*.pt"))[-1]
    out = subprocess.run(
        [sys.executable, "scripts/play.py", f"checkpoint={ckpt}", "episodes=2"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    rate = r"[01]\.\d{3}"
    line = rf"episodes=2 success_rate={rate} distance_error=\d+\.\d{{3}} collision_rate={rate} fall_rate={rate}"
    assert re.fullmatch(line, out.stdout.strip().splitlines()[-1]), out.stdout


def test_unknown_task_lists_valid_ones():
    with pytest.raises(ConfigError, match="valid task options: .*flat"):
        load_config(["task=nope"])


def test_unknown_key_suggests_close_ones():
    with pytest.raises(ConfigError, match="unknown key 'task.rewards.fild_vmf'; did you mean task.rewards.field_vmf"):
        load_config(["task.rewards.fild_vmf=1"])
    with pytest.raises(ConfigError, match="unknown key 'task.rewards.bogus'; did you mean"):
        load_config(["task.rewards.bogus=1"])
    with pytest.raises(ConfigError, match="not key=value"):
        load_config(["num_envs"])


def test_unknown_sim_backend(tmp_path):
    cfg = load_config(["sim.backend=physx", "num_envs=2", f"run_root={tmp_path}"])
    with pytest.raises(ValueError, match="valid: mujoco, warp"):
        train(cfg)


def test_missing_checkpoint_is_clear(tmp_path):
    with pytest.raises(CheckpointError, match="checkpoint not found"):
        play(PlayCfg(checkpoint=str(tmp_path / "missing.pt"), episodes=1))
    with pytest.raises(CheckpointError, match="checkpoint not found"):
        train(_small(tmp_path, f"init={tmp_path / 'missing.pt'}"))
    out = subprocess.run(
        [sys.executable, "scripts/play.py", f"checkpoint={tmp_path / 'missing.pt'}"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 2 and "checkpoint not found" in out.stderr


def test_torchrun_maps_each_rank_to_its_gpu_and_seed():
    from cat.learning.runs import for_this_rank
    from cat.run.config import SimCfg, TrainCfg

    cfg = TrainCfg(sim=SimCfg(backend="warp", device="cuda"), seed=3)
    assert for_this_rank(cfg, {}) is cfg  # single process: unchanged
    ranked = for_this_rank(cfg, {"WORLD_SIZE": "2", "RANK": "1", "LOCAL_RANK": "1"})
    assert ranked.sim.device == "cuda:1" and ranked.seed == 4
    with pytest.raises(ValueError, match="needs sim.device=cuda"):
        for_this_rank(TrainCfg(seed=0), {"WORLD_SIZE": "2", "RANK": "0", "LOCAL_RANK": "0"})


def test_mixed_precision_runs_the_ppo_update_in_bf16_and_the_rollout_in_fp32(tmp_path):
    """algo.mixed_precision=true reaches rsl_rl's use_mixed_precision: the update's critic forward computes in
    bf16 (autocast), the rollout's in fp32; the update's losses stay finite."""
    import torch

    from cat.learning.runs import make_env, make_runner

    cfg = _small(tmp_path, "algo.mixed_precision=true")
    env = make_env(cfg, num_envs=8)
    runner = make_runner(cfg, env, None)
    first = next(m for m in runner.alg.critic.modules() if isinstance(m, torch.nn.Linear))
    dtypes: list[torch.dtype] = []
    first.register_forward_hook(lambda mod, inp, out: dtypes.append(out.dtype))
    losses: list[dict] = []
    update = runner.alg.update

    def spy():
        dtypes.append("update")
        losses.append(update())
        return losses[-1]

    runner.alg.update = spy
    runner.learn(1)
    split = dtypes.index("update")
    assert set(dtypes[:split]) == {torch.float32}  # rollout: values in fp32
    assert set(dtypes[split + 1 :]) == {torch.bfloat16}  # update: bf16 autocast
    assert all(torch.isfinite(torch.tensor(v)) for v in losses[0].values())


def test_max_noise_std_clamps_the_learned_std_and_bad_values_are_refused(tmp_path):
    """algo.max_noise_std reaches rsl_rl's std_range: a policy whose learned std is above it acts with the cap (the
    sampled actions' spread shows it); 0 leaves the std unbounded; a negative cap is one clear error, before any
    env is built."""
    import torch

    from cat.learning.runs import make_env, make_runner, validate_train_cfg

    spreads = {}
    for cap in (0.0, 0.2):
        cfg = _small(tmp_path, "algo.init_noise_std=1.0", f"algo.max_noise_std={cap}")
        env = make_env(cfg, num_envs=4)
        actor = make_runner(cfg, env, None).alg.actor
        obs = env.get_observations()
        torch.manual_seed(0)
        samples = torch.stack([actor(obs, stochastic_output=True) for _ in range(200)])
        spreads[cap] = samples.std(dim=0).mean().item()
    assert 0.9 < spreads[0.0] < 1.1 and 0.17 < spreads[0.2] < 0.23
    with pytest.raises(ValueError, match="algo.max_noise_std=-1.0: must be >= 0"):
        validate_train_cfg(_small(tmp_path, "algo.max_noise_std=-1.0"))


@pytest.mark.parametrize(
    "override, needle",
    [
        ("algo.gamma=1.5", "algo.gamma=1.5: must be in [0, 1]"),
        ("algo.lam=-0.1", "algo.lam=-0.1: must be in [0, 1]"),
        ("algo.learning_rate=0.0", "algo.learning_rate=0.0: must be > 0"),
        ("algo.clip_param=-0.2", "algo.clip_param=-0.2: must be > 0"),
        ("algo.entropy_coef=-0.01", "algo.entropy_coef=-0.01: must be >= 0"),
    ],
)
def test_ppo_constants_out_of_range_are_refused(tmp_path, override, needle):
    """A discount above 1 or a zero rate trains something else without an error: refused before any env is built."""
    from cat.learning.runs import validate_train_cfg

    validate_train_cfg(_small(tmp_path))  # the defaults pass
    with pytest.raises(ValueError, match=re.escape(needle)):
        validate_train_cfg(_small(tmp_path, override))
