"""The eight typical scene types: geometry facts, free space, reachability, determinism, difficulty."""

from __future__ import annotations

import numpy as np
import pytest

from cat.terrain import (
    TYPICAL_KINDS,
    Graded,
    SceneError,
    check_scene,
    make_typical,
    typical_variants,
    warmup_variants,
)
from cat.terrain.graded import GRADED_BY, GRADED_NARROW_Y, graded_kinds
from cat.terrain.typical import WALL_T
from cat.terrain.voxel import free_volume_fraction


@pytest.mark.parametrize("kind", TYPICAL_KINDS)
def test_variants_valid(kind):
    scenes = typical_variants(kind, n=10, seed=0)
    assert len(scenes) == 10
    hashes = set()
    for s in scenes:
        assert s.kind == kind
        assert s.mesh.is_watertight, f"{kind} d={s.difficulty}"
        np.testing.assert_allclose(s.bounds, [[-0.5, -1, 0], [2.5, 1, 1.5]])
        np.testing.assert_allclose(s.start, [0, 0, 0.75])
        np.testing.assert_allclose(s.goals, [[2, 0, 0.75]])
        assert s.grid().shape == (75, 50, 38)
        lo, hi = s.mesh.bounds
        assert np.all(lo >= s.bounds[0] - 1e-6) and np.all(hi <= s.bounds[1] + 1e-6)
        check_scene(s)  # start/goals free with clearance, goal reachable by a humanoid
        # the start region is clear for the robot
        assert np.all(s.clearance(np.c_[s.start_region, [0.75, 0.75]]) > 0.2)
        hashes.add(s.mesh.vertices.round(6).tobytes())
    assert len(hashes) == 10  # ten distinct variants


@pytest.mark.parametrize("kind", TYPICAL_KINDS)
def test_deterministic_and_monotone(kind):
    a, b = make_typical(kind, 0.4, seed=7), make_typical(kind, 0.4, seed=7)
    np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
    np.testing.assert_array_equal(a.mesh.faces, b.mesh.faces)
    assert not np.array_equal(make_typical(kind, 0.4, seed=8).mesh.vertices, a.mesh.vertices)
    free = [free_volume_fraction(make_typical(kind, d, seed=3).occupancy()) for d in np.linspace(0, 1, 5)]
    assert np.all(np.diff(free) <= 1e-9), free
    assert free[-1] < free[0]


def test_released_scene_facts():
    """Hurdle tops 0.08-0.25 m, ceiling bottoms 1.00-1.15 m, slit walls 0.12 m thick, gaps >= 0.32 m."""
    for d in (0.0, 1.0):
        bars = make_typical("multi-hurdle", d, seed=1)
        assert 0.06 <= bars.mesh.bounds[1, 2] <= 0.27
        ceil = make_typical("crouch-pass", d, seed=1)
        occ = ceil.occupancy()
        x, y, z = ceil.grid().axes()
        col = occ[np.argmin(np.abs(x - 1.0)) - 10 : np.argmin(np.abs(x - 1.0)) + 10, np.argmin(np.abs(y)), :]
        bottoms = [z[np.argmax(c)] - 0.02 for c in col if c.any()]
        assert bottoms and 0.98 <= min(bottoms) <= 1.17
        slit = make_typical("side-pass", d, seed=1)
        occ = slit.occupancy()
        walls = occ[:, :, 10].any(1)
        runs = np.diff(np.flatnonzero(np.diff(np.r_[0, walls.astype(int), 0])))[::2]
        assert set(runs.tolist()) <= {3, 4}  # 0.12 m = 3 voxels (+1 at a voxel boundary)
        gap = (~occ[:, :, 10]).sum(1)[walls].max() * 0.04
        assert 0.28 <= gap <= 0.96


def test_bad_inputs():
    with pytest.raises(SceneError, match="unknown typical scene type"):
        make_typical("jump-rope", 0.5, 0)
    with pytest.raises(SceneError, match="difficulty"):
        make_typical("side-pass", 1.5, 0)


@pytest.mark.parametrize("kind", TYPICAL_KINDS)
def test_warmup_variants_are_easier_and_leave_the_paper_scenes_alone(kind):
    """Warm-up scenes (d < 0) are valid, ordered below the paper's easiest in free volume, and the paper's
    variants do not depend on them (their seeds and parameters are untouched)."""
    warm = warmup_variants(kind, 5, seed=0)
    assert [s.difficulty for s in warm] == pytest.approx([-1.0, -0.8, -0.6, -0.4, -0.2])
    for s in warm:
        assert s.kind == kind and s.mesh.is_watertight and len(s.mesh.faces) > 0
        check_scene(s)
    free = [free_volume_fraction(make_typical(kind, d, seed=3).occupancy()) for d in (-1.0, -0.5, 0.0, 1.0)]
    assert np.all(np.diff(free) <= 1e-9), free
    again = typical_variants(kind, 3, seed=0)  # unchanged by building warm-up scenes first
    np.testing.assert_array_equal(again[0].mesh.vertices, make_typical(kind, 0.0, seed=0).mesh.vertices)


@pytest.mark.parametrize("kind", TYPICAL_KINDS)
def test_every_obstacle_is_seen_by_the_field_grid(kind):
    """Each part of every warm-up and paper variant holds a voxel centre: none is solid to the physics but
    missing from the fields (a 2 cm warm-up bar once was, and no policy learned to step over it)."""
    for s in warmup_variants(kind, 10, seed=0) + typical_variants(kind, 10, seed=0):
        assert s.unseen_parts() == [], (kind, s.difficulty)


def _parts(kind: str, d: float) -> list:
    """(bottom, top) heights of a typical scene's parts, lowest first."""
    parts = make_typical(kind, d, seed=0).mesh.split(only_watertight=False)
    return sorted((round(float(p.bounds[0, 2]), 3), round(float(p.bounds[1, 2]), 3)) for p in parts)


def _bar_width(kind: str, d: float) -> float:
    """Floor-level x extent of the lowest part (the bar) of a typical scene."""
    parts = make_typical(kind, d, seed=0).mesh.split(only_watertight=False)
    bar = min(parts, key=lambda p: p.bounds[1, 2])
    return float(bar.bounds[1, 0] - bar.bounds[0, 0])


def test_warmup_extremes():
    """Hurdle-crouch warm-ups teach one skill after the other: at d = -1 a 4.5 cm bar under a ceiling out of reach
    (1.42 m), at d = -0.5 the paper's easiest bar (8 cm) with the ceiling still up, then the ceiling comes down to
    the paper's 1.15 m at d = 0; d outside [-1, 1] is refused."""
    (bar_lo, bar_hi), (ceil_lo, _) = _parts("hurdle-crouch", -1.0)
    assert bar_lo == 0.0 and 0.045 <= bar_hi <= 0.055 and ceil_lo >= 1.4  # (jitter: d +- 0.1)
    for d in (-0.5, 0.0):
        (_, bar_hi), (ceil_lo, _) = _parts("hurdle-crouch", d)
        assert 0.07 <= bar_hi <= 0.09  # the paper's easiest bar (jitter clipped at its easy end)
        assert ceil_lo >= 1.33 if d == -0.5 else 1.14 <= ceil_lo <= 1.17
    assert all(0.045 <= top <= 0.055 for _, top in _parts("multi-hurdle", -1.0))
    for kind, d_full in (("hurdle-crouch", -0.5), ("hurdle-pass", 0.0)):  # bars widen 5 -> 16 cm
        widths = [_bar_width(kind, d) for d in (-1.0, d_full)]
        assert widths[0] <= 0.06 and widths[1] >= 0.14, (kind, widths)  # (jitter)
    with pytest.raises(SceneError, match="difficulty"):
        make_typical("hurdle-crouch", -1.5)


@pytest.mark.parametrize("kind", TYPICAL_KINDS)
def test_unseen_shapes_keep_the_layout_and_change_every_obstacle(kind):
    """``shapes="unseen"`` (the evaluation set of configs/eval/typical_unseen.yaml): valid scenes (watertight, start
    and goal free, goal reachable, every part seen by the field grid) with the paper scenes' bounds, start region
    and goal, none equal to a training scene of any seed the training sets use, and the same difficulty order."""
    unseen = typical_variants(kind, 8, seed=1000, shapes="unseen")
    training = {s.mesh.vertices.round(6).tobytes() for seed in (0, 1000) for s in typical_variants(kind, 10, seed)}
    for u in unseen:
        assert u.kind == kind and u.mesh.is_watertight and u.meta["shapes"] == "unseen"
        check_scene(u)
        assert u.unseen_parts() == [], (kind, u.difficulty)
        np.testing.assert_array_equal(u.start_region, make_typical(kind, u.difficulty, u.seed).start_region)
        np.testing.assert_allclose(u.goals, [[2, 0, 0.75]])
        assert u.mesh.vertices.round(6).tobytes() not in training
    again = make_typical(kind, unseen[3].difficulty, unseen[3].seed, "unseen")
    np.testing.assert_array_equal(again.mesh.vertices, unseen[3].mesh.vertices)
    free = [free_volume_fraction(s.occupancy()) for s in (unseen[0], unseen[-1])]
    assert free[0] > free[1], free
    with pytest.raises(SceneError, match="unknown typical shapes 'odd'; valid: paper, unseen"):
        make_typical(kind, 0.5, 0, "odd")


def _bar_spans(scene) -> list[tuple[float, float]]:
    """(near edge, far edge) in x of each bar of a multi-hurdle scene, in course order."""
    parts = scene.mesh.split(only_watertight=False)
    return sorted((float(p.bounds[0, 0]), float(p.bounds[1, 0])) for p in parts)


def test_graded_pitch_orders_multi_hurdle_warmups_by_their_gap():
    """``Graded(bars=2)``: the floor gap between the two warm-up bars shrinks with d (0.85-0.90 m at d = -1 to
    about 0.3 m at d = -0.1) and the bars stay on the course, whatever the seed; the paper's variants and the
    random layout are untouched by the flag."""
    for seed in range(5):
        scenes = warmup_variants("multi-hurdle", 10, seed, Graded(bars=2))
        gaps = []
        for s in scenes:
            (a0, a1), (b0, b1) = _bar_spans(s)
            assert a0 >= 0.39 and b1 <= 1.75 + 1e-6, (seed, s.difficulty, a0, b1)
            gaps.append(b0 - a1)
        assert 0.84 <= gaps[0] <= 0.91 and 0.28 <= gaps[-1] <= 0.36, (seed, gaps)
        assert all(g1 > g2 - 0.05 for g1, g2 in zip(gaps[:-1], gaps[1:], strict=True)), (
            gaps
        )  # shrinking, up to the 5 cm jitter
        random = warmup_variants("multi-hurdle", 10, seed)
        assert [_bar_spans(s) for s in random] != [_bar_spans(s) for s in scenes]
    for d in (0.0, 0.6):  # the paper's variants: the same with and without the flag
        assert _bar_spans(make_typical("multi-hurdle", d, 3, graded=Graded(bars=2))) == _bar_spans(
            make_typical("multi-hurdle", d, 3)
        )


def test_three_graded_bars_where_they_fit():
    """``Graded(bars=3)``: the warm-ups whose gap leaves room for three bars on the course get a third at the same
    gap (the last ones, gaps <= ~0.45 m), the others are the graded pairs unchanged; the paper's variants never
    change; another count is refused."""
    for seed in range(4):
        pairs = warmup_variants("multi-hurdle", 10, seed, Graded(bars=2))
        threes = warmup_variants("multi-hurdle", 10, seed, Graded(bars=3))
        counts = []
        for two, three in zip(pairs, threes, strict=True):
            spans = _bar_spans(three)
            counts.append(len(spans))
            if len(spans) == 2:
                assert spans == _bar_spans(two)
                continue
            gaps = [b0 - a1 for (_, a1), (b0, _) in zip(spans[:-1], spans[1:], strict=True)]
            assert abs(gaps[0] - gaps[1]) < 0.02 and max(gaps) < 0.5, gaps  # bar widths differ by the jitter
            assert spans[0][0] >= 0.39 and spans[-1][1] <= 1.75 + 1e-6, spans
            assert three.meta["layout"]["bar_top"][2] < 0.09  # warm-up bars, lower than the paper's 8 cm + jitter
        assert counts[:5] == [2] * 5 and counts[-1] == 3, (seed, counts)
        assert counts == sorted(counts), counts  # two bars, then three: ordered by d
    assert _bar_spans(make_typical("multi-hurdle", 0.8, 2, graded=Graded(bars=3))) == _bar_spans(
        make_typical("multi-hurdle", 0.8, 2)
    )
    with pytest.raises(SceneError, match=r"graded bars must be one of \(0, 2, 3\)"):
        Graded(bars=4)


def _slit_walls(scene, k: int = 0) -> tuple[float, float, float]:
    """(near edge x, gap, centre y) of the ``k``-th full-height slit wall pair of a scene, along the course."""
    walls = sorted(
        (p.bounds for p in scene.mesh.split(only_watertight=False) if p.bounds[0, 2] < 0.01 and p.bounds[1, 2] > 1.4),
        key=lambda b: (round(float(b[0, 0]), 3), float(b[0, 1])),
    )
    lo, hi = walls[2 * k], walls[2 * k + 1]
    return float(lo[0, 0]), float(hi[0, 1] - lo[1, 1]), float(hi[0, 1] + lo[1, 1]) / 2


def test_graded_slit_offset_moves_a_narrow_slit_off_the_axis():
    """``Graded(slit_offset=True)``: side-hurdle's warm-ups hold a 0.45-0.50 m slit whose centre leaves the axis as d
    grows (0-3 cm at d = -1, 0.36-0.40 m at d = -0.1, both sides over the seeds), built where the layout says; the
    paper's variants and the other types' warm-ups are untouched."""
    graded = Graded(slit_offset=True)
    sides = set()
    for seed in range(4):
        offsets = []
        for s in warmup_variants("side-hurdle", 10, seed, graded):
            x, gap, yc = _slit_walls(s)
            lay = s.meta["layout"]
            assert 0.45 - 1e-6 <= gap <= 0.50 + 1e-6 and abs(gap - lay["slit_gap"][0]) < 1e-3, (gap, lay)
            assert abs(yc - lay["slit_y"][0]) < 1e-3 and abs(x - lay["x"][0]) < 1e-3, (x, yc, lay)
            offsets.append(abs(yc))
            sides.add(yc > 0)
        assert offsets[0] <= 0.03 + 1e-6 and 0.36 - 1e-6 <= offsets[-1] <= 0.40 + 1e-6, offsets
        assert all(b > a - 0.03 for a, b in zip(offsets[:-1], offsets[1:], strict=True)), offsets  # up to the jitter
    assert sides == {True, False}
    for d in (0.0, 0.7):  # the paper's variants: the same with and without it
        assert _slit_walls(make_typical("side-hurdle", d, 2, graded=graded)) == _slit_walls(
            make_typical("side-hurdle", d, 2)
        )
    other = warmup_variants("side-pass", 3, 1, graded)  # another type's warm-ups: not graded by it
    assert [o.meta["layout"] for o in other] == [o.meta["layout"] for o in warmup_variants("side-pass", 3, 1)]


@pytest.mark.parametrize("kind", ["side-hurdle-crouch", "side-hurdle"])
def test_graded_slit_narrow_narrows_a_slit_ahead_of_the_easiest_paper_variant(kind):
    """``Graded(slit_narrow=True)``: the type's warm-ups hold a slit within 10 cm of the axis narrowing from
    0.90-0.93 m at d = -1 to 0.45-0.48 m at d = -0.1, then what follows the slit in the easiest paper variant (the
    8-10 cm bar; side-hurdle-crouch's 1.13-1.15 m ceiling too), built where the layout says; the paper's variants
    are untouched."""
    graded = Graded(slit_narrow=True)
    for seed in range(3):
        gaps = []
        for s in warmup_variants(kind, 10, seed, graded):
            x, gap, yc = _slit_walls(s)
            lay = s.meta["layout"]
            assert abs(gap - lay["slit_gap"][0]) < 1e-3 and abs(yc - lay["slit_y"][0]) < 1e-3, (gap, yc, lay)
            assert abs(yc) <= GRADED_NARROW_Y + 1e-6 and abs(x - lay["x"][0]) < 1e-3, (x, yc, lay)
            parts = [p.bounds for p in s.mesh.split(only_watertight=False)]
            (top,) = lay["bar_top"]
            assert 0.08 - 1e-6 <= top <= 0.1 and any(abs(b[1, 2] - top) < 1e-3 for b in parts), lay
            if kind == "side-hurdle-crouch":
                (bottom,) = lay["ceiling_bottom"]
                assert 1.13 <= bottom <= 1.15 + 1e-6 and any(abs(b[0, 2] - bottom) < 1e-3 for b in parts), lay
            else:
                assert "ceiling_bottom" not in lay, lay
            gaps.append(gap)
        assert 0.90 - 1e-6 <= gaps[0] <= 0.93 + 1e-6 and 0.45 - 1e-6 <= gaps[-1] <= 0.48 + 1e-6, gaps
        assert all(b < a for a, b in zip(gaps[:-1], gaps[1:], strict=True)), gaps  # 5 cm a level, 3 cm of jitter
    for d in (0.0, 0.7):  # the paper's variants: the same with and without it
        a, b = make_typical(kind, d, 2, graded=graded), make_typical(kind, d, 2)
        assert a.meta["layout"] == b.meta["layout"] and _slit_walls(a) == _slit_walls(b)


def test_graded_slit_narrow_narrows_both_side_pass_slits_near_the_axis():
    """``Graded(slit_narrow=True)`` on side-pass: both warm-up slits lie within 10 cm of the axis (not offset to
    opposite sides), at least 0.45 m apart, each narrowing from 0.90-0.93 m at d = -1 to 0.45-0.48 m at d = -0.1,
    built where the layout says; the paper's variants are untouched."""
    graded = Graded(slit_narrow=True)
    for seed in range(3):
        gaps = []
        for s in warmup_variants("side-pass", 10, seed, graded):
            lay = s.meta["layout"]
            (x0, g0, y0), (x1, g1, y1) = _slit_walls(s, 0), _slit_walls(s, 1)
            assert np.allclose([g0, g1], lay["slit_gap"], atol=1e-3) and np.allclose([y0, y1], lay["slit_y"], atol=1e-3)
            assert np.allclose([x0, x1], lay["x"], atol=1e-3) and x1 - x0 - WALL_T >= 0.45 - 1e-6, lay
            assert max(abs(y0), abs(y1)) <= GRADED_NARROW_Y + 1e-6 and abs(g0 - g1) <= 0.03 + 1e-6, lay
            gaps.append(g0)
        assert 0.90 - 1e-6 <= gaps[0] <= 0.93 + 1e-6 and 0.45 - 1e-6 <= gaps[-1] <= 0.48 + 1e-6, gaps
        assert all(b < a for a, b in zip(gaps[:-1], gaps[1:], strict=True)), gaps
    for d in (0.0, 0.7):
        a, b = make_typical("side-pass", d, 2, graded=graded), make_typical("side-pass", d, 2)
        assert a.meta["layout"] == b.meta["layout"] and _slit_walls(a, 1) == _slit_walls(b, 1)


@pytest.mark.parametrize("kind", ["side-hurdle-crouch", "side-hurdle", "side-pass"])
def test_graded_slit_tight_narrows_slits_as_they_leave_the_axis(kind):
    """``Graded(slit_tight=True)``: each warm-up slit narrows (0.55-0.58 m at d = -1 to 0.34-0.38 m at d = -0.1)
    while its centre leaves the axis (0-3 cm to 0.36-0.39 m), to both sides over the seeds (side-pass: its two slits
    to opposite sides, at least 0.45 m apart), built where the layout says, ahead of the easiest paper variant's bar
    (side-hurdle types); the paper's variants are untouched."""
    graded = Graded(slit_tight=True)
    walls = 2 if kind == "side-pass" else 1
    sides = set()
    for seed in range(3):
        gaps, offsets = [], []
        for s in warmup_variants(kind, 10, seed, graded):
            lay = s.meta["layout"]
            slits = [_slit_walls(s, i) for i in range(walls)]
            assert np.allclose([g for _, g, _ in slits], lay["slit_gap"], atol=1e-3), (slits, lay)
            assert np.allclose([y for _, _, y in slits], lay["slit_y"], atol=1e-3), (slits, lay)
            assert np.allclose([x for x, _, _ in slits], lay["x"][:walls], atol=1e-3), (slits, lay)
            if walls == 2:
                (x0, _, y0), (x1, _, y1) = slits
                assert x1 - x0 - WALL_T >= 0.45 - 1e-6 and (y0 * y1 <= 0), lay
            else:
                (top,) = lay["bar_top"]
                assert 0.08 - 1e-6 <= top <= 0.1, lay
            gaps.append(slits[0][1])
            offsets.append(abs(slits[0][2]))
            sides.add(slits[0][2] > 0)
        assert 0.55 - 1e-6 <= gaps[0] <= 0.58 + 1e-6 and 0.34 - 1e-6 <= gaps[-1] <= 0.38 + 1e-6, gaps
        assert offsets[0] <= 0.03 + 1e-6 and 0.36 - 1e-6 <= offsets[-1] <= 0.39 + 1e-6, offsets
        assert all(b < a + 0.03 for a, b in zip(gaps[:-1], gaps[1:], strict=True)), gaps  # up to the jitter
        assert all(b > a - 0.03 for a, b in zip(offsets[:-1], offsets[1:], strict=True)), offsets
    assert sides == {True, False}
    for d in (0.0, 0.7):  # the paper's variants: the same with and without it
        a, b = make_typical(kind, d, 2, graded=graded), make_typical(kind, d, 2)
        assert a.meta["layout"] == b.meta["layout"] and _slit_walls(a) == _slit_walls(b)


def test_one_warmup_slit_takes_one_grading():
    """A warm-up slit takes one slit grading (offset, width, or both together): two are refused by name."""
    with pytest.raises(SceneError, match="task.warmup_slit_offset and task.warmup_slit_narrow both grade"):
        Graded(slit_offset=True, slit_narrow=True)
    match = "task.warmup_slit_narrow and task.warmup_slit_tight both grade side-hurdle-crouch, side-hurdle or side-pass"
    with pytest.raises(SceneError, match=match):
        Graded(slit_narrow=True, slit_tight=True)


@pytest.mark.parametrize("field", sorted(GRADED_BY))
def test_each_grading_changes_the_warmups_of_the_type_it_names(field):
    """``GRADED_BY`` (what the config checks read) is true to the scenes: a grading changes its own type's warm-ups
    and no other type's."""
    graded = Graded(**{field: 2 if field == "bars" else True})
    ((key, kinds),) = graded_kinds(graded).items()
    assert (kinds, key) == GRADED_BY[field]
    for other in TYPICAL_KINDS:
        a = [s.meta["layout"] for s in warmup_variants(other, 3, 1, graded)]
        b = [s.meta["layout"] for s in warmup_variants(other, 3, 1)]
        assert (a != b) == (other in kinds), other


@pytest.mark.parametrize("seed", [0, 4])
def test_layout_records_what_the_mesh_holds(seed):
    """``meta["layout"]`` (play.py by_scene=true prints it) is the built geometry: a slit's gap, centre and near
    edge, a bar's top, a corridor's width; its lateral entries change sign with the mirror image."""
    for d in (-0.6, 0.2, 0.9):
        s = make_typical("side-hurdle", d, seed)
        lay = s.meta["layout"]
        x0, gap, yc = _slit_walls(s)
        assert lay["x"][0] == pytest.approx(x0, abs=2e-3)  # the slit is placed first
        assert lay["slit_gap"][0] == pytest.approx(gap, abs=2e-3) and lay["slit_y"][0] == pytest.approx(yc, abs=2e-3)
        bar = min(s.mesh.split(only_watertight=False), key=lambda p: p.bounds[1, 2])
        assert lay["bar_top"][0] == pytest.approx(float(bar.bounds[1, 2]), abs=2e-3)
        assert lay["x"][1] == pytest.approx(float(bar.bounds[0, 0]), abs=2e-3)
        m = s.mirrored()
        assert m.meta["layout"]["slit_y"][0] == pytest.approx(_slit_walls(m)[2], abs=2e-3) == -lay["slit_y"][0]
        assert m.meta["layout"]["slit_gap"] == lay["slit_gap"] and s.meta["layout"] is lay  # the original unchanged
        corridor = make_typical("crouch-pass", d, seed)
        blocks = [p.bounds for p in corridor.mesh.split(only_watertight=False) if p.bounds[0, 2] < 0.01]
        width = min(b[0, 1] for b in blocks if b[0, 1] > 0) - max(b[1, 1] for b in blocks if b[1, 1] < 0)
        assert corridor.meta["layout"]["corridor_width"][0] == pytest.approx(float(width), abs=2e-3)
    assert len(make_typical("multi-hurdle", 0.9, seed).meta["layout"]["bar_top"]) == 3


def test_layout_text_prints_a_recorded_layout_and_survives_a_hand_written_one():
    """One token per scene for ``play.py by_scene=true``; a scene file's odd ``layout`` prints, it does not raise."""
    from cat.terrain.scene import layout_text

    s = make_typical("side-hurdle", 0.7, 0)
    lay = s.meta["layout"]
    assert layout_text(lay) == (
        f"slit_gap:{lay['slit_gap'][0]:.2f},slit_y:{lay['slit_y'][0]:.2f},bar_top:{lay['bar_top'][0]:.2f},"
        f"x:{lay['x'][0]:.2f}/{lay['x'][1]:.2f}"
    )
    assert layout_text({"gap": 0.5, "note": ["a b", 2]}) == "gap:0.50,note:ab/2.00"
    assert layout_text([1, 2]) == "[1,2]"


def test_mirror_of_a_hand_written_layout():
    """A scene file's ``layout`` may hold a lone number or text: the mirror image negates lateral numbers only."""
    s = make_typical("side-hurdle", 0.3, 0)
    s.meta["layout"] = {"slit_y": 0.2, "door_y": [0.1, "left"], "x": 0.5}
    assert s.mirrored().meta["layout"] == {"slit_y": -0.2, "door_y": [-0.1, "left"], "x": 0.5}
