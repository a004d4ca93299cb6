"""Field bank over mixed grid shapes: per-scene d/∇d, per-goal F, fp16 storage, 64-bit addressing."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import warp as wp
from scipy.interpolate import RegularGridInterpolator

from cat.fields import FieldBank, FieldCfg, Grid, SceneFields, SceneLayout, bank_bytes, build_fields
from cat.fields._bank_kernel import block_address_kernel

# three grid shapes in one bank (small stand-ins for typical / procedural / indoor), different origins
GRIDS = [
    Grid((-0.5, -1.0, 0.0), 0.04, (19, 13, 10)),
    Grid((2.0, 3.0, 0.0), 0.04, (24, 24, 8)),
    Grid((-1.0, 5.0, 0.1), 0.05, (21, 17, 12)),
]
GOALS = [1, 3, 2]


def _random_scene(grid: Grid, n_goals: int, rng: np.random.Generator) -> SceneFields:
    sdf_grad = rng.normal(size=(*grid.shape, 4)).astype(np.float32)
    force = rng.normal(scale=5.0, size=(n_goals, *grid.shape, 3)).astype(np.float32)
    goals = rng.uniform(-1, 1, (n_goals, 3)) + np.asarray(grid.origin)
    return SceneFields(grid, goals, sdf_grad, force, FieldCfg())


@pytest.fixture(scope="module")
def scenes():
    rng = np.random.default_rng(0)
    return [_random_scene(g, n, rng) for g, n in zip(GRIDS, GOALS, strict=True)]


def _reference(sf: SceneFields, goal: int, pts: np.ndarray) -> np.ndarray:
    """Trilinear F, d, ∇d of one (scene, goal) by scipy, clamped to the voxel-centre span."""
    axes = [sf.grid.axis_centers(a) for a in range(3)]
    pc = np.clip(pts, [a[0] for a in axes], [a[-1] for a in axes])
    data = np.concatenate((sf.force[goal], sf.sdf_grad), axis=-1).astype(np.float64)
    return RegularGridInterpolator(axes, data)(pc)


def _points(bank: FieldBank, idx: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    lo, hi = (t.numpy() for t in bank.field_bounds(torch.as_tensor(idx)))
    u = rng.uniform(-0.1, 1.1, (len(idx), k, 3))  # some points outside their grid
    return (lo[:, None] + u * (hi - lo)[:, None]).astype(np.float32)


def _check_against_reference(bank: FieldBank, scenes, rtol: float, n: int = 96, k: int = 13, fp16=False) -> None:
    rng = np.random.default_rng(1)
    idx = rng.integers(0, bank.num_fields, n)
    pts = _points(bank, idx, k, rng)
    s = bank.query(torch.as_tensor(idx, dtype=torch.int32), torch.as_tensor(pts))
    assert s.values.shape == (n, k, 7)
    for e in range(n):
        sc = int(bank.field_scene[idx[e]])
        goal = idx[e] - int(bank.field_start[sc])
        ref = _reference(scenes[sc], goal, pts[e].astype(np.float64))
        scale = np.abs(ref) if not fp16 else np.abs(scenes[sc].force).max()  # fp16: error of stored values
        err = np.abs(s.values[e].numpy() - ref) / np.maximum(scale, 1.0)
        assert err.max() < rtol, (e, sc, goal, err.max())
        assert np.array_equal(s.inside[e].numpy(), scenes[sc].grid.contains(pts[e]))
    assert (~s.inside).any() and s.inside.any()


def test_mixed_shape_bank_matches_per_field_reference(scenes):
    bank = FieldBank.from_scenes(scenes)
    assert bank.num_scenes == 3 and bank.num_fields == sum(GOALS)
    assert [bank.field_scene[i].item() for i in range(bank.num_fields)] == [0, 1, 1, 1, 2, 2]
    _check_against_reference(bank, scenes, rtol=1e-4)


def test_scene_channels_stored_once(scenes):
    layouts = [SceneLayout(g, n) for g, n in zip(GRIDS, GOALS, strict=True)]
    bank = FieldBank(layouts)
    vox = [g.num_voxels for g in GRIDS]
    assert bank.scene_data.numel() == 4 * sum(vox)  # d, ∇d: once per scene
    assert bank.goal_data.numel() == 3 * sum(v * n for v, n in zip(vox, GOALS, strict=True))  # F: per goal
    assert bank.nbytes == bank_bytes(layouts) == 2 * bank_bytes(layouts, "float16")
    with pytest.raises(RuntimeError, match="never filled"):
        bank.query(torch.zeros(1, dtype=torch.int32), torch.zeros(1, 13, 3))


def test_fp16_bank_close_to_fp32(scenes):
    bank = FieldBank.from_scenes(scenes, dtype="float16")
    assert bank.scene_data.dtype == torch.float16
    _check_against_reference(bank, scenes, rtol=2.0**-11, fp16=True)  # half precision: 2^-11 of a stored value


def test_compact_bank_close_to_fp32(scenes):
    """compact: d, ∇d in float16, F as int8 mantissas with a shared exponent, within 1/128 of the largest
    stored component (half a step of a mantissa whose peak is in [64, 127]) after interpolation."""
    bank = FieldBank.from_scenes(scenes, dtype="compact")
    assert bank.scene_data.dtype == torch.float16 and bank.goal_data.dtype == torch.int8
    _check_against_reference(bank, scenes, rtol=2.0**-7, fp16=True)


def test_compact_storage_bytes_and_encoding():
    layouts = [SceneLayout(g, n) for g, n in zip(GRIDS, GOALS, strict=True)]
    vox = [g.num_voxels for g in GRIDS]
    bank = FieldBank(layouts, dtype="compact")
    assert bank.goal_data.numel() == 4 * sum(v * n for v, n in zip(vox, GOALS, strict=True))  # 3 mantissas + exponent
    assert (
        bank.nbytes == bank_bytes(layouts, "compact") == sum(v * (8 + 4 * n) for v, n in zip(vox, GOALS, strict=True))
    )
    enc = bank.storage.encode_force(torch.tensor([[0.0, 0.0, 0.0], [3.0e4, -1.0, 0.0], [1e-6, 2e-6, -4e-6]]))
    assert enc[0].tolist() == [0, 0, 0, 0]  # F = 0 (the goal itself) stays 0
    for row, f in zip(enc[1:], ([3.0e4, -1.0, 0.0], [1e-6, 2e-6, -4e-6]), strict=True):
        m, e = row[:3].double(), float(row[3])
        assert 64 <= m.abs().max() <= 127
        np.testing.assert_allclose((m * 2.0**e).numpy(), f, atol=max(abs(x) for x in f) / 128)
    fp16_file = torch.tensor([[6.0e4, 6.0e4, 6.0e4]], dtype=torch.float16)  # |F|^2 overflows float16
    assert torch.isfinite(bank.storage.encode_force(fp16_file).float()).all()


def test_offsets_past_2_31_address_the_right_field(scenes):
    """Move the buffers' base pointers 2^32 + 7 elements down and every offset as far up: the same memory,
    reached through offsets an int32 index would wrap. The query must not change (a wrapped or truncated
    offset reads another field or faults)."""
    for dtype in ("float32", "float16", "compact"):
        bank = FieldBank.from_scenes(scenes, dtype=dtype)
        rng = np.random.default_rng(2)
        idx = torch.as_tensor(rng.integers(0, bank.num_fields, 64), dtype=torch.int32)
        pts = torch.as_tensor(_points(bank, idx.numpy(), 13, rng))
        ref = bank.query(idx, pts).values.clone()
        bank._set_ptr_shift(2**32 + 7)
        assert int(bank._offsets[0].min()) > 2**31 and int(bank._offsets[1].max()) > 2**32
        assert torch.equal(bank.query(idx, pts).values, ref)


def test_block_address_is_64_bit():
    """The address arithmetic itself, with offsets far past 2^31 elements (nothing is read)."""
    offsets = np.array([0, 1, 2**31 - 1, 2**31, 2**32 + 3, 3 * 2**33 + 11], dtype=np.int64)
    base, esize = 0x7F00_0000_1000, 12
    out = wp.zeros(len(offsets), dtype=wp.uint64, device="cpu")
    wp.launch(
        block_address_kernel,
        dim=len(offsets),
        inputs=[base, wp.array(offsets, dtype=wp.int64, device="cpu"), esize, out],
        device="cpu",
    )
    assert out.numpy().tolist() == [base + int(o) * esize for o in offsets]


def test_built_fields_share_scene_channels():
    """Real fields of one scene for two goals: the bank stores d, ∇d once and each goal's F, and the query
    equals each Field's own trilinear reference."""
    grid = Grid((0.0, 0.0, 0.0), 0.05, (24, 20, 12))
    occ = np.zeros(grid.shape, bool)
    occ[10:14, 4:16, :8] = True
    fields = build_fields(occ, grid, [(1.0, 0.2, 0.3), (0.1, 0.8, 0.3)])
    other = build_fields(np.zeros((10, 10, 10), bool), Grid((3.0, 0.0, 0.0), 0.05, (10, 10, 10)), [(3.2, 0.2, 0.2)])
    bank = FieldBank.from_scenes([fields, other])
    assert bank.num_scenes == 2 and bank.num_fields == 3
    rng = np.random.default_rng(3)
    for i, f in enumerate([*fields, *other]):
        pts = (np.asarray(f.grid.origin) + rng.uniform(0, 1, (13, 3)) * f.grid.size).astype(np.float32)
        s = bank.query(torch.tensor([i], dtype=torch.int32), torch.as_tensor(pts)[None])
        axes = [f.grid.axis_centers(a) for a in range(3)]
        pc = np.clip(pts.astype(np.float64), [a[0] for a in axes], [a[-1] for a in axes])
        ref = RegularGridInterpolator(axes, f.data[..., :7].astype(np.float64))(pc)
        np.testing.assert_allclose(s.values[0].numpy(), ref, rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(bank.goals[i].numpy(), f.goal, atol=1e-6)


def test_set_scene_offset_and_errors(scenes):
    layouts = [SceneLayout(sf.grid, sf.num_goals) for sf in scenes]
    bank = FieldBank.build(layouts, lambda s: scenes[s], offsets=[(0, 0, 0), (10.0, 0, 0), (0, 20.0, 0)])
    assert bank.scene_grid(1).origin == pytest.approx(np.asarray(GRIDS[1].origin) + [10.0, 0, 0])
    np.testing.assert_allclose(bank.goals[1].numpy(), scenes[1].goals[0] + [10.0, 0, 0], atol=1e-5)
    with pytest.raises(ValueError, match="bank expects"):
        bank.set_scene(0, scenes[1])
    with pytest.raises(ValueError, match="dtype"):
        FieldBank(layouts, dtype="bfloat16")
