"""A sitting's budget (``max_minutes=``): every run of a stage is launched at once with the sitting's end as its
``deadline``, so a run the launcher queues (the sequential launcher runs one at a time, joblib ``n_jobs``) gets only
what is left, one that starts after the end runs nothing, and a core freed early takes the next run at once."""

from __future__ import annotations

import json
import logging
import re
import time
from pathlib import Path

import yaml

from cat.launcher import load_script

REPO = Path(__file__).resolve().parents[1]
COMMON = ["sim=mujoco", "num_envs=4", "algo.num_steps_per_env=4", "algo.save_interval=1"]


def _given(caplog) -> dict[str, float]:
    """The deadline each stage-0 run was launched with, by ``cell@seed``, from the runner's log."""
    return {
        m.group(1): float(m.group(2))
        for r in caplog.records
        if (m := re.match(r"stage 0: (\w+@\d): .* deadline=([\d.]+)", r.getMessage()))
    }


def _run(tmp_path, caplog, cells: dict, extra: list[str]) -> int:
    exp = tmp_path / "sit.yaml"
    exp.write_text(yaml.safe_dump({"common": COMMON, "cells": cells}))
    mod = load_script(REPO / "scripts" / "experiment.py")
    with caplog.at_level(logging.INFO):
        return mod.main([f"experiment={exp}", f"root={tmp_path / 'exps'}", "max_minutes=30", *extra])


def test_sequential_runs_share_the_sittings_end(tmp_path, caplog):
    t0 = time.time()
    cells = {"a": {"task": "flat", "iterations": 1}, "b": {"task": "flat", "iterations": 1, "seeds": [1]}}
    assert _run(tmp_path, caplog, cells, []) == 0
    given = _given(caplog)
    assert set(given) == {"a@0", "b@1"}
    assert given["a@0"] == given["b@1"] and t0 + 29 * 60 < given["a@0"] <= time.time() + 30 * 60
    assert (tmp_path / "exps/sit/runs/a/seed0/model_0.pt").is_file()
    assert (tmp_path / "exps/sit/runs/b/seed1/model_0.pt").is_file()
    state = json.loads((tmp_path / "exps/sit/state.json").read_text())["units"]
    assert all(0 < state[u]["minutes"] < 5 for u in ("a@0", "b@1"))  # each run's own minutes


def test_joblib_gets_every_run_of_a_stage_at_once_seed_major(tmp_path, caplog):
    """Three runs on n_jobs=2 are one launch (a core freed by a run that ends early takes the next at once), seed 0
    of every cell first (a sitting cut short leaves a whole column)."""
    cells = {"a": {"task": "flat", "iterations": 1, "seeds": [0, 1]}, "b": {"task": "flat", "iterations": 1}}
    assert _run(tmp_path, caplog, cells, ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"]) == 0
    given = _given(caplog)
    assert list(given) == ["a@0", "b@0", "a@1"] and len(set(given.values())) == 1
    assert any("launching 3 job(s)" in r.getMessage() for r in caplog.records)
    assert all((tmp_path / f"exps/sit/runs/{u}/model_0.pt").is_file() for u in ("a/seed0", "a/seed1", "b/seed0"))


def test_a_run_started_after_its_deadline_runs_nothing(tmp_path, caplog):
    """What a queued job does when the sitting ended before its turn: no env, no folder, and resume= of a run keeps
    no earlier sitting's deadline (it would stop a later resume at once)."""
    from cat.learning.hydra_cfg import load_config
    from cat.learning.runs import train
    from cat.run.config_file import resume_config

    cfg = load_config([*COMMON, "task=flat", "max_iterations=1", f"run_dir={tmp_path / 'late'}", "deadline=1000"])
    with caplog.at_level(logging.INFO):
        assert train(cfg) is None
    assert "deadline passed before the run started" in caplog.text and not (tmp_path / "late").exists()
    run = train(load_config([*COMMON, "task=flat", "max_iterations=1", f"run_dir={tmp_path / 'run'}"]))
    config = (tmp_path / "run/config.yaml").read_text()
    assert "\ndeadline: 0.0\n" in config
    (tmp_path / "run/config.yaml").write_text(config.replace("\ndeadline: 0.0\n", "\ndeadline: 1000.0\n"))
    assert resume_config(run / "model_0.pt", ["max_iterations=2"]).deadline == 0.0
    assert resume_config(run / "model_0.pt", ["deadline=5"]).deadline == 5.0


def test_runs_queued_past_the_sittings_end_are_left_for_the_next(tmp_path, caplog):
    """Sequential launcher, a 6-second sitting, 1,000 iterations each: the first run stops at the deadline and
    saves; the two queued behind it start after it, run nothing and are left for the next sitting."""
    cells = {"a": {"task": "flat", "iterations": 1000}, "b": {"task": "flat", "iterations": 1000, "seeds": [1, 2]}}
    exp = tmp_path / "sit.yaml"
    exp.write_text(yaml.safe_dump({"common": COMMON, "cells": cells}))
    mod = load_script(REPO / "scripts" / "experiment.py")
    with caplog.at_level(logging.INFO):
        assert mod.main([f"experiment={exp}", f"root={tmp_path / 'exps'}", "max_minutes=0.1"]) == 0
    assert list((tmp_path / "exps/sit/runs/a/seed0").glob("model_*.pt"))  # stopped by the deadline, saved
    assert not (tmp_path / "exps/sit/runs/b/seed1").exists() and not (tmp_path / "exps/sit/runs/b/seed2").exists()
    assert caplog.text.count("deadline passed before the run started") == 2
    assert "ran a@0; left a@0, b@1, b@2" in caplog.text


def test_two_sittings_on_other_cells_keep_each_others_records(tmp_path, caplog):
    """Sitting A reads the state, sitting B (another cell) runs and records its run, then A runs and writes: the
    state keeps both records (A merges entry by entry instead of writing back what it read)."""
    from cat.experiment.runner import ExperimentCfg, Runner

    exp = tmp_path / "sit.yaml"
    cells = {"a": {"task": "flat", "iterations": 1}, "b": {"task": "flat", "iterations": 1}}
    exp.write_text(yaml.safe_dump({"common": COMMON, "cells": cells}))
    root = tmp_path / "exps"
    first = Runner(ExperimentCfg(experiment=str(exp), only=["a"], root=str(root)), [])  # reads the empty state
    mod = load_script(REPO / "scripts" / "experiment.py")
    with caplog.at_level(logging.INFO):
        assert mod.main([f"experiment={exp}", f"root={root}", "only=[b]"]) == 0
        b = json.loads((root / "sit" / "state.json").read_text())["units"]["b@0"]
        assert b["status"] == "done"
        assert first.run() == 0
    units = json.loads((root / "sit" / "state.json").read_text())["units"]
    assert units["b@0"] == b  # B's record survives A's write, unchanged
    assert units["a@0"]["status"] == "done" and units["a@0"]["checkpoint"].endswith("model_0.pt")


def test_a_run_held_by_a_live_sitting_is_left_to_it(tmp_path, caplog):
    """A run another live sitting trains (its record in state.json) is neither started nor wiped by a second
    sitting; once that sitting is gone (its process dead, or on another host its end passed) it is trained."""
    import socket
    import subprocess
    import sys

    from cat.experiment.plan import Plan
    from cat.experiment.spec import load_experiment

    exp = tmp_path / "sit.yaml"
    exp.write_text(yaml.safe_dump({"common": COMMON, "cells": {"a": {"task": "flat", "iterations": 1}}}))
    root = tmp_path / "exps"
    state = root / "sit" / "state.json"
    state.parent.mkdir(parents=True)
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    try:
        held = {"host": socket.gethostname(), "pid": other.pid, "until": None}
        state.write_text(json.dumps({"units": {"a@0": {"sitting": held}}, "tables": {}}))
        run_dir = root / "sit" / "runs" / "a" / "seed0"
        run_dir.mkdir(parents=True)  # the other sitting's run, before its first checkpoint
        mod = load_script(REPO / "scripts" / "experiment.py")
        with caplog.at_level(logging.INFO):
            assert mod.main([f"experiment={exp}", f"root={root}"]) == 0
        assert f"a@0 is being trained by the sitting of pid {other.pid}" in caplog.text
        assert run_dir.is_dir() and not list(run_dir.iterdir())  # neither wiped nor trained into
        assert json.loads(state.read_text())["units"]["a@0"]["sitting"] == held  # its record kept
    finally:
        other.kill()
        other.wait()
    caplog.clear()
    with caplog.at_level(logging.INFO):
        assert mod.main([f"experiment={exp}", f"root={root}"]) == 0
    assert (run_dir / "model_0.pt").is_file()
    assert "sitting" not in json.loads(state.read_text())["units"]["a@0"]  # released when its stage ended
    # on another host the record's end decides
    plan = Plan(load_experiment(str(exp)), str(root))
    for until, holds in ((time.time() + 600, True), (time.time() - 1, False), (None, True)):
        held = {"host": "elsewhere", "pid": 1, "until": until}
        state.write_text(json.dumps({"units": {"a@0": {"sitting": held}}, "tables": {}}))
        assert ("a@0" in plan.holders([plan.units["a@0"]])) == holds, until


def test_a_run_another_sitting_took_over_keeps_that_sittings_record(tmp_path, caplog, monkeypatch):
    """A run this sitting stopped early (a signal to its job) may be taken over by a second sitting, with a newer
    recipe, before this sitting's stage ends: this sitting then leaves the unit's record as the other wrote it
    (else its older hash would make the next sitting move the newer run aside as stale)."""
    import socket
    import subprocess
    import sys

    import cat.experiment.runner as runner

    exp = tmp_path / "sit.yaml"
    exp.write_text(yaml.safe_dump({"common": COMMON, "cells": {"a": {"task": "flat", "iterations": 1}}}))
    state = tmp_path / "exps" / "sit" / "state.json"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    theirs = {"hash": "newer", "sitting": {"host": socket.gethostname(), "pid": other.pid, "until": None}}
    real = runner.launch

    def launch_then_taken_over(*args, **kwargs):
        results = real(*args, **kwargs)
        now = json.loads(state.read_text())
        now["units"]["a@0"] = theirs
        state.write_text(json.dumps(now))
        return results

    monkeypatch.setattr(runner, "launch", launch_then_taken_over)
    try:
        mod = load_script(REPO / "scripts" / "experiment.py")
        with caplog.at_level(logging.INFO):
            assert mod.main([f"experiment={exp}", f"root={tmp_path / 'exps'}"]) == 0
        assert f"a@0: now trained by the sitting of pid {other.pid}" in caplog.text
        assert json.loads(state.read_text())["units"]["a@0"] == theirs
    finally:
        other.kill()
        other.wait()
