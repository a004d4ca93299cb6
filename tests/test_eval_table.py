"""scripts/eval_table.py end to end with real rsl_rl checkpoints and MuJoCo: hold reference, determinism,
tables recomputed from trials.csv, bad input, atomic output; the run's scene seed."""

from __future__ import annotations

import csv
import importlib.util
import logging
import math
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from cat.eval import evaluate as evaluate_mod
from cat.eval.evaluate import EvalTableCfg, evaluate, scene_groups
from cat.eval.manifest import ManifestError, load_manifest
from cat.eval.runner import run_scene_group
from cat.eval.table import render_by_scene
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import load_run_config, make_env, train
from cat.terrain import TYPICAL_KINDS, make_typical, typical_variants

REPO = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("eval_table_script", REPO / "scripts" / "eval_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory) -> list[Path]:
    """Two 1-iteration flat PPO runs (training seeds 0 and 1)."""
    root = tmp_path_factory.mktemp("runs")
    out = []
    for seed in (0, 1):
        cfg = load_config(
            ["task=flat", "num_envs=8", "max_iterations=1", f"run_root={root}", "algo.num_steps_per_env=8"]
            + [f"seed={seed}", f"run_name=s{seed}"]
        )
        out.append(sorted(train(cfg).glob("model_*.pt"))[-1])
    return out


@pytest.fixture(scope="module")
def scene_dirs(tmp_path_factory) -> dict[str, Path]:
    """Two one-scene folders standing in for Table II's easy / hard sets."""
    root = tmp_path_factory.mktemp("unseen")
    dirs = {}
    for name, kind, d in (("easy", "side-pass", 0.0), ("hard", "hurdle-crouch", 1.0)):
        make_typical(kind, d, seed=11).save(root / name / "s0")
        dirs[name] = root / name
    return dirs


def _manifest(path: Path, **content) -> Path:
    path.write_text(yaml.safe_dump(content))
    return path


def _rows(folder: Path) -> list[dict]:
    with open(folder / "trials.csv") as f:
        return list(csv.DictReader(f))


def test_hold_on_every_typical_type(tmp_path):
    """Zero actions: never a success on any type. Over 5 s the passive G1 topples (its ankle PD stiffness is
    below m·g·h), so DE <= the start distance; in the first 0.5 s it stands: DE within 5 cm of it."""
    man = _manifest(tmp_path / "m.yaml", methods={"Hold": ["hold"]}, table1={"scene_seed": 0, "variants": 1})
    for time_s in (5.0, 0.5):
        rows, _ = evaluate(EvalTableCfg(manifest=str(man), out=str(tmp_path / "o"), trials_per_scene=2, time_s=time_s))
        assert sorted({r["group"] for r in rows}) == sorted(TYPICAL_KINDS) and len(rows) == 16
        for r in rows:
            d0 = math.hypot(float(r["goal_x"]) - float(r["start_x"]), float(r["goal_y"]) - float(r["start_y"]))
            de = float(r["de"])
            assert r["success"] == "0" and r["reach_time"] == ""
            assert de <= d0 + 1e-3, r
            if time_s == 0.5:
                assert abs(de - d0) <= 0.05 and r["fell"] == "0", r
        if time_s == 5.0:
            assert sum(r["fell"] == "1" for r in rows) >= 12  # most topple within 5 s


def _cells(md: str) -> dict[tuple[str, str], tuple[float, float, float, float]]:
    """(method, column) -> (SR, SR std, DE, DE std) parsed from a rendered Markdown table."""
    out = {}
    cols: list[str] = []
    for line in md.splitlines():
        if line.startswith("| Method"):
            cols = [c.strip().rsplit(" ", 3)[0] for c in line.strip("|").split("|")[1::2]]
        elif line.startswith("| ") and cols:
            cells = [c.strip().strip("*") for c in line.strip().strip("|").split("|")]
            for i, col in enumerate(cols):
                sr, de = cells[1 + 2 * i], cells[2 + 2 * i]
                (a, b), (c, d) = (tuple(float(x) for x in v.split(" ± ")) for v in (sr, de))
                out[cells[0], col] = (a, b, c, d)
    return out


def _recompute(rows: list[dict], table: str) -> dict[tuple[str, str], tuple[float, float, float, float]]:
    """Independent recomputation of the documented aggregation from trials.csv."""
    out = {}
    rows = [r for r in rows if r["table"] == table]
    for method in {r["method"] for r in rows}:
        mine = [r for r in rows if r["method"] == method]
        by_seed = len({r["seed"] for r in mine}) >= 2
        for group in {r["group"] for r in mine}:
            units: dict[str, list[dict]] = {}
            for r in mine:
                if r["group"] == group:
                    units.setdefault(r["seed"] if by_seed else r["scene"], []).append(r)
            sr = [100 * np.mean([int(r["success"]) for r in u]) for u in units.values()]
            de = [np.mean([float(r["de"]) for r in u]) for u in units.values()]

            def sd(v):
                return statistics.stdev(v) if len(v) > 1 else 0.0

            title = "-".join(w.capitalize() for w in group.split("-"))
            out[method, title] = (np.mean(sr), sd(sr), np.mean(de), sd(de))
    return out


def test_tables_are_deterministic_and_recomputable(tmp_path, checkpoints, scene_dirs):
    man = _manifest(
        tmp_path / "m.yaml",
        methods={"Ours": [str(c) for c in checkpoints], "Hold": ["hold"]},
        table1={"scene_seed": 0, "variants": 1},
        table2={k: str(v) for k, v in scene_dirs.items()},
    )
    outs = []
    for k in range(2):
        out = tmp_path / f"out{k}"
        res = subprocess.run(
            # 1 s trials keep the test short; determinism and aggregation do not depend on the window
            [
                sys.executable,
                "scripts/eval_table.py",
                f"manifest={man}",
                f"out={out}",
                "trials_per_scene=1",
                "time_s=1",
            ],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert res.returncode == 0, res.stderr[-3000:]
        outs.append(out)
    assert (outs[0] / "trials.csv").read_text() == (outs[1] / "trials.csv").read_text()
    assert "| Ours |" in res.stdout and "Table II" in res.stdout
    rows = _rows(outs[0])
    assert set(rows[0]) >= {"method", "seed", "table", "group", "scene", "goal", "success", "de", "collided", "fell",
                            "reach_time"}  # fmt: skip
    assert len(rows) == 3 * (8 + 2)  # 3 checkpoints x (8 typical + 2 unseen scenes) x 1 start
    for table in ("table1", "table2"):
        md = (outs[0] / f"{table}.md").read_text()
        got, want = _cells(md), _recompute(rows, table)
        assert set(got) == set(want)
        for key, (sr, sr_sd, de, de_sd) in want.items():
            assert got[key] == pytest.approx((round(sr, 1), round(sr_sd, 1), round(de, 2), round(de_sd, 2)), abs=1e-9)
        assert "Ours: over training seeds, n = 2" in md and "Hold: over scenes (one checkpoint), n = 1" in md
        tex = (outs[0] / f"{table}.tex").read_text()
        assert "\\begin{tabular}" in tex and "\\bottomrule" in tex and "$\\pm$" in tex
        # best DE per column is bold in both renderings
        for line in md.splitlines():
            if line.startswith("| Ours") or line.startswith("| Hold"):
                assert line.count("**") % 2 == 0


def _run_script(args: list[str], caplog) -> tuple[int, str]:
    caplog.clear()
    with caplog.at_level(logging.ERROR):
        code = _script().main(args)
    return code, " ".join(r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR)


def _broken_layout(checkpoint: Path, tmp_path: Path) -> Path:
    """A copy of a run whose config.yaml lists one observation term fewer than its weights were trained on."""
    run = tmp_path / "edited_run"
    shutil.copytree(checkpoint.parent, run)
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    cfg["task"]["observations"]["actor"]["terms"].remove("gait_phase")
    (run / "config.yaml").write_text(yaml.safe_dump(cfg))
    return run / checkpoint.name


def test_per_type_row_plays_each_column_with_its_own_checkpoint(tmp_path, checkpoints, scene_dirs):
    """A row of specialists: each listed Table I column is played by that type's checkpoint on the same trials
    as the other rows; unlisted columns and Table II stay empty."""
    a, b = (str(c) for c in checkpoints)
    man = _manifest(
        tmp_path / "m.yaml",
        methods={"Spec": {"side-pass": [a], "hurdle-crouch": [b]}, "Ours": [a]},
        table1={"scene_seed": 0, "variants": 1},
        table2={"easy": str(scene_dirs["easy"])},
    )
    rows, files = evaluate(
        EvalTableCfg(manifest=str(man), out=str(tmp_path / "o"), trials_per_scene=2, time_s=0.5, max_envs=4)
    )
    spec = [r for r in rows if r["method"] == "Spec"]
    assert sorted((r["group"], r["checkpoint"]) for r in spec) == sorted(
        [("hurdle-crouch", b)] * 2 + [("side-pass", a)] * 2
    )
    assert all(r["table"] == "table1" for r in spec)
    start = ("scene", "goal", "start", "start_x", "start_y", "start_yaw")
    ours = {(r["group"], *(r[k] for k in start)): r for r in rows if r["method"] == "Ours"}
    for r in spec:  # same trials as the full row; side-pass is the very same checkpoint, so the same outcome
        twin = ours[(r["group"], *(r[k] for k in start))]
        if r["group"] == "side-pass":
            assert (r["success"], r["de"], r["fell"]) == (twin["success"], twin["de"], twin["fell"])
    t1 = files["table1.md"]
    spec_lines = [line for line in t1.splitlines() if line.startswith("| Spec |")]
    assert len(spec_lines) == 2 and all(line.count("–") == 6 for line in spec_lines)  # 3 of 4 columns per block
    assert "Spec: each column played by that type's own checkpoint(s)" in t1
    assert "| Spec |" not in files["table2.md"] and "| Ours |" in files["table2.md"]
    by_scene = [line for line in files["table2_by_scene.md"].splitlines() if line.startswith("| Easy |")]
    assert by_scene and all(line.count("|") == 5 for line in by_scene)  # column, scene, trials, Ours


def test_unseen_shapes_table_plays_other_scenes_of_the_same_layouts(tmp_path):
    """``table1: {shapes: unseen}`` plays the typical layouts built from unseen obstacle shapes: the same starts and
    goals as the paper shapes' table, other scenes (meshes), and the caption says which scenes they are."""
    base = {"methods": {"Hold": ["hold"]}}
    paper = _manifest(tmp_path / "p.yaml", **base, table1={"scene_seed": 1000, "variants": 1})
    unseen = _manifest(tmp_path / "u.yaml", **base, table1={"scene_seed": 1000, "variants": 1, "shapes": "unseen"})
    (a, _), (b, files) = (
        evaluate(EvalTableCfg(manifest=str(m), out=str(tmp_path / m.stem), trials_per_scene=1, time_s=0.6))
        for m in (paper, unseen)
    )
    assert [(r["group"], r["start_x"], r["goal_x"]) for r in a] == [(r["group"], r["start_x"], r["goal_x"]) for r in b]
    groups = [scene_groups(load_manifest(m))["table1"] for m in (paper, unseen)]
    for g_paper, g_unseen in zip(*groups, strict=True):
        assert g_paper.name == g_unseen.name and g_unseen.scenes[0].meta["shapes"] == "unseen"
        assert not np.array_equal(g_paper.scenes[0].mesh.vertices, g_unseen.scenes[0].mesh.vertices)
    assert "built from unseen obstacle shapes (scene seeds 1000..1000)" in files["table1.md"]


@pytest.mark.parametrize("name", ["table1", "typical_unseen"])
def test_shipped_table1_manifest_names_shipped_checkpoints(monkeypatch, name):
    """configs/eval/table1.yaml (and its unseen-shapes twin) stays in step with checkpoints/ (a re-shipped
    specialist renames its file)."""
    monkeypatch.chdir(REPO)  # the manifest's paths are relative to the repository root
    man = load_manifest(REPO / "configs" / "eval" / f"{name}.yaml")
    assert man.table1 is not None and all(Path(r.checkpoint).is_file() for rs in man.methods.values() for r in rs)
    kinds = {r.kind for r in man.methods["Ours (specialists)"]}
    assert kinds <= set(TYPICAL_KINDS) and len(kinds) >= 4


def test_bad_input_names_the_problem_and_writes_nothing(tmp_path, checkpoints, scene_dirs, caplog):
    ok = str(checkpoints[0])
    empty = tmp_path / "empty"
    empty.mkdir()
    edited = str(_broken_layout(checkpoints[0], tmp_path))
    cases = {
        "missing": ({"methods": {"A": [str(tmp_path / "nope" / "model_9.pt")]}, "table1": {}}, "checkpoint not found"),
        "unknown_method": ({"methods": {"A": ["ppo_baseline"]}, "table1": {}}, "unknown method 'ppo_baseline'"),
        "unknown_key": ({"methods": {"A": [ok]}, "table4": {}}, "unknown manifest key 'table4'"),
        "unknown_t1": ({"methods": {"A": [ok]}, "table1": {"scene_sed": 0}}, "unknown table1 key 'scene_sed'"),
        "bad_shapes": (
            {"methods": {"A": [ok]}, "table1": {"shapes": "novel"}},
            "table1 shapes must be one of paper, unseen, got 'novel'",
        ),
        "empty_dir": (
            {"methods": {"A": [ok]}, "table2": {"easy": str(empty)}},
            f"no scenes (scene.json) under {empty}",
        ),
        "row_layouts": ({"methods": {"A": [ok, edited]}, "table1": {}}, f"checkpoint {edited} observation layout"),
        "ckpt_layout": ({"methods": {"A": [edited]}, "table1": {}}, f"checkpoint {edited} does not fit"),
        "unknown_type": ({"methods": {"A": {"hurdle": [ok]}}, "table1": {}}, "method 'A': unknown scene type 'hurdle'"),
        "per_type_t2": (
            {"methods": {"A": {"side-pass": [ok]}}, "table2": {"easy": str(scene_dirs["easy"])}},
            "method 'A' gives a checkpoint per scene type, which only table1 has",
        ),
        "type_layouts": (
            {"methods": {"A": {"side-pass": [ok, edited]}}, "table1": {}},
            f"method 'A' type 'side-pass': checkpoint {edited} observation layout",
        ),
    }
    for name, (content, message) in cases.items():
        man = _manifest(tmp_path / f"{name}.yaml", **content)
        out = tmp_path / f"out_{name}"
        code, err = _run_script([f"manifest={man}", f"out={out}"], caplog)
        assert code == 2 and message in err, (name, err)
        assert not out.exists(), name
    with pytest.raises(ManifestError, match="manifest not found"):
        evaluate(EvalTableCfg(manifest=str(tmp_path / "none.yaml"), out=str(tmp_path / "o")))
    code, err = _run_script(["manifest=x.yaml", "outt=y"], caplog)
    assert code == 2 and "unknown key 'outt'; did you mean out?" in err


def test_a_column_of_linked_scene_folders_is_accepted(tmp_path, checkpoints, scene_dirs):
    """A Table II column may be a folder of symbolic links to scene folders (a split of a generated set, as
    experiment=table2's held-out procedural columns): the manifest finds them as the runner does."""
    linked = tmp_path / "linked"
    linked.mkdir()
    (linked / "s0").symlink_to(scene_dirs["easy"] / "s0", target_is_directory=True)
    man = load_manifest(
        _manifest(tmp_path / "m.yaml", methods={"A": [str(checkpoints[0])]}, table2={"easy": str(linked)})
    )
    assert man.table2 == {"easy": str(linked)}


def test_failure_during_evaluation_leaves_no_output(tmp_path, monkeypatch, caplog, scene_dirs):
    """An error after some trials ran (here: injected into the second column's run) writes nothing."""
    man = _manifest(tmp_path / "m.yaml", methods={"Hold": ["hold"]}, table2={k: str(v) for k, v in scene_dirs.items()})
    out = tmp_path / "out"
    real, calls = evaluate_mod.run_trials, []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise ValueError("simulated failure in the second column")
        return real(*args, **kwargs)

    monkeypatch.setattr(evaluate_mod, "run_trials", failing)
    code, err = _run_script([f"manifest={man}", f"out={out}", "trials_per_scene=1"], caplog)
    assert code == 2 and "simulated failure" in err and len(calls) == 2
    assert not out.exists()
    # an earlier complete output is left as it was
    monkeypatch.setattr(evaluate_mod, "run_trials", real)
    assert _run_script([f"manifest={man}", f"out={out}", "trials_per_scene=1"], caplog)[0] == 0
    before = {p.name: p.read_text() for p in out.iterdir()}
    calls.clear()
    monkeypatch.setattr(evaluate_mod, "run_trials", failing)
    assert _run_script([f"manifest={man}", f"out={out}", "trials_per_scene=1"], caplog)[0] == 2
    assert {p.name: p.read_text() for p in out.iterdir()} == before


def test_scene_seed_is_not_the_rl_seed(tmp_path):
    """Typical scenes come from task.scene_seed; the RL seed does not change them; play/eval rebuild them."""
    base = [
        "task=hurdle_crouch",
        "task.scene_variants=2",
        "task.warmup_variants=0",
        "num_envs=2",
        f"run_root={tmp_path}",
    ]
    a = make_env(load_config([*base, "seed=5", "task.scene_seed=3"]))
    b = make_env(load_config([*base, "seed=6", "task.scene_seed=3"]))
    want = typical_variants("hurdle-crouch", 2, 3)
    for env in (a, b):
        for got, ref in zip(env.scenes.scenes, want, strict=True):
            np.testing.assert_array_equal(got.mesh.vertices, ref.mesh.vertices)
    group = run_scene_group(load_config([*base, "seed=5", "task.scene_seed=3"]).task)
    for got, ref in zip(group.scenes, want, strict=True):
        np.testing.assert_array_equal(got.mesh.vertices, ref.mesh.vertices)
    other = run_scene_group(load_config([*base, "task.scene_seed=3"]).task, scene_seed=4)
    assert not np.array_equal(other.scenes[0].mesh.vertices, want[0].mesh.vertices)


def test_old_run_configs_keep_their_scenes(tmp_path):
    """A config.yaml from before task.scene_seed: its scenes were built from the RL seed, so that is kept."""
    run = tmp_path / "old"
    run.mkdir()
    (run / "model_0.pt").write_bytes(b"")
    cfg = {"seed": 7, "task": {"task": "hurdle_crouch", "scene_kind": "hurdle-crouch"}}
    (run / "config.yaml").write_text(yaml.safe_dump(cfg))
    assert load_run_config(run / "model_0.pt").task.scene_seed == 7
    cfg["task"]["scene_seed"] = 2
    (run / "config.yaml").write_text(yaml.safe_dump(cfg))
    assert load_run_config(run / "model_0.pt").task.scene_seed == 2


def test_generalist_runs_are_evaluated_one_group_at_a_time():
    """A run over several typical groups names the group to evaluate; each group gives its own kind's variants."""
    task = load_config(["task=generalist", "task.scene_variants=2", "task.scene_groups=[crouch-pass,side-pass]"]).task
    with pytest.raises(ValueError, match=r"several scene groups \['crouch-pass', 'side-pass'\].*scene_kind="):
        run_scene_group(task)
    for kind in ("crouch-pass", "side_pass"):
        group = run_scene_group(task, scene_kind=kind)
        want = typical_variants(kind.replace("_", "-"), 2, task.scene_seed)
        assert [s.kind for s in group.scenes] == [kind.replace("_", "-")] * 2
        for got, ref in zip(group.scenes, want, strict=True):
            np.testing.assert_array_equal(got.mesh.vertices, ref.mesh.vertices)
    assert task.scene_groups == ["crouch-pass", "side-pass"]  # the run's config is left as it was
    with pytest.raises(ValueError, match="scene_kind='stairs' is not a typical kind"):
        run_scene_group(task, scene_kind="stairs")


def test_by_scene_breakdown_counts_each_scenes_trials():
    """The per-scene table: SR, contact and fall per (column, scene, method) from the trial rows alone; a method
    that did not play a scene shows –, and the trial count of each scene is printed."""

    def row(method, group, scene, success, collided, fell):
        return {
            "table": "table2",
            "method": method,
            "group": group,
            "scene": scene,
            "success": str(success),
            "collided": str(collided),
            "fell": str(fell),
        }

    rows = [
        row("A", "easy", "s1", 1, 0, 0),
        row("A", "easy", "s1", 0, 1, 1),
        row("A", "easy", "s1", 0, 1, 0),
        row("A", "easy", "s1", 1, 0, 0),
        row("B", "easy", "s1", 0, 0, 1),
        row("B", "easy", "s1", 0, 0, 1),
        row("B", "easy", "s1", 1, 0, 0),
        row("B", "easy", "s1", 1, 0, 0),
        row("A", "hard", "s2", 0, 1, 0),
        {**row("A", "easy", "s1", 1, 0, 0), "table": "table1"},
    ]
    md = render_by_scene(rows, "table2", ["A", "B"], ["easy", "hard"])
    lines = [line for line in md.splitlines() if line.startswith("| Easy") or line.startswith("| Hard")]
    assert lines == ["| Easy | s1 | 4 | 50 (50 / 25) | 50 (0 / 50) |", "| Hard | s2 | 1 | 0 (100 / 0) | – |"]


def test_clearance_adds_the_contact_depth_report(tmp_path, checkpoints, scene_dirs):
    """clearance=true: the same trials (trials.csv unchanged), plus clearance.md with one line per (row, column)
    whose physical SR agrees with trials.csv; refused with perception in the loop."""
    man = _manifest(tmp_path / "m.yaml", methods={"Hold": ["hold"]}, table2={k: str(v) for k, v in scene_dirs.items()})
    base = EvalTableCfg(manifest=str(man), out=str(tmp_path / "o"), trials_per_scene=2, time_s=0.5)
    rows, files = evaluate(base)
    rows_c, files_c = evaluate(EvalTableCfg(**{**base.__dict__, "clearance": True}))
    assert rows_c == rows and "clearance.md" not in files
    lines = [x for x in files_c["clearance.md"].splitlines() if x.startswith("- ")]
    assert [x.split(":")[0] for x in lines] == ["- Hold / table2 / easy", "- Hold / table2 / hard"]
    for line in lines:
        assert line.split(": ", 1)[1].startswith("success=0.000 tolerant_success=1cm:")
    with pytest.raises(ManifestError, match="clearance=true .* needs perception=ground_truth"):
        evaluate(EvalTableCfg(**{**base.__dict__, "clearance": True, "perception": "lidar"}), live=object())
