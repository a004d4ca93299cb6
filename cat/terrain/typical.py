"""The paper's eight typical scene types (Table I), parametric in a difficulty d ∈ [0, 1] and a seed.

Every typical scene is 3.0 × 2.0 × 1.5 m, origin (−0.5, −1, 0), course along +x from the start (0, 0)
to the goal (2, 0) at ``GOAL_HEIGHT``. Obstacles sit in x ∈ [0.4, 1.75] and span the whole width, so the
robot must use the skill the type names. Building blocks (sizes from the released scenes, narrowed where
needed for a G1 to physically pass):

* hurdle bar: horizontal cylinder across the course, radius 0.08 → 0.15 m, top 0.08 → 0.25 m;
* ceiling: slab from the top of the scene down to 1.15 → 1.00 m (G1 head ≈ 1.24 m standing);
* slit wall: 0.12 m thick, full height, gap 0.90 → 0.32 m (0.25 m in the released scenes is below a
  G1's ~0.2 m torso depth plus our 0.1 m body-radius margin);
* corridor ("-pass" types): solid blocks from the sides leaving a channel 1.3 → 0.75 m wide.

Arrows read easy → hard (d = 0 → 1). Positions, gaps and small per-variant jitter come from the seed;
sizes grow monotonically with d for a fixed seed, so the free-volume fraction falls with d.

``shapes="unseen"`` builds the same layouts (the same draws of positions, gaps and sizes for a seed) from
obstacle shapes no training scene has: a hurdle is a square beam, a wedge or a row of blocks; a ceiling a pair of
pipes, a sloped slab or a thin table top; a slit wall a deep cabinet or a pillar beside a wall; a corridor side a
row of furniture blocks of mixed heights, none inside the channel. The evaluation of skills on shapes never
trained on (``configs/eval/typical_unseen.yaml``); the shape draws use a generator of their own.

Negative difficulties (d ∈ [−1, 0)) interpolate from trivially easy values to the paper's easiest at d = 0, one
skill after the other: bars rise from ``BAR_TOP_WARMUP`` (4.5 cm) to 8 cm and widen from 5 cm to the paper's
16 cm over d ∈ [−1, −0.5] (over all of [−1, 0] in types without a ceiling) under a ceiling out of reach, then
ceilings come down from ``CLEAR_CEILING`` (above a walking G1) to 1.15 m over [−0.5, 0]; slit gaps narrow from
1.3 m and corridors from 1.8 m over [−1, 0]. (Bars first: a policy that learned to crouch before meeting its first
bar kept its crouched, foot-dragging gait and every bar contact was a foot landing against the bar's base;
docs/results.md. A 5 cm strip fits between a walking gait's footprints by chance, a 16 cm one only when steps are
placed for it, so the width gives the curriculum its first successes.) They are training-only warm-up scenes
(``warmup_variants``) that let a difficulty curriculum start where a walking policy already succeeds; the paper's
variants and every evaluation use d ∈ [0, 1]. ``Graded`` swaps a type's warm-up ramp for a ladder of the skill its
hard variants need (multi-hurdle: the bar pitch, a third bar; side-hurdle: the slit's offset at a narrow gap;
side-hurdle-crouch, side-hurdle and side-pass: the slit's width, or its width and offset together); the ladders
are specified in ``cat.terrain.graded``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import trimesh

from cat.terrain.graded import (
    GRADED_FIRST_BAR,
    GRADED_GAP,
    GRADED_NARROW_GAP,
    GRADED_NARROW_Y,
    GRADED_SLIT_GAP,
    GRADED_SLIT_OFFSET,
    GRADED_TIGHT_GAP,
    GRADED_TIGHT_OFFSET,
    NOT_GRADED,
    Graded,
)
from cat.terrain.primitives import bar, box, combine, crop_parts, vcylinder, xz_prism
from cat.terrain.scene import GOAL_HEIGHT, Scene, SceneError

TYPICAL_KINDS = (
    "hurdle-crouch",
    "side-hurdle-crouch",
    "side-hurdle",
    "side-crouch",
    "hurdle-pass",
    "crouch-pass",
    "side-pass",
    "multi-hurdle",
)


def kind_name(name: str) -> str:
    """A scene kind as scenes spell it: task names and command lines use ``_`` (side_pass), kinds ``-``."""
    return name.replace("_", "-")


BOUNDS = np.array([[-0.5, -1.0, 0.0], [2.5, 1.0, 1.5]])
START = np.array([0.0, 0.0, GOAL_HEIGHT])
GOAL = np.array([2.0, 0.0, GOAL_HEIGHT])
START_REGION = np.array([[-0.3, -0.3], [0.1, 0.3]])
COURSE = (0.4, 1.75)  # x range holding obstacles
WALL_T = 0.12
HEIGHT = float(BOUNDS[1, 2])
HALF_W = float(BOUNDS[1, 1])
CLEAR_CEILING = 1.42  # warm-up ceiling at d = -1: above a walking G1 (head sphere top 1.33 m at home pose) [m]
# The easiest warm-up bar: the lowest, narrowest bar the 4 cm field grid still sees (occupancy tests voxel centres,
# the lowest at z = 2 cm: a bar must be about 5 cm wide there; a 2 cm bar was invisible to the field and to the
# elevation map, so no policy could learn to avoid it). A walking gait can clear it; feet must not land on it.
BAR_TOP_WARMUP = 0.045  # [m]
BAR_RADIUS_WARMUP = 0.025  # 5 cm wide at 2 cm height, 3 cm at the floor [m]
BAR_SPAN, CEILING_SPAN = (-1.0, -0.5), (-0.5, 0.0)  # warm-up ranges of d over which bars rise, ceilings drop
WARMUP = (-1.0, 0.0)  # the whole warm-up range: bars in scenes without a ceiling grow over all of it


def lerp(a: float, b: float, t: float) -> float:
    return float(a + (b - a) * np.clip(t, 0.0, 1.0))


# What a typical scene records of its layout (``Scene.meta["layout"]``: name -> values in placement order, metres):
# sizes drawn from d (bar tops, ceiling undersides, slit gaps, corridor widths), a slit's centre across the course
# (``slit_y``: lateral, so it changes sign in a mirrored scene) and each placed element's near edge along it (``x``).
# ``play.py by_scene=true`` prints it (``cat.terrain.scene.layout_text``) beside each scene's results: where a policy
# fails, and on which layouts.
LAYOUT_KEYS = ("bar_top", "ceiling_bottom", "slit_gap", "slit_y", "corridor_width", "x")


SHAPES = ("paper", "unseen")  # the paper's building blocks (training, Table I) | shapes no training scene has


class _Params:
    """Difficulty-driven parameters with a small per-seed jitter (monotone in d for a fixed seed); ``srng`` draws
    the unseen shapes (None: the paper's), apart from ``rng`` so a seed's layout is the same in both."""

    def __init__(
        self, d: float, rng: np.random.Generator, srng: np.random.Generator | None = None, graded: Graded = NOT_GRADED
    ):
        self.d, self.rng, self.srng, self.graded = d, rng, srng, graded
        self.layout: dict[str, list[float]] = {}  # what ``note`` recorded: the scene's ``meta["layout"]``

    def note(self, name: str, value: float) -> float:
        """Record one drawn size or position under ``name`` (one of ``LAYOUT_KEYS``) and return it."""
        if name not in LAYOUT_KEYS:
            raise ValueError(f"unknown layout key {name!r}; valid: {', '.join(LAYOUT_KEYS)}")
        self.layout.setdefault(name, []).append(round(float(value), 3))
        return value

    def __call__(
        self,
        easy: float,
        hard: float,
        jitter: float = 0.1,
        trivial: float | None = None,
        span: tuple[float, float] = (-1.0, 0.0),
    ) -> float:
        """``easy`` at d = 0, ``hard`` at d = 1; warm-up scenes (d < 0) go from ``trivial`` to ``easy`` as d
        crosses ``span`` (sizes without a ``trivial`` value stay at ``easy``)."""
        t = self.d + self.rng.uniform(-jitter, jitter)
        if self.d >= 0 or trivial is None:
            return lerp(easy, hard, t)
        lo, hi = span
        return lerp(trivial, easy, (t - lo) / (hi - lo))


# Each element is (x-extent, builder(x0) -> parts); builders close over their parameters.
Element = tuple[float, Callable[[float], list[trimesh.Trimesh]]]


def _bar(p: _Params, span: tuple[float, float] = BAR_SPAN) -> Element:
    """Hurdle bar; ``span``: the warm-up range of d over which it grows (all of [−1, 0] when no ceiling follows)."""
    top = p.note("bar_top", p(0.08, 0.25, trivial=BAR_TOP_WARMUP, span=span))
    r = max(p(0.08, 0.15, trivial=BAR_RADIUS_WARMUP, span=span), top / 2)  # resting on the floor
    if p.srng is not None:
        return _unseen_hurdle(p.srng, top, 2 * r)
    return 2 * r, lambda x0: [bar("y", (x0 + r, 0.0, top - r), r, 2 * HALF_W)]


def _ceiling(p: _Params, depth: tuple[float, float] = (0.3, 0.6)) -> Element:
    bottom, dep = p.note("ceiling_bottom", p(1.15, 1.00, trivial=CLEAR_CEILING, span=CEILING_SPAN)), p(*depth)
    if p.srng is not None:
        return dep, _unseen_ceiling(p.srng, bottom, dep)
    return dep, lambda x0: [box((x0, -HALF_W, bottom), (x0 + dep, HALF_W, HEIGHT))]


def _slit_parts(x0: float, gap: float, yc: float) -> list[trimesh.Trimesh]:
    lo, hi = yc - gap / 2, yc + gap / 2
    return [box((x0, -HALF_W, 0.0), (x0 + WALL_T, lo, HEIGHT)), box((x0, hi, 0.0), (x0 + WALL_T, HALF_W, HEIGHT))]


def _slit(p: _Params, yc: float | None = None) -> Element:
    gap = p.note("slit_gap", p(0.90, 0.32, jitter=0.05, trivial=1.3))
    if yc is None:
        yc = p.rng.uniform(-1, 1) * (HALF_W - 0.15 - gap / 2) * 0.6
    p.note("slit_y", yc)
    if p.srng is not None:
        return _unseen_slit(p.srng, gap, yc)
    return WALL_T, lambda x0: _slit_parts(x0, gap, yc)


def _low_door(p: _Params) -> Element:
    """Slit wall whose gap is capped by a lintel, continued by a ceiling: side-step and crouch at once."""
    gap, yc = p(0.90, 0.36, jitter=0.05, trivial=1.3, span=BAR_SPAN), p.rng.uniform(-0.25, 0.25)
    bottom, dep = p(1.15, 1.00, trivial=CLEAR_CEILING, span=CEILING_SPAN), p(0.2, 0.5)
    p.note("slit_gap", gap)
    p.note("slit_y", yc)
    p.note("ceiling_bottom", bottom)
    if p.srng is not None:
        wall, walls = _unseen_slit(p.srng, gap, yc)
        ceiling = _unseen_ceiling(p.srng, bottom, wall + dep)
        return wall + dep, lambda x0: walls(x0) + ceiling(x0)

    def build(x0: float) -> list[trimesh.Trimesh]:
        return _slit_parts(x0, gap, yc) + [box((x0, -HALF_W, bottom), (x0 + WALL_T + dep, HALF_W, HEIGHT))]

    return WALL_T + dep, build


UNSEEN_SHAPES_STREAM = 7  # the unseen shapes' generator: default_rng([seed, kind index, 7])


def _unseen_hurdle(rng: np.random.Generator, top: float, width: float) -> Element:
    """A hurdle of the bar's top and footprint: a square beam, a wedge rising to ``top``, or a row of blocks with
    4 cm gaps (heights 80-100 % of ``top``)."""
    style = int(rng.integers(3))
    if style == 0:
        return width, lambda x0: [box((x0, -HALF_W, 0.0), (x0 + width, HALF_W, top))]
    if style == 1:
        depth = width
        up = bool(rng.integers(2))  # the steep face toward the robot or away from it
        tri = [(0.0, 0.0), (depth, 0.0), (depth, top)] if up else [(0.0, 0.0), (depth, 0.0), (0.0, top)]
        return depth, lambda x0: [xz_prism([(x0 + x, z) for x, z in tri], -HALF_W, HALF_W)]
    edges = [-HALF_W]
    while edges[-1] < HALF_W:
        edges.append(edges[-1] + float(rng.uniform(0.25, 0.5)))
    heights = rng.uniform(0.8, 1.0, len(edges) - 1) * top

    def blocks(x0: float) -> list[trimesh.Trimesh]:
        return [
            box((x0, a + 0.02, 0.0), (x0 + width, b - 0.02, float(h)))
            for a, b, h in zip(edges[:-1], edges[1:], heights, strict=True)
        ]

    return width, blocks


def _unseen_ceiling(rng: np.random.Generator, bottom: float, depth: float) -> Callable[[float], list[trimesh.Trimesh]]:
    """What hangs at ``bottom`` over ``depth`` of course: two pipes at its ends, a slab whose underside slopes
    from 12 cm higher down to ``bottom``, or a 4 cm table top with free space above."""
    style = int(rng.integers(3))
    if style == 0:
        r = float(rng.uniform(0.05, 0.1))
        return lambda x0: [
            bar("y", (x0 + x, 0.0, bottom + r), r, 2 * HALF_W) for x in (r, max(depth - r, r))
        ]  # fmt: skip
    if style == 1:
        rise = 0.12
        return lambda x0: [
            xz_prism([(x0, bottom + rise), (x0 + depth, bottom), (x0 + depth, HEIGHT), (x0, HEIGHT)], -HALF_W, HALF_W)
        ]
    return lambda x0: [box((x0, -HALF_W, bottom), (x0 + depth, HALF_W, bottom + 0.04))]


def _unseen_slit(rng: np.random.Generator, gap: float, yc: float) -> Element:
    """A gap of width ``gap`` at ``yc``: between two deep cabinets (0.25-0.35 m, full height), or between a
    pillar (radius 6-10 cm) on one side and a wall on the other."""
    lo, hi = yc - gap / 2, yc + gap / 2
    if int(rng.integers(2)) == 0:
        deep = float(rng.uniform(0.25, 0.35))
        return deep, lambda x0: [
            box((x0, -HALF_W, 0.0), (x0 + deep, lo, HEIGHT)),
            box((x0, hi, 0.0), (x0 + deep, HALF_W, HEIGHT)),
        ]
    r = float(rng.uniform(0.06, 0.1))
    left = bool(rng.integers(2))  # the pillar's side

    def parts(x0: float) -> list[trimesh.Trimesh]:
        if left:  # pillar at the low-y edge of the gap, a thin wall behind it to the side; a wall on the other side
            return [vcylinder((x0 + r, lo - r), r, 0.0, HEIGHT), box((x0, -HALF_W, 0.0), (x0 + 2 * r, lo - r, HEIGHT)),
                    box((x0, hi, 0.0), (x0 + 2 * r, HALF_W, HEIGHT))]  # fmt: skip
        return [vcylinder((x0 + r, hi + r), r, 0.0, HEIGHT), box((x0, hi + r, 0.0), (x0 + 2 * r, HALF_W, HEIGHT)),
                box((x0, -HALF_W, 0.0), (x0 + 2 * r, lo, HEIGHT))]  # fmt: skip

    return 2 * r, parts


def _unseen_corridor(rng: np.random.Generator, half: float, x0: float, x1: float) -> list[trimesh.Trimesh]:
    """Each side of a channel of half-width ``half``: furniture blocks 0.25-0.5 m long, 0.8 m to full height,
    their inner faces 0-10 cm back from the channel (never inside it; one of them at its edge)."""
    parts = []
    for sign in (-1.0, 1.0):
        x, side = x0, []
        while x < x1:
            length = float(rng.uniform(0.25, 0.5))
            length = x1 - x if x1 - x - length < 0.1 else length  # no sliver at the end
            side.append(
                [x, x + length, float(rng.uniform(0.0, 0.1)), float(rng.choice([rng.uniform(0.8, 1.0), HEIGHT]))]
            )
            x += length
        side[int(rng.integers(len(side)))][2] = 0.0  # the channel is exactly as narrow as the paper's somewhere
        for a, b, back, h in side:
            inner = half + back
            lo, hi = (-HALF_W, -inner) if sign < 0 else (inner, HALF_W)
            parts.append(box((a, lo, 0.0), (b, hi, h)))
    return parts


def _sequence(elements: list[Element], p: _Params, min_gap: float = 0.25) -> list[trimesh.Trimesh]:
    """Place elements along the course with random gaps (at least ``min_gap`` when they fit); notes each one's
    near edge (``x``)."""
    length = COURSE[1] - COURSE[0]
    spare = length - sum(e for e, _ in elements)
    n_gaps = len(elements) + 1
    if spare < 0:
        raise SceneError(f"typical elements need {length - spare:.2f} m of course, only {length:.2f} m")
    inner = max(min(min_gap, spare / max(n_gaps - 2, 1)), 0.0) if len(elements) > 1 else 0.0
    rest = spare - inner * (len(elements) - 1)
    w = p.rng.dirichlet(np.ones(n_gaps))
    gaps = rest * w
    gaps[1:-1] += inner
    parts, x = [], COURSE[0] + gaps[0]
    for (ext, build), g in zip(elements, gaps[1:], strict=True):
        parts += build(p.note("x", x))
        x += ext + g
    return parts


def _graded_bars(p: _Params) -> list[trimesh.Trimesh]:
    """Two warm-up bars whose first position and floor gap shrink with d (``GRADED_FIRST_BAR``, ``GRADED_GAP``);
    with ``p.graded.bars == 3`` a third at the same gap when the three fit on the course from its start."""
    bars = [_bar(p, WARMUP), _bar(p, WARMUP)]
    t = p.d - WARMUP[0]
    x0 = lerp(*GRADED_FIRST_BAR, t) + p.rng.uniform(0.0, 0.05)
    gap = lerp(*GRADED_GAP, t) + p.rng.uniform(0.0, 0.05)
    widest = max(w for w, _ in bars)
    if p.graded.bars == 3 and COURSE[0] + 3 * widest + 2 * gap <= COURSE[1]:
        bars.append(_bar(p, WARMUP))
    end = x0
    for i, (w, _) in enumerate(bars):
        end = end + w + gap if i < len(bars) - 1 else end + w
    x = x0 - max(end - COURSE[1], 0.0)  # the last bar ends on the course
    parts = []
    for w, build in bars:
        parts += build(p.note("x", x))
        x = x + w + gap
    return parts


def _offset_slit(p: _Params) -> Element:
    """A warm-up slit ``GRADED_SLIT_GAP`` wide whose centre leaves the axis as d grows (``GRADED_SLIT_OFFSET``)."""
    return _off_axis_slit(p, GRADED_SLIT_GAP, 0.05, lerp(*GRADED_SLIT_OFFSET, p.d - WARMUP[0]))


def _narrow_slit(p: _Params) -> Element:
    """A warm-up slit near the axis narrowing with d (``GRADED_NARROW_GAP``, ``GRADED_NARROW_Y``)."""
    gap = p.note("slit_gap", lerp(*GRADED_NARROW_GAP, p.d - WARMUP[0]) + p.rng.uniform(0.0, 0.03))
    yc = p.note("slit_y", p.rng.uniform(-GRADED_NARROW_Y, GRADED_NARROW_Y))
    return WALL_T, lambda x0: _slit_parts(x0, gap, yc)


def _tight_slit(p: _Params, side: float | None = None) -> Element:
    """A warm-up slit narrowing as it leaves the axis, both with d (``GRADED_TIGHT_GAP``, ``GRADED_TIGHT_OFFSET``),
    to ``side`` (±1; None: either side, drawn)."""
    t = p.d - WARMUP[0]
    return _off_axis_slit(p, lerp(*GRADED_TIGHT_GAP, t), 0.03, lerp(*GRADED_TIGHT_OFFSET, t), side)


def _off_axis_slit(p: _Params, gap: float, gap_jitter: float, offset: float, side: float | None = None) -> Element:
    """A warm-up slit ``gap`` wide (+ up to ``gap_jitter``) whose centre is ``offset`` off the axis (+ up to 3 cm)
    to ``side`` (±1; None: either, drawn): the graded offset and tight ladders' slit."""
    gap = p.note("slit_gap", gap + p.rng.uniform(0.0, gap_jitter))
    side = float(p.rng.choice([-1.0, 1.0])) if side is None else side
    yc = p.note("slit_y", side * (offset + p.rng.uniform(0.0, 0.03)))
    return WALL_T, lambda x0: _slit_parts(x0, gap, yc)


def _bar_and_ceiling(p: _Params) -> list[Element]:
    """Side-hurdle-crouch's bar and ceiling, after its slit."""
    return [_bar(p), _ceiling(p, (0.25, 0.4))]


def _warmup_bar(p: _Params) -> list[Element]:
    """Side-hurdle's bar, after its slit: grown over the whole warm-up range (no ceiling follows)."""
    return [_bar(p, WARMUP)]


def _easiest(p: _Params, build: Callable[[_Params], list[Element]]) -> list[Element]:
    """``build``'s elements as the easiest paper variant draws them (d = 0 and its jitter), whatever ``p.d``;
    recorded in ``p``'s layout."""
    q = _Params(0.0, p.rng)
    q.layout = p.layout
    return build(q)


def _corridor(p: _Params) -> list[trimesh.Trimesh]:
    half = p.note("corridor_width", p(1.3, 0.75, jitter=0.05, trivial=1.8)) / 2
    x0, x1 = COURSE[0] - 0.05, COURSE[1] - 0.05
    if p.srng is not None:
        return _unseen_corridor(p.srng, half, x0, x1)
    return [box((x0, -HALF_W, 0.0), (x1, -half, HEIGHT)), box((x0, half, 0.0), (x1, HALF_W, HEIGHT))]


def _layout(kind: str, p: _Params) -> list[trimesh.Trimesh]:
    if kind == "hurdle-crouch":
        return _sequence([_bar(p), _ceiling(p)], p)
    if kind == "side-hurdle-crouch":
        if p.graded.slit_narrow and p.d < 0:
            return _sequence([_narrow_slit(p), *_easiest(p, _bar_and_ceiling)], p)
        if p.graded.slit_tight and p.d < 0:
            return _sequence([_tight_slit(p), *_easiest(p, _bar_and_ceiling)], p)
        return _sequence([_slit(p), *_bar_and_ceiling(p)], p)
    if kind == "side-hurdle":
        if p.graded.slit_offset and p.d < 0:
            return _sequence([_offset_slit(p), *_warmup_bar(p)], p)
        if p.graded.slit_narrow and p.d < 0:
            return _sequence([_narrow_slit(p), *_easiest(p, _warmup_bar)], p)
        if p.graded.slit_tight and p.d < 0:
            return _sequence([_tight_slit(p), *_easiest(p, _warmup_bar)], p)
        return _sequence([_slit(p), *_warmup_bar(p)], p)
    if kind == "side-crouch":
        return _sequence([_low_door(p)], p)
    if kind == "hurdle-pass":
        return _corridor(p) + _sequence([_bar(p, WARMUP)], p)
    if kind == "crouch-pass":
        return _corridor(p) + _sequence([_ceiling(p, (0.4, 0.9))], p)
    if kind == "side-pass":
        if p.graded.slit_narrow and p.d < 0:
            return _sequence([_narrow_slit(p), _narrow_slit(p)], p, min_gap=0.45)
        if p.graded.slit_tight and p.d < 0:
            side = float(p.rng.choice([-1.0, 1.0]))
            return _sequence([_tight_slit(p, side), _tight_slit(p, -side)], p, min_gap=0.45)
        off = p(0.2, 0.45) * p.rng.choice([-1.0, 1.0])
        return _sequence([_slit(p, yc=off), _slit(p, yc=-off)], p, min_gap=0.45)
    if kind == "multi-hurdle":
        n = 2 if p.d < 0.5 else 3
        if p.graded.bars and p.d < 0:
            return _graded_bars(p)
        return _sequence([_bar(p, WARMUP) for _ in range(n)], p, min_gap=0.3)
    raise SceneError(f"unknown typical scene type {kind!r}; valid: {', '.join(TYPICAL_KINDS)}")


def make_typical(
    kind: str, difficulty: float = 0.5, seed: int = 0, shapes: str = "paper", graded: Graded = NOT_GRADED
) -> Scene:
    """One typical scene of ``kind`` (see ``TYPICAL_KINDS``); deterministic in (kind, difficulty, seed, shapes).

    ``difficulty`` ∈ [0, 1] spans the paper's range; [−1, 0) is the training-only warm-up range. ``shapes``: the
    paper's building blocks, or ``unseen`` ones (module docstring; evaluation only, never a training scene).
    ``graded``: how a warm-up grades its type's hard part (``Graded``); the paper's variants never change.
    """
    if not -1.0 <= difficulty <= 1.0:
        raise SceneError(f"difficulty must be in [-1, 1] ([0, 1] for the paper's scenes), got {difficulty}")
    if shapes not in SHAPES:
        raise SceneError(f"unknown typical shapes {shapes!r}; valid: {', '.join(SHAPES)}")
    key = [seed, TYPICAL_KINDS.index(kind) if kind in TYPICAL_KINDS else 99]
    srng = np.random.default_rng([*key, UNSEEN_SHAPES_STREAM]) if shapes == "unseen" else None
    params = _Params(difficulty, np.random.default_rng(key), srng, graded)
    parts = crop_parts(_layout(kind, params), BOUNDS[0], BOUNDS[1])
    return Scene(
        mesh=combine(parts),
        bounds=BOUNDS.copy(),
        start=START.copy(),
        goals=GOAL[None].copy(),
        kind=kind,
        difficulty=float(difficulty),
        seed=int(seed),
        start_region=START_REGION.copy(),
        meta={
            "family": "typical",
            "primitive_parts": True,
            "layout": params.layout,
            **({"shapes": shapes} if shapes != "paper" else {}),
        },
    )


def typical_variants(kind: str, n: int = 10, seed: int = 0, shapes: str = "paper") -> list[Scene]:
    """``n`` variants of ``kind`` with difficulties spread evenly over [0, 1] and seeds seed..seed+n-1."""
    ds = np.linspace(0.0, 1.0, n) if n > 1 else np.array([0.5])
    return [make_typical(kind, float(d), seed + i, shapes) for i, d in enumerate(ds)]


WARMUP_SEED_OFFSET = 10_000  # warm-up scenes never share a seed with the paper's variants


def warmup_variants(kind: str, n: int, seed: int = 0, graded: Graded = NOT_GRADED) -> list[Scene]:
    """``n`` training-only scenes of ``kind`` easier than the paper's easiest: difficulties −1, −1 + 1/n, …,
    −1/n (seeds ``WARMUP_SEED_OFFSET`` + seed + i), so a curriculum climbs from walking to the paper's range.
    ``graded``: how they grade the type's hard part (``Graded``)."""
    ds = -1.0 + np.arange(n) / max(n, 1)
    return [make_typical(kind, float(d), WARMUP_SEED_OFFSET + seed + i, graded=graded) for i, d in enumerate(ds)]
