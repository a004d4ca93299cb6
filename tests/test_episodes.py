"""Free episode sampling on scene sets (cat.envs.episodes) and the paper's data groups (cat.terrain.data_groups)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import torch
import trimesh

from cat.envs.config import EnvCfg
from cat.envs.episodes import EpisodeCfg, EpisodeError, EpisodeSampler
from cat.envs.scene_set import SceneSet, SceneSetError, scene_fields
from cat.envs.traversal_env import TraversalEnv
from cat.eval.test_set import candidate
from cat.terrain import Scene, SceneError, make_indoor
from cat.terrain.data_groups import DATA_GROUPS, DataGroupError, select
from cat.terrain.dataset import GenScenesCfg, jobs

LO, HI = 1.0, 2.5


def corridor_scene(goal_in_wall: bool = True) -> Scene:
    """A 4 x 4 m scene with one free corridor |y| < 0.7 between 2 m walls; goals: one in the corridor, one in an
    enclosed 1.2 x 0.7 m pocket of the lower wall (no start in range fits there) and optionally one inside the
    upper wall (no fields can be built for it: sampler tests only)."""
    boxes = [
        [[-2.0, 0.7, 0.0], [2.0, 2.0, 2.0]],  # upper wall
        [[-2.0, -0.9, 0.0], [2.0, -0.7, 2.0]],  # lower wall, around the pocket
        [[-2.0, -2.0, 0.0], [2.0, -1.6, 2.0]],
        [[-2.0, -1.6, 0.0], [-0.6, -0.9, 2.0]],
        [[0.6, -1.6, 0.0], [2.0, -0.9, 2.0]],
    ]
    goals = [(1.6, 0.0), (0.0, -1.25)] + ([(0.0, 1.2)] if goal_in_wall else [])
    return Scene(
        trimesh.util.concatenate([trimesh.creation.box(bounds=b) for b in boxes]),
        bounds=[[-2.0, -2.0, 0.0], [2.0, 2.0, 2.0]],
        start=(-1.5, 0.0),
        goals=goals,
        kind="user",
    )


def test_free_starts_lie_in_the_corridor_and_reach_their_goal_in_range():
    scene = corridor_scene()
    sampler = EpisodeSampler([scene], EpisodeCfg(mode="free", goal_distance=(LO, HI)), scene.grid().voxel)
    assert sampler.starts[0].goals_served.tolist() == [True, False, False]  # corridor, pocket, wall
    gen = torch.Generator().manual_seed(0)
    for _ in range(200):
        xy, g = sampler.sample(0, 1.0, gen)
        assert g == 0  # only the corridor goal is ever served
        assert abs(xy[1]) <= 0.7 - 0.4 + scene.grid().voxel  # stand radius from the walls
        # in a straight corridor the geodesic is the straight distance (8-connected paths: within a voxel or two)
        d = float(np.linalg.norm(scene.goals[0, :2] - xy))
        assert LO - 0.1 <= d <= HI + 0.1
        assert scene.clearance(np.array([[xy[0], xy[1], z] for z in (0.1, 0.7, 1.3)])).min() > 0.3


def test_free_sampling_follows_the_seed_and_the_distance_curriculum():
    scene = corridor_scene()
    sampler = EpisodeSampler([scene], EpisodeCfg(mode="free", goal_distance=(LO, HI)), scene.grid().voxel)

    def draw(seed: int, progress: float) -> np.ndarray:
        gen = torch.Generator().manual_seed(seed)
        return np.array([sampler.sample(0, progress, gen)[0] for _ in range(50)])

    np.testing.assert_array_equal(draw(3, 1.0), draw(3, 1.0))
    assert not np.array_equal(draw(3, 1.0), draw(4, 1.0))
    near = np.linalg.norm(draw(5, 0.2) - scene.goals[0, :2], axis=1)
    assert near.max() <= LO + 0.2 * (HI - LO) + 0.1  # early in the curriculum: goals close by
    far = np.linalg.norm(draw(5, 1.0) - scene.goals[0, :2], axis=1)
    assert far.max() > LO + 0.5 * (HI - LO)


def test_env_free_starts_are_collision_free_standing_poses():
    """Real MuJoCo: every env reset into a free start of the corridor scene stands without touching a wall."""
    scene = corridor_scene(goal_in_wall=False)
    cfg = EnvCfg(num_envs=16, scene_kind="user", episodes=EpisodeCfg(mode="free", goal_distance=(LO, HI)))
    scenes = SceneSet([scene], lambda i: scene_fields(scene, None, None), 16, episodes=cfg.episodes)
    env = TraversalEnv(cfg, sim="mujoco", scenes=scenes, seed=2)
    for _ in range(3):
        env.reset_idx(torch.arange(16))
        env._update_state()
        assert not env.state.collision.any()
        xy = env.sim.qpos[:, :2].numpy()
        assert np.all(np.abs(xy[:, 1]) < 0.35)
        np.testing.assert_allclose(env.goals[:, :2].numpy(), np.tile(scene.goals[0, :2], (16, 1)), atol=1e-5)


def test_a_goal_range_no_scene_serves_is_refused_before_the_bank():
    scene = corridor_scene()
    with pytest.raises(EpisodeError, match=r"goal_distance=\[5.0, 6.0\]"):
        far = EpisodeCfg(mode="free", goal_distance=(5.0, 6.0))
        SceneSet([scene], lambda i: pytest.fail("fields built"), 4, episodes=far)
    with pytest.raises(EpisodeError, match="goal_distance"):
        EpisodeSampler([scene], EpisodeCfg(mode="free", goal_distance=(2.0, 1.0)), 0.04)
    with pytest.raises(EpisodeError, match="mode"):
        EpisodeSampler([scene], EpisodeCfg(mode="anywhere"), 0.04)


def test_scene_mode_keeps_the_start_region_draws():
    """Without free episodes the draws are the scene's start region, exactly as before (shipped runs unchanged)."""
    scene = corridor_scene()
    ss = SceneSet.__new__(SceneSet)  # only the sampling state is needed: no bank
    ss.scenes, ss.offsets, ss.episodes = [scene], np.zeros((1, 3)), None
    ss.scene_of_env, ss._goal_idx = torch.zeros(8, dtype=torch.long), torch.zeros(8, dtype=torch.long)
    start, goal, _ = ss.sample_episode(torch.arange(8), torch.Generator().manual_seed(0))
    lo, hi = scene.start_region
    assert np.all(start[:, :2].numpy() >= lo) and np.all(start[:, :2].numpy() <= hi)


def test_data_groups_select_the_documented_scenes():
    diffs = list(np.linspace(0.0, 1.0, 20))
    kinds = ["procedural"] * 20 + ["indoor"] * 6 + ["hurdle-crouch"] * 3
    d = diffs + [0.2] * 6 + [0.5] * 3
    seeds = list(range(29))
    counts = {}
    for name in DATA_GROUPS:
        m = select(kinds, d, seeds, name)
        assert m[20:].all()  # indoor crops and the typical mix are in every group
        proc = np.flatnonzero(m[:20])
        counts[name] = len(proc)
        lo, hi = DATA_GROUPS[name].difficulty
        assert all(lo - 1e-9 <= diffs[i] <= hi + 1e-9 for i in proc)
    in_easy = sum(x <= 0.6 for x in diffs)
    assert counts == {
        "base": 0,
        "syn_partial_easy": (in_easy + 1) // 2,
        "syn_full_easy": in_easy,
        "syn_full_hard": sum(0.4 - 1e-9 <= x for x in diffs),
    }
    with pytest.raises(DataGroupError, match="valid: base"):
        select(kinds, d, seeds, "syn_everything")


def test_gen_scenes_builds_each_group_with_one_command(tmp_path):
    """``gen_scenes.py data=<group>`` lists exactly the procedural scenes the group selects from the superset."""
    base = dict(out=str(tmp_path), typical_variants=0, indoor=3, procedural=10)
    full = [j.folder.name for j in jobs(GenScenesCfg(**base, data="all"))]
    diffs = list(np.linspace(0.0, 1.0, 10))
    for name in DATA_GROUPS:
        got = [j.folder.name for j in jobs(GenScenesCfg(**base, data=name))]
        m = select(["procedural"] * 10, diffs, list(range(10)), name)
        want = [f"proc_{i:03d}" for i in np.flatnonzero(m)]
        assert [n for n in got if n.startswith("proc")] == want
        assert [n for n in got if n.startswith("indoor")] == [f"indoor_{i:03d}" for i in range(3)]
        assert set(got) <= set(full)


def test_scene_folder_errors_name_the_problem(tmp_path):
    with pytest.raises(SceneSetError, match="not found"):
        SceneSet.from_dir(tmp_path / "missing", 4)
    with pytest.raises(SceneSetError, match="no scene folder"):
        SceneSet.from_dir(tmp_path, 4)
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "scene.json").write_text("{not json")
    with pytest.raises(SceneError, match="broken/scene.json: invalid JSON"):
        SceneSet.from_dir(tmp_path, 4)
    (tmp_path / "broken" / "scene.json").unlink()
    hard = corridor_scene()
    hard.kind, hard.difficulty = "procedural", 0.9
    hard.save(tmp_path / "procedural" / "p")
    with pytest.raises(SceneSetError, match="in data group 'syn_full_easy'"):
        SceneSet.from_dir(tmp_path, 4, data="syn_full_easy")


def _mesh_hash(scene: Scene) -> str:
    m = scene.mesh
    return hashlib.sha256(np.round(m.vertices, 5).tobytes() + m.faces.tobytes()).hexdigest()


def test_unseen_test_scenes_are_never_in_a_training_group():
    """The test stream's houses and crops differ from the training stream's for the same seeds (by mesh hash);
    the training groups draw indoor crops from the training stream only (``gen_scenes`` jobs)."""
    train = {_mesh_hash(make_indoor(s)) for s in range(3)}
    test = [candidate(s, 4) for s in range(3)]
    assert all(_mesh_hash(t) not in train for t in test if t is not None)
    assert all(t.meta.get("test_stream") == 1 for t in test if t is not None)


def test_evaluation_never_samples_free_episodes():
    """Trials place start and goal themselves: a free-episode run is evaluated with the scenes' own sampling off."""
    from cat.eval.runner import EvalCfg, eval_task

    task = EnvCfg(num_envs=4, episodes=EpisodeCfg(mode="free", goal_distance=(5.0, 6.0)))
    assert eval_task(task, 4, EvalCfg()).episodes.mode == "scene"
    assert task.episodes.mode == "free"  # the run's config is not changed


def test_goal_stand_radius_serves_only_goals_a_robot_can_stand_at():
    """Two corridor goals, one in the open and one 0.15 m from the upper wall: at ``goal_stand_radius=0.24`` only
    the open one is served (every draw heads for it); at 0 both are; a radius no goal meets is one clear error."""
    scene = corridor_scene(goal_in_wall=False)
    scene.goals = np.array([[1.6, 0.0, scene.goals[0, 2]], [1.2, 0.55, scene.goals[0, 2]]])
    voxel = scene.grid().voxel
    both = EpisodeSampler([scene], EpisodeCfg(mode="free", goal_distance=(LO, HI)), voxel)
    assert both.starts[0].goals_served.tolist() == [True, True]
    cfg = EpisodeCfg(mode="free", goal_distance=(LO, HI), goal_stand_radius=0.24)
    open_only = EpisodeSampler([scene], cfg, voxel)
    assert open_only.starts[0].goals_served.tolist() == [True, False]
    gen = torch.Generator().manual_seed(0)
    assert {open_only.sample(0, 1.0, gen)[1] for _ in range(50)} == {0}
    with pytest.raises(EpisodeError, match="goal_stand_radius=0.7"):
        EpisodeSampler([scene], EpisodeCfg(mode="free", goal_distance=(LO, HI), goal_stand_radius=0.7), voxel)
    with pytest.raises(EpisodeError, match="goal_stand_radius must be >= 0"):
        EpisodeSampler([scene], EpisodeCfg(mode="free", goal_stand_radius=-0.1), voxel)
