"""Matplotlib renders of scenes for the docs: a shaded 3-D view and a top-down height map."""

from __future__ import annotations

import logging
import os

import numpy as np

from cat.terrain.scene import Scene
from cat.terrain.voxel import ReachCfg, passable_columns


def traversal_classes(scene: Scene, cfg: ReachCfg | None = None) -> np.ndarray:
    """Per floor column: 0 free, 1 hurdle (low obstacle only), 2 crouch (overhead obstacle), 3 blocked."""
    cfg = cfg or ReachCfg()
    occ, grid = scene.occupancy(), scene.grid()
    z = grid.axes()[2]
    passable = passable_columns(occ, grid, cfg)
    low = occ[:, :, z <= cfg.step_height].any(2)
    high = occ[:, :, z > cfg.step_height].any(2)
    cls = np.zeros(occ.shape[:2], dtype=int)
    cls[passable & low] = 1
    cls[passable & high] = 2
    cls[~passable] = 3
    return cls


def _visible_triangles(scene: Scene, eye: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Front-facing triangles, large ones subdivided so matplotlib's per-polygon depth sort works."""
    import trimesh

    mesh = scene.mesh
    if len(mesh.faces) == 0:
        return np.zeros((0, 3, 3)), np.zeros((0, 3))
    front = mesh.face_normals @ eye > 0
    v, f = mesh.vertices, mesh.faces[front]
    if len(f) < max_faces // 8:
        v, f = trimesh.remesh.subdivide_to_size(v, f, max_edge=0.15)
    tris = v[f]
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    if len(tris) > max_faces:
        keep = np.random.default_rng(0).choice(len(tris), max_faces, replace=False)
        tris, n = tris[keep], n[keep]
    return tris, n


def render_scene(scene: Scene, path: str | os.PathLike, title: str | None = None, max_faces: int = 60000) -> None:
    """Save a PNG with a 3-D view (obstacles, start green, goals red) and a top-down height map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    lo, hi = scene.bounds
    fig = plt.figure(figsize=(12, 4.6))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    elev, azim = 32.0, -60.0
    eye = np.array([np.cos(np.radians(elev)) * np.cos(np.radians(azim)),
                    np.cos(np.radians(elev)) * np.sin(np.radians(azim)), np.sin(np.radians(elev))])  # fmt: skip
    tris, n = _visible_triangles(scene, eye, max_faces)
    if len(tris):
        light = np.array([0.4, -0.5, 0.77])
        shade = 0.35 + 0.65 * np.clip(n @ light / np.linalg.norm(light), 0, 1)
        height = np.clip(tris[:, :, 2].mean(1) / max(hi[2], 1e-6), 0, 1)
        colors = plt.cm.viridis(0.15 + 0.7 * height)[:, :3] * shade[:, None]
        ax.add_collection3d(Poly3DCollection(tris, facecolors=colors, edgecolors=colors, linewidths=0.3))
    ax.scatter(*scene.start, c="lime", s=50, depthshade=False, edgecolors="k")
    ax.scatter(*scene.goals.T, c="red", s=40, depthshade=False, edgecolors="k")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)
    ax.view_init(elev=elev, azim=azim)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")

    ax2 = fig.add_subplot(1, 2, 2)
    cls = traversal_classes(scene)
    cmap = ListedColormap(["white", "#4c78a8", "#f58518", "#444444"])
    ax2.imshow(cls.T, origin="lower", extent=[lo[0], hi[0], lo[1], hi[1]], cmap=cmap, vmin=-0.5, vmax=3.5)
    ax2.plot(*scene.start[:2], "o", color="lime", mec="k", ms=8)
    ax2.plot(*scene.goals[:, :2].T, "o", color="red", mec="k", ms=7)
    ax2.set_aspect("equal")
    ax2.set_xlabel("x [m]")
    ax2.set_ylabel("y [m]")
    handles = [Patch(color=c, label=t) for c, t in zip(cmap.colors[1:], ("hurdle", "crouch", "blocked"), strict=True)]
    ax2.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.suptitle(title or f"{scene.kind}  (difficulty {scene.difficulty:.2f}, seed {scene.seed})")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def render_docs(
    out_dir: str | os.PathLike = "docs/img", difficulty: float = 0.6, seed: int = 0, indoor_seed: int = 8
) -> list[str]:
    """The docs' PNGs: one ``scene_<type>.png`` per typical type, plus procedural and indoor."""
    from pathlib import Path

    from cat.terrain.indoor import make_indoor
    from cat.terrain.procedural import make_procedural
    from cat.terrain.typical import TYPICAL_KINDS, make_typical

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scenes = [(k, make_typical(k, difficulty, seed)) for k in TYPICAL_KINDS]
    scenes += [("procedural", make_procedural(difficulty, seed)), ("indoor", make_indoor(indoor_seed))]
    paths = []
    for name, scene in scenes:
        path = out / f"scene_{name.replace('-', '_')}.png"
        render_scene(scene, path)
        paths.append(str(path))
    return paths


if __name__ == "__main__":  # python -m cat.terrain.render [out_dir]
    import sys

    logging.basicConfig(level=logging.INFO)
    for path in render_docs(*sys.argv[1:2]):
        logging.getLogger("render").info("wrote %s", path)
