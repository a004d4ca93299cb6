"""Left/right mirror maps of term columns, the building blocks of the terms' ``mirror`` declarations.

A map is ``(perm, sign)``: ``mirrored[:, i] = sign[i] * value[:, perm[i]]`` under the reflection y -> -y of the
world (the x-z plane of the robot's yaw frame); ``cat.envs.symmetry`` assembles them per group.
"""

from __future__ import annotations

import numpy as np

Mirror = tuple[list[int], list[float]]

POLAR: Mirror = ([0, 1, 2], [1.0, -1.0, 1.0])  # gravity, goal, velocities, positions, field directions
AXIAL: Mirror = ([0, 1, 2], [-1.0, 1.0, -1.0])  # angular velocity
FIELD_LINK: Mirror = ([0, 1, 2, 3, 4, 5, 6], [1.0, -1.0, 1.0, 1.0, -1.0, 1.0, 1.0])  # F_H (3), grad d (3), d


def mirror_name(name: str) -> str:
    """``left_x`` <-> ``right_x``; other names map to themselves."""
    if name.startswith("left_"):
        return "right_" + name[5:]
    if name.startswith("right_"):
        return "left_" + name[6:]
    return name


def joint_mirror(names: list[str]) -> Mirror:
    """(perm, sign) over joints: mirrored[i] = sign[i] * q[perm[i]]; roll / yaw joints flip sign."""
    perm = [names.index(mirror_name(n)) for n in names]
    sign = [-1.0 if ("roll" in n or "yaw" in n) else 1.0 for n in names]
    return perm, sign


def link_mirror(names: list[str], per_link: Mirror) -> Mirror:
    """Mirror of a (K, d) link block flattened to K*d: links swap sides, each link's d values by ``per_link``."""
    d = len(per_link[0])
    perm, sign = [], []
    for name in names:
        k = names.index(mirror_name(name))
        perm += [k * d + j for j in per_link[0]]
        sign += per_link[1]
    return perm, sign


def grid_mirror(shape: tuple[int, ...], layers: int = 1) -> Mirror:
    """(perm, sign) of ``layers`` row-major grids of ``shape`` (along, across, ...): the across axis reverses."""
    idx = np.arange(layers * int(np.prod(shape))).reshape((layers, *shape))
    return np.flip(idx, axis=2).reshape(-1).tolist(), [1.0] * idx.size
