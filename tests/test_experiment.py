"""scripts/experiment.py on real 1-iteration runs: DAG order, skip when done, resume when unfinished, a changed
cell re-running only itself and what reads it; bad experiments refused in one line before anything is written;
hydra's joblib launcher running two real training jobs in parallel processes."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from cat.launcher import load_script

REPO = Path(__file__).resolve().parents[1]
COMMON = ["sim=mujoco", "num_envs=4", "algo.num_steps_per_env=4", "algo.save_interval=1"]


def _write(tmp_path: Path, cells: dict, tables: dict | None = None, name: str = "exp") -> str:
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"common": COMMON, "cells": cells, "tables": tables or {}}))
    return str(path)


def _experiment(args: list[str], caplog) -> tuple[int, list[str]]:
    mod = load_script(REPO / "scripts" / "experiment.py")
    caplog.clear()
    with caplog.at_level(logging.INFO):
        code = mod.main(args)
    return code, [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]


def _mtimes(root: Path) -> dict[str, float]:
    return {str(p.relative_to(root)): p.stat().st_mtime for p in root.glob("runs/*/seed*/model_*.pt")}


def _summary(caplog) -> str:
    return next(r.getMessage() for r in reversed(caplog.records) if "experiment exp: ran" in r.getMessage())


def test_dag_skip_resume_and_rerun_of_a_changed_cell(tmp_path, caplog, capsys):
    root = tmp_path / "exps"
    cells = {
        "spec": {"task": "flat", "init": "prior", "iterations": 1},  # declared first, runs second
        "prior": {"task": "flat", "iterations": 1},
        "other": {"task": "flat", "iterations": 1, "seeds": [1]},
    }
    exp = _write(tmp_path, cells)
    args = [f"experiment={exp}", f"root={root}"]
    code, errors = _experiment(args, caplog)
    assert code == 0 and not errors, errors
    assert "left nothing" in _summary(caplog)
    folder = root / "exp"
    spec = yaml.safe_load((folder / "runs/spec/seed0/config.yaml").read_text())
    prior_ckpt = folder / "runs/prior/seed0/model_0.pt"
    assert spec["init"] == str(prior_ckpt)  # the specialist started from the prior's final checkpoint
    assert prior_ckpt.stat().st_mtime < (folder / "runs/spec/seed0/model_0.pt").stat().st_mtime
    assert (folder / "runs/other/seed1/model_0.pt").is_file()
    first = _mtimes(folder)

    code, _ = _experiment(args, caplog)  # done: nothing runs
    assert code == 0 and "ran nothing; left nothing" in _summary(caplog) and _mtimes(folder) == first

    cells["spec"]["iterations"] = 2  # a larger budget: the run is unfinished and continues in its folder
    exp = _write(tmp_path, cells)
    _experiment([*args, "dry_run=true"], caplog)
    out = capsys.readouterr().out
    assert "spec@0 (resume from iteration 1 of 2)" in out and "\nto train: 1 iterations (cells with" in out
    code, _ = _experiment(args, caplog)
    assert code == 0 and "ran spec@0;" in _summary(caplog)
    after = _mtimes(folder)
    assert after["runs/spec/seed0/model_0.pt"] == first["runs/spec/seed0/model_0.pt"]  # resumed, not restarted
    assert "runs/spec/seed0/model_1.pt" in after
    assert yaml.safe_load((folder / "runs/spec/seed0/config.yaml").read_text())["resume"].endswith("model_0.pt")

    cells["prior"]["overrides"] = ["algo.learning_rate=0.0002"]  # prior changed: it and spec re-run, other not
    exp = _write(tmp_path, cells)
    code, _ = _experiment([*args, "dry_run=true"], caplog)  # the dry run names what changed
    assert "# changed since its run: algo.learning_rate: 0.0003 -> 0.0002" in capsys.readouterr().out
    code, _ = _experiment(args, caplog)
    assert "prior@0: changed since its run (algo.learning_rate: 0.0003 -> 0.0002)" in caplog.text
    assert "spec@0: changed since its run (no config value differs: its inputs (init / teacher" in caplog.text
    assert code == 0 and "ran prior@0, spec@0;" in _summary(caplog)
    again = _mtimes(folder)
    assert again["runs/other/seed1/model_0.pt"] == first["runs/other/seed1/model_0.pt"]
    assert again["runs/prior/seed0/model_0.pt"] > first["runs/prior/seed0/model_0.pt"]
    assert again["runs/spec/seed0/model_1.pt"] > after["runs/spec/seed0/model_1.pt"]
    assert len(list((folder / "runs/prior").glob("seed0.stale-*"))) == 1  # the old run kept aside


def test_a_run_made_by_hand_is_adopted_and_an_interrupted_one_resumes(tmp_path, caplog):
    from cat.experiment.plan import Plan
    from cat.experiment.spec import load_experiment

    exp = _write(tmp_path, {"prior": {"task": "flat", "iterations": 2}})
    args = [f"experiment={exp}", f"root={tmp_path / 'exps'}"]
    plan = Plan(load_experiment(exp), str(tmp_path / "exps"))
    fresh = plan.fresh_overrides(plan.units["prior@0"])  # the command dry_run prints, run by hand
    assert load_script(REPO / "scripts" / "train.py").main(fresh) == 0
    code, _ = _experiment(args, caplog)
    assert code == 0 and "ran nothing; left nothing" in _summary(caplog)

    run = tmp_path / "exps/exp/runs/prior/seed0"
    first = (run / "model_0.pt").stat().st_mtime
    (run / "model_1.pt").unlink()  # as if the sitting had been killed after the first checkpoint
    code, _ = _experiment(args, caplog)
    assert code == 0 and "ran prior@0;" in _summary(caplog) and (run / "model_1.pt").is_file()
    assert (run / "model_0.pt").stat().st_mtime == first  # continued from it, not restarted
    assert yaml.safe_load((run / "config.yaml").read_text())["resume"] == str(run / "model_0.pt")


def test_dry_run_prints_chains_and_writes_nothing(tmp_path, capsys, caplog):
    cells = {
        "prior": {"task": "flat", "iterations": 2},
        "spec": {"init": "prior", "iterations": 3, "legs": [{"iterations": 5, "overrides": ["seed=3"]}]},
    }
    exp = _write(tmp_path, cells)
    code, errors = _experiment([f"experiment={exp}", f"root={tmp_path / 'exps'}", "dry_run=true"], caplog)
    out = capsys.readouterr().out
    assert code == 0 and not errors
    assert out.index("prior@0") < out.index("spec@0") and "prior@0 (run)" in out
    assert "to train: 7 iterations" in out  # prior's 2 and spec's 5 (its last leg's count)
    assert f"init={tmp_path / 'exps/exp/runs/prior/seed0/model_1.pt'}" in out
    assert f"resume={tmp_path / 'exps/exp/runs/spec/seed0/model_2.pt'} max_iterations=5 seed=3" in out
    assert not (tmp_path / "exps").exists()


@pytest.mark.parametrize(
    "cells, extra, needle",
    [
        (
            {"a": {"init": "b", "iterations": 1}, "b": {"init": "a", "iterations": 1}},
            [],
            "cycle a -> b -> a",
        ),
        ({"a": {"init": "priorr", "iterations": 1}, "prior": {"iterations": 1}}, [], "did you mean prior"),
        ({"a": {"init": "/no/such/model_3.pt", "iterations": 1}}, [], "checkpoint not found: /no/such/model_3.pt"),
        ({"a": {"iterations": 1}}, ["hydra/launcher=nosuch"], "unknown hydra/launcher 'nosuch'"),
        ({"a": {"iterations": 1}}, ["hydra/launcher=joblib", "hydra.launcher.n_jobz=2"], "'hydra.launcher.n_jobz'"),
        ({"a": {"iterations": 1, "tsk": "flat"}}, [], "did you mean task"),
        ({"a": {"task": "flatt", "iterations": 1}}, [], "valid task options"),
        ({"a": {"task": "flat"}}, [], "give one budget"),
        ({"a": {"iterations": 1}}, ["max_minutes=-1307"], "max_minutes=-1307: must be >= 0"),
        ({"a": {"iterations": 1}}, ["torch_threads=0"], "torch_threads=0: must be >= 1"),
    ],
)
def test_bad_experiment_one_line_nothing_written(tmp_path, caplog, cells, extra, needle):
    exp = _write(tmp_path, cells)
    code, errors = _experiment([f"experiment={exp}", f"root={tmp_path / 'exps'}", *extra], caplog)
    assert code == 2 and len(errors) == 1 and needle in errors[0], errors
    assert not (tmp_path / "exps").exists()


@pytest.mark.parametrize(
    "table, needle",
    [
        ({"methods": {"Ours": "a"}, "table1": {}}, "row 'Ours' must be a list"),
        ({"methods": {"Ours": ["b"]}, "table1": {}}, "unknown cell 'b'"),
        ({"methods": {"Ours": ["a"]}}, "needs table1:, table2: and/or table3:"),
        ({"methods": {"Ours": ["a"]}, "table1": {}, "perception": "lidar", "live_workers": 0}, "live_workers must"),
        ({"methods": {"Ours": ["a"]}, "table1": {}, "live_workers": 2}, "needs perception: lidar"),
        ({"methods": {"Ours": {"manifest": "/no/such.yaml"}}, "table1": {}}, "manifest not found: /no/such.yaml"),
        ({"methods": {"No": {"manifest": str(REPO / "configs/eval/table1.yaml")}}, "table1": {}}, "no row 'No'"),
    ],
)
def test_bad_table_one_line_nothing_written(tmp_path, caplog, table, needle):
    exp = _write(tmp_path, {"a": {"iterations": 1}}, {"t": table})
    code, errors = _experiment([f"experiment={exp}", f"root={tmp_path / 'exps'}"], caplog)
    assert code == 2 and len(errors) == 1 and needle in errors[0], errors
    assert not (tmp_path / "exps").exists()


def test_a_row_from_an_eval_manifest_is_that_manifests_row(tmp_path, monkeypatch):
    """``{manifest: <eval manifest>}`` reads the row of the same name there, so a hand-picked row is defined once."""
    from cat.experiment.spec import load_experiment

    monkeypatch.chdir(REPO)
    manifest = tmp_path / "picked.yaml"
    row = {"crouch-pass": ["checkpoints/crouch_pass/model_599.pt"]}
    manifest.write_text(yaml.safe_dump({"methods": {"Picked": row, "Other": ["a"]}, "table1": {}}))
    table = {"methods": {"Picked": {"manifest": str(manifest)}, "Ours": ["a"]}, "table1": {}}
    spec = load_experiment(_write(tmp_path, {"a": {"iterations": 1}}, {"t": table}))
    assert spec.tables["t"].methods == {"Picked": row, "Ours": ["a"]}
    assert sorted(spec.tables["t"].references()) == ["a", "checkpoints/crouch_pass/model_599.pt"]
    shipped = load_experiment("table1").tables["specialists"].methods["Ours (specialists)"]
    assert shipped == yaml.safe_load((REPO / "configs/eval/table1.yaml").read_text())["methods"]["Ours (specialists)"]


def test_live_workers_reach_the_table_command_but_not_its_hash(tmp_path, capsys, caplog):
    """A LiDAR table's worker count is a speed setting: eval_table.py gets it, the table's identity ignores it."""
    from cat.experiment.plan import Plan
    from cat.experiment.spec import load_experiment

    hashes = []
    for workers in (1, 2):
        table = {"methods": {"Ours": ["a"]}, "table1": {}, "perception": "lidar", "live_workers": workers}
        exp = _write(tmp_path, {"a": {"iterations": 1}}, {"t": table})
        code, errors = _experiment([f"experiment={exp}", f"root={tmp_path / 'exps'}", "dry_run=true"], caplog)
        out = capsys.readouterr().out
        assert code == 0 and not errors and "perception=lidar" in out
        assert ("live_workers=2" in out) == (workers == 2)
        spec = load_experiment(exp)
        plan = Plan(spec, str(tmp_path / "exps"))
        hashes.append(plan.table_hash(spec.tables["t"]))
    assert hashes[0] is not None and hashes[0] == hashes[1]


def test_unknown_experiment_and_option(caplog):
    code, errors = _experiment(["experiment=nosuch"], caplog)
    assert code == 2 and len(errors) == 1 and "unknown experiment 'nosuch'" in errors[0] and "smoke" in errors[0]
    code, errors = _experiment(["experiment=smoke", "dryrun=true"], caplog)
    assert code == 2 and len(errors) == 1 and "did you mean dry_run" in errors[0]


def test_train_refuses_an_unknown_launcher(tmp_path, caplog):
    mod = load_script(REPO / "scripts" / "train.py")
    with caplog.at_level(logging.ERROR):
        code = mod.main(["-m", "task=flat", "seed=0,1", "hydra/launcher=rayy", f"run_root={tmp_path / 'runs'}"])
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert code == 2 and len(errors) == 1 and "unknown hydra/launcher 'rayy'" in errors[0] and "joblib" in errors[0]
    assert not (tmp_path / "runs").exists()


def test_joblib_runs_two_real_jobs_in_parallel_processes(tmp_path):
    sweep = tmp_path / "sweep"
    res = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "train.py"), "-m", "task=flat", "seed=0,1", *COMMON,
         "max_iterations=1", "torch_threads=1", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2",
         f"hydra.sweep.dir={sweep}"],
        capture_output=True, text=True, timeout=900, env={**os.environ, "PYTHONPATH": str(REPO)}, cwd=tmp_path,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    assert "Joblib.Parallel(n_jobs=2" in res.stderr
    seeds = [yaml.safe_load((sweep / k / "config.yaml").read_text())["seed"] for k in ("0", "1")]
    assert seeds == [0, 1] and all((sweep / k / "model_0.pt").is_file() for k in ("0", "1"))
    # each job ran in its own worker process: rsl_rl records the process in neither file, the job log line does
    assert res.stderr.count("INFO cat.launcher: job: train.py") == 2


@pytest.mark.slow
@pytest.mark.parametrize("launcher", ["joblib", "submitit_local"])
def test_smoke_end_to_end_then_nothing(tmp_path, launcher):
    def call() -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, str(REPO / "scripts" / "experiment.py"), "experiment=smoke", f"root={tmp_path}",
             f"hydra/launcher={launcher}"],
            capture_output=True, text=True, timeout=1800, env={**os.environ, "PYTHONPATH": str(REPO)},
        )  # fmt: skip

    res = call()
    assert res.returncode == 0 and "left nothing" in res.stderr, res.stderr[-3000:]
    assert (tmp_path / "smoke/tables/table1/trials.csv").is_file()
    res = call()
    assert res.returncode == 0 and "ran nothing; left nothing" in res.stderr, res.stderr[-3000:]


def _leaves(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict) and v:
            out.update(_leaves(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out


def test_shipped_recipes_compose_the_shipped_configs(tmp_path):
    """experiment=shipped: each cell's overrides (all legs) give its checkpoint's config.yaml, and its chain ends
    at the shipped model_<it>.pt."""
    from omegaconf import OmegaConf

    from cat.experiment.plan import VOLATILE, Plan
    from cat.experiment.spec import load_experiment
    from cat.learning.hydra_cfg import load_config
    from cat.learning.runs import load_run_config

    exp = load_experiment("shipped")
    plan = Plan(exp, str(tmp_path))
    shipped = sorted(
        p.name
        for p in (REPO / "checkpoints").iterdir()
        if (p / "config.yaml").is_file() and not (p / "average.yaml").is_file()  # averaged: next test
    )
    assert shipped and set(shipped) <= set(exp.cells)
    for name in shipped:
        unit = plan.units[f"{name}@0"]
        ckpt = REPO / "checkpoints" / name / unit.checkpoint().name
        assert ckpt.is_file(), f"{name}: the recipe ends at {ckpt.name}, not shipped"
        overrides = unit.base + [o for leg in unit.cell.legs for o in leg.overrides]
        mine = _leaves(OmegaConf.to_container(OmegaConf.structured(load_config(overrides))))
        theirs = _leaves(OmegaConf.to_container(OmegaConf.structured(load_run_config(ckpt))))
        keys = {k for k in set(mine) | set(theirs) if k.split(".")[0] not in VOLATILE and k != "seed"}
        if theirs.get("sim.obstacles") == "physical":  # field-judged contact's settings are inert in physical worlds
            keys = {k for k in keys if not k.startswith("sim.field_contact.")}
        assert {k: (mine.get(k), theirs.get(k)) for k in keys if mine.get(k) != theirs.get(k)} == {}, name


def test_averaged_checkpoints_are_their_recipe():
    """A shipped folder made by scripts/average.py (no training recipe) is reproduced by its average.yaml: the
    parents are shipped, the config is parent a's, and averaging them again gives the shipped weights (to float32
    rounding: re-expressing b's first layer in a's normaliser is a matrix product, whose summation order is the
    CPU's BLAS kernel's; on another CPU a bias may differ in its last bit, 1.2e-7, where the two parents differ by
    orders of magnitude more)."""
    import torch
    import yaml

    from cat.learning.average import average_states, network_pairs

    folders = sorted(p for p in (REPO / "checkpoints").iterdir() if (p / "average.yaml").is_file())
    assert folders, "no averaged checkpoint shipped (generalist_hybrid_v3, v4)"
    for folder in folders:
        note = yaml.safe_load((folder / "average.yaml").read_text())
        a, b = REPO / note["a"], REPO / note["b"]
        assert a.is_file() and b.is_file(), folder.name
        assert (folder / "config.yaml").read_text() == (a.parent / "config.yaml").read_text(), folder.name
        (model,) = folder.glob("model_*.pt")
        mine, ck_a, ck_b = (torch.load(p, weights_only=True) for p in (model, a, b))
        pairs = network_pairs(a, ck_a, b, ck_b)
        assert sorted(k for k in mine if k.endswith("_state_dict")) == sorted(ka for ka, _ in pairs), folder.name
        for ka, kb in pairs:
            again = average_states(ck_a[ka], ck_b[kb], float(note["alpha"]))
            for k in mine[ka]:
                torch.testing.assert_close(mine[ka][k], again[k], rtol=1e-6, atol=1e-6, msg=f"{folder.name}: {ka}.{k}")


def test_a_spent_sitting_leaves_the_rest_for_the_next(tmp_path, caplog, monkeypatch):
    import itertools

    import cat.experiment.runner as runner

    ticks = itertools.count(0.0, 1.0)  # each reading of the sitting's clock one second later: 0.6 ms is spent
    monkeypatch.setattr(runner, "clock", lambda: next(ticks))
    exp = _write(tmp_path, {"prior": {"task": "flat", "iterations": 1}, "spec": {"init": "prior", "iterations": 1}})
    code, errors = _experiment([f"experiment={exp}", f"root={tmp_path / 'exps'}", "max_minutes=0.00001"], caplog)
    assert code == 0 and not errors
    assert "ran nothing; left prior@0, spec@0" in _summary(caplog)
    assert not (tmp_path / "exps/exp/runs").exists()


def test_a_key_added_at_its_old_behaviour_keeps_the_run_hashes(tmp_path):
    """sim.field_storage came after runs were hashed: at float32 (what they did) it is left out of the hash, so
    unfinished runs still resume; another value is another run."""
    from cat.experiment.plan import Plan, _comparable
    from cat.experiment.spec import load_experiment
    from cat.learning.hydra_cfg import load_config

    assert "field_storage" not in _comparable(load_config([]))["sim"]
    assert _comparable(load_config(["sim.field_storage=compact"]))["sim"]["field_storage"] == "compact"
    # a nested key (task.episodes.goal_stand_radius) likewise
    assert "goal_stand_radius" not in _comparable(load_config(["task=scenes"]))["task"]["episodes"]
    on = _comparable(load_config(["task=scenes", "task.episodes.goal_stand_radius=0.24"]))
    assert on["task"]["episodes"]["goal_stand_radius"] == 0.24
    assert "max_noise_std" not in _comparable(load_config([]))["algo"]  # likewise algo.max_noise_std at 0
    assert _comparable(load_config(["algo.max_noise_std=0.5"]))["algo"]["max_noise_std"] == 0.5
    assert "warmup_bar_pitch" not in _comparable(load_config(["task=multi_hurdle"]))["task"]  # likewise, at false
    assert _comparable(load_config(["task=multi_hurdle", "task.warmup_bar_pitch=true"]))["task"]["warmup_bar_pitch"]
    hashes = []
    for storage in ("float32", "compact"):
        cells = {
            "prior": {"task": "flat", "iterations": 2},
            "same": {"task": "flat", "iterations": 2, "overrides": [f"sim.field_storage={storage}"]},
        }
        plan = Plan(load_experiment(_write(tmp_path, cells)), str(tmp_path / "exps"))
        hashes.append((plan.units["prior@0"].hash, plan.units["same@0"].hash))
    assert hashes[0][0] == hashes[0][1] == hashes[1][0] != hashes[1][1]


def test_field_contact_defaults_never_restart_a_physical_run(tmp_path):
    """A physical run's hash leaves sim.field_contact out; a state recorded in an earlier form of it (before keys were
    added) is re-keyed, for the run and for what reads it; a field run is re-keyed only if its judgement is the one
    that form stood for."""
    from cat.experiment.plan import FIELD_CONTACT_HASHED, Plan, _comparable
    from cat.experiment.spec import load_experiment
    from cat.learning.hydra_cfg import load_config

    assert "field_contact" not in _comparable(load_config([]))["sim"]
    assert "field_contact" in _comparable(load_config(["sim.obstacles=field"]))["sim"]
    old_field = ["sim.obstacles=field", "sim.field_contact.margin=0.005", "sim.field_contact.substeps=false",
                 "sim.field_contact.sdf=field", "sim.field_contact.cores=false"]  # fmt: skip
    cells = {
        "prior": {"task": "flat", "iterations": 2},
        "next": {"task": "flat", "iterations": 2, "init": "prior"},
        "old_field": {"task": "flat", "iterations": 2, "overrides": old_field},
        "new_field": {"task": "flat", "iterations": 2, "overrides": ["sim.obstacles=field"]},
    }
    plan = Plan(load_experiment(_write(tmp_path, cells)), str(tmp_path / "exps"))
    form = 0  # FIELD_CONTACT_HASHED[0]: {spacing, margin 0.005}
    assert FIELD_CONTACT_HASHED[form][0]["margin"] == 0.005
    earlier = {k: plan.unit_hash(u, form) for k, u in plan.units.items()}
    assert earlier["new_field@0"] is None  # its judgement is not that form's
    assert earlier["prior@0"] != plan.units["prior@0"].hash and earlier["next@0"] != plan.units["next@0"].hash
    for key, u in plan.units.items():
        u.run_dir.mkdir(parents=True)
        (u.run_dir / "model_1.pt").write_bytes(b"")  # the final checkpoint
        plan.state["units"][key] = {"hash": earlier[key] or "0123456789abcdef", "run_dir": str(u.run_dir)}
    status = {k: plan.status(u) for k, u in plan.units.items()}
    assert status == {"prior@0": "done", "next@0": "done", "old_field@0": "done", "new_field@0": "stale"}
    assert plan.state["units"]["prior@0"]["hash"] == plan.units["prior@0"].hash  # re-keyed


def test_every_hashed_train_key_is_recorded():
    """A key added to (or removed from) TrainCfg changes every run hash, so every unfinished run would restart as
    "changed" and finished ones be moved aside (it happened: algo.rehearsal). A new key must be declared in
    NEUTRAL_DEFAULTS at the value that reproduces what earlier runs did, or recorded here as a real change."""
    from cat.experiment.plan import NEUTRAL_DEFAULTS, VOLATILE, train_keys

    lines = (REPO / "tests/data/hashed_train_keys.txt").read_text().splitlines()
    recorded = {line for line in lines if not line.startswith("#")}
    hashed = {
        ".".join(k)
        for k in train_keys()
        if k[0] not in VOLATILE and not any(k[: len(n)] == n for n in NEUTRAL_DEFAULTS)
    }
    assert not hashed - recorded, f"TrainCfg keys not in NEUTRAL_DEFAULTS nor recorded: {sorted(hashed - recorded)}"
    assert not recorded - hashed, f"recorded keys TrainCfg no longer has: {sorted(recorded - hashed)}"
    assert ("algo", "rehearsal") in NEUTRAL_DEFAULTS  # rehearsal off is plain PPO, what runs before it did


def test_a_shipped_run_is_restored_in_a_fresh_clone_and_another_recipes_is_not(tmp_path, caplog, capsys):
    """experiments/ is not committed: a run shipped to <shipped>/<experiment>/<cell>/seed<k> is copied back into a
    fresh experiments folder (done, not trained again) and its downstream cell starts from it; a shipped folder of
    another recipe is left alone and that cell trains anew."""
    from cat.experiment.plan import Plan
    from cat.experiment.spec import load_experiment

    cells = {"prior": {"task": "flat", "iterations": 2}, "other": {"task": "flat", "iterations": 1}}
    path = tmp_path / "exp.yaml"
    spec = {"common": COMMON, "cells": cells, "shipped": str(tmp_path / "shipped")}
    path.write_text(yaml.safe_dump(spec))
    plan = Plan(load_experiment(str(path)), str(tmp_path / "first"))
    train, ship = load_script(REPO / "scripts" / "train.py"), load_script(REPO / "scripts" / "ship.py")
    for name, extra in (("prior", []), ("other", ["algo.entropy_coef=0.01"])):  # "other": not its recipe
        unit = plan.units[f"{name}@0"]
        run = unit.run_dir
        assert train.main([*plan.fresh_overrides(unit), *extra]) == 0
        assert ship.main([f"checkpoint={run}", f"out={tmp_path / 'shipped/exp' / name / 'seed0'}"]) == 0
    shipped = (tmp_path / "shipped/exp/prior/seed0/model_1.pt").read_bytes()

    cells["next"] = {"task": "flat", "init": "prior", "iterations": 1}
    path.write_text(yaml.safe_dump(spec))
    args = [f"experiment={path}", f"root={tmp_path / 'exps'}"]
    code, _ = _experiment([*args, "dry_run=true"], caplog)
    out = capsys.readouterr().out
    assert code == 0 and f"prior@0 (restore {tmp_path / 'shipped/exp/prior/seed0'}: done)" in out
    assert "other@0 (run)" in out and not (tmp_path / "exps").exists()
    code, errors = _experiment(args, caplog)
    assert code == 0 and not errors
    assert "ran other@0, next@0; left nothing" in _summary(caplog)
    assert "other@0: " in caplog.text and "is another recipe's run: not restored" in caplog.text
    run = tmp_path / "exps/exp/runs"
    assert (run / "prior/seed0/model_1.pt").read_bytes() == shipped  # the shipped file, not a retrained one
    assert not (run / "prior/seed0/model_0.pt").exists()
    assert yaml.safe_load((run / "next/seed0/config.yaml").read_text())["init"] == str(run / "prior/seed0/model_1.pt")


def test_a_shipped_chain_is_restored_under_another_root(tmp_path, caplog, capsys):
    """A chained cell trained under one experiment root records its init under that root; shipped, it is still
    its own run under another root (the same upstream run's file), so a fresh clone restores the whole chain
    whatever ``root=`` it runs with. An init naming another upstream run is not adopted."""
    from cat.experiment.plan import Plan
    from cat.experiment.spec import load_experiment

    cells = {"prior": {"task": "flat", "iterations": 2}, "next": {"task": "flat", "init": "prior", "iterations": 1}}
    path = tmp_path / "exp.yaml"
    spec = {"common": COMMON, "cells": cells, "shipped": str(tmp_path / "shipped")}
    path.write_text(yaml.safe_dump(spec))
    plan = Plan(load_experiment(str(path)), str(tmp_path / "first"))
    train, ship = load_script(REPO / "scripts" / "train.py"), load_script(REPO / "scripts" / "ship.py")
    for name in ("prior", "next"):
        unit = plan.units[f"{name}@0"]
        assert train.main(plan.fresh_overrides(unit)) == 0
        assert ship.main([f"checkpoint={unit.run_dir}", f"out={tmp_path / 'shipped/exp' / name / 'seed0'}"]) == 0
    recorded = yaml.safe_load((tmp_path / "shipped/exp/next/seed0/config.yaml").read_text())["init"]
    assert recorded == str(tmp_path / "first/exp/runs/prior/seed0/model_1.pt")

    other = Plan(load_experiment(str(path)), str(tmp_path / "exps"))
    assert other.same_input(recorded, other.path_of("prior@0"))
    assert not other.same_input(recorded.replace("/prior/", "/elsewhere/"), other.path_of("prior@0"))
    code, _ = _experiment([f"experiment={path}", f"root={tmp_path / 'exps'}", "dry_run=true"], caplog)
    out = capsys.readouterr().out
    assert code == 0 and "another recipe" not in caplog.text
    for name in ("prior", "next"):
        assert f"{name}@0 (restore {tmp_path / 'shipped/exp' / name / 'seed0'}: done)" in out, out
