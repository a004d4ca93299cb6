"""Robustness sweep through the simulated perception (issue 32, item 4): each row's SR as one perception error grows.

A sweep file (``configs/eval/perception_sweep.yaml``) names a base setting and axes: fields of ``LiveSettingCfg``
with their levels. For each axis and level the manifest is evaluated with ``perception=lidar`` at the base
setting with that one field changed (``cat.eval.evaluate``, the same trials at every level), and the SR and DE of
every row are collected: ``sweep.csv`` (axis, level, method, trials, sr, de) and one plot, SR against the level,
a panel per axis (``perception_sweep.png``).

A sweep is hours on a small machine, so each finished level is kept under ``<out>/levels/`` (its rows, keyed by
everything that decides them: manifest text, setting, trials, seed, window) and a rerun with the same ``out``
plays only the levels not kept (a level whose setting equals one kept under another axis, such as each axis's base
level, is read from it); a level is written whole or not at all.
"""

from __future__ import annotations

import csv
import hashlib
import io
import logging
from dataclasses import dataclass, fields, replace
from pathlib import Path

import yaml

from cat.deploy.live_eval import LiveSettingCfg, LiveTrials, load_setting
from cat.eval.evaluate import EvalTableCfg, evaluate, write_atomically

log = logging.getLogger(__name__)

SWEEP_COLUMNS = ("axis", "level", "method", "trials", "sr", "de")


@dataclass
class SweepCfg:
    """``scripts/perception_sweep.py key=value`` options."""

    manifest: str = "???"
    out: str = "???"
    sweep: str = "configs/eval/perception_sweep.yaml"
    trials_per_scene: int = 1
    seed: int = 0
    time_s: float = 5.0
    radius: float = 0.1
    live_workers: int = 1  # processes sharing a column's scenes (speed only: the trials are the same)


def load_sweep(path: str) -> tuple[str, LiveSettingCfg, dict[str, list[float]]]:
    """(base name, base setting, {axis: levels}); ``ValueError`` naming a bad entry."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"sweep file not found: {p}")
    raw = yaml.safe_load(p.read_text()) or {}
    unknown = sorted(set(raw) - {"base", "axes"})
    if unknown:
        raise ValueError(f"sweep {p}: unknown key {unknown[0]!r}; valid: base, axes")
    base = str(raw.get("base", "default"))
    axes = raw.get("axes") or {}
    valid = {f.name for f in fields(LiveSettingCfg)}
    if not isinstance(axes, dict) or not axes:
        raise ValueError(f"sweep {p}: axes must map setting fields to lists of levels")
    for axis, levels in axes.items():
        if axis not in valid:
            raise ValueError(f"sweep {p}: unknown axis {axis!r}; valid: {', '.join(sorted(valid))}")
        if not isinstance(levels, list) or not levels or not all(isinstance(v, int | float) for v in levels):
            raise ValueError(f"sweep {p}: axis {axis!r} needs a list of numbers, got {levels!r}")
    return base, load_setting(base), {str(a): [float(v) for v in levels] for a, levels in axes.items()}


def _level_key(cfg: SweepCfg, manifest_text: str, setting: LiveSettingCfg) -> str:
    """What decides a level's rows (not ``live_workers``: trials do not depend on where they run)."""
    parts = (manifest_text, repr(setting), cfg.trials_per_scene, cfg.seed, cfg.time_s, cfg.radius)
    return hashlib.sha256(repr(parts).encode()).hexdigest()[:16]


def _read_rows(text: str) -> list[dict]:
    return list(csv.DictReader(io.StringIO(text)))


def _write_rows(rows: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=SWEEP_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def run_sweep(cfg: SweepCfg) -> tuple[list[dict], dict[str, str]]:
    """(sweep rows, {file name: text}). Writes only the finished levels' rows under ``<out>/levels/`` and reuses
    those a previous sitting kept."""
    base_name, base, axes = load_sweep(cfg.sweep)
    kept = Path(cfg.out) / "levels"
    manifest_text = Path(cfg.manifest).read_text() if Path(cfg.manifest).is_file() else cfg.manifest
    rows = []
    for axis, levels in axes.items():
        for level in levels:
            setting = replace(base, **{axis: type(getattr(base, axis))(level)})
            name = f"{base_name} with {axis}={level:g}"
            key = _level_key(cfg, manifest_text, setting)
            cache = kept / f"{axis}={level:g}-{key}.csv"
            # any axis's file of this setting (each axis's base level is the base setting) holds the same trials
            hits = sorted(kept.glob(f"*-{key}.csv"))
            if hits:
                log.info("sweep: %s kept from a previous sitting (%s)", name, hits[0])
                rows += [{**r, "axis": axis, "level": f"{level:g}"} for r in _read_rows(hits[0].read_text())]
                continue
            ecfg = EvalTableCfg(
                manifest=cfg.manifest,
                out=cfg.out,
                trials_per_scene=cfg.trials_per_scene,
                seed=cfg.seed,
                time_s=cfg.time_s,
                radius=cfg.radius,
                perception="lidar",
                perception_setting=name,
            )
            log.info("sweep: %s", name)
            trials, _ = evaluate(ecfg, LiveTrials(setting, cfg.live_workers))
            mine_rows = []
            for method in dict.fromkeys(r["method"] for r in trials):
                mine = [r for r in trials if r["method"] == method]
                sr = 100.0 * sum(int(r["success"]) for r in mine) / len(mine)
                de = sum(float(r["de"]) for r in mine) / len(mine)
                mine_rows.append(
                    {"axis": axis, "level": f"{level:g}", "method": method, "trials": str(len(mine)),
                     "sr": f"{sr:.1f}", "de": f"{de:.4f}"}
                )  # fmt: skip
            write_atomically(kept, {cache.name: _write_rows(mine_rows)})
            rows += mine_rows
    return rows, {"sweep.csv": _write_rows(rows)}


def plot(rows: list[dict], path: str | Path, title: str = "") -> None:
    """SR against the level, one panel per axis, a line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes = list(dict.fromkeys(r["axis"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, panels = plt.subplots(1, len(axes), figsize=(4.2 * len(axes), 3.4), squeeze=False)
    for ax, axis in zip(panels[0], axes, strict=True):
        for m in methods:
            pts = [(float(r["level"]), float(r["sr"])) for r in rows if r["axis"] == axis and r["method"] == m]
            ax.plot(*zip(*pts, strict=True), marker="o", label=m)
        ax.set_xlabel(axis)
        ax.set_ylabel("SR (%)")
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
    panels[0][0].legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
