"""Scene: obstacle mesh + bounds + start + goals, saved as a folder (``scene.json`` + ``mesh.ply``).

Conventions: z up, metres, the floor is the plane z = 0 (not part of the mesh). Start and goals are
points at ``GOAL_HEIGHT`` (0.75 m, about the G1 pelvis) above the floor; the env spawns the robot's
base at its own standing height over the start's xy. ``scene.json`` is written last, so a folder
with a valid ``scene.json`` is complete.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from cat.terrain.voxel import VOXEL, GridSpec, ReachCfg, occupancy, reachable

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
GOAL_HEIGHT = 0.75
MESH_FILE = "mesh.ply"
OCC_FILE = "occupancy.npz"
SCENE_FILE = "scene.json"
FIELDS_DIR = "fields"
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


class SceneError(ValueError):
    """A scene or scene file is invalid; the message names the file or the problem."""


@dataclass
class Scene:
    """An obstacle scene the env can load and fields can be built on.

    ``bounds`` is (2, 3) min/max corners; ``start`` (3,), ``goals`` (G, 3); ``start_region`` (2, 2) xy
    min/max corners of the area the env may spawn in; ``meta`` holds generator parameters.

    Memory (a training set holds hundreds): a loaded scene reads its mesh on first use (``load``; field-judged
    training never needs it, and a parsed mesh with trimesh's bookkeeping is ~2 MiB), and the occupancy is cached
    bit-packed (1/8 of a bool grid), each ``occupancy()`` call unpacking a fresh array (~1 ms).
    """

    mesh: trimesh.Trimesh
    bounds: np.ndarray
    start: np.ndarray
    goals: np.ndarray
    kind: str = "user"
    difficulty: float = 0.0
    seed: int | None = None
    start_region: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    _occ: dict = field(default_factory=dict, repr=False, compare=False)  # voxel -> (packed bits, shape)
    _unseen: dict = field(default_factory=dict, repr=False, compare=False)
    _mesh_file: Path | None = field(default=None, repr=False, compare=False)  # read on first use of ``mesh``

    def __getattr__(self, name: str):
        """Only reached for an attribute not set: ``mesh`` of a loaded scene before its first use."""
        path = self.__dict__.get("_mesh_file")
        if name == "mesh" and path is not None:
            self.mesh = load_mesh(path, allow_empty=True)
            return self.mesh
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __post_init__(self) -> None:
        self.bounds = np.asarray(self.bounds, dtype=np.float64).reshape(2, 3)
        self.start = _point3(self.start, "start")
        self.goals = np.atleast_2d(np.asarray(self.goals, dtype=np.float64))
        if self.goals.shape[1] == 2:
            self.goals = np.c_[self.goals, np.full(len(self.goals), GOAL_HEIGHT)]
        if self.goals.ndim != 2 or self.goals.shape[1] != 3 or not np.all(np.isfinite(self.goals)):
            raise SceneError(f"goals must be finite (G, 2|3) points, got shape {self.goals.shape}")
        if self.start_region is None:
            self.start_region = np.array([self.start[:2] - 0.1, self.start[:2] + 0.1])
        self.start_region = np.asarray(self.start_region, dtype=np.float64).reshape(2, 2)
        if not np.all(self.bounds[1] > self.bounds[0]):
            raise SceneError(f"bounds must have max > min, got {self.bounds.tolist()}")

    def mirrored(self) -> Scene:
        """The scene reflected left/right (y -> -y): mesh, bounds, start region, start and goals.

        A policy that learned one handedness (e.g. a side pass always opening to the left first) scores very
        differently on the mirror image of its scenes; ``play.py mirror=true`` evaluates it there."""
        flip = np.array([1.0, -1.0, 1.0])
        mesh = self.mesh.copy()
        mesh.apply_transform(np.diag([1.0, -1.0, 1.0, 1.0]))  # trimesh re-winds faces of a reflection
        lo, hi = self.bounds * flip
        region = self.start_region * flip[:2]
        return Scene(
            mesh=mesh,
            bounds=np.array([np.minimum(lo, hi), np.maximum(lo, hi)]),
            start=self.start * flip,
            goals=self.goals * flip,
            kind=self.kind,
            difficulty=self.difficulty,
            seed=self.seed,
            start_region=np.array([np.minimum(*region), np.maximum(*region)]),
            meta=_mirrored_meta(self.meta),
        )

    # ------------------------------------------------------------------------------------ grids
    def grid(self, voxel: float = VOXEL) -> GridSpec:
        """Voxel grid over the scene bounds (centres at origin + (i+½)·voxel)."""
        return GridSpec.from_bounds(self.bounds, voxel)

    def occupancy(self, voxel: float = VOXEL) -> np.ndarray:
        """Boolean occupancy on ``grid(voxel)`` (cached bit-packed; a fresh array each call)."""
        if voxel not in self._occ:
            self._unseen[voxel] = []
            self.set_occupancy(occupancy(self.mesh, self.grid(voxel), self._unseen[voxel]), voxel)
        bits, shape = self._occ[voxel]
        return np.unpackbits(bits, count=int(np.prod(shape))).view(bool).reshape(shape)

    def set_occupancy(self, occ: np.ndarray, voxel: float = VOXEL) -> None:
        """Cache ``occ`` (a bool grid of ``grid(voxel)``'s shape, e.g. the one a generator voxelised)."""
        shape = self.grid(voxel).shape
        if occ.shape != tuple(shape):
            raise SceneError(f"occupancy of shape {occ.shape} does not match the scene grid {tuple(shape)}")
        self._occ[voxel] = (np.packbits(np.asarray(occ, dtype=bool).ravel()), tuple(shape))

    def unseen_parts(self, voxel: float = VOXEL) -> list[np.ndarray]:
        """Bounds (2, 3) of the obstacle parts that hold no voxel centre of ``grid(voxel)``: the physics collides
        with them but the occupancy, the fields and the maps miss them (``cat.terrain.voxel.occupancy``)."""
        if voxel not in self._unseen:
            self._occ.pop(voxel, None)  # an occupancy read from a file did not look at the parts: compute both once
            self.occupancy(voxel)
        return self._unseen[voxel]

    def reachable_goals(self, cfg: ReachCfg | None = None, voxel: float = VOXEL) -> np.ndarray:
        """Boolean per goal: reachable from the start by a humanoid (see ``cat.terrain.voxel``)."""
        return reachable(self.occupancy(voxel), self.grid(voxel), self.start, self.goals, cfg)

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point to the obstacle surface (positive when outside the solid)."""
        pts = np.atleast_2d(points)
        if len(self.mesh.faces) == 0:
            return np.full(len(pts), np.inf)
        _, dist, _ = trimesh.proximity.closest_point(self.mesh, pts)
        inside = self.occupancy()[tuple(np.clip(self.grid().index(pts), 0, np.array(self.grid().shape) - 1).T)]
        return np.where(inside, -dist, dist)

    # ----------------------------------------------------------------------------------- file I/O
    def to_json(self) -> dict:
        return {
            "format_version": FORMAT_VERSION,
            "kind": self.kind,
            "difficulty": float(self.difficulty),
            "seed": self.seed,
            "bounds": self.bounds.tolist(),
            "start": self.start.tolist(),
            "start_region": self.start_region.tolist(),
            "goals": self.goals.tolist(),
            "goal_height": GOAL_HEIGHT,
            "mesh": MESH_FILE,
            "grid": self.grid().to_dict(),
            "meta": self.meta,
        }

    def save(self, folder: str | os.PathLike, occupancy: bool = True) -> Path:
        """Write ``mesh.ply`` (+ ``occupancy.npz``) then ``scene.json`` (last: it marks a complete folder).

        The occupancy on the default grid is a cache (bit-packed) so loading skips re-voxelising the mesh.
        """
        validate_mesh(self.mesh, "scene mesh", allow_empty=True)
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        data = json.dumps(self.to_json(), indent=1)
        tmp = folder / (MESH_FILE + ".tmp")
        tmp.write_bytes(trimesh.exchange.ply.export_ply(self.mesh, encoding="binary"))
        tmp.replace(folder / MESH_FILE)
        if occupancy:
            occ = self.occupancy()
            np.savez_compressed(folder / "occupancy.tmp.npz", bits=np.packbits(occ.ravel()), shape=occ.shape)
            (folder / "occupancy.tmp.npz").replace(folder / OCC_FILE)
        (folder / (SCENE_FILE + ".tmp")).write_text(data)
        (folder / (SCENE_FILE + ".tmp")).replace(folder / SCENE_FILE)
        return folder

    @classmethod
    def load(cls, folder: str | os.PathLike) -> Scene:
        """Read a scene folder written by ``save``; errors name the offending file."""
        folder = Path(folder)
        path = folder / SCENE_FILE
        if not path.is_file():
            raise SceneError(f"{path}: no scene file (incomplete or not a scene folder)")
        try:
            raw = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise SceneError(f"{path}: invalid JSON ({err})") from err
        if raw.get("format_version") != FORMAT_VERSION:
            raise SceneError(f"{path}: unsupported format_version {raw.get('format_version')!r}")
        mesh_path = folder / raw.get("mesh", MESH_FILE)
        check_mesh_path(mesh_path)  # read on first use (class docstring); a missing file fails here
        try:
            scene = cls(
                mesh=None,
                bounds=np.array(raw["bounds"]),
                start=np.array(raw["start"]),
                goals=np.array(raw["goals"]),
                kind=str(raw["kind"]),
                difficulty=float(raw["difficulty"]),
                seed=raw.get("seed"),
                start_region=np.array(raw["start_region"]) if raw.get("start_region") else None,
                meta=raw.get("meta", {}),
            )
        except (KeyError, ValueError, TypeError) as err:
            raise SceneError(f"{path}: bad scene description ({err!r})") from err
        del scene.mesh  # reads mesh_path on first use
        scene._mesh_file = mesh_path
        scene._load_occupancy(folder / OCC_FILE)
        return scene

    def _load_occupancy(self, path: Path) -> None:
        """Fill the occupancy cache from ``occupancy.npz`` if present and matching the grid."""
        if not path.is_file():
            return
        try:
            data = np.load(path)
            shape = tuple(int(v) for v in data["shape"])
            if shape != self.grid().shape:
                log.warning("%s: shape %s does not match the scene grid; ignored", path, shape)
                return
            bits = np.asarray(data["bits"], dtype=np.uint8)
            if bits.size != (int(np.prod(shape)) + 7) // 8:
                raise ValueError(f"{bits.size} bytes of bits for a grid of shape {shape}")
            self._occ[VOXEL] = (bits, shape)
        except (OSError, KeyError, ValueError) as err:
            log.warning("%s: unreadable occupancy cache (%s); re-voxelising the mesh", path, err)

    @staticmethod
    def fields_dir(folder: str | os.PathLike) -> Path:
        """Where precomputed fields for the scene's goals live (``<folder>/fields``)."""
        return Path(folder) / FIELDS_DIR

    @classmethod
    def from_mesh(
        cls,
        path: str | os.PathLike,
        start,
        goal,
        bounds: np.ndarray | None = None,
        kind: str = "user",
        check: bool = False,
    ) -> Scene:
        """Any obstacle mesh (OBJ/PLY/STL...) plus a start and goal(s) becomes a scene.

        ``start``/``goal`` may be xy (z = ``GOAL_HEIGHT``) or xyz; ``goal`` may hold several goals.
        Default bounds: the mesh and points padded by 0.5 m in xy, z from the floor to max(1.5 m, top).
        With ``check`` the start and goals must be in free space and reachable.
        """
        mesh = load_mesh(path)
        if not mesh.is_watertight:
            log.warning("%s: mesh is not watertight; its inside is taken from voxelising the surface", path)
        start = _point3(start, "start")
        goals = np.atleast_2d(np.asarray(goal, dtype=np.float64))
        if goals.shape[1] == 2:
            goals = np.c_[goals, np.full(len(goals), GOAL_HEIGHT)]
        if bounds is None:
            pts = np.vstack([mesh.bounds, start[None], goals])
            lo, hi = pts.min(0) - 0.5, pts.max(0) + 0.5
            lo[2], hi[2] = 0.0, max(1.5, float(mesh.bounds[1, 2]))
            bounds = np.array([lo, hi])
        scene = cls(mesh=mesh, bounds=bounds, start=start, goals=goals, kind=kind, meta={"source": str(path)})
        if check:
            check_scene(scene)
        return scene


def _mirrored_meta(meta: dict) -> dict:
    """``meta`` of a scene's mirror image: ``mirrored`` toggled, lateral layout entries (``meta["layout"]`` keys
    ending in ``_y``, e.g. a slit's centre) negated."""
    out = {**meta, "mirrored": not meta.get("mirrored", False)}
    if isinstance(meta.get("layout"), dict):
        out["layout"] = {k: _negated(vs) if k.endswith("_y") else vs for k, vs in meta["layout"].items()}
    return out


def _negated(values: object) -> object:
    """A lateral layout entry of the mirror image: numbers negated, in a list or alone (a hand-written scene file may
    hold either); anything else is kept as written."""
    if isinstance(values, list | tuple):
        return [_negated(v) for v in values]
    return -values if isinstance(values, int | float) and not isinstance(values, bool) else values


def layout_text(layout: object) -> str:
    """``meta["layout"]`` as one token, ``slit_gap:0.49,slit_y:-0.30,x:0.67/1.15`` (centimetre precision); a layout
    written by hand in a scene file prints as it is rather than failing."""
    if not isinstance(layout, dict):
        return str(layout).replace(" ", "")
    vals = {k: v if isinstance(v, list | tuple) else [v] for k, v in layout.items()}
    num = (int, float, np.floating, np.integer)
    return ",".join(
        f"{k}:{'/'.join(f'{x:.2f}' if isinstance(x, num) and not isinstance(x, bool) else str(x) for x in vs)}"
        for k, vs in vals.items()
    ).replace(" ", "")


def _point3(p, name: str) -> np.ndarray:
    p = np.asarray(p, dtype=np.float64).reshape(-1)
    if p.shape == (2,):
        p = np.r_[p, GOAL_HEIGHT]
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise SceneError(f"{name} must be a finite xy or xyz point, got {p.tolist()}")
    return p


def validate_mesh(mesh: trimesh.Trimesh, source: str, allow_empty: bool = False) -> trimesh.Trimesh:
    """Raise ``SceneError`` naming ``source`` for empty meshes, NaN/inf vertices or bad face indices."""
    if not isinstance(mesh, trimesh.Trimesh):
        raise SceneError(f"{source}: not a triangle mesh (got {type(mesh).__name__})")
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        if allow_empty:
            return mesh
        raise SceneError(f"{source}: mesh has no triangles")
    if not np.all(np.isfinite(mesh.vertices)):
        raise SceneError(f"{source}: mesh has NaN or infinite vertex coordinates")
    if mesh.faces.min() < 0 or mesh.faces.max() >= len(mesh.vertices):
        raise SceneError(f"{source}: mesh faces index missing vertices")
    return mesh


def check_mesh_path(path: Path) -> None:
    """A mesh file that exists, in a format we read (its content is checked when it is read)."""
    if not path.is_file():
        raise SceneError(f"{path}: mesh file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise SceneError(f"{path}: unsupported mesh format {path.suffix!r} (use one of {MESH_SUFFIXES})")


def load_mesh(path: str | os.PathLike, allow_empty: bool = False) -> trimesh.Trimesh:
    """Load one triangle mesh (scenes are flattened), with clear errors naming the file."""
    path = Path(path)
    check_mesh_path(path)
    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as err:  # trimesh raises many types on garbage input
        raise SceneError(f"{path}: could not read mesh ({type(err).__name__}: {err})") from err
    if isinstance(loaded, trimesh.Scene):  # force="mesh" on an empty scene
        loaded = loaded.to_mesh() if loaded.geometry else trimesh.Trimesh()
    if isinstance(loaded, trimesh.Trimesh) and len(loaded.faces) == 0 and not allow_empty:
        raise SceneError(f"{path}: file holds no triangles (empty or not a mesh)")
    return validate_mesh(loaded, str(path), allow_empty=allow_empty)


def check_scene(scene: Scene, min_clearance: float = 0.05, cfg: ReachCfg | None = None) -> None:
    """Raise ``SceneError`` unless start and goals are in free space and every goal is reachable; warn about
    obstacle parts too thin for the field grid (invisible to the policy, solid to the physics)."""
    unseen = scene.unseen_parts()
    if unseen:
        log.warning(
            "%d obstacle part(s) hold no voxel centre of the %.2f m field grid: the fields and maps miss them but "
            "the physics collides with them (make them at least a voxel thick); bounds: %s",
            len(unseen),
            VOXEL,
            [b.round(3).tolist() for b in unseen[:5]],
        )
    pts = np.vstack([scene.start[None], scene.goals])
    lo, hi = scene.bounds
    outside = np.any((pts < lo) | (pts > hi), axis=1)
    if outside.any():
        raise SceneError(f"points outside the scene bounds: {pts[outside].tolist()}")
    clear = scene.clearance(pts)
    if np.any(clear < min_clearance):
        bad = pts[clear < min_clearance]
        raise SceneError(f"start/goal too close to obstacles (< {min_clearance} m): {bad.tolist()}")
    ok = scene.reachable_goals(cfg)
    if not ok.all():
        raise SceneError(f"goals not reachable from the start {scene.start.tolist()}: {scene.goals[~ok].tolist()}")
