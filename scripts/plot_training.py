"""Plot a run's training curves from ``metrics.csv``: ``python scripts/plot_training.py run=<run_dir> [out=<png>]``.

Panels: mean episode return, episode length, goal-reached rate and distance error per iteration; the default
output is ``<run_dir>/training.png``.
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from cat.cli import Script, dataclass_loader, run  # noqa: E402

PANELS = [
    ("Train/mean_reward", "mean episode return"),
    ("Train/mean_episode_length", "mean episode length [steps]"),
    ("Metrics/reached_rate", "goal reached within 0.1 m (ended episodes)"),
    ("Metrics/distance_error", "distance error DE [m]"),
]


def read_metrics(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    path = run_dir / "metrics.csv"
    if not path.is_file():
        raise ValueError(f"no metrics.csv in {run_dir} (is it a run folder with at least one iteration?)")
    series: dict[str, list[tuple[int, float]]] = defaultdict(list)
    with path.open() as f:
        for row in csv.DictReader(f):
            series[row["tag"]].append((int(row["iteration"]), float(row["value"])))
    return series


@dataclass
class PlotCfg:
    run: str = ""  # run folder (with metrics.csv)
    out: str = ""  # PNG path; default <run>/training.png


def plot(cfg: PlotCfg) -> int:
    run_dir = Path(cfg.run)
    out = Path(cfg.out) if cfg.out else run_dir / "training.png"
    series = read_metrics(run_dir)
    fps = [v for _, v in series.get("Perf/total_fps", [])]
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5))
    for ax, (tag, label) in zip(axes.flat, PANELS, strict=True):
        pts = series.get(tag, [])
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], lw=1.2)
        ax.set_xlabel("iteration")
        ax.set_title(label, fontsize=10)
        ax.grid(alpha=0.3)
    title = f"{run_dir.name}"
    if fps:
        title += f"  (mean {sum(fps) / len(fps):.0f} env steps/s incl. learning)"
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(out)
    return 0


SCRIPT = Script(
    name="plot_training",
    doc=__doc__,
    load=dataclass_loader(PlotCfg, required=("run",)),
    job=plot,
    keys=["run", "out"],
    errors=(ValueError,),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
