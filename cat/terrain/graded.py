"""How training-only warm-up scenes grade a typical type's hard part (``Graded``): the ladders a curriculum climbs
before the paper's variants, their constants, and the task keys that turn them on (``GRADED_BY``).

The scenes themselves are built in ``cat.terrain.typical``; this module only says what each ladder grades, so the
config checks (``cat.envs.scene_source``) and the builders read one definition.
"""

from __future__ import annotations

from dataclasses import dataclass

from cat.terrain.scene import SceneError

# Graded bar pitch (multi-hurdle warm-ups, ``Graded.bars``): the first bar's near edge and the floor gap between the
# bars shrink with d from the first to the second value (+ up to 5 cm of jitter each), instead of random gaps.
# The gap, not the bar height, sets a warm-up's success (docs/multi_hurdle.md, "The bar pitch"); the paper's
# three-bar variants leave 0.23-0.32 m. With ``Graded.bars=3`` a third bar follows at the same gap wherever it fits on
# the course (gaps up to ~0.4 m: the last warm-ups), the step from two bars to the paper's three.
GRADED_FIRST_BAR = (0.70, 0.40)  # [m] from the course origin (the start region ends at x = 0.1)
GRADED_GAP = (0.85, 0.25)  # [m]
GRADED_BARS = (0, 2, 3)  # bars of a graded warm-up (0: not graded, random gaps)
# Graded slit offset (side-hurdle warm-ups, ``Graded.slit_offset``): a slit as narrow as the paper's middle variants
# (+ up to 5 cm) whose centre moves off the course's axis as d grows, to either side (+ up to 3 cm), ahead of a
# warm-up bar. The paper's variants put their offsets only on their narrowest slits (``_slit``), where a policy
# that turns side-on at the wall before lining up with the slit fails (docs/results.md, "Side-hurdle: where the
# hard variants fail"); here the offset is the only thing that grows.
GRADED_SLIT_GAP = 0.45  # [m]
GRADED_SLIT_OFFSET = (0.0, 0.40)  # [m], d = -1 -> 0
# Graded slit width (side-hurdle-crouch, side-hurdle and side-pass warm-ups, ``Graded.slit_narrow``): a slit near the
# axis (centre within ``GRADED_NARROW_Y``) narrowing from the paper's widest gap to its narrow ones as d grows (+ up
# to 3 cm), ahead of what follows the slit in the type's easiest paper variant (d = 0): side-hurdle-crouch's bar and
# ceiling, side-hurdle's bar; side-pass's two slits are both such slits (near the axis, not offset to opposite
# sides). The hurdle-crouch lineage passes the paper's slits down to ~0.57 m and none from 0.50 m (docs/results.md,
# "Side-hurdle-crouch and side-hurdle: could one start the other?"), the side-pass specialist none of its two
# narrowest pairs (0.39 / 0.32 m); here the slit's width is the only thing that grows. (Not the 4.5 cm warm-up bar:
# the hurdle-crouch lineage trips on it, 3.5 % of trials passing even the widest slit.)
GRADED_NARROW_GAP = (0.90, 0.40)  # [m], d = -1 -> 0
GRADED_NARROW_Y = 0.10  # [m]
# Graded slit width and offset together (side-hurdle-crouch, side-hurdle and side-pass warm-ups,
# ``Graded.slit_tight``): a slit narrowing as its centre leaves the axis, both as d grows (+ up to 3 cm each), to
# either side (side-pass: two slits on opposite sides), ahead of what follows the slit in the type's easiest paper
# variant. The paper's hardest slits are narrow *and* off the axis (side-hurdle 0.48 m at 0.30 m and 0.32 m at
# 0.21 m; side-pass pairs of 0.32-0.45 m at 0.35-0.45 m), where the width ladder's cells fail (docs/results.md,
# "Sixteenth sitting"); the ladder starts at a slit those cells pass (0.55 m on the axis) and ends past the paper's
# corner, one diagonal through the two gradings above.
GRADED_TIGHT_GAP = (0.55, 0.32)  # [m], d = -1 -> 0
GRADED_TIGHT_OFFSET = (0.0, 0.40)  # [m], d = -1 -> 0

SLIT_GRADINGS = ("slit_offset", "slit_narrow", "slit_tight")  # the fields that build a warm-up slit


@dataclass(frozen=True)
class Graded:
    """How training-only warm-ups (d < 0) grade a type's hard part, instead of the default ramp: multi-hurdle's
    bars at a pitch shrinking with d (``bars``: 2, or 3 where they fit; 0: random gaps), side-hurdle's slit moving
    off the axis at a narrow gap (``slit_offset``), the slit of side-hurdle-crouch and side-hurdle narrowing ahead
    of the rest of the type's easiest paper variant and side-pass's two slits narrowing near the axis
    (``slit_narrow``), or those slits narrowing as they leave the axis (``slit_tight``). Each applies to the types
    ``GRADED_BY`` names only; the paper's variants never change. At most one slit grading: each builds the slit."""

    bars: int = 0
    slit_offset: bool = False
    slit_narrow: bool = False
    slit_tight: bool = False

    def __post_init__(self):
        if self.bars not in GRADED_BARS:
            raise SceneError(f"graded bars must be one of {GRADED_BARS} (0: random gaps), got {self.bars}")
        on = [f for f in SLIT_GRADINGS if getattr(self, f)]
        if len(on) > 1:  # each would build the type's warm-up slit
            (kinds_a, key_a), (kinds_b, key_b) = GRADED_BY[on[0]], GRADED_BY[on[1]]
            both = kinds_text(tuple(k for k in kinds_a if k in kinds_b))
            raise SceneError(f"{key_a} and {key_b} both grade {both}'s warm-up slit: set one")


NOT_GRADED = Graded()
# The typical types each ``Graded`` field grades, and the task key that turns it on: what both the training set's
# and the warm-up diagnostic's checks read (cat.envs.scene_source), so another grading is one more row here.
GRADED_BY = {
    "bars": (("multi-hurdle",), "task.warmup_bar_pitch"),
    "slit_offset": (("side-hurdle",), "task.warmup_slit_offset"),
    "slit_narrow": (("side-hurdle-crouch", "side-hurdle", "side-pass"), "task.warmup_slit_narrow"),
    "slit_tight": (("side-hurdle-crouch", "side-hurdle", "side-pass"), "task.warmup_slit_tight"),
}


def graded_kinds(graded: Graded) -> dict[str, tuple[str, ...]]:
    """The gradings ``graded`` turns on: its task key -> the typical types whose warm-ups it changes."""
    return {key: kinds for field, (kinds, key) in GRADED_BY.items() if getattr(graded, field)}


def kinds_text(kinds: tuple[str, ...]) -> str:
    """``("a", "b", "c")`` as ``a, b or c`` (messages naming the types a grading applies to)."""
    return " or ".join([", ".join(kinds[:-1]), kinds[-1]] if len(kinds) > 1 else list(kinds))
