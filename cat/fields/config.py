"""Constants of HumanoidPF that the paper leaves open (see docs/fields.md for the reasons)."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields


@dataclass
class FieldCfg:
    """HumanoidPF constants. Units: metres, seconds; potentials are dimensionless."""

    eta: float = 1.0
    """Attraction gain: U_att = eta * geodesic distance, so |F_att| = eta (Eikonal)."""
    d0: float = 0.3
    """Repulsion influence range (m): U_rep = 0 for d > d0."""
    xi: float = 0.0068
    """Repulsion gain: repulsion equals attraction (|F_rep| = eta) at d = d0/2 = 0.15 m with eta = 1."""
    d_min: float = 0.02
    """Distances below this (incl. inside obstacles) are clamped to it in U_rep so F stays finite."""
    lam: float = 1.0
    """Collision-urgency scale lambda in w1 = lam * max(-grad d . v, 0.5) * exp(-d)."""
    w_root: float = 1.0
    """Priority weight w0 of the root link (pelvis)."""
    w_other: float = 0.5
    """Priority weight w0 of every other link."""
    kappa_max: float = 10.0
    """vMF concentration scale: kappa = kappa_max * |F_H|."""
    kappa_cap: float = 100.0
    """Safety clip on kappa (fast links near obstacles); far above typical values (< 30)."""
    goal_init_radius: float = 4.0
    """Voxels within this many voxels of the goal start with their exact Euclidean distance."""

    def to_dict(self) -> dict:
        return asdict(self)

    def build_dict(self) -> dict:
        """The constants a built field depends on (:data:`BUILD_KEYS`); the others act at query time."""
        return {k: getattr(self, k) for k in BUILD_KEYS}


BUILD_KEYS = ("eta", "d0", "xi", "d_min", "goal_init_radius")
"""FieldCfg entries baked into stored F and d: a saved field built under other values is stale."""


class StaleFieldError(ValueError):
    """A saved field does not match what is asked for (other build constants, grid or goals): rebuild it."""


def cfg_from_dict(values: dict) -> FieldCfg:
    """FieldCfg from saved values, ignoring keys this version does not know (missing ones take defaults)."""
    known = {f.name for f in fields(FieldCfg)}
    return FieldCfg(**{k: v for k, v in values.items() if k in known})


def read_saved_header(z, path, version_key: str, version: int, cfg: FieldCfg | None) -> tuple[dict, tuple]:
    """The build constants and ``(origin, voxel, shape)`` of a saved ``.npz`` field file ``z``, after checking its
    format version (``z[version_key]`` must equal ``version``) and, with ``cfg``, its build constants
    (:func:`check_built_with`); raises :class:`StaleFieldError` naming ``path``."""
    found = int(z[version_key]) if version_key in z else -1
    if found != version:
        raise StaleFieldError(f"{path}: format version {found}, expected {version}")
    saved = json.loads(str(z["cfg"]))
    if cfg is not None:
        check_built_with(saved, cfg, str(path))
    return saved, (tuple(z["origin"]), float(z["voxel"]), tuple(int(v) for v in z["shape"]))


def check_built_with(saved: dict, cfg: FieldCfg, source: str) -> None:
    """Raise :class:`StaleFieldError` (one line, naming ``source`` and the differing constants) unless the
    saved build constants equal ``cfg``'s."""
    diff = []
    for k in BUILD_KEYS:
        want, got = float(getattr(cfg, k)), saved.get(k)
        if got is None or not math.isclose(float(got), want, rel_tol=1e-9, abs_tol=0.0):
            diff.append(f"{k} saved {got} != {want}")
    if diff:
        raise StaleFieldError(f"{source}: built under another field config ({'; '.join(diff)})")
