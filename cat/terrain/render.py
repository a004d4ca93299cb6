"""Matplotlib renders of scenes for the docs: a shaded 3-D view and a top-down height map."""

from __future__ import annotations

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


def render_scene(scene: Scene, path: str | os.PathLike, title: str | None = None, max_faces: int = 60000) -> None:
    """Save a PNG with a 3-D view (obstacles, start green, goals red) and a top-down height map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    lo, hi = scene.bounds
    fig = plt.figure(figsize=(11, 4.6))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    mesh = scene.mesh
    if len(mesh.faces):
        faces = np.arange(len(mesh.faces))
        if len(faces) > max_faces:
            faces = np.random.default_rng(0).choice(faces, max_faces, replace=False)
        tris = mesh.triangles[faces]
        n = mesh.face_normals[faces]
        light = np.array([0.4, -0.5, 0.77])
        shade = 0.35 + 0.65 * np.clip(n @ light / np.linalg.norm(light), 0, 1)
        height = np.clip(tris[:, :, 2].mean(1) / max(hi[2], 1e-6), 0, 1)
        colors = plt.cm.viridis(0.15 + 0.7 * height)[:, :3] * shade[:, None]
        ax.add_collection3d(Poly3DCollection(tris, facecolors=colors, edgecolors="none", linewidths=0))
    ax.scatter(*scene.start, c="lime", s=50, depthshade=False, edgecolors="k")
    ax.scatter(*scene.goals.T, c="red", s=40, depthshade=False, edgecolors="k")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)
    ax.view_init(elev=28, azim=-60)
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
