"""Budgeted, resumable training: ``max_minutes`` stops cleanly and saves; ``resume=`` continues the same run
(iteration count, optimiser, normaliser, RNG, env snapshot) and gives the same next update as no stop at all."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest
import torch

from cat.learning.hydra_cfg import load_config
from cat.learning.runners import clear_stop_signal, stop_signal_received
from cat.learning.runs import resume_config, train


def _base(tmp_path, *extra: str):
    return [
        "task=flat",
        "num_envs=8",
        "algo.num_steps_per_env=8",
        "algo.save_interval=1",
        f"run_root={tmp_path}",
        *extra,
    ]


def test_resume_gives_the_same_next_update(tmp_path):
    full = train(load_config(_base(tmp_path, "max_iterations=3", "run_name=full")))
    part = train(load_config(_base(tmp_path, "max_iterations=2", "run_name=part")))
    assert not (part / "model_2.pt").exists()
    again = train(resume_config(part / "model_1.pt", ["max_iterations=3"]))
    assert again == part  # the same run folder
    a = torch.load(full / "model_2.pt", weights_only=True)
    b = torch.load(part / "model_2.pt", weights_only=True)
    assert a["iter"] == b["iter"] == 2
    for key in ("actor_state_dict", "critic_state_dict"):
        for name, value in a[key].items():
            torch.testing.assert_close(b[key][name], value, rtol=0, atol=0, msg=f"{key}.{name} differs")
    assert a["optimizer_state_dict"]["param_groups"][0]["lr"] == b["optimizer_state_dict"]["param_groups"][0]["lr"]


def test_a_learning_rate_given_on_resume_replaces_the_optimisers(tmp_path):
    run = train(load_config(_base(tmp_path, "max_iterations=2", "algo.schedule=fixed")))
    kept = train(resume_config(run / "model_1.pt", ["max_iterations=3"]))
    lr = torch.load(kept / "model_2.pt", weights_only=True)["optimizer_state_dict"]["param_groups"][0]["lr"]
    assert lr == pytest.approx(3e-4)  # the run's own rate when none is given
    train(resume_config(run / "model_2.pt", ["max_iterations=4", "algo.learning_rate=1e-5"]))
    lr = torch.load(run / "model_3.pt", weights_only=True)["optimizer_state_dict"]["param_groups"][0]["lr"]
    assert lr == pytest.approx(1e-5)


def test_resume_from_an_earlier_checkpoint_redoes_the_later_rows(tmp_path):
    run = train(load_config(_base(tmp_path, "max_iterations=3")))  # logged iterations 0, 1, 2
    train(resume_config(run / "model_1.pt", ["max_iterations=3"]))  # as after a kill past model_1: redo 2
    rows = [ln.split(",")[:2] for ln in (run / "metrics.csv").read_text().splitlines()[1:]]
    per_tag = {}
    for it, tag in rows:
        per_tag.setdefault(tag, []).append(int(it))
    assert per_tag["Loss/surrogate"] == [0, 1, 2]  # one value per iteration, the redone one last


def test_max_minutes_stops_saves_and_resume_counts_on(tmp_path):
    run = train(load_config(_base(tmp_path, "max_iterations=50", "max_minutes=0.0001")))
    saved = sorted(run.glob("model_*.pt"))
    assert [p.name for p in saved] == ["model_0.pt"]  # stopped after the first complete iteration
    snap = torch.load(run / "env_0.pt", weights_only=True)  # tensors and plain data (cat/checkpoint_io.py)
    assert type(snap["obs"]) is dict and torch.is_tensor(snap["sim"]["qpos"])
    resumed = resume_config(saved[0], ["max_iterations=2"])
    assert resumed.max_minutes == 0.0 and resumed.deadline == 0.0  # the earlier sitting's budget is not carried over
    assert resume_config(saved[0], ["max_minutes=7"]).max_minutes == 7.0  # one given again holds
    train(resumed)
    assert torch.load(run / "model_1.pt", weights_only=True)["iter"] == 1
    assert (run / "metrics_1.rrd").is_file()  # the resumed part is recorded beside the first


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGUSR1, signal.SIGINT])
def test_a_stop_signal_saves_the_iteration_and_resume_counts_on(tmp_path, signum):
    """A kill, a scheduler's notice or Ctrl-C mid-run: the iteration finishes, is saved, the run resumes."""
    before = signal.getsignal(signum)
    folder = tmp_path / "run"

    def send_once_training():
        deadline = time.monotonic() + 120
        while not (folder / "model_0.pt").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(os.getpid(), signum)

    sender = threading.Thread(target=send_once_training, daemon=True)
    sender.start()
    try:
        long_run = _base(tmp_path, "max_iterations=100000", "algo.save_interval=100000", f"run_dir={folder}")
        run = train(load_config(long_run))
        sender.join()
        assert stop_signal_received() == signum
        # the next run of this process (a sweep's, a sitting's) does not start: the user asked the process to stop
        assert train(load_config(_base(tmp_path, "max_iterations=2", f"run_dir={tmp_path / 'next'}"))) is None
        assert not (tmp_path / "next").exists()
    finally:
        clear_stop_signal()
    assert run == folder
    (last,) = [p for p in run.glob("model_*.pt") if p.name != "model_0.pt"]  # the stop's save, nothing else
    it = torch.load(last, weights_only=True)["iter"]
    assert 1 <= it < 1000 and (run / f"env_{it}.pt").is_file()
    assert signal.getsignal(signum) == before  # the process's own handler is back
    train(resume_config(last, [f"max_iterations={it + 2}"]))
    assert torch.load(run / f"model_{it + 1}.pt", weights_only=True)["iter"] == it + 1


@pytest.mark.parametrize(
    "override, message",
    [
        ("num_envs=0", "num_envs=0: must be >= 1"),
        ("max_iterations=0", "max_iterations=0: must be >= 1"),
        ("max_iterations=-1", "max_iterations=-1: must be >= 1"),
        ("max_minutes=-2", "max_minutes=-2.0: must be >= 0"),
        ("task.scene_kind=no-such-kind", "no-such-kind"),
    ],
)
def test_bad_values_fail_before_a_run_folder_exists(tmp_path, override, message):
    with pytest.raises(ValueError, match=message):
        train(load_config(_base(tmp_path, override)))
    assert not list(tmp_path.rglob("config.yaml"))


def test_run_folders_never_collide_and_record_the_commit(tmp_path):
    cfg = load_config(_base(tmp_path, "max_iterations=1"))
    a, b = train(cfg), train(cfg)
    assert a != b and a.parent == b.parent
    diff = next((a / "git").glob("*.diff"), None)
    assert diff is not None and "--- git commit ---" in diff.read_text()
    rows = (a / "metrics.csv").read_text().splitlines()[1:]
    assert rows and all(int(r.split(",")[0]) == 0 for r in rows)  # one axis: iterations only (no seconds)
