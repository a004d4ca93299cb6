"""The fused field-contact kernel (``FieldBank.min_sdf_on_bodies``) judges exactly as the torch reference.

``FieldContact.body_sdf`` (one Warp launch: pose the body points, trilinear d, min per body, culling) against
``FieldContact.body_sdf_torch`` (torch transforms + ``bank.query`` per point): the constructed 2 cm-inside /
1 cm-clear poses, random rigid poses over typical scenes (in and out of the grid, non-finite, float32 and float16
banks), and a random-action rollout (``tests/test_field_contact.py``'s agreement fixture compares the two on
every step too).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from cat.envs.config import EnvCfg
from cat.envs.field_contact import CULL_SLACK, FieldContact
from cat.envs.scene_set import SceneSet
from cat.envs.traversal_env import TraversalEnv
from cat.fields import FieldBank, Grid, contact_sdf, sdf_from_occupancy
from cat.fields.body_points import BodyPoints
from cat.terrain.primitives import box
from cat.terrain.voxel import GridSpec, occupancy
from tests.test_field_contact import FACE_X, front_offset, pose_at, wall_env


def assert_same_judgement(fc: FieldContact, fused: torch.Tensor, ref: torch.Tensor) -> None:
    """Same contact decisions; same d up to float rounding wherever either is below the cull horizon.

    Above ``margin + CULL_SLACK / 2`` a geom may be culled by one and not the other (its centre rounds across the
    cull distance): both are then far from contact, so values are compared capped there."""
    m = fc.cfg.margin
    assert torch.equal(fused < m, ref < m)
    cap = m + 0.5 * CULL_SLACK
    torch.testing.assert_close(fused.clamp(max=cap), ref.clamp(max=cap), rtol=0.0, atol=2e-5)


def both(fc: FieldContact, bank, idx, pos, quat, cull: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """The fused kernel and the torch reference, both on the fields' d (the reference reads d only; the contact
    SDF goes through the same kernel: ``test_contact_sdf_is_read_in_place_of_d``)."""
    fc.cull, sdf, fc.cfg.sdf = cull, fc.cfg.sdf, "field"
    try:
        return fc.body_sdf(bank, idx, pos, quat), fc.body_sdf_torch(bank, idx, pos, quat)
    finally:
        fc.cull, fc.cfg.sdf = True, sdf


def test_constructed_poses_inside_and_clear_judge_the_same():
    """2 cm into the wall and 1 cm clear (and a world with its wall far away): equal d per body, equal contact."""
    env = wall_env("field", faces=(FACE_X, 1.4))
    fc, bank, idx = env.field_contact, env.field_source.bank, env.field_source.field_idx
    dx = front_offset(env)
    for depth, expect in ((0.02, [True, False]), (-0.01, [False, False])):
        pose_at(env, FACE_X + depth - dx)
        pos, quat = fc.poses(env.sim.sensordata.float())
        for cull in (True, False):
            fused, ref = both(fc, bank, idx, pos, quat, cull)
            assert_same_judgement(fc, fused, ref)
            assert ((fused < fc.cfg.margin).any(-1)).tolist() == expect
        assert env.state.collision.tolist() == expect  # the env's judgement is the fused one
        assert abs(float(fused[0].min()) - (-depth)) < 1e-4  # the frontmost point is `depth` into the wall


@pytest.fixture(scope="module")
def typical_env() -> TraversalEnv:
    """8 field-mode worlds over two typical kinds, two variants each."""
    sset = SceneSet.typical(["hurdle-crouch", "side-pass"], 8, variants=2)
    return TraversalEnv(EnvCfg(num_envs=8), scenes=sset, obstacles="field")


def copy_bank(src: FieldBank, dtype: str = "float32") -> FieldBank:
    """A bank of ``src``'s scenes, fields and placement in storage ``dtype`` (no contact SDF)."""
    bank = FieldBank(src.layouts, dtype)
    bank.scene_data.copy_(src.scene_data)
    bank.goal_data.copy_(src.goal_data)
    bank.scene_origin.copy_(src.scene_origin)
    bank._unfilled.clear()
    return bank


def random_poses(bank: FieldBank, idx: torch.Tensor, nb: int, g: torch.Generator, spill: float = 0.3):
    """Body positions uniform over each field's grid box grown by ``spill`` m (some points out of the grid), and
    uniformly random orientations."""
    lo, hi = bank.field_bounds(idx)
    u = torch.rand(len(idx), nb, 3, generator=g)
    pos = (lo - spill)[:, None] + u * (hi - lo + 2 * spill)[:, None]
    q = torch.randn(len(idx), nb, 4, generator=g)
    return pos, q / q.norm(dim=-1, keepdim=True)


@pytest.mark.parametrize("dtype", ["float32", "float16"])
def test_random_poses_judge_the_same(typical_env, dtype):
    env = typical_env
    fc = env.field_contact
    src = env.field_source.bank
    bank = src if dtype == "float32" else copy_bank(src, "float16")
    g = torch.Generator().manual_seed(0)
    idx = torch.randint(0, bank.num_fields, (512,), generator=g)
    pos, quat = random_poses(bank, idx, len(fc.bodies), g)
    pos[0, 3] = math.nan  # a non-finite body is clear, its neighbours are judged as usual
    quat[1, 2] = math.inf
    for cull in (True, False):
        fused, ref = both(fc, bank, idx, pos, quat, cull)
        assert_same_judgement(fc, fused, ref)
        assert math.isinf(fused[0, 3]) and math.isinf(fused[1, 2])
    touching = int((fused < fc.cfg.margin).sum())
    assert 0.05 * fused.numel() < touching < 0.95 * fused.numel()  # the poses exercise both outcomes
    assert torch.isinf(fused).any() and torch.isfinite(fused).any()


def test_thread_layouts_and_cpu_splits_give_the_same_result(typical_env):
    """One thread per world (the CPU default) or per (world, body) (the CUDA default), in one launch or two."""
    env = typical_env
    fc, bank = env.field_contact, env.field_source.bank
    g = torch.Generator().manual_seed(5)
    idx = torch.randint(0, bank.num_fields, (300,), generator=g)
    pos, quat = random_poses(bank, idx, len(fc.bodies), g)
    packed = fc.body_points(bank.device)
    threads = bank.num_threads
    try:
        results = []
        for n_threads in (1, 2):
            bank.num_threads = n_threads
            results += [bank.min_sdf_on_bodies(idx, pos, quat, packed, thread_per_body=t) for t in (False, True)]
    finally:
        bank.num_threads = threads
    for r in results[1:]:
        assert torch.equal(r, results[0])


def test_rollout_judges_the_same(typical_env):
    """Random actions from the episode starts: every control step, the env's sensors, both judgements."""
    env = typical_env
    fc, bank = env.field_contact, env.field_source.bank
    g = torch.Generator().manual_seed(3)
    for _ in range(30):
        env.step(0.5 * torch.randn(env.num_envs, env.num_actions, generator=g))
        pos, quat = fc.poses(env.sim.sensordata.float())
        fused, ref = both(fc, bank, env.field_source.field_idx, pos, quat)
        assert_same_judgement(fc, fused, ref)


def test_contact_sdf_is_read_in_place_of_d(typical_env):
    """``contact=True`` reads the bank's contact SDF through the same kernel: a contact grid of d + c per scene gives
    the d result + c; the env's contact grids differ from d only near the obstacles, mostly by d's voxel error
    (more where an obstacle leaves the grid, e.g. through its top, which the occupancy SDF cannot see)."""
    env = typical_env
    fc, src = env.field_contact, env.field_source.bank
    assert fc.cfg.sdf == "mesh" and src.contact_data is not None  # the default judgement built the contact SDF
    for s in range(src.num_scenes):
        d = torch.from_numpy(src.scene_sdf(s))
        c = torch.from_numpy(src.contact_data[int(src.scene_offset[s]) :][: d.numel()].view(d.shape).numpy())
        changed = (c - d).abs() > 1e-6
        assert changed.any() and (d[changed].abs() < fc.cfg.band).all()
        assert (c - d)[changed].abs().quantile(0.9) < 0.03
    bank = copy_bank(src)
    g = torch.Generator().manual_seed(7)
    idx = torch.randint(0, bank.num_fields, (200,), generator=g)
    pos, quat = random_poses(bank, idx, len(fc.bodies), g)
    packed = fc.body_points(bank.device)
    with pytest.raises(RuntimeError, match="no contact SDF"):
        bank.min_sdf_on_bodies(idx, pos, quat, packed, contact=True)
    shift = torch.linspace(-0.05, 0.05, bank.num_scenes)
    for s in range(bank.num_scenes):
        bank.set_contact_sdf(s, bank.scene_sdf(s) + float(shift[s]))
    with pytest.raises(ValueError, match="contact SDF of shape"):
        bank.set_contact_sdf(0, bank.scene_sdf(0)[1:])
    on_d = bank.min_sdf_on_bodies(idx, pos, quat, packed, cull=False)
    on_c = bank.min_sdf_on_bodies(idx, pos, quat, packed, cull=False, contact=True)
    expect = on_d + shift[bank.field_scene[idx].long()][:, None]
    assert torch.equal(torch.isinf(on_c), torch.isinf(on_d)) and torch.isfinite(on_d).any()
    finite = torch.isfinite(on_d)
    torch.testing.assert_close(on_c[finite], expect[finite], rtol=0.0, atol=1e-5)


def test_contact_sdf_is_exact_near_a_box_off_the_voxel_grid():
    """A box whose faces fall mid-voxel: d from its 4 cm occupancy is off by up to ~2 cm; the contact SDF equals the
    box's exact signed distance at every voxel centre within the band, and d elsewhere."""
    lo, hi = np.array([0.013, -0.31, 0.0]), np.array([0.057, 0.29, 0.43])  # a 4.4 cm bar
    grid = Grid((-0.6, -0.6, 0.0), 0.04, (30, 30, 20))
    mesh = box(tuple(lo), tuple(hi))
    d = sdf_from_occupancy(occupancy(mesh, GridSpec(grid.origin, grid.voxel, grid.shape)), grid)
    c = contact_sdf(mesh, grid, d, band=0.1)
    centres = np.stack(np.meshgrid(*[grid.origin[i] + grid.voxel * (np.arange(n) + 0.5) for i, n in
                                     enumerate(grid.shape)], indexing="ij"), axis=-1)  # fmt: skip
    q = np.abs(centres - (lo + hi) / 2) - (hi - lo) / 2  # the analytic box SDF
    exact = np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)
    near = np.abs(d) < 0.1
    assert np.abs(d - exact)[near].max() > 0.01  # the occupancy SDF is off here
    np.testing.assert_allclose(c[near], exact[near], atol=1e-5)
    np.testing.assert_array_equal(c[~near], d[~near].astype(np.float32))


def test_body_points_packing_keeps_every_point_with_its_body():
    groups = [torch.rand(k, 3) for k in (3, 5, 2, 4)]
    centre = torch.arange(12.0).view(4, 3)
    packed, order = BodyPoints.from_groups(groups, [1, 0, 1, 2], centre, [0.1, 0.2, 0.3, 0.4], torch.device("cpu"))
    assert order == [1, 0, 2, 3] and packed.num_bodies == 3
    assert packed.body_start.tolist() == [0, 1, 3, 4] and packed.group_start.tolist() == [0, 5, 8, 10, 14]
    torch.testing.assert_close(packed.points[5:8], groups[0])
    torch.testing.assert_close(packed.cull, torch.tensor([0.2, 0.1, 0.3, 0.4]))
    torch.testing.assert_close(packed.centre, centre[[1, 0, 2, 3]])


def test_bench_field_contact_prints_its_lines(capsys):
    """``scripts/bench.py field_contact`` at a tiny size: one line per (placement, impl), same contact fraction."""
    import importlib.util
    import re
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("bench_script", Path(__file__).parents[1] / "scripts" / "bench.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    args = ["field_contact", "--envs", "8", "--scenes", "2", "--warmup", "2", "--steps", "1", "--repeat", "1"]
    assert bench.main(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert re.fullmatch(r"case=contact_sdf scenes=2 env_build_s=[\d.]+ contact_sdf_s_per_scene=[\d.]+", lines[-13])
    pattern = (
        r"case=field_contact impl=(torch|fused|contact|substeps) placement=(start|anywhere|course) envs=8 scenes=2 "
        r"points=(\d+) contact_frac=([\d.]+) ms_per_step=([\d.]+) cpu_ms_per_step=([\d.]+)"
    )
    found = [re.fullmatch(pattern, line) for line in lines[-12:]]
    assert all(found), lines
    assert [(m.group(1), m.group(2)) for m in found] == [
        (impl, place) for place in ("start", "anywhere", "course") for impl in ("torch", "fused", "contact", "substeps")
    ]
    for torch_line, fused_line in zip(found[::4], found[1::4], strict=True):  # the same judgement on d
        assert torch_line.group(4) == fused_line.group(4)


def test_group_offsets_inflate_the_points(typical_env):
    """A group's offset is subtracted from d at its points (a capsule is its axis inflated by its radius): the same
    points packed with offsets 0 and c give results c apart, and culling with the grown cull distance changes
    nothing."""
    env = typical_env
    fc, bank = env.field_contact, env.field_source.bank
    g = torch.Generator().manual_seed(11)
    idx = torch.randint(0, bank.num_fields, (200,), generator=g)
    pos, quat = random_poses(bank, idx, len(fc.bodies), g)
    groups, bodies, n = fc.geom_points, fc.geom_body.tolist(), len(fc.geom_points)
    c = 0.03
    cull = (fc.geom_radius - fc.geom_offset + fc.cfg.margin + CULL_SLACK).tolist()
    plain = BodyPoints.from_groups(groups, bodies, fc.geom_centre, cull, bank.device, [0.0] * n)[0]
    grown = BodyPoints.from_groups(groups, bodies, fc.geom_centre, [x + c for x in cull], bank.device, [c] * n)[0]
    a = bank.min_sdf_on_bodies(idx, pos, quat, plain, cull=False)
    b = bank.min_sdf_on_bodies(idx, pos, quat, grown, cull=False)
    finite = torch.isfinite(a)
    assert finite.any() and torch.equal(torch.isinf(b), ~finite)
    torch.testing.assert_close(b[finite], a[finite] - c, rtol=0.0, atol=1e-6)
    culled = bank.min_sdf_on_bodies(idx, pos, quat, grown, cull=True)
    near = b < fc.cfg.margin
    assert torch.equal(culled < fc.cfg.margin, near) and near.any()
    assert (fc.geom_offset > 0).any()  # the G1's capsules and spheres are judged by their cores
