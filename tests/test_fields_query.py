"""Field bank trilinear query (vs numpy) and priority weighting (the multi-modal dilemma)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.interpolate import RegularGridInterpolator

from cat.fields import FieldBank, Grid, build_field, humanoid_pf, priority_weights

GRID = Grid((-0.5, -1.0, 0.0), 0.04, (75, 50, 38))
GOAL = (2.0, 0.0, 0.75)
# 13 links relative to the pelvis (root first), left/right symmetric
LINKS = np.array(
    [[0, 0, 0], [0, 0, 0.2], [0, 0, 0.45], [0, 0.12, -0.7], [0, -0.12, -0.7], [0, 0.1, -0.4], [0, -0.1, -0.4]]
    + [[0.1, 0.3, -0.2], [0.1, -0.3, -0.2], [0, 0.18, 0.25], [0, -0.18, 0.25], [0, 0.25, 0.05], [0, -0.25, 0.05]]
)


def _pillar(shift: int) -> np.ndarray:
    """0.2 × 0.4 m pillar across the course, moved ``shift`` voxels along y (the tiny asymmetry)."""
    occ = np.zeros(GRID.shape, bool)
    occ[35:40, 20 + shift : 30 + shift, :] = True
    return occ


@pytest.fixture(scope="module")
def fields():
    return [build_field(_pillar(-1), GRID, GOAL), build_field(_pillar(1), GRID, GOAL)]


def _reference(field, pts):
    """Trilinear F, d, ∇d (the bank's channels: ``field.data`` minus the geodesic) by scipy."""
    axes = [field.grid.axis_centers(a) for a in range(3)]
    pc = np.clip(pts, [a[0] for a in axes], [a[-1] for a in axes])  # documented clamp-to-edge rule
    return RegularGridInterpolator(axes, field.data[..., :7].astype(np.float64))(pc)


def test_trilinear_query_matches_numpy(fields):
    shifted = fields[1]
    # same data under another origin: each env must use its own field's origin
    moved = type(shifted)(
        Grid((0.3, -0.7, 0.1), GRID.voxel, GRID.shape), shifted.goal, shifted.data, shifted.geodesic, shifted.potential
    )
    bank_fields = [fields[0], moved]
    bank = FieldBank.from_fields(bank_fields)
    rng = np.random.default_rng(0)
    n, k = 64, 13
    idx = rng.integers(0, 2, n)
    pts = rng.uniform([-0.7, -1.2, -0.1], [3.3, 1.5, 1.7], (n, k, 3))
    s = bank.query(torch.as_tensor(idx, dtype=torch.int32), torch.as_tensor(pts, dtype=torch.float32))
    assert s.values.shape == (n, k, 7) and s.inside.shape == (n, k)
    for e in range(n):
        f = bank_fields[idx[e]]
        ref = _reference(f, pts[e].astype(np.float32).astype(np.float64))
        scale = np.maximum(np.abs(ref), 1.0)
        assert np.all(np.abs(s.values[e].numpy() - ref) / scale < 1e-4)
        assert np.array_equal(s.inside[e].numpy(), f.grid.contains(pts[e]))
    assert (~s.inside).any() and s.inside.any()


def test_query_at_voxel_centres_is_exact_and_outside_clamps(fields):
    f = fields[0]
    bank = FieldBank.from_fields([f])
    ijk = np.array([[3, 4, 5], [0, 0, 0], [74, 49, 37], [40, 20, 10]])
    pts = GRID.index_to_world(ijk)[None].astype(np.float32)
    s = bank.query(torch.zeros(1, dtype=torch.int32), torch.as_tensor(pts))
    assert np.allclose(s.values[0].numpy(), f.data[tuple(ijk.T)][:, :7], rtol=1e-6, atol=1e-6)
    assert s.inside.all()
    far = torch.tensor([[[-5.0, -5.0, -5.0], [10.0, 0.0, 0.75]]])
    s = bank.query(torch.zeros(1, dtype=torch.int32), far)
    assert not s.inside.any()
    assert np.allclose(s.values[0, 0].numpy(), f.data[0, 0, 0, :7], atol=1e-6)
    assert np.allclose(s.sdf[0, 1].item(), _reference(f, np.array([[10.0, 0.0, 0.75]]))[0, 3], atol=1e-5)


def test_priority_weights_values():
    grad_d = torch.tensor([[[1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]]])
    v = torch.tensor([[[-2.0, 0, 0], [1.0, 0, 0], [0, -1.0, 0]]])
    d = torch.tensor([[0.1, 0.5, -0.2]])
    w0, w1 = priority_weights(grad_d, d, v, lam=2.0)
    assert torch.allclose(w0, torch.tensor([1.0, 0.5, 0.5]))
    expect = 2.0 * torch.tensor([2.0 * np.exp(-0.1), 0.5 * np.exp(-0.5), 1.0])
    assert torch.allclose(w1[0], expect.float())
    F = torch.tensor([[[3.0, 4.0, 0.0], [0.0, 0.0, 0.0], [0.0, 2.0, 0.0]]])
    FH = humanoid_pf(F, grad_d, d, v, lam=2.0)
    assert torch.allclose(FH.norm(dim=-1)[0, [0, 2]], (w0 * w1)[0, [0, 2]])
    assert torch.allclose(FH[0, 0] / FH[0, 0].norm(), torch.tensor([0.6, 0.8, 0.0]))
    assert torch.all(FH[0, 1] == 0)  # F = 0 (the goal itself) → no direction


def test_priority_weighting_resolves_symmetric_dilemma(fields):
    """A pillar straight ahead, shifted by one voxel: left links are pushed left, right links right.
    The weighted whole-body guidance Σ F_H picks the side the asymmetry favours, keeps it during the
    approach, flips with the mirrored scene, and commits more strongly than unweighted unit fields."""
    bank = FieldBank.from_fields(fields)
    v = torch.tensor([0.5, 0.0, 0.0]).expand(1, 13, 3)
    for which, side in ((0, 1.0), (1, -1.0)):
        for x in (0.0, 0.2, 0.4, 0.6):
            pts = torch.tensor(LINKS + [x, 0.0, 0.78], dtype=torch.float32)[None]
            s = bank.query(torch.tensor([which], dtype=torch.int32), pts)
            unit = s.force / s.force.norm(dim=-1, keepdim=True)
            assert (unit[0, 3:, 1] > 0).any() and (unit[0, 3:, 1] < 0).any()  # the dilemma: links disagree
            FH = humanoid_pf(s.force, s.grad_sdf, s.sdf, v)
            lateral = FH[0, :, 1].sum() / FH[0].norm(dim=-1).sum()
            unweighted = unit[0, :, 1].mean()
            assert side * lateral > 0.02
            assert side * lateral > side * unweighted


def test_query_rejects_bad_field_index_and_survives_nan(fields):
    bank = FieldBank.from_fields(fields)
    pts = torch.zeros(2, 13, 3)
    with pytest.raises(IndexError):
        bank.query(torch.tensor([0, 2], dtype=torch.int32), pts)
    pts[0, 0] = float("nan")
    s = bank.query(torch.tensor([0, 1], dtype=torch.int32), pts)
    assert not s.inside[0, 0] and torch.isfinite(s.values).all()


def test_query_pf_combines_query_and_weights(fields):
    bank = FieldBank.from_fields(fields)
    pts = torch.tensor(LINKS + [0.3, 0.0, 0.78], dtype=torch.float32)[None].repeat(2, 1, 1)
    vel = torch.randn(2, 13, 3)
    idx = torch.tensor([0, 1], dtype=torch.int32)
    s, FH = bank.query_pf(idx, pts, vel)
    ref = humanoid_pf(s.force, s.grad_sdf, s.sdf, vel)
    assert torch.allclose(FH, ref)
