"""The ``scripts/eval_table.py`` manifest: which checkpoints form which table row, which tables to build.

```yaml
methods:                  # table row -> one checkpoint per training seed; `hold` = built-in reference policy
  Ours: [runs/a/model_1500.pt, runs/b/model_1500.pt]
  Hold: [hold]
  Specialists:            # or, for Table I only: scene type -> its own checkpoints (a specialist per column)
    hurdle-pass: [checkpoints/hurdle_pass/model_2712.pt]
    crouch-pass: [checkpoints/crouch_pass/model_599.pt]
table1: {scene_seed: 0}   # optional: the 8 typical types, 10 variants each (paper Table I); `variants: n`,
                          # `shapes: unseen` (the same layouts from obstacle shapes no training scene has)
table2:                   # optional: unseen scene folders (paper Table II), one column per entry
  easy: data/test_unseen/easy
  hard: data/test_unseen/hard
table3: {scene_seed: 0}   # optional: Table III's 4 types (crouch-pass, hurdle-pass, side-pass, hurdle-crouch);
                          # `variants: n`, `kinds: [...]` (typical types) as for table1
```

A per-type row plays each Table I column with that type's checkpoints and leaves the types it does not list
empty ("–"); it has no Table II cells (no one specialist stands for an unseen scene). Everything is checked
before any trial runs: unknown keys or scene types, a missing checkpoint or ``config.yaml``, an empty scene
folder, checkpoints of one row (of one type, in a per-type row) trained on different observation layouts, a
per-type row without ``table1``. Errors are ``ManifestError`` with one line naming the offending entry.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from cat.checkpoint_io import CheckpointError
from cat.envs.obs_groups import groups_layout
from cat.envs.scene_set import scene_folders
from cat.run.config import TrainCfg, policy_model
from cat.run.config_file import load_run_config
from cat.terrain import TYPICAL_KINDS
from cat.terrain.typical import SHAPES as TYPICAL_SHAPES

HOLD = "hold"
TOP_KEYS = ("methods", "table1", "table2", "table3")
TABLE1_KEYS = ("scene_seed", "variants", "shapes")
TABLE3_KINDS = ("crouch-pass", "hurdle-pass", "side-pass", "hurdle-crouch")  # paper Table III's columns


class ManifestError(ValueError):
    """A manifest entry that cannot be evaluated; the message names it."""


@dataclass
class MethodRun:
    """One checkpoint of a row (``checkpoint`` None: the hold policy) and its run config."""

    method: str
    seed: int  # index of the checkpoint in the row (training seed slot)
    checkpoint: str | None
    config: TrainCfg
    kind: str | None = None  # a per-type row's Table I column; None: every column of every table

    def plays(self, table: str, group: str) -> bool:
        """Whether this checkpoint is evaluated on column ``group`` of ``table``."""
        return self.kind is None or (table == "table1" and group == self.kind)


@dataclass
class Manifest:
    methods: dict[str, list[MethodRun]]
    table1: dict | None = None  # {"scene_seed": int, "variants": int, "shapes": "paper" | "unseen"}
    table2: dict[str, str] = field(default_factory=dict)  # column -> scene folder
    table3: dict | None = None  # {"scene_seed": int, "variants": int, "kinds": [typical types]}

    def per_type_methods(self) -> list[str]:
        """Rows that give a checkpoint per Table I scene type (specialists) rather than one for every column."""
        return [name for name, runs in self.methods.items() if runs[0].kind is not None]


def obs_layout(cfg: TrainCfg) -> tuple:
    """What fixes the policy's input: per group it reads (PPO's actor or the distilled student), the terms in
    order, whether the field block is live, and the grid sizes of its map terms (``group_layout``)."""
    return groups_layout(cfg.task, policy_model(cfg.algo).obs_groups)


def load_manifest(path: str | os.PathLike) -> Manifest:
    """Parse and check ``path`` (relative paths inside resolve against the current directory)."""
    p = Path(path)
    if not p.is_file():
        raise ManifestError(f"manifest not found: {p}")
    try:
        raw = yaml.safe_load(p.read_text())
    except yaml.YAMLError as err:
        raise ManifestError(f"manifest {p} is not valid YAML: {err}") from err
    if not isinstance(raw, dict):
        raise ManifestError(f"manifest {p} must be a mapping with keys {', '.join(TOP_KEYS)}")
    unknown = sorted(set(raw) - set(TOP_KEYS))
    if unknown:
        raise ManifestError(f"unknown manifest key {unknown[0]!r}; valid: {', '.join(TOP_KEYS)}")
    methods = _methods(raw.get("methods"))
    table1 = _table1(raw.get("table1")) if "table1" in raw else None
    table2 = _table2(raw.get("table2")) if "table2" in raw else {}
    table3 = _table3(raw.get("table3")) if "table3" in raw else None
    if table1 is None and not table2 and table3 is None:
        raise ManifestError("manifest asks for no table: add table1, table2 and/or table3")
    manifest = Manifest(methods, table1, table2, table3)
    per_type = manifest.per_type_methods()
    if per_type and table1 is None:
        raise ManifestError(
            f"method {per_type[0]!r} gives a checkpoint per scene type, which only table1 has: add table1"
        )
    return manifest


def _methods(raw) -> dict[str, list[MethodRun]]:
    if not isinstance(raw, dict) or not raw:
        raise ManifestError("manifest needs 'methods': a mapping of row name -> list of checkpoints (or [hold])")
    out = {}
    for name, entries in raw.items():
        name = str(name)
        if not isinstance(entries, dict):
            out[name] = _seed_runs(name, entries, None)
            continue
        if not entries:
            raise ManifestError(f"method {name!r}: a per-type row needs at least one scene type")
        out[name] = []
        for kind, kind_entries in entries.items():
            if kind not in TYPICAL_KINDS:
                raise ManifestError(f"method {name!r}: unknown scene type {kind!r}; valid: {', '.join(TYPICAL_KINDS)}")
            out[name] += _seed_runs(name, kind_entries, str(kind))
    return out


def _seed_runs(name: str, entries, kind: str | None) -> list[MethodRun]:
    """One row's (or one type's) checkpoints, one per training seed, sharing an observation layout."""
    where = f"method {name!r}" + (f" type {kind!r}" if kind else "")
    if isinstance(entries, str):
        entries = [entries]
    if not isinstance(entries, list) or not entries:
        raise ManifestError(f"{where}: expected a list of checkpoints (or [hold]), got {entries!r}")
    runs = [_method_run(name, i, str(e), kind) for i, e in enumerate(entries)]
    if len(runs) > 1 and any(r.checkpoint is None for r in runs):
        raise ManifestError(f"{where}: 'hold' is a row of its own, not mixed with checkpoints")
    layout = obs_layout(runs[0].config)
    for r in runs[1:]:
        if obs_layout(r.config) != layout:
            raise ManifestError(
                f"{where}: checkpoint {r.checkpoint} observation layout {obs_layout(r.config)} "
                f"differs from the method's ({runs[0].checkpoint}: {layout})"
            )
    return runs


def _method_run(method: str, seed: int, entry: str, kind: str | None) -> MethodRun:
    if entry == HOLD:
        return MethodRun(method, seed, None, TrainCfg(), kind)
    if not (entry.endswith(".pt") or os.sep in entry or "/" in entry):
        raise ManifestError(
            f"method {method!r}: unknown method {entry!r} (a checkpoint path model_*.pt or the built-in 'hold')"
        )
    try:
        cfg = load_run_config(entry)
    except CheckpointError as err:
        raise ManifestError(f"method {method!r}: {err}") from err
    return MethodRun(method, seed, entry, cfg, kind)


def _table1(raw) -> dict:
    if not isinstance(raw, dict):
        raise ManifestError(f"table1 must be a mapping like {{scene_seed: 0}}, got {raw!r}")
    unknown = sorted(set(raw) - set(TABLE1_KEYS))
    if unknown:
        raise ManifestError(f"unknown table1 key {unknown[0]!r}; valid: {', '.join(TABLE1_KEYS)}")
    out = {"scene_seed": raw.get("scene_seed", 0), "variants": raw.get("variants", 10)}
    for k, v in out.items():
        if not isinstance(v, int) or isinstance(v, bool) or (k == "variants" and v < 1):
            raise ManifestError(f"table1 {k} must be a {'positive ' if k == 'variants' else ''}integer, got {v!r}")
    shapes = raw.get("shapes", "paper")
    if shapes not in TYPICAL_SHAPES:
        raise ManifestError(f"table1 shapes must be one of {', '.join(TYPICAL_SHAPES)}, got {shapes!r}")
    return {**out, "shapes": shapes}


def _table3(raw) -> dict:
    """Table III: typical types (``kinds``, default the paper's four), ``variants`` each from ``scene_seed``."""
    raw = dict(raw or {}) if isinstance(raw, dict) or raw is None else raw
    if not isinstance(raw, dict):
        raise ManifestError(f"table3 must be a mapping like {{scene_seed: 0}}, got {raw!r}")
    kinds = raw.pop("kinds", list(TABLE3_KINDS))
    if not isinstance(kinds, list) or not kinds or any(k not in TYPICAL_KINDS for k in kinds):
        raise ManifestError(f"table3 kinds must be a list of typical types ({', '.join(TYPICAL_KINDS)}), got {kinds!r}")
    try:
        out = _table1(raw)
    except ManifestError as err:
        raise ManifestError(str(err).replace("table1", "table3")) from None
    return {**out, "kinds": [str(k) for k in kinds]}


def _table2(raw) -> dict[str, str]:
    if not isinstance(raw, dict) or not raw:
        raise ManifestError(f"table2 must map column names to scene folders (easy: ..., hard: ...), got {raw!r}")
    out = {}
    for name, folder in raw.items():
        root = Path(str(folder))
        if not root.is_dir():
            raise ManifestError(f"table2 {name!r}: scene folder not found: {root}")
        if not scene_folders(root):  # the runner's own search (it follows symbolic links)
            raise ManifestError(f"table2 {name!r}: no scenes (scene.json) under {root}")
        out[str(name)] = str(root)
    return out
