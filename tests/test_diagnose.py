"""scripts/diagnose.py: the two diagnostic conditions are what they say (real env, real shipped policy)."""

from __future__ import annotations

from pathlib import Path

import torch
import yaml

from cat.launcher import load_script

REPO = Path(__file__).resolve().parents[1]
DIAG = load_script(REPO / "scripts" / "diagnose.py")
CROUCH = str(REPO / "checkpoints/crouch_pass/model_599.pt")


def test_arms_changes_only_the_shoulder_roll_defaults():
    base = yaml.safe_load((REPO / "robots/g1/g1.yaml").read_text())
    mine = yaml.safe_load(DIAG._arms(0.1).read_text())
    changed = {a[0]: (a[1], b[1]) for a, b in zip(base["joints"], mine["joints"], strict=True) if a != b}
    assert changed == {"left_shoulder_roll_joint": (0.3, 0.1), "right_shoulder_roll_joint": (-0.3, -0.1)}
    assert {k: v for k, v in base.items() if k != "joints"} == {k: v for k, v in mine.items() if k != "joints"}


def test_symmetrised_policy_is_mirror_equivariant():
    """pi_sym(M o) = M pi_sym(o) on real observations of a real env and a shipped (lateralised) policy."""
    from cat.envs.symmetry import MirrorMap
    from cat.eval.runner import EvalCfg, make_eval_env, run_scene_group
    from cat.learning.runs import load_run_config
    from cat.run.policy import load_policy

    run_cfg = load_run_config(CROUCH)
    group = run_scene_group(run_cfg.task, 0, None, None, False)
    obstacles = run_cfg.sim.obstacles
    env = make_eval_env(run_cfg.task, group, 4, EvalCfg(), sim="mujoco", device="cpu", trained_obstacles=obstacles)
    policy = load_policy(CROUCH, env, run_cfg)
    m = MirrorMap.of_env(env)
    sym = DIAG._Symmetrised(policy, m)
    with torch.no_grad():
        for _ in range(3):
            obs = env.get_observations()
            a, b = sym(m.mirror_obs(obs)), m.mirror_actions(sym(obs))
            assert torch.allclose(a, b, atol=1e-5)
            assert not torch.allclose(policy(m.mirror_obs(obs)), m.mirror_actions(policy(obs)), atol=1e-3)
            env.step(sym(obs))


def test_bad_case_and_missing_roll_are_one_line(caplog):
    assert DIAG.main(["nonsense"]) == 2 and "a case, one of arms, symmetrised" in caplog.text
    assert DIAG.main(["arms", f"checkpoint={CROUCH}"]) == 2 and "arms needs roll=<radians>" in caplog.text
