"""Tables I and II from per-trial rows: aggregation (defined here, once) and Markdown / LaTeX rendering.

Per (method, column): SR = 100 × the fraction of successful trials, DE = the mean of the trials' DE.
Mean ± std are over *units*: the method's training seeds when it has >= 2 checkpoints (each seed's SR / DE
over all its trials in the column), otherwise the column's scenes (each scene's SR / DE over its trials);
the mean is the mean of the units, the std their sample standard deviation (n - 1; 0 for one unit). The
caption says which. Best per column (highest SR, lowest DE, as displayed) in bold; ties all bold.

Rows are the strings written to ``trials.csv``; numbers are parsed back from them, so every table entry can
be recomputed from the CSV alone.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass

CSV_COLUMNS = (
    "method",
    "seed",
    "checkpoint",
    "table",
    "group",
    "scene",
    "goal",
    "start",
    "start_x",
    "start_y",
    "start_yaw",
    "goal_x",
    "goal_y",
    "success",
    "de",
    "collided",
    "fell",
    "reach_time",
)
TITLES = {
    "table1": "Table I: traversal of the 8 typical scene types (paper Table I)",
    "table2": "Table II: zero-shot traversal of unseen indoor scenes (paper Table II)",
    "table3": "Table III: students of the same teachers by exteroceptive block (paper Table III)",
}


@dataclass(frozen=True)
class Cell:
    sr: float
    sr_std: float
    de: float
    de_std: float
    units: int


def aggregate(rows: Sequence[dict], table: str) -> tuple[dict[tuple[str, str], Cell], dict[str, str]]:
    """(cells keyed by (method, group), basis per method: "seeds" or "scenes") for ``table``'s rows."""
    rows = [r for r in rows if r["table"] == table]
    seeds: dict[str, set] = {}
    for r in rows:
        seeds.setdefault(r["method"], set()).add(r["seed"])
    basis = {m: ("seeds" if len(s) >= 2 else "scenes") for m, s in seeds.items()}
    units: dict[tuple[str, str], dict[str, list[dict]]] = {}
    for r in rows:
        key = r["seed"] if basis[r["method"]] == "seeds" else r["scene"]
        units.setdefault((r["method"], r["group"]), {}).setdefault(key, []).append(r)
    cells = {}
    for k, by_unit in units.items():
        sr = [100.0 * sum(int(r["success"]) for r in u) / len(u) for u in by_unit.values()]
        de = [sum(float(r["de"]) for r in u) / len(u) for u in by_unit.values()]
        cells[k] = Cell(statistics.fmean(sr), _std(sr), statistics.fmean(de), _std(de), len(sr))
    return cells, basis


def _std(values: list[float]) -> float:
    return statistics.stdev(values) if len(values) >= 2 else 0.0


def _title(group: str) -> str:
    return "-".join(w.capitalize() for w in group.split("-"))


def _best(cells: dict, methods: Sequence[str], group: str) -> tuple[str | None, str | None]:
    """Displayed best SR and DE strings of a column."""
    present = [cells[m, group] for m in methods if (m, group) in cells]
    if not present:
        return None, None
    return f"{max(c.sr for c in present):.1f}", f"{min(c.de for c in present):.2f}"


def caption(table: str, methods: Sequence[str], basis: dict[str, str], units: dict[str, int], note: str) -> str:
    """One-paragraph caption: what the numbers are and what the ± is over, per method."""
    parts = []
    for m in methods:
        if m in basis:
            what = "training seeds" if basis[m] == "seeds" else "scenes (one checkpoint)"
            parts.append(f"{m}: over {what}, n = {units[m]}")
    return (
        f"{TITLES.get(table, table)}. SR (%) and DE (m), mean ± std; std {'; '.join(parts)}. {note} "
        "Best per column in bold."
    )


def _blocks(groups: Sequence[str], per_block: int) -> list[list[str]]:
    return [list(groups[i : i + per_block]) for i in range(0, len(groups), per_block)]


def render_markdown(rows: Sequence[dict], table: str, methods: Sequence[str], groups: Sequence[str], note: str) -> str:
    """The table in Markdown (8 types: two blocks of 4 columns, as in the paper)."""
    cells, basis = aggregate(rows, table)
    units = {m: max((c.units for (mm, _), c in cells.items() if mm == m), default=0) for m in methods}
    out = [f"**{caption(table, methods, basis, units, note)}**", ""]
    for block in _blocks(groups, 4):
        head = ["Method"] + [f"{_title(g)} {h}" for g in block for h in ("SR (%) ↑", "DE (m) ↓")]
        out += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        best = {g: _best(cells, methods, g) for g in block}
        for m in methods:
            line = [m]
            for g in block:
                c = cells.get((m, g))
                if c is None:
                    line += ["–", "–"]
                    continue
                sr, de = f"{c.sr:.1f}", f"{c.de:.2f}"
                sr_txt, de_txt = f"{sr} ± {c.sr_std:.1f}", f"{de} ± {c.de_std:.2f}"
                line.append(f"**{sr_txt}**" if sr == best[g][0] else sr_txt)
                line.append(f"**{de_txt}**" if de == best[g][1] else de_txt)
            out.append("| " + " | ".join(line) + " |")
        out.append("")
    return "\n".join(out)


def render_by_scene(rows: Sequence[dict], table: str, methods: Sequence[str], groups: Sequence[str]) -> str:
    """Per scene of each column: every method's SR over that scene's trials, with its contact and fall rates.

    The breakdown behind a column's mean ± std over scenes (Table II's 15 per column): which scenes a method
    passes and whether it fails them by touching or by falling. All from the trial rows, as the tables are."""
    rows = [r for r in rows if r["table"] == table]
    trials: dict[tuple[str, str, str], list[dict]] = {}
    for r in rows:
        trials.setdefault((r["group"], r["scene"], r["method"]), []).append(r)
    head = ["Column", "Scene", "Trials"] + [f"{m}: SR % (contact / fall %)" for m in methods]
    out = [
        f"**{TITLES.get(table, table)}, per scene.** SR over each scene's trials; contact and fall: the share of "
        "those trials that touched an obstacle or fell (a trial may do both).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for group in groups:
        scenes = sorted({s for g, s, _ in trials if g == group})
        for scene in scenes:
            counts = {len(trials[group, scene, m]) for m in methods if (group, scene, m) in trials}
            line = [_title(group), scene, "/".join(str(n) for n in sorted(counts))]
            for m in methods:
                ts = trials.get((group, scene, m))
                if not ts:
                    line.append("–")
                    continue
                pct = {k: 100.0 * sum(int(t[k]) for t in ts) / len(ts) for k in ("success", "collided", "fell")}
                line.append(f"{pct['success']:.0f} ({pct['collided']:.0f} / {pct['fell']:.0f})")
            out.append("| " + " | ".join(line) + " |")
    return "\n".join(out + [""])


def _tex_escape(text: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("_", r"\_"), ("#", r"\#")):
        text = text.replace(a, b)
    return text.replace("±", r"$\pm$")


def render_latex(rows: Sequence[dict], table: str, methods: Sequence[str], groups: Sequence[str], note: str) -> str:
    """The table in LaTeX (booktabs), the paper's layout: per column SR (%) and DE (m) with a small ± std."""
    cells, basis = aggregate(rows, table)
    units = {m: max((c.units for (mm, _), c in cells.items() if mm == m), default=0) for m in methods}
    width = min(4, len(groups))
    lines = [
        "% needs \\usepackage{booktabs}",
        "\\begin{table*}[t]",
        "\\centering",
        "\\begin{tabular}{l" + " cc" * width + "}",
        "\\toprule",
    ]
    for b, block in enumerate(_blocks(groups, 4)):
        if b:
            lines.append("\\midrule")
        heads = " & ".join(f"\\multicolumn{{2}}{{c}}{{\\textbf{{{_tex_escape(_title(g))}}}}}" for g in block)
        rules = " ".join(f"\\cmidrule(lr){{{2 + 2 * i}-{3 + 2 * i}}}" for i in range(len(block)))
        metric = " & ".join("\\textit{SR(\\%)} $\\uparrow$ & \\textit{DE(m)} $\\downarrow$" for _ in block)
        lines += [f" & {heads} \\\\", rules, f" & {metric} \\\\", "\\midrule"]
        best = {g: _best(cells, methods, g) for g in block}
        for m in methods:
            entries = [_tex_escape(m)]
            for g in block:
                c = cells.get((m, g))
                if c is None:
                    entries += ["--", "--"]
                    continue
                sr, de = f"{c.sr:.1f}", f"{c.de:.2f}"
                sr_txt = f"{sr}{{\\scriptsize{{}} $\\pm${c.sr_std:.1f}}}"
                de_txt = f"{de}{{\\scriptsize{{}} $\\pm${c.de_std:.2f}}}"
                entries.append(f"\\textbf{{{sr_txt}}}" if sr == best[g][0] else sr_txt)
                entries.append(f"\\textbf{{{de_txt}}}" if de == best[g][1] else de_txt)
            lines.append(" & ".join(entries) + " \\\\")
    lines += [
        "\\bottomrule",
        "\\end{tabular}",
        f"\\caption{{{_tex_escape(caption(table, methods, basis, units, note))}}}",
        f"\\label{{tab:{table}}}",
        "\\end{table*}",
        "",
    ]
    return "\n".join(lines)
