"""Procedurally furnished houses (the embedded default for indoor crops; 3D-FRONT is licence-gated).

Furniture is built from convex boxes/prisms with realistic dimensions (metres): bed 2.0 × 1.6 × 0.5
with a 1.0 m headboard, dining table 1.4 × 0.8 × 0.75 on legs, chairs (seat 0.45, backrest to 0.9),
sofa 2.0 × 0.9 (seat 0.42, back 0.8), shelf 0.9 × 0.35 × 1.8, desk 1.2 × 0.6 × 0.75, coffee table,
floor lamp 1.6 m, pendant lamps hanging to 1.2–1.5 m, a wall shelf at 1.1–1.3 m, and floor clutter
(boxes, balls) low enough to step over. Houses have one or two rooms (walls 0.12 m thick, 2.6 m tall,
a 0.9 m door between rooms).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import trimesh

from cat.terrain.primitives import box, vcylinder

WALL_T = 0.12
WALL_H = 2.6
DOOR_W = 0.9
Parts = list[trimesh.Trimesh]


@dataclass
class House:
    """Obstacle parts (z-up, floor at z = 0) and the walkable floor as flat triangles."""

    parts: Parts
    floor: trimesh.Trimesh
    name: str = "house"
    tags: list[str] = field(default_factory=list)  # one per part: "arch" | "furniture"


# ------------------------------------------------------------------------------ furniture (local)
# Local frame: footprint centred at the origin, back towards -y, standing on z = 0.
def _legs(hx: float, hy: float, h: float, t: float, inset: float = 0.03) -> Parts:
    xs, ys = (-hx + inset, hx - inset - t), (-hy + inset, hy - inset - t)
    return [box((x, y, 0.0), (x + t, y + t, h)) for x in xs for y in ys]


def table(w: float = 1.4, d: float = 0.8, h: float = 0.75) -> Parts:
    return [box((-w / 2, -d / 2, h - 0.04), (w / 2, d / 2, h))] + _legs(w / 2, d / 2, h - 0.04, 0.05)


def chair(rng: np.random.Generator) -> Parts:
    s, seat = rng.uniform(0.42, 0.5), rng.uniform(0.43, 0.47)
    back = rng.uniform(0.85, 0.95)
    return (
        [box((-s / 2, -s / 2, seat - 0.04), (s / 2, s / 2, seat))]
        + _legs(s / 2, s / 2, seat - 0.04, 0.035, 0.01)
        + [box((-s / 2, -s / 2, seat), (s / 2, -s / 2 + 0.04, back))]
    )


def bed(rng: np.random.Generator) -> Parts:
    w, length = rng.choice([0.9, 1.4, 1.6, 1.8]), rng.uniform(1.95, 2.1)
    base = box((-w / 2, -length / 2, 0.0), (w / 2, length / 2, 0.5))
    return [base, box((-w / 2, -length / 2, 0.0), (w / 2, -length / 2 + 0.08, 1.0))]


def sofa(rng: np.random.Generator) -> Parts:
    w, d = rng.uniform(1.6, 2.2), rng.uniform(0.85, 0.95)
    return [
        box((-w / 2, -d / 2, 0.0), (w / 2, d / 2, 0.42)),
        box((-w / 2, -d / 2, 0.42), (w / 2, -d / 2 + 0.2, 0.8)),
        box((-w / 2, -d / 2 + 0.2, 0.42), (-w / 2 + 0.15, d / 2, 0.62)),
        box((w / 2 - 0.15, -d / 2 + 0.2, 0.42), (w / 2, d / 2, 0.62)),
    ]


def shelf(rng: np.random.Generator) -> Parts:
    w, d, h = rng.uniform(0.8, 1.2), 0.35, rng.uniform(1.7, 1.9)
    t = 0.025
    parts = [box((-w / 2, -d / 2, 0.0), (-w / 2 + t, d / 2, h)), box((w / 2 - t, -d / 2, 0.0), (w / 2, d / 2, h))]
    parts.append(box((-w / 2, -d / 2, 0.0), (w / 2, -d / 2 + t, h)))  # back panel
    for z in np.linspace(0.05, h - t, 5):
        parts.append(box((-w / 2 + t, -d / 2 + t, z), (w / 2 - t, d / 2, z + t)))
    return parts


def floor_lamp(rng: np.random.Generator) -> Parts:
    h = rng.uniform(1.5, 1.7)
    base, pole = vcylinder((0, 0), 0.15, 0.0, 0.03), vcylinder((0, 0), 0.015, 0.03, h - 0.25)
    return [base, pole, vcylinder((0, 0), 0.2, h - 0.25, h)]


def pendant_lamp(rng: np.random.Generator) -> Parts:
    bottom = rng.uniform(1.2, 1.5)
    shade = vcylinder((0, 0), rng.uniform(0.15, 0.3), bottom, bottom + 0.25)
    return [shade, vcylinder((0, 0), 0.01, bottom + 0.25, WALL_H)]


def wall_shelf(rng: np.random.Generator) -> Parts:
    z, w = rng.uniform(1.1, 1.3), rng.uniform(0.6, 1.2)
    return [box((-w / 2, -0.15, z), (w / 2, 0.15, z + 0.03))]


def clutter(rng: np.random.Generator) -> Parts:
    if rng.random() < 0.35:
        r = rng.uniform(0.05, 0.13)
        return [trimesh.creation.icosphere(subdivisions=1, radius=r).apply_translation([0, 0, r])]
    e = rng.uniform([0.1, 0.1, 0.05], [0.45, 0.4, 0.28])
    return [box((-e[0] / 2, -e[1] / 2, 0.0), (e[0] / 2, e[1] / 2, e[2]))]


def dining_set(rng: np.random.Generator) -> Parts:
    w, d = rng.uniform(1.2, 1.6), rng.uniform(0.75, 0.9)
    parts = table(w, d, 0.75)
    for side in (-1, 1):
        for x in np.linspace(-w / 4, w / 4, 2 if w > 1.3 else 1):
            if rng.random() < 0.85:
                yaw = 0.0 if side < 0 else np.pi
                parts += _place(chair(rng), (x, side * (d / 2 + rng.uniform(0.05, 0.3)), 0.0), yaw)
    return parts


def desk_set(rng: np.random.Generator) -> Parts:
    return table(1.2, 0.6, 0.75) + _place(chair(rng), (0.0, 0.45 + rng.uniform(0.0, 0.2), 0.0), np.pi)


def coffee_table(rng: np.random.Generator) -> Parts:
    return table(rng.uniform(0.8, 1.1), rng.uniform(0.5, 0.65), rng.uniform(0.4, 0.48))


def _place(parts: Parts, pos, yaw: float) -> Parts:
    tf = trimesh.transformations.rotation_matrix(yaw, [0, 0, 1])
    tf[:3, 3] = pos
    return [p.copy().apply_transform(tf) for p in parts]


# ----------------------------------------------------------------------------------- house layout
# (builder, against a wall?, keep-clear margin in metres)
ROOM_ITEMS: dict[str, list[tuple[Callable[[np.random.Generator], Parts], bool, float]]] = {
    "bedroom": [(bed, True, 0.3), (shelf, True, 0.2), (desk_set, True, 0.2), (floor_lamp, False, 0.1)],
    "living": [
        (sofa, True, 0.3),
        (coffee_table, False, 0.3),
        (dining_set, False, 0.25),
        (shelf, True, 0.2),
        (floor_lamp, False, 0.1),
    ],
}


class _Room:
    def __init__(self, lo: np.ndarray, hi: np.ndarray, kind: str):
        self.lo, self.hi, self.kind = lo, hi, kind
        self.taken: list[tuple[np.ndarray, np.ndarray]] = []

    def free(self, lo: np.ndarray, hi: np.ndarray, margin: float) -> bool:
        if np.any(lo < self.lo) or np.any(hi > self.hi):
            return False
        return all(np.any(hi + margin <= a) or np.any(lo - margin >= b) for a, b in self.taken)

    def place(self, parts: Parts, rng: np.random.Generator, wall: bool, margin: float, tries: int = 40) -> Parts:
        for _ in range(tries):
            k = int(rng.integers(4))
            yaw = k * np.pi / 2
            local = _place(parts, (0, 0, 0), yaw)
            b = trimesh.util.concatenate(local).bounds
            half = (b[1, :2] - b[0, :2]) / 2
            mid = (b[1, :2] + b[0, :2]) / 2
            if wall:  # back (local -y) against the wall the yaw points it to
                back = np.array([np.sin(yaw), -np.cos(yaw)])
                c = rng.uniform(self.lo + half, self.hi - half)
                axis = int(np.argmax(np.abs(back)))
                c[axis] = self.lo[axis] + half[axis] if back[axis] < 0 else self.hi[axis] - half[axis]
            else:
                c = rng.uniform(self.lo + half, self.hi - half)
            if np.any(self.hi - self.lo < 2 * half):
                continue
            lo, hi = c - half, c + half
            if self.free(lo, hi, margin):
                self.taken.append((lo, hi))
                return _place(local, (*(c - mid), 0.0), 0.0)
        return []


def make_house(rng: np.random.Generator, clutter_count: tuple[int, int] = (4, 10)) -> House:
    """A one- or two-room furnished house; the floor is its interior rectangle."""
    size = rng.uniform([6.0, 5.0], [9.0, 7.5])
    parts: Parts = []
    lo, hi = np.zeros(2), size
    t = WALL_T
    parts += [
        box((-t, -t, 0), (size[0] + t, 0, WALL_H)),
        box((-t, size[1], 0), (size[0] + t, size[1] + t, WALL_H)),
        box((-t, 0, 0), (0, size[1], WALL_H)),
        box((size[0], 0, 0), (size[0] + t, size[1], WALL_H)),
    ]
    rooms: list[_Room] = []
    if rng.random() < 0.7:
        xs = rng.uniform(0.4, 0.6) * size[0]
        door = rng.uniform(0.3, size[1] - 0.3 - DOOR_W)
        parts += [
            box((xs - t / 2, 0, 0), (xs + t / 2, door, WALL_H)),
            box((xs - t / 2, door + DOOR_W, 0), (xs + t / 2, size[1], WALL_H)),
            box((xs - t / 2, door, 2.05), (xs + t / 2, door + DOOR_W, WALL_H)),
        ]
        rooms = [_Room(lo, np.array([xs - t / 2, size[1]]), "bedroom"), _Room(np.array([xs + t / 2, 0]), hi, "living")]
        for r in rooms:  # keep the doorway clear
            r.taken.append((np.array([xs - 0.7, door - 0.15]), np.array([xs + 0.7, door + DOOR_W + 0.15])))
    else:
        rooms = [_Room(lo, hi, "living")]
    tags = ["arch"] * len(parts)
    for room in rooms:
        for build, wall, margin in ROOM_ITEMS[room.kind]:
            placed = room.place(build(rng), rng, wall, margin)
            parts += placed
            tags += ["furniture"] * len(placed)
            if build is dining_set and placed and rng.random() < 0.8:  # pendant over the table
                b = trimesh.util.concatenate(placed).bounds
                lamp = _place(pendant_lamp(rng), (*((b[0, :2] + b[1, :2]) / 2), 0.0), 0.0)
                parts += lamp
                tags += ["furniture"] * len(lamp)
        if rng.random() < 0.6:
            ws = room.place(wall_shelf(rng), rng, True, 0.0)
            parts += ws
            tags += ["furniture"] * len(ws)
        for _ in range(int(rng.integers(*clutter_count))):
            c = room.place(clutter(rng), rng, False, 0.1, tries=10)
            parts += c
            tags += ["furniture"] * len(c)
    corners = [[0, 0, 0], [size[0], 0, 0], [size[0], size[1], 0], [0, size[1], 0]]
    floor = trimesh.Trimesh(corners, [[0, 1, 2], [0, 2, 3]])
    return House(parts=parts, floor=floor, name="procedural_house", tags=tags)
