"""What an experiment's cells and tables need now: each training run's config hash, status and next command.

A unit is one seed of one cell, trained in ``<experiment>/runs/<cell>/seed<k>/``. Its hash covers the resolved
training config (``configs/train.yaml`` + the cell's overrides), its legs, and the identity of what it reads (an
upstream unit's hash and budget, or a checkpoint file's bytes); budgets and per-sitting keys are left out, so a
larger budget continues a run instead of restarting it. A unit is ``done`` when the state records its hash and
its final checkpoint exists, ``resume`` when its run stands at an earlier checkpoint with the same hash, ``run``
otherwise (a stale folder of another hash is moved aside, never deleted).

A physical run's hash leaves ``sim.field_contact`` out (it judges nothing there). Hashes recorded before that, or
before keys were added to ``sim.field_contact`` (``FIELD_CONTACT_HASHED``), are recognised and re-keyed, so a
change of the field-contact defaults never restarts a run it does not touch.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import math
import os
import re
import typing
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import OmegaConf

from cat.experiment.sitting import live_sitting, this_sitting
from cat.experiment.spec import BIG_ITERATIONS, Cell, Experiment, ExperimentError, Table
from cat.learning.hydra_cfg import load_config

# keys that do not change what a run learns (or are the budget, handled apart)
VOLATILE = ("run_dir", "run_root", "run_name", "max_minutes", "deadline", "max_iterations", "verbose", "torch_threads")
VOLATILE += ("init", "resume", "teachers")
NEUTRAL_DEFAULTS = {
    ("sim", "field_storage"): "float32",
    ("task", "episodes", "goal_stand_radius"): 0.0,
    ("algo", "max_noise_std"): 0.0,
    ("task", "curriculum", "group_weights"): {},
    ("task", "warmup_bar_pitch"): False,
    ("task", "warmup_bars"): 2,
    ("task", "warmup_slit_offset"): False,
    ("task", "warmup_slit_narrow"): False,
    ("task", "warmup_slit_tight"): False,
    ("task", "rewards", "shin_barrier"): 0.0,
    ("task", "rewards", "params", "shin_margin"): 0.02,
    ("task", "rewards", "params", "shin_radius"): 0.045,
    ("algo", "rehearsal"): {  # off: plain PPO
        "learning_rate": 0.0,
        "num_learning_epochs": 1,
        "num_mini_batches": 4,
        "max_grad_norm": 1.0,
    },
}
"""Keys added after runs were hashed, with the value that reproduces what those runs did: left out of the hash at
that value, so adding the key does not make every unfinished run "changed" (a key added at its old behaviour)."""
FIELD_CONTACT_HASHED = (
    ({"spacing": 0.03, "margin": 0.005}, {"substeps": False, "sdf": "field", "cores": False}),
    ({"spacing": 0.03, "margin": 0.004, "substeps": True, "sdf": "mesh", "band": 0.1}, {"cores": False}),
)
"""Earlier forms of ``sim.field_contact`` in run hashes (until 2026-12-04, and until 2026-12-05), each with the values
of the keys added since that reproduce its judgement: a recorded hash of one of these forms is the same run
(physical runs: whatever it held; field runs: when their judgement is that one)."""
STATE_FILE = "state.json"


def latest_checkpoint(run_dir: Path) -> tuple[int, Path] | None:
    """The highest ``model_<it>.pt`` of a run folder."""
    found = []
    for p in run_dir.glob("model_*.pt"):
        m = re.fullmatch(r"model_(\d+)\.pt", p.name)
        if m:
            found.append((int(m.group(1)), p))
    return max(found) if found else None


def train_keys(cls=None, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every leaf key of ``TrainCfg`` as a path (a dict- or list-valued key is one leaf): what a run hash can read.
    tests/data/hashed_train_keys.txt records them, so that a key added later must be declared in
    ``NEUTRAL_DEFAULTS`` (or as a change of what runs learn) before every unfinished run reads as changed."""
    from cat.run.config import TrainCfg

    cls = cls or TrainCfg
    hints = typing.get_type_hints(cls)
    out: list[tuple[str, ...]] = []
    for f in dataclasses.fields(cls):
        sub = hints[f.name]
        out += train_keys(sub, (*prefix, f.name)) if dataclasses.is_dataclass(sub) else [(*prefix, f.name)]
    return out


def _comparable(cfg) -> dict:
    """A TrainCfg as a dict without the keys that do not change what a run learns (``sim.field_contact`` of a
    physical run among them)."""
    out = OmegaConf.to_container(OmegaConf.structured(cfg))
    for key in VOLATILE:
        out.pop(key, None)
    if out.get("sim", {}).get("obstacles") == "physical":
        out["sim"].pop("field_contact", None)
    for path, neutral in NEUTRAL_DEFAULTS.items():
        parent = out
        for part in path[:-1]:
            parent = parent.get(part) if isinstance(parent, dict) else None
        if isinstance(parent, dict) and parent.get(path[-1], neutral) == neutral:
            parent.pop(path[-1], None)
    return out


_ABSENT = "(absent)"


def _diff(a: dict, b: dict, prefix: str = "") -> list[str]:
    """``key: a -> b`` for every leaf where two nested dicts differ (dotted keys, sorted)."""
    out = []
    for key in sorted(set(a) | set(b)):
        x, y = a.get(key, _ABSENT), b.get(key, _ABSENT)
        if isinstance(x, dict) and isinstance(y, dict):
            out += _diff(x, y, f"{prefix}{key}.")
        elif x != y:
            out.append(f"{prefix}{key}: {x} -> {y}")
    return out


def _earlier_form(config: dict, form: int) -> dict | None:
    """``config`` (a ``_comparable`` dict) as ``FIELD_CONTACT_HASHED[form]`` hashed it; None: a field run whose
    judgement is not that form's."""
    hashed, behaviour = FIELD_CONTACT_HASHED[form]
    out = copy.deepcopy(config)
    fc = out["sim"].get("field_contact")
    if fc is not None and any(fc.get(k) != v for k, v in {**hashed, **behaviour}.items()):
        return None
    out["sim"]["field_contact"] = dict(hashed)
    return out


def _digest(ident: dict) -> str:
    return hashlib.sha256(json.dumps(ident, sort_keys=True, default=str).encode()).hexdigest()[:16]


def file_digest(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:16]


@dataclass
class Unit:
    """One seed of one cell."""

    cell: Cell
    seed: int
    run_dir: Path
    base: list[str]  # scripts/train.py overrides of a fresh run (without init / teachers / run_dir)
    iterations: int  # the first leg's budget (a count)
    hash: str = ""
    inputs: dict[str, str] = field(default_factory=dict)  # "init" / "teachers" -> upstream unit key or path
    config: dict = field(default_factory=dict)  # the hashed config (``_comparable``)

    @property
    def key(self) -> str:
        return f"{self.cell.name}@{self.seed}"

    @property
    def timed(self) -> bool:
        """A minutes budget and no iteration count: the run ends when its minutes are spent."""
        return self.cell.minutes is not None and self.cell.iterations is None

    @property
    def final(self) -> int:
        """Iterations of the whole run (last leg's)."""
        return self.cell.legs[-1].iterations if self.cell.legs else self.iterations

    def checkpoint(self) -> Path:
        """The checkpoint that downstream cells and tables read: the run's last (``model_<final-1>.pt``, or the
        latest one for a minutes budget)."""
        if self.timed:
            latest = latest_checkpoint(self.run_dir)
            return latest[1] if latest else self.run_dir / "model_<latest>.pt"
        return self.run_dir / f"model_{self.final - 1}.pt"


class Plan:
    """The units of an experiment, hashed in DAG order, with its folder and state."""

    def __init__(self, exp: Experiment, root: str | None = None):
        self.exp = exp
        self.folder = Path(root or exp.root) / exp.name
        self.units: dict[str, Unit] = {}
        self.stages = exp.stages()
        for stage in self.stages:
            for name in stage:
                for seed in exp.cells[name].seeds:
                    unit = self._unit(exp.cells[name], seed)
                    self.units[unit.key] = unit
        self.state = self.read_state()
        self._read = copy.deepcopy(self.state)  # as read: what this process has not changed since

    # -- units -------------------------------------------------------------------------------------------------
    def _unit(self, cell: Cell, seed: int) -> Unit:
        base = [f"task={cell.task}", f"method={cell.method}", f"algo={cell.algo}", *self.exp.common]
        base += [*cell.overrides, f"seed={seed}"]
        try:
            cfg = load_config(base)
        except ExperimentError:
            raise
        except Exception as err:  # hydra_cfg.ConfigError & co: name the cell
            raise ExperimentError(f"cell {cell.name}: {err}") from None
        iterations = cell.iterations or BIG_ITERATIONS
        if cell.env_steps is not None:
            per_iter = (cfg.num_envs or cfg.task.num_envs) * cfg.algo.num_steps_per_env
            iterations = math.ceil(cell.env_steps / per_iter)
        unit = Unit(cell, seed, self.folder / "runs" / cell.name / f"seed{seed}", base, iterations)
        unit.config = _comparable(cfg)
        if cell.init:
            unit.inputs["init"] = self._ref(cell.init, seed)
        for k, teacher in enumerate(cell.teachers):
            unit.inputs[f"teacher{k}"] = self._ref(teacher, seed)
        unit.hash = self.unit_hash(unit)
        return unit

    def unit_hash(self, unit: Unit, form: int | None = None) -> str | None:
        """The unit's hash, or (``form``) the one ``FIELD_CONTACT_HASHED[form]`` gave it (None: not of that form)."""
        config = unit.config if form is None else _earlier_form(unit.config, form)
        inputs = {k: self.identity(v, form) for k, v in unit.inputs.items()}
        if config is None or None in inputs.values():
            return None
        return _digest(
            {"config": config, "legs": [[g.iterations, g.overrides] for g in unit.cell.legs], "inputs": inputs}
        )

    def _ref(self, ref: str, seed: int) -> str:
        """A cell reference -> the upstream unit key (same seed if that cell has it, else its first), with
        ``/model_<it>.pt`` kept when it names a file of the run."""
        cell = self.exp.cell_of(ref)
        if cell is None:
            return ref
        seeds = self.exp.cells[cell[0]].seeds
        key = f"{cell[0]}@{seed if seed in seeds else seeds[0]}"
        return f"{key}/{cell[1]}" if cell[1] else key

    def unit_of(self, ref: str) -> tuple[Unit, str | None] | None:
        key, _, file = ref.partition("/")
        return (self.units[key], file or None) if key in self.units else None

    def identity(self, ref: str, form: int | None = None) -> str | None:
        """What a unit's hash reads of ``ref`` (an upstream unit's hash in ``form`` too, None if it has none)."""
        if (found := self.unit_of(ref)) is not None:
            u, file = found
            h = u.hash if form is None else self.unit_hash(u, form)
            return None if h is None else f"{h}:{file or u.final}:{u.cell.minutes}"
        return f"{ref}:{file_digest(ref)}" if Path(ref).is_file() else ref

    def rekey(self, recorded: str | None, current: str, earlier) -> bool:
        """True when ``recorded`` is one of the ``earlier(form)`` hashes of what now hashes to ``current``."""
        return (
            recorded is not None
            and recorded != current
            and recorded in {earlier(f) for f in range(len(FIELD_CONTACT_HASHED))}
        )

    def path_of(self, ref: str) -> str:
        """A unit key (``/model_<it>.pt``) or a checkpoint path -> the checkpoint file to read."""
        if (found := self.unit_of(ref)) is None:
            return ref
        u, file = found
        return str(u.run_dir / file) if file else str(u.checkpoint())

    def units_of(self, names: list[str]) -> list[Unit]:
        return [u for u in self.units.values() if u.cell.name in names]

    # -- state -------------------------------------------------------------------------------------------------
    def read_state(self) -> dict:
        path = self.folder / STATE_FILE
        if not path.is_file():
            return {"units": {}, "tables": {}}
        try:
            state = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise ExperimentError(f"{path}: not readable JSON ({err})") from None
        state.setdefault("units", {})
        state.setdefault("tables", {})
        return state

    def write_state(self) -> None:
        """Write the state, merged entry by entry with the file as it is now: an entry this process has not
        changed since it read the file is taken from the file, so two sittings of one experiment on different
        cells (``only=``, two machines on a shared disk) do not drop each other's records."""
        now = self.read_state()
        for section in ("units", "tables"):
            mine, read = self.state[section], self._read[section]
            for key, entry in now[section].items():
                if key not in mine or mine[key] == read.get(key):
                    mine[key] = entry
        self.folder.mkdir(parents=True, exist_ok=True)
        tmp = self.folder / f"{STATE_FILE}.{os.getpid()}.tmp"
        tmp.write_text(json.dumps(self.state, indent=1, sort_keys=True))
        tmp.replace(self.folder / STATE_FILE)
        self._read = copy.deepcopy(self.state)

    def hold(self, unit: Unit, until: float | None) -> None:
        """Mark the unit as trained by this sitting (host, pid, its end as Unix time or None) until :meth:`release`."""
        entry = self.state["units"].setdefault(unit.key, {})
        entry["sitting"] = this_sitting(until)

    def release(self, unit: Unit) -> None:
        self.state["units"].get(unit.key, {}).pop("sitting", None)

    def holders(self, units: list[Unit]) -> dict[str, str]:
        """Who else trains each of ``units`` now, by unit key, from the state file as it is (read once): another
        live process on this host, or a sitting on another host whose end has not passed (one without an end holds
        until its record is removed). Units nobody else trains are left out."""
        records = self.read_state()["units"]
        out = {}
        for unit in units:
            if (held := records.get(unit.key, {}).get("sitting")) and (by := live_sitting(held)):
                out[unit.key] = by
        return out

    def minutes_used(self, unit: Unit) -> float:
        return float(self.state["units"].get(unit.key, {}).get("minutes", 0.0))

    @staticmethod
    def run_config(unit: Unit, folder: Path | None = None):
        """The TrainCfg of the run in the unit's folder (or ``folder``: a shipped copy), its latest checkpoint's;
        None without a readable one."""
        from cat.learning.runs import load_run_config

        folder = folder or unit.run_dir
        latest = latest_checkpoint(folder)
        if latest is None or not (folder / "config.yaml").is_file():
            return None
        try:
            return load_run_config(latest[1])
        except Exception:  # an unreadable or foreign config
            return None

    def changes(self, unit: Unit, limit: int = 4) -> str:
        """What differs between the run in the unit's folder and the unit now, for a stale run's message: the
        config keys (``key: theirs -> now``), else what else a hash reads (inputs, legs, the set of keys: a key
        added to ``TrainCfg`` without a ``NEUTRAL_DEFAULTS`` entry)."""
        theirs = self.run_config(unit)
        if theirs is None:
            return "its config is not readable"
        diffs = _diff(_comparable(theirs), _comparable(load_config(list(unit.base))))
        if not diffs:
            return "no config value differs: its inputs (init / teacher checkpoints), its legs, or the keys hashed"
        more = f" and {len(diffs) - limit} more" if len(diffs) > limit else ""
        return "; ".join(diffs[:limit]) + more

    def adoptable(self, unit: Unit, folder: Path | None = None) -> bool:
        """A run that the state does not know (its printed command run by hand, e.g. under torchrun; ``folder``: a
        shipped copy) is the unit's when its config.yaml is the unit's config at the leg it stands in, with the
        expected inputs."""
        raw = self.run_config(unit, folder)
        if raw is None:  # none, or an unreadable or foreign config: not this unit's run
            return False
        try:
            theirs = _comparable(raw)
            legs = unit.cell.legs
            # the config after each leg (a leg's keys are in it once the run resumed into that leg)
            mine = [_comparable(load_config([*unit.base, *(o for leg in legs[:j] for o in leg.overrides)]))
                    for j in range(len(legs) + 1)]  # fmt: skip
        except Exception:  # a foreign config: not this unit's run
            return False
        fresh = dict(o.split("=", 1) for o in self.fresh_overrides(unit))
        teachers = [t for t in fresh.get("teachers", "[]").strip("[]").split(",") if t]
        return (
            theirs in mine
            and self.same_input(raw.init or None, fresh.get("init"))
            and len(raw.teachers) == len(teachers)
            and all(self.same_input(a, b) for a, b in zip(raw.teachers, teachers, strict=True))
        )

    def same_input(self, theirs: str | None, mine: str | None) -> bool:
        """Whether a run's recorded input (init, a teacher) is the checkpoint this plan gives the unit: the same
        path, or the same upstream run's file under another experiment root (a run trained under
        ``experiments/``, restored under ``root=<elsewhere>``: ``<experiment>/runs/<cell>/seed<k>/model_<it>.pt``
        alike)."""
        if theirs == mine or theirs is None or mine is None:
            return theirs == mine
        try:
            rel = Path(mine).relative_to(self.folder)
        except ValueError:  # a checkpoint outside the experiment (a shipped prior): the path must match
            return False
        tail = (self.exp.name, *rel.parts)
        return Path(theirs).parts[-len(tail) :] == tail

    def status(self, unit: Unit) -> str:
        """``done``, ``resume`` (same hash, an earlier checkpoint), ``stale`` (another hash) or ``run``."""
        latest = latest_checkpoint(unit.run_dir)
        recorded = self.state["units"].get(unit.key, {}).get("hash")
        if latest is None:
            return "run"
        if recorded is None and self.adoptable(unit):
            self.state["units"][unit.key] = {"hash": unit.hash, "run_dir": str(unit.run_dir), "adopted": True}
            recorded = unit.hash
        if self.rekey(recorded, unit.hash, lambda f: self.unit_hash(unit, f)):  # the hash's form changed, not the run
            self.state["units"][unit.key]["hash"] = recorded = unit.hash
        if recorded != unit.hash:
            return "stale"
        it, _ = latest
        if unit.timed:
            done = self.minutes_used(unit) >= unit.cell.minutes
            return "done" if done or it + 1 >= BIG_ITERATIONS else "resume"
        return "done" if it + 1 >= unit.final else "resume"

    def leg(self, unit: Unit) -> tuple[int, list[str]]:
        """The (max_iterations, overrides) of the leg the run stands in."""
        latest = latest_checkpoint(unit.run_dir)
        done = latest[0] + 1 if latest else 0
        legs = [(unit.iterations, [])] + [(leg.iterations, leg.overrides) for leg in unit.cell.legs]
        return next((leg for leg in legs if leg[0] > done), legs[-1])

    # -- commands ----------------------------------------------------------------------------------------------
    def fresh_overrides(self, unit: Unit) -> list[str]:
        out = [*unit.base, f"max_iterations={unit.iterations}"]
        if "init" in unit.inputs:
            out.append(f"init={self.path_of(unit.inputs['init'])}")
        teachers = [self.path_of(v) for k, v in unit.inputs.items() if k.startswith("teacher")]
        if teachers:
            out.append(f"teachers=[{','.join(teachers)}]")
        return [*out, f"run_dir={unit.run_dir}"]

    def resume_overrides(self, unit: Unit, at: Path, iterations: int, leg: list[str]) -> list[str]:
        return [f"resume={at}", f"max_iterations={iterations}", *leg]

    def chain(self, unit: Unit) -> list[list[str]]:
        """Every scripts/train.py command of the unit from scratch: the first leg, then each resumed leg."""
        out = [self.fresh_overrides(unit)]
        last = unit.iterations
        for leg in unit.cell.legs:
            at = unit.run_dir / f"model_{last - 1}.pt"
            out.append(self.resume_overrides(unit, at, leg.iterations, leg.overrides))
            last = leg.iterations
        return out

    # -- tables ------------------------------------------------------------------------------------------------
    def table_refs(self, table: Table) -> list[str]:
        """Unit keys (every seed of a referenced cell) and checkpoint paths the table reads."""
        out = []
        for ref in table.references():
            cell = self.exp.cell_of(ref)
            if cell is None:
                out.append(ref)
            else:
                out += [f"{cell[0]}@{s}" + (f"/{cell[1]}" if cell[1] else "") for s in self.exp.cells[cell[0]].seeds]
        return out

    def manifest(self, table: Table) -> dict:
        """The scripts/eval_table.py manifest of a table, cells replaced by their checkpoints (every seed)."""

        def paths(entries: list) -> list[str]:
            out = []
            for e in entries:
                cell = self.exp.cell_of(str(e))
                if cell is None:
                    out.append(str(e))
                    continue
                tail = f"/{cell[1]}" if cell[1] else ""
                out += [self.path_of(f"{cell[0]}@{s}{tail}") for s in self.exp.cells[cell[0]].seeds]
            return out

        methods = {}
        for row, entries in table.methods.items():
            methods[row] = {k: paths(v) for k, v in entries.items()} if isinstance(entries, dict) else paths(entries)
        out: dict = {"methods": methods}
        if table.table1 is not None:
            out["table1"] = dict(table.table1)
        if table.table2 is not None:
            out["table2"] = dict(table.table2)
        if table.table3 is not None:
            out["table3"] = dict(table.table3)
        return out

    def table_dir(self, table: Table) -> Path:
        return self.folder / "tables" / table.name

    def table_hash(self, table: Table, form: int | None = None) -> str | None:
        inputs = [self.identity(r, form) for r in self.table_refs(table) if r != "hold"]
        if None in inputs:
            return None
        return _digest({
            "manifest": self.manifest(table),
            "opts": [table.trials_per_scene, table.seed, table.max_envs, table.sim]
            + ([table.perception, table.perception_setting] if table.perception != "ground_truth" else []),
            "inputs": inputs,
        })  # fmt: skip

    def table_done(self, table: Table) -> bool:
        recorded = self.state["tables"].get(table.name, {}).get("hash")
        current = self.table_hash(table)
        if self.rekey(recorded, current, lambda f: self.table_hash(table, f)):
            self.state["tables"][table.name]["hash"] = recorded = current
        return recorded == current and (self.table_dir(table) / "trials.csv").is_file()

    def table_overrides(self, table: Table) -> list[str]:
        out = self.table_dir(table)
        return [
            f"manifest={out / 'manifest.yaml'}",
            f"out={out}",
            f"trials_per_scene={table.trials_per_scene}",
            f"seed={table.seed}",
            f"max_envs={table.max_envs}",
            f"sim={table.sim}",
            *(
                [f"perception={table.perception}", f"perception_setting={table.perception_setting}"]
                + ([f"live_workers={table.live_workers}"] if table.live_workers > 1 else [])
                if table.perception != "ground_truth"
                else []
            ),
        ]
