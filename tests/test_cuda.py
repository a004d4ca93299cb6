"""The CUDA paths, against their CPU twins: the field bank's query, mujoco_warp envs with scenes (per-world geom
slots, captured CUDA graphs). Skipped without a CUDA device; ``scripts/gpu/check.sh`` runs them on a lent GPU,
together with the backend parity tests on CUDA (``CAT_WARP_TEST_DEVICE=cuda:0``, tests/test_sim_parity.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cat.envs.config import EnvCfg
from cat.envs.scene_set import SceneSet
from cat.envs.traversal_env import TraversalEnv
from cat.fields import FieldBank, FieldCfg, Grid, SceneFields


def _cuda() -> bool:
    if not torch.cuda.is_available():
        return False
    import warp as wp

    return wp.get_cuda_device_count() > 0


pytestmark = pytest.mark.skipif(not _cuda(), reason="no CUDA device (torch and Warp must both see one)")

GRIDS = [Grid((-0.5, -1.0, 0.0), 0.04, (19, 13, 10)), Grid((2.0, 3.0, 0.0), 0.05, (24, 24, 8))]


def _scenes(rng: np.random.Generator) -> list[SceneFields]:
    out = []
    for grid, goals in zip(GRIDS, (2, 3), strict=True):
        sdf_grad = rng.normal(size=(*grid.shape, 4)).astype(np.float32)
        force = rng.normal(scale=5.0, size=(goals, *grid.shape, 3)).astype(np.float32)
        goal_xyz = rng.uniform(-1, 1, (goals, 3)) + np.asarray(grid.origin)
        out.append(SceneFields(grid, goal_xyz, sdf_grad, force, FieldCfg()))
    return out


@pytest.mark.parametrize("dtype", ["float32", "float16"])
def test_bank_query_on_cuda_equals_the_cpu_query(dtype):
    scenes = _scenes(np.random.default_rng(0))
    cpu = FieldBank.from_scenes(scenes, dtype, "cpu")
    gpu = FieldBank.from_scenes(scenes, dtype, "cuda:0")
    assert gpu.scene_data.is_cuda
    rng = np.random.default_rng(1)
    n, k = 512, 13
    idx = torch.as_tensor(rng.integers(0, cpu.num_fields, n), dtype=torch.int32)
    lo, hi = cpu.field_bounds(idx)
    pts = lo[:, None] + torch.as_tensor(rng.uniform(-0.1, 1.1, (n, k, 3)), dtype=torch.float32) * (hi - lo)[:, None]
    a = cpu.query(idx, pts)
    b = gpu.query(idx.cuda(), pts.cuda())
    torch.cuda.synchronize()
    assert torch.equal(a.inside, b.inside.cpu()) and not a.inside.all() and a.inside.any()
    torch.testing.assert_close(b.values.cpu(), a.values, atol=1e-5, rtol=1e-5)


def test_warp_env_on_cuda_with_per_world_scenes_steps_and_stays_finite():
    """Two typical kinds, one scene per world (geom slots), on CUDA: state on the GPU, every env on a field of
    its own scene, observations and rewards finite through 20 steps and a reset of every env."""
    n = 64
    sset = SceneSet.typical(["hurdle-crouch", "side-pass"], n, variants=2, device="cuda:0", per_world=True)
    env = TraversalEnv(EnvCfg(num_envs=n), sim="warp", device="cuda:0", scenes=sset, seed=0)
    assert env.device.type == "cuda" and env.sim.qpos.is_cuda
    gen = torch.Generator().manual_seed(0)
    for k in range(20):
        if k == 10:
            env.reset_idx(torch.arange(n, device=env.device))
        obs, rew, _, _ = env.step((0.3 * (2 * torch.rand(n, env.num_actions, generator=gen) - 1)).cuda())
        assert torch.isfinite(rew).all()
        for group in obs.keys():
            assert torch.isfinite(obs[group]).all(), group
    scene_of_field = sset.bank.field_scene.to(env.device)[env.field_source.field_idx].long().cpu()
    assert torch.equal(scene_of_field, sset.scene_of_env.cpu())
