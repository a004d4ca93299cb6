"""2-D slice figures of a field (SDF background, obstacles, unit-force arrows).

``python -m cat.fields.viz docs/img/fields_slice.png`` renders the docs figure (typical scene)."""

from __future__ import annotations

import sys

import numpy as np

from cat.fields.field import Field, build_field
from cat.fields.scenes import TYPICAL_GOAL, TYPICAL_GRID, hurdle_crouch

_AXES = {"x": 0, "y": 1, "z": 2}


def plot_slice(ax, f: Field, axis: str, value: float, step: int = 2) -> None:
    """Draw the slice ``axis = value`` (m) of ``f`` on a matplotlib ``ax``."""
    a = _AXES[axis]
    k = int(np.clip(np.floor((value - f.grid.origin[a]) / f.grid.voxel), 0, f.grid.shape[a] - 1))
    keep = [i for i in range(3) if i != a]
    sl = [slice(None)] * 3
    sl[a] = k
    sdf = f.sdf[tuple(sl)].T
    force = f.force[tuple(sl)][..., keep]
    u, v = force[..., 0].T, force[..., 1].T
    n = np.hypot(u, v) + 1e-12
    c0, c1 = (f.grid.axis_centers(i) for i in keep)
    ext = [f.grid.origin[keep[0]], f.grid.upper[keep[0]], f.grid.origin[keep[1]], f.grid.upper[keep[1]]]
    im = ax.imshow(np.clip(sdf, -0.2, 1.0), origin="lower", extent=ext, cmap="viridis")
    ax.contourf(c0, c1, sdf, levels=[-1e9, 0.0], colors=["#444444"])
    ax.contour(c0, c1, sdf, levels=[0.3], colors="w", linewidths=0.6, linestyles="--")
    X, Y = np.meshgrid(c0, c1)
    free = sdf > 0
    s = (slice(None, None, step), slice(None, None, step))
    m = free[s]
    ax.quiver(X[s][m], Y[s][m], (u / n)[s][m], (v / n)[s][m], color="w", scale=45, width=0.003)
    gx, gy = (f.goal[i] for i in keep)
    ax.plot(gx, gy, "r*", ms=12)
    names = "xyz"
    ax.set_xlabel(f"{names[keep[0]]} [m]")
    ax.set_ylabel(f"{names[keep[1]]} [m]")
    ax.set_title(f"{axis} = {value:.2f} m")
    return im


def render_docs_figure(path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f = build_field(hurdle_crouch(), TYPICAL_GRID, TYPICAL_GOAL)
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    plot_slice(axs[0], f, "y", 0.0)
    im = plot_slice(axs[1], f, "z", 0.5)
    fig.colorbar(im, ax=axs, label="signed distance d [m] (clipped)", shrink=0.85)
    fig.suptitle("HumanoidPF, hurdle-crouch scene: arrows F/|F| (F = −∇(η·geo + U_rep)); dashed: d = d0")
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    render_docs_figure(sys.argv[1] if len(sys.argv) > 1 else "fields_slice.png")
