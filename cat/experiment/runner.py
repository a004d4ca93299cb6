"""``scripts/experiment.py``: train what an experiment is missing, stage by stage, through hydra's launcher;
then evaluate its tables. State lives in ``<root>/<name>/state.json``; a second call with nothing changed does
nothing."""

from __future__ import annotations

import logging
import shlex
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import yaml
from tqdm import tqdm

from cat.experiment.plan import Plan, Unit
from cat.experiment.restore import restorable, restore_shipped
from cat.experiment.spec import ExperimentError, load_experiment
from cat.launcher import check_launcher, launch

log = logging.getLogger(__name__)
clock = time.monotonic  # the sitting's wall clock (a test steps it to spend a budget deterministically)
SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


@dataclass
class ExperimentCfg:
    """``scripts/experiment.py key=value`` options."""

    experiment: str = "???"  # configs/experiment/<name>.yaml (or a yaml path)
    only: list[str] | None = None  # these cells / tables and the cells they need (default: everything)
    dry_run: bool = False  # print the plan and every unit's command chain; run and write nothing
    max_minutes: float = 0.0  # > 0: this sitting's wall-clock budget; unfinished runs resume next time
    root: str | None = None  # experiments folder (default: the file's root:, else experiments/)
    torch_threads: int = 1  # each training job's torch threads (jobs of a stage share the cores)


def _cmd(script: str, overrides: list[str]) -> str:
    """The command line, quoted for a POSIX shell (lists and dicts hold brackets and braces)."""
    return f"python scripts/{script}.py " + " ".join(shlex.quote(o) for o in overrides)


class Runner:
    def __init__(self, cfg: ExperimentCfg, hydra_args: list[str]):
        check_launcher(hydra_args)  # an unknown launcher is refused before anything is computed or written
        if cfg.max_minutes < 0:  # a past end time typed as minutes left: never read as "no budget"
            raise ValueError(f"max_minutes={cfg.max_minutes:g}: must be >= 0 (0 = no budget)")
        if cfg.torch_threads < 1:
            raise ValueError(f"torch_threads={cfg.torch_threads}: must be >= 1")
        self.cfg, self.hydra_args = cfg, list(hydra_args)
        self.exp = load_experiment(cfg.experiment)
        self.plan = Plan(self.exp, cfg.root)
        names = self.exp.closure(list(cfg.only)) if cfg.only else [*self.exp.cells, *self.exp.tables]
        self.cells = [c for c in self.exp.cells if c in names]
        self.tables = [t for t in self.exp.tables if t in names]
        self.start = clock()
        self.ran: list[str] = []
        self.failed: list[str] = []

    # -- plan --------------------------------------------------------------------------------------------------
    def describe(self) -> str:
        """Each unit's status and full command chain, then each table's eval command."""
        lines = [f"experiment {self.exp.name}: {self.plan.folder}"]
        if self.exp.note:
            lines.append(f"  {self.exp.note}")
        left = 0  # iterations still to train over the units shown
        held = self.plan.holders(self.plan.units_of(self.cells))
        for k, stage in enumerate(self.plan.stages):
            for unit in self.plan.units_of([c for c in stage if c in self.cells]):
                status = self.plan.status(unit)
                shown = status
                shipped = restorable(self.plan, unit) if unit.key not in held else None
                if shipped is not None:  # what the sitting will copy in before it trains
                    it, folder = shipped
                    status = "done" if it + 1 >= unit.final else "resume"
                    shown = f"restore {folder}: " + ("done" if status == "done" else f"resume from iteration {it + 1}")
                    left += unit.final - it - 1
                elif status == "resume":
                    done = self._latest(unit)[0] + 1
                    shown = f"resume from iteration {done}" + ("" if unit.timed else f" of {unit.final}")
                    left += 0 if unit.timed else unit.final - done
                elif status != "done":
                    left += 0 if unit.timed else unit.final
                if unit.key in held:
                    shown += f", being trained by {held[unit.key]}"
                lines.append(f"[stage {k}] {unit.key} ({shown}) -> {unit.checkpoint()}")
                if status == "stale":
                    lines.append(f"  # changed since its run: {self.plan.changes(unit)}")
                if unit.cell.note:
                    lines.append(f"  # {unit.cell.note}")
                lines += [f"  {_cmd('train', o)}" for o in self.plan.chain(unit)]
        for name in self.tables:
            table = self.exp.tables[name]
            status = "done" if self.plan.table_done(table) else "run"
            lines.append(f"[table] {name} ({status}) -> {self.plan.table_dir(table)}")
            lines.append(f"  {_cmd('eval_table', self.plan.table_overrides(table))}")
        lines.append(f"to train: {left} iterations (cells with a minutes budget not counted)")
        return "\n".join(lines)

    def minutes_left(self) -> float | None:
        if self.cfg.max_minutes <= 0:
            return None
        return self.cfg.max_minutes - (clock() - self.start) / 60.0

    # -- run ---------------------------------------------------------------------------------------------------
    def run(self) -> int:
        if self.cfg.dry_run:
            print(self.describe())
            return 0
        units = self.plan.units_of(self.cells)
        held = self.plan.holders(units)
        restore_shipped(self.plan, [u for u in units if u.key not in held])
        todo = [u for u in units if self.plan.status(u) != "done"]
        tables = [self.exp.tables[t] for t in self.tables if not self.plan.table_done(self.exp.tables[t])]
        done_before = len(units) - len(todo)
        log.info("experiment %s: %d run(s) done, %d to train, %d table(s) to build", self.exp.name,
                 done_before, len(todo), len(tables))  # fmt: skip
        with tqdm(total=len(todo) + len(tables), desc=self.exp.name, unit="job") as bar:
            for k, stage in enumerate(self.plan.stages):
                units = [u for u in self.plan.units_of([c for c in stage if c in self.cells]) if u in todo]
                if not units:
                    continue
                left = self.minutes_left()
                if left is not None and left <= 0:
                    log.info("max_minutes=%g spent: stopping before stage %d", self.cfg.max_minutes, k)
                    break
                blocked = [u for u in units if not self._inputs_ready(u)]
                if blocked:
                    log.warning("stage %d: %s wait for unfinished inputs", k, ", ".join(u.key for u in blocked))
                held = self.plan.holders([u for u in units if u not in blocked])
                for key, by in held.items():
                    log.warning("stage %d: %s is being trained by %s: left to it", k, key, by)
                # seed-major: a sitting trains seed 0 of every cell before any seed 1 (a column first stands whole)
                ready = sorted((u for u in units if u not in blocked and u.key not in held), key=lambda u: u.seed)
                if ready:
                    self._train_stage(k, ready, left)
                bar.update(len(ready))
            ready_tables = [t for t in tables if all(self._ref_ready(r) for r in self.plan.table_refs(t))]
            if ready_tables and (self.minutes_left() is None or self.minutes_left() > 0):
                self._eval_stage(ready_tables)
                bar.update(len(ready_tables))
        log.info("%s", self.summary())
        return 1 if self.failed else 0

    def _ref_ready(self, ref: str) -> bool:
        found = self.plan.unit_of(ref)
        return found is None or self.plan.status(found[0]) == "done"

    def _inputs_ready(self, unit: Unit) -> bool:
        return all(self._ref_ready(r) for r in unit.inputs.values())

    def _job(self, unit: Unit, deadline: float | None) -> list[str]:
        status = self.plan.status(unit)
        if status == "stale":
            aside = unit.run_dir.with_name(f"{unit.run_dir.name}.stale-{time.strftime('%Y%m%d-%H%M%S')}")
            log.warning("%s: changed since its run (%s): moving %s aside to %s and training it anew", unit.key,
                        self.plan.changes(unit), unit.run_dir, aside)  # fmt: skip
            unit.run_dir.rename(aside)
            status = "run"
        if status == "run":
            if unit.run_dir.exists():
                shutil.rmtree(unit.run_dir)  # no checkpoint: a start that never saved
            unit.run_dir.parent.mkdir(parents=True, exist_ok=True)
            overrides = self.plan.fresh_overrides(unit)
        else:
            _, at = self._latest(unit)
            iterations, leg = self.plan.leg(unit)
            overrides = self.plan.resume_overrides(unit, at, iterations, leg)
        overrides += [f"torch_threads={self.cfg.torch_threads}"]
        if unit.cell.minutes is not None:  # the cell's own wall-clock budget, what earlier sittings left of it
            overrides.append(f"max_minutes={max(unit.cell.minutes - self.plan.minutes_used(unit), 0.01):.3f}")
        if deadline is not None:
            overrides.append(f"deadline={deadline:.0f}")
        return overrides

    @staticmethod
    def _latest(unit: Unit):
        from cat.experiment.plan import latest_checkpoint

        return latest_checkpoint(unit.run_dir)

    def _train_stage(self, k: int, units: list[Unit], left: float | None) -> None:
        """Launch a stage's runs together. With a sitting budget every job gets the sitting's end as its
        ``deadline`` (Unix time): a job the launcher starts late (``basic`` runs one at a time, ``joblib``
        ``n_jobs``) has only what is left, one that starts after it runs nothing, and a core freed by a run that
        ends early takes the next run at once; runs not finished resume next sitting."""
        deadline = None if left is None else time.time() + 60.0 * left
        jobs = [self._job(u, deadline) for u in units]
        for unit, job in zip(units, jobs, strict=True):
            log.info("stage %d: %s: %s", k, unit.key, _cmd("train", job))
            entry = self.plan.state["units"].setdefault(unit.key, {})
            entry.update(hash=unit.hash, run_dir=str(unit.run_dir), cell=unit.cell.name, seed=unit.seed)
            self.plan.hold(unit, deadline)  # another sitting leaves it alone until released
        self.plan.write_state()  # before launching: a sitting killed mid-stage still resumes its runs
        before = [self._latest(u) for u in units]
        t0 = time.monotonic()
        results = launch(SCRIPTS / "train.py", jobs, self._hydra(f"stage{k}"), name=f"{self.exp.name}-stage{k}")
        stage_minutes = (time.monotonic() - t0) / 60.0
        taken = self.plan.holders(units)  # a run this sitting stopped early and another sitting took over since
        for unit, result, prior in zip(units, results, before, strict=True):
            if unit.key in taken:  # its record is that sitting's now (its recipe may be newer than this one's)
                log.warning("%s: now trained by %s: its record is left to it", unit.key, taken[unit.key])
                continue
            self.plan.release(unit)
            entry = self.plan.state["units"][unit.key]
            entry["minutes"] = entry.get("minutes", 0.0) + (stage_minutes if result.minutes is None else result.minutes)
            status = self.plan.status(unit) if result.code == 0 else "failed"
            entry["status"] = status
            if status == "done":
                entry["checkpoint"] = str(unit.checkpoint())
            if result.code:
                self.failed.append(unit.key)
            elif self._latest(unit) != prior:  # not a job that started after the deadline
                self.ran.append(unit.key)
        self.plan.write_state()

    def _eval_stage(self, tables) -> None:
        jobs = []
        for table in tables:
            out = self.plan.table_dir(table)
            out.mkdir(parents=True, exist_ok=True)
            (out / "manifest.yaml").write_text(yaml.safe_dump(self.plan.manifest(table), sort_keys=False))
            jobs.append(self.plan.table_overrides(table))
            log.info("tables: %s: %s", table.name, _cmd("eval_table", jobs[-1]))
        results = launch(SCRIPTS / "eval_table.py", jobs, self._hydra("tables"), name=f"{self.exp.name}-tables")
        for table, result in zip(tables, results, strict=True):
            if result.code == 0:
                self.plan.state["tables"][table.name] = {"hash": self.plan.table_hash(table)}
                self.ran.append(f"table {table.name}")
            else:
                self.failed.append(f"table {table.name}")
        self.plan.write_state()

    def _hydra(self, stage: str) -> list[str]:
        args = list(self.hydra_args)
        if not any(a.startswith("hydra.sweep.dir=") for a in args):
            args.append(f"hydra.sweep.dir={self.plan.folder / 'launch' / stage}")
        return args

    def summary(self) -> str:
        units = self.plan.units_of(self.cells)
        left = [u.key for u in units if self.plan.status(u) != "done"]
        left += [f"table {t}" for t in self.tables if not self.plan.table_done(self.exp.tables[t])]
        parts = [f"ran {', '.join(self.ran) or 'nothing'}"]
        if self.failed:
            parts.append(f"failed {', '.join(self.failed)}")
        parts.append(f"left {', '.join(left) or 'nothing'}")
        return f"experiment {self.exp.name}: " + "; ".join(parts) + f" ({self.plan.folder})"


def run_experiment(cfg: ExperimentCfg, hydra_args: list[str]) -> int:
    if cfg.experiment in ("", "???"):
        raise ExperimentError("missing experiment= (see --help)")
    return Runner(cfg, hydra_args).run()
