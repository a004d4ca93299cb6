"""``scripts/bench.py learner`` (cat/bench/learner.py): one line per learner setting, PPO built as training does."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

from cat.bench.learner import LearnerSetting, build_ppo


def test_ppo_is_built_with_the_setting_s_networks_and_schedule():
    s = LearnerSetting(epochs=2, mini_batches=3, actor=(32, 16), critic=(64,))
    ppo = build_ppo(s, envs=12, steps=4, actor_obs=184, critic_obs=232, actions=12)
    assert (ppo.num_learning_epochs, ppo.num_mini_batches) == (2, 3)
    linear = lambda m: [x.out_features for x in m.modules() if hasattr(x, "out_features")]  # noqa: E731
    assert linear(ppo.actor)[:3] == [32, 16, 12] and linear(ppo.critic)[:2] == [64, 1]


def test_bench_learner_prints_one_line_per_setting(capsys):
    spec = importlib.util.spec_from_file_location("bench_script", Path(__file__).parents[1] / "scripts" / "bench.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    args = ["learner", "--envs", "16", "--steps", "4", "--repeat", "1", "--only-defaults"]
    assert bench.main(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    pattern = (
        r"case=learner threads=(\d) epochs=5 mini_batches=4 actor=256-128-64 critic=512-256-128 envs=16 steps=4 "
        r"update_ms=(\d+) cpu_ms=(\d+)"
    )
    found = [re.fullmatch(pattern, line) for line in lines]
    assert all(found) and [m.group(1) for m in found] == ["1", "2"], lines
