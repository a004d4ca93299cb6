"""The paper's four training data groups (Table II): which indoor crops and procedural scenes a run trains on.

One hybrid scene folder holds the superset (``scripts/gen_scenes.py data=all``: ``indoor`` crops and
``procedural`` scenes with difficulties spread evenly over [0, 1]); a group is a selection from it
(``task.data=<group>``), so the groups are nested and share their indoor crops:

=================  =====================================================================================
``base``           indoor crops only
``syn_partial_easy`` + every other procedural scene of difficulty <= 0.6 (ranked by difficulty, then seed)
``syn_full_easy``  + every procedural scene of difficulty <= 0.6
``syn_full_hard``  + every procedural scene of difficulty in [0.4, 1.0]
=================  =====================================================================================

Scenes of other kinds in the folder (typical types, user meshes) pass through every group unchanged: they are the
typical skills kept in the mix. The paper used 139 indoor + 216 procedural scenes; this machine's default is
``GROUP_SIZES`` (docs/scenes.md says why).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SELECTED_KINDS = ("indoor", "procedural")
GROUP_SIZES = {"indoor": 40, "procedural": 40}  # the superset on this machine (paper: 139 + 216)


@dataclass(frozen=True)
class DataGroup:
    """A selection of a hybrid scene folder."""

    name: str
    description: str
    procedural_every: int = 0  # keep every k-th procedural scene in range (0: none)
    difficulty: tuple[float, float] = (0.0, 1.0)  # procedural difficulty range (inclusive)


DATA_GROUPS: dict[str, DataGroup] = {
    g.name: g
    for g in (
        DataGroup("base", "indoor crops only"),
        DataGroup("syn_partial_easy", "indoor + half of the procedural scenes with difficulty <= 0.6", 2, (0.0, 0.6)),
        DataGroup("syn_full_easy", "indoor + all procedural scenes with difficulty <= 0.6", 1, (0.0, 0.6)),
        DataGroup("syn_full_hard", "indoor + all procedural scenes with difficulty 0.4-1.0", 1, (0.4, 1.0)),
    )
}


class DataGroupError(ValueError):
    """An unknown data group, or one that selects no scene."""


def data_group(name: str) -> DataGroup:
    if name not in DATA_GROUPS:
        raise DataGroupError(f"unknown data group {name!r}; valid: {', '.join(DATA_GROUPS)}")
    return DATA_GROUPS[name]


def select(kinds: list[str], difficulties: list[float], seeds: list[int | None], name: str) -> np.ndarray:
    """Boolean mask of the scenes (given by kind, difficulty, seed) that data group ``name`` trains on."""
    group = data_group(name)
    kinds_a = np.asarray(kinds, dtype=object)
    keep = ~np.isin(kinds_a, SELECTED_KINDS)  # other kinds pass through
    keep |= kinds_a == "indoor"
    lo, hi = group.difficulty
    eps = 1e-9
    proc = [i for i, k in enumerate(kinds) if k == "procedural" and lo - eps <= difficulties[i] <= hi + eps]
    if group.procedural_every > 0:
        ranked = sorted(proc, key=lambda i: (difficulties[i], seeds[i] if seeds[i] is not None else -1, i))
        keep[ranked[:: group.procedural_every]] = True
    return keep
