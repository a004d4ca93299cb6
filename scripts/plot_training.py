"""Plot a run's training curves from ``metrics.csv``: ``python scripts/plot_training.py run=<run_dir> [out=<png>]``.

Panels: mean episode return, episode length, goal-reached rate, distance error, success rate (the paper's metric)
and contact rate per iteration (a panel a run did not log stays empty); the default
output is ``<run_dir>/training.png``. ``runs=[a,b,c]`` draws a chain of runs, each started from the previous one's
final checkpoint (``init=``), end to end over cumulative env steps (each run's ``config.yaml`` gives its steps per
iteration), with a dashed line where each run begins; ``out=`` is then required.
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib
import yaml

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from cat.cli import Script, dataclass_loader, run  # noqa: E402

PANELS = [
    ("Train/mean_reward", "mean episode return"),
    ("Train/mean_episode_length", "mean episode length [steps]"),
    ("Metrics/reached_rate", "goal reached within 0.1 m (ended episodes)"),
    ("Metrics/distance_error", "distance error DE [m]"),
    ("Metrics/success_rate", "success: reached, no contact, no fall (ended episodes)"),
    ("Metrics/collision_rate", "touched an obstacle (ended episodes)"),
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


def steps_per_iteration(run_dir: Path) -> int:
    """Env steps of one iteration of the run (``num_envs`` or ``task.num_envs``, times ``algo.num_steps_per_env``)."""
    path = run_dir / "config.yaml"
    if not path.is_file():
        raise ValueError(f"no config.yaml in {run_dir} (needed for the env steps of a chain)")
    cfg = yaml.safe_load(path.read_text())
    envs = cfg.get("num_envs") or cfg["task"]["num_envs"]
    return int(envs) * int(cfg["algo"]["num_steps_per_env"])


def chain(run_dirs: list[Path]) -> tuple[dict[str, list[tuple[float, float]]], list[float]]:
    """The runs' series end to end over cumulative env steps [M], and the env steps where each run begins."""
    series: dict[str, list[tuple[float, float]]] = defaultdict(list)
    starts, offset = [], 0.0
    for run_dir in run_dirs:
        per_it = steps_per_iteration(run_dir) / 1e6
        own = read_metrics(run_dir)
        starts.append(offset)
        last = max((it for pts in own.values() for it, _ in pts), default=-1)
        for tag, pts in own.items():
            series[tag] += [(offset + (it + 1) * per_it, v) for it, v in pts]
        offset += (last + 1) * per_it
    return series, starts


@dataclass
class PlotCfg:
    run: str = ""  # run folder (with metrics.csv)
    runs: list[str] = field(default_factory=list)  # or a chain of run folders, each from the previous one's end
    out: str = ""  # PNG path; default <run>/training.png (required with runs)


def plot(cfg: PlotCfg) -> int:
    if bool(cfg.run) == bool(cfg.runs):
        raise ValueError("give run=<run folder> or runs=[<run folder>,...] (one of them)")
    if cfg.runs and not cfg.out:
        raise ValueError("runs=[...] needs out=<png>")
    if cfg.runs:
        run_dirs = [Path(r) for r in cfg.runs]
        series, starts = chain(run_dirs)
        xlabel, out, name = "env steps [M]", Path(cfg.out), " → ".join(d.name for d in run_dirs)
    else:
        run_dir = Path(cfg.run)
        series, starts = read_metrics(run_dir), []
        xlabel, out, name = "iteration", Path(cfg.out) if cfg.out else run_dir / "training.png", run_dir.name
    fps = [v for _, v in series.get("Perf/total_fps", [])]
    fig, axes = plt.subplots(2, 3, figsize=(14, 6.5))
    for ax, (tag, label) in zip(axes.flat, PANELS, strict=True):
        pts = series.get(tag, [])
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], lw=1.2)
        for x in starts[1:]:
            ax.axvline(x, color="grey", ls="--", lw=0.8)
        ax.set_xlabel(xlabel)
        ax.set_title(label, fontsize=10)
        ax.grid(alpha=0.3)
    title = name
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
    load=dataclass_loader(PlotCfg),
    job=plot,
    keys=["run", "runs", "out"],
    errors=(ValueError,),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
