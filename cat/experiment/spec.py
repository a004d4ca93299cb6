"""``configs/experiment/<name>.yaml``: the cells (training runs) of an experiment and the tables built from them.

```yaml
root: experiments            # optional: the experiment lives in <root>/<name>/ (root= on the command line wins)
shipped: checkpoints         # optional: a run shipped to <shipped>/<name>/<cell>/seed<k>/ is restored (restore.py)
common: [sim=mujoco]         # optional: overrides of every cell (scripts/train.py keys)
cells:
  prior:                     # a cell: one training run per seed
    task: flat               # configs/task/<task>.yaml; also method: (configs/method), algo: (configs/algo)
    iterations: 1500         # budget: iterations, or env_steps (-> iterations), or minutes (over sittings)
    seeds: [0]
    overrides: [num_envs=4096]
  crouch:
    task: crouch_pass
    init: prior              # another cell (same seed, else its first) or a checkpoint path; prior/model_99.pt:
                             # that file of the cell's run (a leg's end: model_<leg iterations - 1>.pt)
    iterations: 600
    legs:                    # optional: resumed legs after the first, each up to its own iteration count
      - {iterations: 900, overrides: [task.ghost_share=0.5]}
  student:
    algo: distill
    teachers: [crouch, checkpoints/side_pass/model_1019.pt]
tables:
  table1:                    # a scripts/eval_table.py manifest whose checkpoints may be cells (all their seeds)
    methods: {Ours: [student], Specialists: {crouch-pass: [crouch]}}
    table1: {scene_seed: 0}
    trials_per_scene: 10     # also seed:, max_envs:, sim:
    equal_budget: [Ours]     # rows that may differ only in method (check_equal_budget)
  picked:
    methods: {Ours (specialists): {manifest: configs/eval/table1.yaml}}   # that manifest's row of this name
    table1: {scene_seed: 0}
```

Everything is checked on load (``ExperimentError``, one line naming the entry): unknown keys, a budget that is
not exactly one of the three, an ``init`` / teacher / table entry that is neither a cell nor an existing file, a
cycle.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field, fields
from pathlib import Path

import yaml

from cat.cli import CliError, unknown_key_message

EXPERIMENT_DIR = Path(__file__).resolve().parents[2] / "configs" / "experiment"
BIG_ITERATIONS = 1_000_000  # a minutes-only budget: the run stops on time, not on a count


class ExperimentError(CliError):
    """A bad experiment file or option: one line naming the entry, exit code 2."""


@dataclass
class Leg:
    """A resumed leg of a cell's run: continue its last checkpoint up to ``iterations`` with ``overrides``."""

    iterations: int
    overrides: list[str] = field(default_factory=list)


@dataclass
class Cell:
    name: str
    task: str = "flat"
    method: str = "ours"
    algo: str = "ppo"
    init: str | None = None  # a cell name or a checkpoint path
    teachers: list[str] = field(default_factory=list)  # algo=distill: cells or checkpoint paths, in group order
    iterations: int | None = None
    env_steps: int | None = None
    minutes: float | None = None
    seeds: list[int] = field(default_factory=lambda: [0])
    overrides: list[str] = field(default_factory=list)
    legs: list[Leg] = field(default_factory=list)
    note: str = ""  # what the recipe stands for (printed by dry_run)

    def inputs(self) -> list[str]:
        """Checkpoint references this cell reads (init first, then teachers)."""
        return ([self.init] if self.init else []) + list(self.teachers)


@dataclass
class Table:
    name: str
    methods: dict
    table1: dict | None = None
    table2: dict | None = None
    table3: dict | None = None  # Table III's typical types (the manifest's table3)
    trials_per_scene: int = 10
    seed: int = 0
    max_envs: int = 256
    sim: str = "mujoco"
    perception: str = "ground_truth"  # eval_table.py perception= (lidar: through the simulated LiDAR and map)
    perception_setting: str = "default"  # with lidar: configs/eval/perception/<name>.yaml
    live_workers: int = 1  # with lidar: processes sharing a column's scenes (speed only: the trials are the same)
    equal_budget: list[str] = field(default_factory=list)  # rows that may differ only in method (one cell each)

    def references(self) -> list[str]:
        """Every checkpoint entry of its rows (cell names or paths)."""
        out = []
        for row in self.methods.values():
            for entries in row.values() if isinstance(row, dict) else [row]:
                out += [str(e) for e in entries]
        return out


@dataclass
class Experiment:
    name: str
    cells: dict[str, Cell]
    tables: dict[str, Table] = field(default_factory=dict)
    common: list[str] = field(default_factory=list)
    root: str = "experiments"
    note: str = ""
    shipped: str = "checkpoints"  # shipped runs: <shipped>/<name>/<cell>/seed<k>/ (scripts/ship.py out=)

    def cell_of(self, ref: str) -> tuple[str, str | None] | None:
        """``prior`` -> (prior, None) (its final checkpoint); ``prior/model_99.pt`` -> (prior, model_99.pt);
        None for a checkpoint path."""
        if ref in self.cells:
            return ref, None
        head, _, tail = ref.partition("/")
        if head in self.cells and re.fullmatch(r"model_\d+\.pt", tail):
            return head, tail
        return None

    def deps(self, name: str) -> list[str]:
        """Cells that cell or table ``name`` reads."""
        refs = self.cells[name].inputs() if name in self.cells else self.tables[name].references()
        return list(dict.fromkeys(c[0] for r in refs if (c := self.cell_of(r))))

    def stages(self) -> list[list[str]]:
        """Cells grouped by depth in the DAG (a cell runs after every cell it reads); tables come after."""
        depth: dict[str, int] = {}

        def visit(name: str, path: tuple[str, ...]) -> int:
            if name in path:
                cycle = " -> ".join((*path[path.index(name) :], name))
                raise ExperimentError(f"experiment {self.name}: cycle {cycle}")
            if name not in depth:
                depth[name] = 1 + max((visit(d, (*path, name)) for d in self.deps(name)), default=-1)
            return depth[name]

        for name in self.cells:
            visit(name, ())
        return [[c for c in self.cells if depth[c] == d] for d in range(max(depth.values(), default=-1) + 1)]

    def closure(self, names: list[str]) -> list[str]:
        """``names`` (cells or tables) and every cell they need."""
        out: list[str] = []

        def add(name: str) -> None:
            if name in out:
                return
            for d in self.deps(name):
                add(d)
            out.append(name)

        for name in names:
            if name not in self.cells and name not in self.tables:
                valid = list(self.cells) + list(self.tables)
                raise ExperimentError(f"only={name}: " + unknown_key_message(name, valid).replace("key", "cell"))
            add(name)
        return out


def _check_keys(what: str, raw: dict, schema, extra: tuple[str, ...] = ()) -> None:
    valid = [f.name for f in fields(schema) if f.name != "name"] + list(extra)
    for key in raw:
        if key not in valid:
            raise ExperimentError(f"{what}: {unknown_key_message(str(key), valid)}")


def _as_list(what: str, value) -> list:
    if value is None:
        return []
    if not isinstance(value, list):
        raise ExperimentError(f"{what} must be a list, got {value!r}")
    return value


def _cell(name: str, raw: dict) -> Cell:
    what = f"cell {name}"
    if not isinstance(raw, dict):
        raise ExperimentError(f"{what} must be a mapping, got {raw!r}")
    _check_keys(what, raw, Cell)
    legs = []
    for k, leg in enumerate(_as_list(f"{what}: legs", raw.get("legs"))):
        if not isinstance(leg, dict):
            raise ExperimentError(f"{what}: legs[{k}] must be a mapping, got {leg!r}")
        _check_keys(f"{what}: legs[{k}]", leg, Leg)
        if "iterations" not in leg:
            raise ExperimentError(f"{what}: legs[{k}] needs iterations:")
        overrides = _as_list(f"{what}: legs[{k}].overrides", leg.get("overrides"))
        legs.append(Leg(int(leg["iterations"]), [str(o) for o in overrides]))
    cell = Cell(
        name=name,
        **{k: raw[k] for k in ("task", "method", "algo", "init", "note") if raw.get(k) is not None},
        teachers=[str(t) for t in _as_list(f"{what}: teachers", raw.get("teachers"))],
        iterations=raw.get("iterations"),
        env_steps=raw.get("env_steps"),
        minutes=raw.get("minutes"),
        seeds=[int(s) for s in _as_list(f"{what}: seeds", raw.get("seeds", [0]))],
        overrides=[str(o) for o in _as_list(f"{what}: overrides", raw.get("overrides"))],
        legs=legs,
    )
    budgets = [k for k in ("iterations", "env_steps", "minutes") if getattr(cell, k) is not None]
    if cell.minutes is not None and cell.iterations is not None:
        budgets.remove("iterations")  # a count caps a minutes budget
    if len(budgets) != 1:
        raise ExperimentError(f"{what}: give one budget (iterations, env_steps or minutes), got {budgets or 'none'}")
    for key in budgets:
        if getattr(cell, key) <= 0:
            raise ExperimentError(f"{what}: {key}={getattr(cell, key)} must be > 0")
    if not cell.seeds:
        raise ExperimentError(f"{what}: seeds is empty")
    last = cell.iterations or 0
    for k, leg in enumerate(legs):
        if leg.iterations <= last:
            raise ExperimentError(f"{what}: legs[{k}].iterations={leg.iterations} must exceed the leg before ({last})")
        last = leg.iterations
    if legs and cell.iterations is None:
        raise ExperimentError(f"{what}: legs need an iterations budget for the first leg")
    return cell


def _table(name: str, raw: dict) -> Table:
    what = f"table {name}"
    if not isinstance(raw, dict):
        raise ExperimentError(f"{what} must be a mapping, got {raw!r}")
    _check_keys(what, raw, Table)
    if not isinstance(raw.get("methods"), dict) or not raw["methods"]:
        raise ExperimentError(f"{what}: needs methods: {{row: [cells or checkpoints]}}")
    raw = {**raw, "methods": {row: _manifest_row(what, row, e) for row, e in raw["methods"].items()}}
    for row, entries in raw["methods"].items():
        columns = entries.values() if isinstance(entries, dict) else [entries]
        if not all(isinstance(c, list) and c and all(isinstance(e, str) for e in c) for c in columns):
            raise ExperimentError(
                f"{what}: row {row!r} must be a list of cells / checkpoints, or {{scene type: [...]}}, got {entries!r}"
            )
    if raw.get("table1") is None and raw.get("table2") is None and raw.get("table3") is None:
        raise ExperimentError(f"{what}: needs table1:, table2: and/or table3:")
    if raw.get("perception", "ground_truth") not in ("ground_truth", "lidar"):
        raise ExperimentError(f"{what}: perception must be ground_truth or lidar, got {raw['perception']!r}")
    workers = raw.get("live_workers", 1)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ExperimentError(f"{what}: live_workers must be a whole number >= 1, got {workers!r}")
    if workers > 1 and raw.get("perception", "ground_truth") != "lidar":
        raise ExperimentError(f"{what}: live_workers={workers} needs perception: lidar (ground truth runs batched)")
    rows = _as_list(f"{what}: equal_budget", raw.get("equal_budget"))
    for row in rows:
        if row not in raw["methods"]:
            raise ExperimentError(f"{what}: equal_budget names {row!r}, not a row; rows: {', '.join(raw['methods'])}")
    return Table(name=name, **{**raw, "equal_budget": [str(r) for r in rows]})


def _manifest_row(what: str, row: str, entries):
    """A row given as ``{manifest: configs/eval/<name>.yaml}`` is that eval manifest's row of the same name, so a row
    chosen by hand (the specialists, each cell picked on a selection set) has one definition; other rows as given."""
    if not (isinstance(entries, dict) and set(entries) == {"manifest"}):
        return entries
    path = Path(str(entries["manifest"]))
    if not path.is_file():
        raise ExperimentError(f"{what}: row {row!r}: manifest not found: {path}")
    methods = (yaml.safe_load(path.read_text()) or {}).get("methods")
    if not isinstance(methods, dict) or row not in methods:
        rows = ", ".join(methods) if isinstance(methods, dict) else "none"
        raise ExperimentError(f"{what}: row {row!r}: {path} has no row {row!r}; its rows: {rows}")
    return methods[row]


EQUAL_KEYS = ("task", "algo", "init", "overrides", "iterations", "env_steps", "legs")
"""What equal-budget rows share (their cells differ only in ``method``; seeds: one list's prefixes)."""


def check_equal_budget(exp: Experiment, table: Table) -> None:
    """The rows of ``table.equal_budget`` are trained alike but for the method. A row is one cell (one policy per
    method over every type) or a mapping type -> one cell (one policy per (method, type)); every row has the same
    form and the same types. Per column, the rows' cells share task (scenes, curriculum), algo, init (prior),
    overrides, budget and legs, and their seeds are prefixes of one list (seed 0 for every row, more seeds for
    some); a minutes budget is no equal budget (machines differ). An init may also be the row's own cell of another
    column, the same column for every row (each method continues its own policy: a chain of equal budgets). The
    trials are the table's, the same for every row. One ``ExperimentError`` naming the row (and column) and the
    difference."""
    what = f"table {table.name}: equal_budget"
    columns: dict[str | None, dict[str, Cell]] = {}  # None: one cell per row plays every column
    own: dict[str, dict[str, str | None]] = {}  # row -> its cells -> their column (an init may name one)
    forms: dict[str, tuple] = {}
    for row in table.equal_budget:
        entries = table.methods[row]
        per_type = entries if isinstance(entries, dict) else {None: entries}
        forms[row] = tuple(per_type)
        for column, refs in per_type.items():
            cell = exp.cell_of(refs[0]) if isinstance(refs, list) and len(refs) == 1 else None
            if cell is None or cell[1] is not None:
                where = f"row {row!r}" + (f", column {column!r}," if column else "")
                raise ExperimentError(
                    f"{what}: {where} must be one cell (a policy per method, or per method and type), got {refs!r}"
                )
            columns.setdefault(column, {})[row] = exp.cells[cell[0]]
            own.setdefault(row, {})[cell[0]] = column
            if exp.cells[cell[0]].minutes is not None:
                raise ExperimentError(f"{what}: row {row!r} (cell {cell[0]}) has a minutes budget; give env_steps")
    if len(set(forms.values())) > 1:
        first = next(iter(forms))
        odd = next(r for r, f in forms.items() if f != forms[first])
        shape = {
            r: "one cell" if f == (None,) else f"types {list(f)}" for r, f in ((first, forms[first]), (odd, forms[odd]))
        }
        raise ExperimentError(f"{what}: row {odd!r} ({shape[odd]}) is not shaped like row {first!r} ({shape[first]})")
    for column, cells in columns.items():
        _check_column(what + (f": column {column!r}" if column else ""), cells, own)


def _check_column(what: str, cells: dict[str, Cell], own: dict[str, dict[str, str | None]]) -> None:
    """The cells of one column (row -> cell) differ only in method; seeds are prefixes of one list. ``own``: each
    row's cells and their columns, so that an init naming the row's own cell compares as that column."""
    longest = max((c.seeds for c in cells.values()), key=len)
    for key in EQUAL_KEYS:
        values = {row: _comparable_value(cell, key, own[row]) for row, cell in cells.items()}
        reprs = [repr(v) for v in values.values()]
        usual = max(reprs, key=reprs.count)  # the value most rows have: the odd row out is named
        others = [r for r, v in values.items() if repr(v) == usual]
        for row, value in values.items():
            if repr(value) != usual:
                raise ExperimentError(
                    f"{what}: row {row!r} (cell {cells[row].name}) differs from {', '.join(map(repr, others))} in "
                    f"{key}: {value!r} vs {values[others[0]]!r}"
                )
    for row, cell in cells.items():
        if cell.seeds != longest[: len(cell.seeds)]:
            raise ExperimentError(
                f"{what}: row {row!r} (cell {cell.name}) trains seeds {cell.seeds}, not a prefix of {longest}"
            )


def _comparable_value(cell: Cell, key: str, own: dict[str, str | None]):
    value = getattr(cell, key)
    if key == "init" and value in own:
        return f"the row's own {own[value]} cell"
    if key == "overrides":
        return sorted(value)
    if key == "legs":
        return [(leg.iterations, sorted(leg.overrides)) for leg in value]
    return value


def experiment_path(name: str) -> Path:
    """``configs/experiment/<name>.yaml``, or ``name`` itself when it is a yaml file."""
    if name.endswith((".yaml", ".yml")):
        return Path(name)
    return EXPERIMENT_DIR / f"{name}.yaml"


def experiment_names() -> list[str]:
    return sorted(p.stem for p in EXPERIMENT_DIR.glob("*.yaml"))


def load_experiment(name: str) -> Experiment:
    """Parse and check an experiment; nothing is run or written."""
    path = experiment_path(name)
    if not path.is_file():
        raise ExperimentError(f"unknown experiment {name!r}; experiments: {', '.join(experiment_names())}")
    raw = yaml.safe_load(path.read_text()) or {}
    top = ("root", "common", "cells", "tables", "note", "shipped")
    for key in raw:
        if key not in top:
            raise ExperimentError(f"experiment {path.stem}: {unknown_key_message(str(key), list(top))}")
    if not isinstance(raw.get("cells"), dict) or not raw["cells"]:
        raise ExperimentError(f"experiment {path.stem}: needs cells:")
    exp = Experiment(
        name=path.stem,
        cells={str(k): _cell(str(k), v) for k, v in raw["cells"].items()},
        tables={str(k): _table(str(k), v) for k, v in (raw.get("tables") or {}).items()},
        common=[str(o) for o in _as_list("common", raw.get("common"))],
        root=str(raw.get("root", "experiments")),
        note=str(raw.get("note", "")),
        shipped=str(raw.get("shipped", "checkpoints")),
    )
    clash = set(exp.cells) & set(exp.tables)
    if clash:
        raise ExperimentError(f"experiment {exp.name}: {sorted(clash)[0]!r} is both a cell and a table")
    for cell in exp.cells.values():
        for ref in cell.inputs():
            _check_reference(exp, f"cell {cell.name}: {'init' if ref == cell.init else 'teacher'}", ref)
    for table in exp.tables.values():
        for ref in table.references():
            if ref != "hold":
                _check_reference(exp, f"table {table.name}", ref)
        check_equal_budget(exp, table)
    exp.stages()  # a cycle is an error now
    return exp


def _check_reference(exp: Experiment, what: str, ref: str) -> None:
    cell = exp.cell_of(ref)
    if cell is not None:
        last = exp.cells[cell[0]].legs[-1].iterations if exp.cells[cell[0]].legs else exp.cells[cell[0]].iterations
        if cell[1] and last is not None and int(cell[1][6:-3]) >= last:
            raise ExperimentError(f"{what}: {ref} is past the cell's last iteration ({last - 1})")
        return
    if os.sep in ref or ref.endswith(".pt"):
        if not Path(ref).is_file():
            raise ExperimentError(f"{what}: checkpoint not found: {ref}")
        return
    raise ExperimentError(f"{what}: {unknown_key_message(ref, list(exp.cells)).replace('key', 'cell')}")
