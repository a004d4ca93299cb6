"""The Table I equal-budget protocol (configs/experiment/table1.yaml, docs/evaluation.md): every baseline row is
trained like Ours but for its method, and each method's env reads and rewards what docs/baselines.md says."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from cat.experiment.plan import Plan
from cat.experiment.spec import ExperimentError, load_experiment
from cat.learning.hydra_cfg import load_config
from cat.learning.runs import make_env

ROWS = ["ASTraversal", "Humanoid Parkour", "Ours w/o OBS_field", "Ours w/o R_field", "Ours"]
EXPERIMENT = Path(__file__).resolve().parents[1] / "configs" / "experiment" / "table1.yaml"


def _row_cell(table, row: str, column: str = "crouch-pass") -> str:
    return table.methods[row][column][0]


COLUMNS = {"crouch-pass": "crouch_pass", "side-crouch": "side_crouch", "side-pass": "side_pass"}  # -> its task


def test_every_row_has_the_same_budget_scenes_prior_and_trials():
    """One policy per (method, type): in each column every row trains the same task from the same prior."""
    exp = load_experiment("table1")
    table = exp.tables["table1"]
    assert table.equal_budget == ROWS
    assert list(table.methods)[:5] == ROWS and "Ours (specialists)" in table.methods
    columns = {tuple(table.methods[r]) for r in ROWS}
    assert columns == {tuple(COLUMNS)}
    plan = Plan(exp, root="/nonexistent")
    names = {_row_cell(table, r) for r in ROWS}
    units = [u for u in plan.units.values() if u.cell.name in names]
    assert {u.iterations for u in units} == {1018}  # 25 M env steps at 1024 envs x 24 steps
    assert {u.inputs["init"] for u in units} == {"checkpoints/flat/model_770.pt"}
    assert {exp.cells[n].task for n in names} == {"crouch_pass"}
    seeds = {r: exp.cells[_row_cell(table, r)].seeds for r in ROWS}
    two = ("Ours", "Ours w/o OBS_field", "Ours w/o R_field")  # Ours and the strongest baselines (paper's, ours)
    assert all(seeds[r] == [0, 1] for r in two)
    assert all(s == [0] for r, s in seeds.items() if r not in two)
    methods = {exp.cells[_row_cell(table, r)].method for r in ROWS}
    assert methods == {"ours", "wo_obs_field", "wo_r_field", "astraversal", "humanoid_parkour"}


@pytest.mark.parametrize("column,before", [("side-crouch", "crouch-pass"), ("side-pass", "side-crouch")])
def test_a_later_column_continues_each_rows_own_run_of_the_column_before(column, before):
    """Every row's cell starts from that row's own cell of the column before (same seed) for 25 M more env steps."""
    exp = load_experiment("table1")
    table = exp.tables["table1"]
    plan = Plan(exp, root="/nonexistent")
    for row in ROWS:
        cell = exp.cells[_row_cell(table, row, column)]
        first = _row_cell(table, row, before)
        assert cell.init == first and cell.task == COLUMNS[column] and cell.method == exp.cells[first].method
        assert set(cell.seeds) <= set(exp.cells[first].seeds)  # each seed continues its own run
        assert cell.env_steps == 25_000_000 and cell.overrides == ["task.mirror_scenes=true"]
        for seed in cell.seeds:
            unit = plan.units[f"{cell.name}@{seed}"]
            assert unit.inputs["init"] == f"{first}@{seed}"  # its own first-column run of the same seed


def test_the_dry_run_counts_the_iterations_to_train(tmp_path):
    """An env-step budget is an iteration count: nothing trained or shipped, every run of the experiment is left to
    do; the shipped runs (restored by the runner) are not."""
    from cat.experiment.restore import restorable
    from cat.experiment.runner import ExperimentCfg, Runner

    runner = Runner(ExperimentCfg(experiment="table1", root=str(tmp_path)), [])
    units = runner.plan.units_of(runner.cells)
    budgeted = [u for u in units if u.cell.env_steps]  # iterations = ceil(env steps / (1,024 envs x 24 steps))
    assert all(u.final == math.ceil(u.cell.env_steps / (1024 * 24)) for u in budgeted)
    assert {u.final for u in budgeted if u.cell.env_steps == 25_000_000} == {1018}
    shipped = {u.key: found[0] + 1 for u in units if (found := restorable(runner.plan, u))}
    assert "ours_crouch_pass@0" in shipped  # the column's shipped runs
    left = sum(u.final - shipped.get(u.key, 0) for u in units)
    assert runner.describe().endswith(f"to train: {left} iterations (cells with a minutes budget not counted)")
    runner.exp.shipped = str(tmp_path / "nothing_shipped")
    assert runner.describe().endswith(
        f"to train: {sum(u.final for u in units)} iterations (cells with a minutes budget not counted)"
    )


def test_the_first_protocol_stays_loadable_as_its_record():
    """experiment=table1_all_types: one policy per method over all eight types (the 0 % finding of 2026-12-04)."""
    exp = load_experiment("table1_all_types")
    assert exp.cells["ours"].task == "typical" and exp.cells["ours"].env_steps == 25_000_000
    assert exp.tables["table1"].equal_budget == ["Ours"]


def _variant(tmp_path, edit) -> str:
    raw = yaml.safe_load(EXPERIMENT.read_text())
    edit(raw)
    path = tmp_path / "table1.yaml"
    path.write_text(yaml.safe_dump(raw))
    return str(path)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda r: r["cells"]["astraversal_crouch_pass"].update(overrides=["task.scene_variants=5"]),
         r"column 'crouch-pass': row 'ASTraversal' \(cell astraversal_crouch_pass\) differs from .* in overrides"),
        (lambda r: r["cells"]["wo_r_field_crouch_pass"].update(env_steps=30_000_000),
         r"row 'Ours w/o R_field' \(cell wo_r_field_crouch_pass\) differs .* in env_steps: 30000000 vs 25000000"),
        (lambda r: r["cells"]["humanoid_parkour_crouch_pass"].update(init="checkpoints/flat/model_501.pt"),
         r"row 'Humanoid Parkour' .* in init"),
        (lambda r: r["cells"]["humanoid_parkour_crouch_pass"].update(task="hurdle_pass"),
         r"row 'Humanoid Parkour' .* in task"),
        (lambda r: r["cells"]["astraversal_crouch_pass"].update(seeds=[1]),
         r"trains seeds \[1\], not a prefix of \[0, 1\]"),
        (lambda r: (r["cells"]["ours_crouch_pass"].pop("env_steps"), r["cells"]["ours_crouch_pass"].update(minutes=60)),
         r"row 'Ours' \(cell ours_crouch_pass\) has a minutes budget"),
        (lambda r: r["tables"]["table1"]["methods"].update({"Ours": ["ours_crouch_pass"]}),
         r"row 'Ours' \(one cell\) is not shaped like row 'ASTraversal' "
         r"\(types \['crouch-pass', 'side-crouch', 'side-pass'\]\)"),
        (lambda r: r["tables"]["table1"]["methods"].update(
            {"Ours": {"crouch-pass": ["ours_crouch_pass", "wo_r_field_crouch_pass"]}}),
         r"row 'Ours', column 'crouch-pass', must be one cell"),
        (lambda r: r["tables"]["table1"]["equal_budget"].append("Ours (generalist)"),
         r"equal_budget names 'Ours \(generalist\)', not a row"),
        (lambda r: r["cells"]["astraversal_side_crouch"].update(init="ours_crouch_pass"),
         r"column 'side-crouch': row 'ASTraversal' \(cell astraversal_side_crouch\) differs .* in init: "
         r"'ours_crouch_pass' vs \"the row's own crouch-pass cell\""),
        (lambda r: r["cells"]["humanoid_parkour_side_crouch"].update(init="checkpoints/crouch_pass/model_599.pt"),
         r"row 'Humanoid Parkour' \(cell humanoid_parkour_side_crouch\) differs .* in init"),
    ],
)  # fmt: skip
def test_a_row_that_differs_is_refused_naming_the_difference(tmp_path, edit, message):
    with pytest.raises(ExperimentError, match=message):
        load_experiment(_variant(tmp_path, edit))


SHARED = ["gyro", "projected_gravity", "joint_pos", "joint_vel", "last_action", "leg_targets", "goal_command",
          "gait_phase"]  # fmt: skip
PRIVILEGED = ["base_lin_vel", "base_height", "link_positions", "foot_contacts", "dr_scales"]
# docs/baselines.md, on the typical task (the episode ends at the first contact: collision 0 unless a method sets it)
DOCUMENTED = {
    "ours": (["field_block"], {"field_vmf": 0.2, "sdf_barrier": -2.0, "foot_sole_barrier": -2.0}, "field"),
    "wo_obs_field": (["elevation_map"], {"field_vmf": 0.2, "sdf_barrier": -2.0, "foot_sole_barrier": -2.0}, "field"),
    "wo_r_field": (["field_block"], {"collision": -20.0}, "straight"),
    "astraversal": (["elevation_map"], {"map_clearance": -2.0}, "straight"),
    "humanoid_parkour": (["ground_map", "overhead_map"], {"collision": -20.0}, "straight"),
}
METHOD_TERMS = {"field_vmf", "sdf_barrier", "foot_sole_barrier", "map_clearance", "collision"}


@pytest.mark.parametrize("method", list(DOCUMENTED))
def test_each_method_builds_the_documented_groups_and_rewards(tmp_path, method):
    one_scene = ["task.scene_groups=[hurdle-crouch]", "task.scene_variants=1", "task.warmup_variants=0"]
    cfg = load_config(["task=typical", f"method={method}", *one_scene, "num_envs=2", f"run_root={tmp_path}"])
    env = make_env(cfg)
    obs_terms, method_rewards, command = DOCUMENTED[method]
    assert env.observation_groups.groups["actor"] == SHARED + obs_terms
    assert env.observation_groups.groups["critic"] == SHARED + obs_terms + PRIVILEGED
    weights = {k: w for k, (w, _) in env.reward_terms.items()}
    assert {k: v for k, v in weights.items() if k in METHOD_TERMS} == method_rewards
    common = {k: v for k, v in weights.items() if k not in METHOD_TERMS}
    ours = {k: v for k, v in load_config(["task=typical"]).task.rewards.__dict__.items() if isinstance(v, float)}
    assert common == {k: v for k, v in ours.items() if v != 0.0 and k not in METHOD_TERMS}
    assert env.cfg.command.source == command
    assert env.cfg.rewards.params.heading_gate == ("field" if command == "field" else "none")
    obs = env.get_observations()
    assert obs["actor"].shape == (2, len(env.observation_groups.term_columns(env, "actor")))


@pytest.mark.parametrize("task", ["multi_hurdle", "side_hurdle", "side_hurdle_crouch", "typical"])
def test_bar_tasks_ride_the_swing_foot_target_on_the_bars(task):
    """The shipped hurdle recipes' swing-foot target (7 cm above the bar 0.3 m ahead), in the task files of the types
    still to train (docs/multi_hurdle.md: with 0 the term is 8x weaker before the feet hit the bars)."""
    params = load_config([f"task={task}"]).task.rewards.params
    assert params.foot_clearance_lookahead == 0.3 and params.foot_clearance_min_only


@pytest.mark.parametrize("column", list(COLUMNS))
@pytest.mark.parametrize("row", ROWS)
def test_each_rows_column_cell_builds_and_steps(tmp_path, row, column):
    """Each column's cells: each method's env builds on the column's task and steps (the run would start)."""
    import torch

    exp = load_experiment("table1")
    cell = exp.cells[_row_cell(exp.tables["table1"], row, column)]
    small = ["task.scene_variants=1", "task.warmup_variants=1", "num_envs=2", f"run_root={tmp_path}"]
    cfg = load_config([f"task={cell.task}", f"method={cell.method}", *cell.overrides, *small])
    env = make_env(cfg)
    env.step(torch.zeros(env.num_envs, env.num_actions))
    assert env.cfg.scene_kind == column and env.curriculum is not None


@pytest.mark.parametrize("cell,shipped", [("spec_side_crouch", "side_crouch"), ("spec_hurdle_pass", "hurdle_pass")])
def test_a_continued_specialist_adopts_its_shipped_run(tmp_path, cell, shipped):
    """The cells that continue a shipped specialist are its own recipe: its folder copied in is adopted and
    resumes from its last checkpoint (not a fresh run, not a stale one)."""
    import shutil

    from cat.experiment.plan import latest_checkpoint

    plan = Plan(load_experiment("table1"), str(tmp_path))
    unit = plan.units[f"{cell}@0"]
    src = EXPERIMENT.parents[2] / "checkpoints" / shipped
    it, latest = latest_checkpoint(src)
    unit.run_dir.mkdir(parents=True)
    for name in ("config.yaml", latest.name):
        shutil.copy(src / name, unit.run_dir / name)
    assert plan.status(unit) == "resume"
    assert it < unit.final - 1
