"""The scripts keep hydra's promises (--help, --cfg job, -m, hydra.run.dir / hydra.sweep.dir) and fail in one
line (exit code 2) with nothing left behind."""

from __future__ import annotations

import importlib.util
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
SMALL = ["task=flat", "num_envs=4", "max_iterations=1", "algo.num_steps_per_env=4"]


def _run(script: str, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, str(REPO / "scripts" / script), *args],
        capture_output=True, text=True, timeout=600, env=env, cwd=cwd,
    )  # fmt: skip


def _script(name: str = "train"):
    """scripts/<name>.py as a module, to run its command line in-process (same code path, no start-up cost)."""
    spec = importlib.util.spec_from_file_location(f"{name}_script", REPO / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses defined in the script look their module up
    spec.loader.exec_module(mod)
    return mod


def _one_error_line(res: subprocess.CompletedProcess, needle: str) -> None:
    assert res.returncode == 2, res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("ERROR")]
    assert len(errors) == 1 and needle in errors[0], res.stderr
    assert "Traceback" not in res.stderr


def test_help_and_cfg_job_build_nothing(tmp_path):
    res = _run("train.py", "--help", cwd=tmp_path)
    assert res.returncode == 0 and "task={" in res.stdout and "--cfg job" in res.stdout
    res = _run("train.py", *SMALL, "--cfg", "job", cwd=tmp_path)
    assert res.returncode == 0 and "max_iterations: 1" in res.stdout
    assert not list(tmp_path.iterdir())


def test_multirun_and_hydra_dirs(tmp_path):
    small = [a for a in SMALL if not a.startswith("task=")]
    sweep = [
        "task=flat,side_pass",
        "seed=0,1",
        "task.scene_variants=1",
        "task.warmup_variants=0",
    ]  # two tasks x two seeds
    res = _run("train.py", "-m", *small, *sweep, f"hydra.sweep.dir={tmp_path / 'sweep'}")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "sweep").iterdir()) == ["0", "1", "2", "3"]
    tasks = []
    for k in ("0", "1", "2", "3"):
        assert list((tmp_path / "sweep" / k).glob("model_*.pt"))
        tasks.append(yaml.safe_load((tmp_path / "sweep" / k / "config.yaml").read_text())["task"]["task"])
    assert tasks == ["flat", "flat", "side_pass", "side_pass"]
    res = _run("train.py", *SMALL, f"hydra.run.dir={tmp_path / 'exact'}")
    assert res.returncode == 0 and (tmp_path / "exact" / "config.yaml").is_file()


@pytest.mark.parametrize(
    "args, needle",
    [
        (["num_env=3"], "did you mean num_envs"),
        (["max_iterations=abc"], "could not be converted to Integer"),
        (["num_envs=0"], "num_envs=0"),
        (["max_iterations=0"], "max_iterations=0"),
        (["task=flatt"], "valid task options"),
        (["sim=warpp"], "valid sim options"),
        (["init=/no/such.pt"], "checkpoint not found"),
        (["--cfg"], "--cfg takes"),
        (["hydra.job.chdir=true"], "not supported"),
        (["-m", "seed=0,1", "max_iterations=1,0"], "max_iterations=0"),  # every job checked before any runs
    ],
)
def test_bad_input_one_line_nothing_left(tmp_path, caplog, args, needle):
    mod = _script()
    with caplog.at_level(logging.ERROR):
        code = mod.run(mod.SCRIPT, [*args, f"run_root={tmp_path / 'runs'}"])
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert code == 2 and len(errors) == 1 and needle in errors[0], errors
    assert not (tmp_path / "runs").exists()


def test_corrupt_checkpoint_is_one_line_from_the_real_script(tmp_path):
    bad = tmp_path / "model_3.pt"
    bad.write_bytes(b"definitely not a torch file")
    res = _run("train.py", *SMALL, f"init={bad}", f"run_root={tmp_path / 'runs'}")
    _one_error_line(res, "model_3.pt: not a readable checkpoint")
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    "name, key",
    [
        ("play", "checkpoint"),
        ("eval_table", "manifest"),
        ("gen_scenes", "out"),
        ("gen_test_set", "out"),
        ("plot_training", "run"),
        ("mesh_to_scene", "mesh"),
        ("click_and_traverse", "scene"),
        ("export", "checkpoint"),
    ],
)
def test_every_script_helps_and_suggests(tmp_path, caplog, capsys, name, key):
    mod = _script(name)
    assert mod.run(mod.SCRIPT, ["--help"]) == 0 and key in capsys.readouterr().out
    with caplog.at_level(logging.ERROR):
        assert mod.run(mod.SCRIPT, [f"{key}x=1"]) == 2
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and f"did you mean {key}" in errors[0], errors


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from cat.learning.hydra_cfg import load_config
    from cat.learning.runs import train

    return train(load_config([*SMALL, f"run_root={tmp_path_factory.mktemp('runs')}"]))


@pytest.mark.parametrize(
    "args, needle",
    [
        (["episodes=0"], "episodes must be >= 1"),
        (["num_envs=0"], "num_envs must be >= 1"),
        (["sim=warpp"], "unknown sim backend 'warpp'"),
        (["record=/no/such/folder/x.rrd"], "does not exist"),
        (["time_s=0"], "time_s must be > 0"),
        (["warmup_pitch=true"], "warmup_pitch= chooses the warm-up layout: it needs warmup=true"),
        (["warmup_slit=tight"], "warmup_slit= chooses the warm-up layout: it needs warmup=true"),
        (["warmup=true", "warmup_slit=wide"], "warmup_slit='wide': valid: offset, narrow, tight, none"),
    ],
)
def test_play_refuses_bad_values(tiny_run, caplog, args, needle):
    mod = _script("play")
    with caplog.at_level(logging.ERROR):
        code = mod.main([f"checkpoint={tiny_run}", *args])
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert code == 2 and len(errors) == 1 and needle in errors[0], errors


def test_resume_overrides_keys_only_the_runs_task_has(tiny_run, tmp_path):
    """``resume=`` reads the run's config before the overrides: a group only that run defines can be changed."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    cfg["task"]["observations"]["probe"] = {"terms": ["gyro"], "noise": False}
    (run / "config.yaml").write_text(yaml.safe_dump(cfg))
    ckpt = next(run.glob("model_*.pt"))
    loaded = _script()._load([f"resume={ckpt}", "task.observations.probe.noise=true", "max_iterations=3"])
    assert loaded.task.observations["probe"].noise is True and loaded.max_iterations == 3
    assert loaded.resume == str(ckpt)


def test_plot_training_draws_a_chain_of_runs_over_env_steps(tmp_path, caplog):
    """``runs=[a,b]``: the second run's iterations continue after the first's env steps (each run's own steps per
    iteration); a chain without ``out=``, or both ``run`` and ``runs``, is one clear error."""
    mod = _script("plot_training")
    dirs = []
    for name, envs, iters in (("a", 8, 3), ("b", 16, 2)):
        d = tmp_path / name
        d.mkdir()
        (d / "config.yaml").write_text(f"num_envs: {envs}\ntask: {{num_envs: 4}}\nalgo: {{num_steps_per_env: 10}}\n")
        rows = ["iteration,tag,value"] + [f"{i},Train/mean_reward,{i + 1}" for i in range(iters)]
        (d / "metrics.csv").write_text("\n".join(rows) + "\n")
        dirs.append(d)
    series, starts = mod.chain(dirs)
    xs = [x for x, _ in series["Train/mean_reward"]]
    assert starts == pytest.approx([0.0, 240e-6]) and xs == pytest.approx([80e-6, 160e-6, 240e-6, 400e-6, 560e-6])
    out = tmp_path / "chain.png"
    assert mod.main([f"runs=[{dirs[0]},{dirs[1]}]", f"out={out}"]) == 0 and out.stat().st_size > 0
    with caplog.at_level(logging.ERROR):
        assert mod.main([f"runs=[{dirs[0]}]"]) == 2
        assert mod.main([f"run={dirs[0]}", f"runs=[{dirs[1]}]", f"out={out}"]) == 2
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert "needs out=" in errors[0] and "one of them" in errors[1], errors


def test_a_missing_robot_model_is_one_line_from_any_script(tmp_path, monkeypatch, caplog):
    """Without the robot model (MENAGERIE_ROOT naming an empty folder, offline) a script prints one line naming
    MENAGERIE_ROOT and exits 2 (``cat.errors.SetupError``), instead of a stack trace from deep in the env."""
    from cat.errors import SetupError

    monkeypatch.setenv("MENAGERIE_ROOT", str(tmp_path))
    play = _script("play")
    with caplog.at_level(logging.ERROR):
        code = play.main([f"checkpoint={REPO / 'checkpoints' / 'flat' / 'model_770.pt'}", "episodes=1"])
    assert code == 2
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "MENAGERIE_ROOT" in errors[0].getMessage() and not errors[0].exc_info
    from cat.envs.robot import MenagerieModelError

    assert issubclass(MenagerieModelError, SetupError)
