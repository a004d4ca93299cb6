"""``body_clearance`` (cat/envs/body_clearance.py): each collision body's distance to the nearest obstacle, as an
observation, on real MuJoCo worlds of a constructed wall scene, in both obstacle modes."""

from __future__ import annotations

import pytest
import torch

from cat.envs.body_clearance import CLEARANCE_CLIP, clearance_bodies
from cat.envs.config import ACTOR_TERMS, PRIVILEGED_TERMS, EnvCfg, ObsGroupCfg
from cat.envs.mdp.mirror import mirror_name
from cat.envs.mdp.registry import obs_term
from cat.envs.robot import load_robot_cfg
from cat.envs.scene_set import SceneSet, scene_fields
from cat.envs.traversal_env import TraversalEnv
from tests.test_field_contact import FACE_X, front_x, pose_at, wall_scene


def clearance_cfg(n: int) -> EnvCfg:
    groups = {
        "actor": ObsGroupCfg(terms=[*ACTOR_TERMS, "body_clearance"], noise=True),
        "critic": ObsGroupCfg(terms=list(PRIVILEGED_TERMS), extends="actor"),
    }
    return EnvCfg(num_envs=n, observations=groups)


def clearance_env(obstacles: str, per_world: bool = True) -> TraversalEnv:
    """Two worlds of one wall scene: per-world scene models, or the one model of a shared scene."""
    scenes = [wall_scene(), wall_scene()] if per_world else [wall_scene()]
    sset = SceneSet(scenes, [scene_fields(s, None, None) for s in scenes], 2, per_world=per_world)
    return TraversalEnv(clearance_cfg(2), scenes=sset, obstacles=obstacles)


def term_block(env: TraversalEnv) -> torch.Tensor:
    """The body_clearance columns of the (noise-free) critic group."""
    obs = env.observation_groups.compute(env, commit=False)["critic"]
    start = sum(obs_term(t).size(env.cfg, env.robot) for t in ACTOR_TERMS)
    return obs[:, start : start + len(clearance_bodies(env.robot))]


@pytest.mark.parametrize("obstacles,per_world", [("physical", True), ("physical", False), ("field", True)])
def test_clearance_reads_the_gap_to_a_wall(obstacles, per_world):
    env = clearance_env(obstacles, per_world)
    assert env.sim.model.nsensor > 0 and env.body_clearance is not None
    pose_at(env, 0.0)
    dx = front_x(env.body_clearance.fc, env.sim.sensordata.float())  # frontmost judged surface, root at x = 0
    for gap in (0.03, -0.02, 0.5):
        pose_at(env, FACE_X - gap - dx)
        c = term_block(env)
        assert c.shape == (2, len(clearance_bodies(env.robot)))
        want = max(min(gap, CLEARANCE_CLIP), -CLEARANCE_CLIP)
        assert torch.allclose(c.amin(dim=1), torch.full((2,), want), atol=3e-3), (gap, c.amin(dim=1))
        assert float(c.max()) <= CLEARANCE_CLIP and float(c.min()) >= -CLEARANCE_CLIP
    pose_at(env, FACE_X - 0.03 - dx)
    c = term_block(env)[0]
    names = clearance_bodies(env.robot)
    assert float(c[names.index("pelvis")]) > float(c.min())  # the nearest surface is a limb's, not the root's


def test_clearance_columns_mirror_left_and_right_bodies():
    robot = load_robot_cfg()
    names = clearance_bodies(robot)
    assert "left_ankle_roll_link" in names and "right_wrist_yaw_link" in names
    perm, sign = obs_term("body_clearance").mirror(EnvCfg(), robot)
    assert [names[i] for i in perm] == [mirror_name(n) for n in names]
    assert sign == [1.0] * len(names)


def test_clearance_on_flat_ground_reads_clear():
    """No scene, no obstacle: every body reads +clip (what evaluation's scene-less probe env builds, too)."""
    env = TraversalEnv(clearance_cfg(2))
    c = term_block(env)
    assert c.shape == (2, len(clearance_bodies(env.robot))) and bool((c == CLEARANCE_CLIP).all())


def test_a_policy_reading_clearance_is_not_deployed():
    from cat.deploy.runtime import _check_deployable

    with pytest.raises(ValueError, match="body_clearance.*does not compute"):
        _check_deployable(clearance_cfg(1), ["actor"])
