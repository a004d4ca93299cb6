"""Shipped runs restored into an experiment's folder, so a fresh clone does not train them again.

``experiments/`` is not committed; what is, is each finished (or paused) run shipped with ``scripts/ship.py
out=<shipped>/<experiment>/<cell>/seed<k>`` (``shipped:`` in the experiment file, default ``checkpoints``). A unit
whose run folder holds no checkpoint gets that shipped folder copied in when it is the unit's own run (the same
adoption test as a run made by hand: config at its leg, init and teachers), and the runner then finds it done, or
resumes it from its env snapshot. A shipped folder of another recipe is left alone (the unit trains anew, the
folder is named in the log), and so is one without an env snapshot that is not final (``ship.py weights_only``:
nothing to resume from). Cells with a minutes budget are not restored (the minutes spent live in the state).
"""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

from cat.experiment.plan import Plan, Unit, latest_checkpoint

log = logging.getLogger(__name__)


def shipped_dir(plan: Plan, unit: Unit) -> Path:
    return Path(plan.exp.shipped) / plan.exp.name / unit.cell.name / f"seed{unit.seed}"


def restorable(plan: Plan, unit: Unit) -> tuple[int, Path] | None:
    """(iteration, shipped folder) of the unit's shipped run when its own folder has no checkpoint and the shipped
    one is the unit's own and can serve (final, or resumable); else None."""
    if unit.timed or latest_checkpoint(unit.run_dir) is not None:
        return None
    folder = shipped_dir(plan, unit)
    latest = latest_checkpoint(folder) if folder.is_dir() else None
    if latest is None:
        return None
    it = latest[0]
    if not plan.adoptable(unit, folder):
        log.info("%s: %s is another recipe's run: not restored", unit.key, folder)
        return None
    if it + 1 < unit.final and not (folder / f"env_{it}.pt").is_file():
        log.info("%s: %s stops at iteration %d without an env snapshot: not restored", unit.key, folder, it + 1)
        return None
    return it, folder


def restore_shipped(plan: Plan, units: list[Unit]) -> list[str]:
    """Copy each restorable unit's shipped run into its run folder (a whole copy first, then one rename); the
    keys restored."""
    out = []
    for unit in units:
        found = restorable(plan, unit)
        if found is None:
            continue
        it, folder = found
        tmp = unit.run_dir.with_name(f"{unit.run_dir.name}.restoring")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(folder, tmp)
        if unit.run_dir.exists():
            shutil.rmtree(unit.run_dir)  # no checkpoint in it: a start that never saved
        tmp.rename(unit.run_dir)
        log.info("%s: restored the shipped run %s (iteration %d of %d)", unit.key, folder, it + 1, unit.final)
        out.append(unit.key)
    return out
