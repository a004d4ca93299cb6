"""Import layering of ``cat/``: dependencies point down, and no two modules import each other.

Every module's imports are read with ``ast`` (nothing is imported), function-level imports included (they run
too); imports under ``if TYPE_CHECKING:`` are left out (annotations only). Two rules:

(a) **No cycles**: no set of modules that import each other, directly or through others.
(b) **Layers point down**, in the order of issue 29::

        fields -> terrain -> physics (cat/envs/sim) -> envs -> viz -> run -> eval -> learning -> deploy -> top

    A module may import its own layer and any layer before it. ``viz`` (rerun recording of rollouts, used by
    play and the demo; it imports no other layer) sits just above envs, whose rollouts it draws. ``run`` (what a
    training run leaves behind: its config schema, config.yaml and policy network) sits below ``eval``, which
    plays checkpoints, and ``learning``, which writes them. On top, one
    rank: ``bench`` (the benchmarks, ``cat/bench``), ``experiment`` (the job runner of ``scripts/experiment.py``)
    and any other top-level module that is not a utility; ``scripts/`` are above all (not parsed here).

    **Shared utilities** sit below every layer, may be imported by all and must import no layer:
    ``cat/__init__.py``, ``cat/cli.py`` (the command-line front end of every script), ``cat/errors.py`` (its
    ``CliError``, raised by every layer) and ``cat/launcher.py``
    (its hydra launcher for ``-m`` jobs), ``cat/checkpoint_io.py`` (safe checkpoint loading: torch and
    tensordict only) and ``cat/checkpoint_convert.py`` (its conversion script).

Violations that exist today and cannot be fixed cheaply are listed in ``KNOWN_CYCLES`` and ``KNOWN_UPWARD``, each
with why. The test fails on any violation not listed, and on a listed one that no longer occurs (stale): the lists
can only shrink.
"""

from __future__ import annotations

import ast
from pathlib import Path

CAT = Path(__file__).resolve().parents[1] / "cat"

LAYERS = (
    "fields",
    "terrain",
    "physics",
    "envs",
    "viz",
    "run",
    "eval",
    "learning",
    "deploy",
    "bench",
    "experiment",
    "app",
)
TOP = {"bench", "experiment", "app"}  # one rank: on top of the product layers, like scripts/
UTILITIES = {"cat", "cat.cli", "cat.errors", "cat.launcher", "cat.checkpoint_io", "cat.checkpoint_convert"}

# Import cycles (strongly connected module sets) that remain, each a frozenset of modules, with why.
KNOWN_CYCLES: dict[frozenset[str], str] = {}

# Upward imports (importer, imported) that remain, with why. Module names, not packages, so a new upward import
# from another module of the same package is caught.
KNOWN_UPWARD: dict[tuple[str, str], str] = {}


def _layer(module: str) -> str | None:
    """The layer of a ``cat`` module (``None``: a shared utility)."""
    if module in UTILITIES:
        return None
    parts = module.split(".")
    if parts[1] == "envs" and len(parts) > 2 and parts[2] == "sim":
        return "physics"
    if len(parts) == 2 and not (CAT / parts[1]).is_dir():
        return "app"  # a top-level module that is not a utility (e.g. a job runner): on top, like scripts/
    if parts[1] not in LAYERS:
        raise AssertionError(f"{module}: not in any layer; add its package to LAYERS (and the docstring)")
    return parts[1]


def _rank(layer: str) -> int:
    return LAYERS.index("bench") if layer in TOP else LAYERS.index(layer)


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(CAT.rglob("*.py")):
        rel = path.relative_to(CAT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (
        isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING"
    )


def _imports(module: str, path: Path, known: set[str]) -> set[str]:
    """The ``cat`` modules ``module`` imports at run time (a ``from pkg import name`` of a submodule names it)."""
    tree = ast.parse(path.read_text(), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()

    def add(name: str) -> None:
        while name and name not in known:  # an attribute of a module: the module
            name = name.rpartition(".")[0]
        if name and name != module:
            found.add(name)

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "cat":
                    add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            if source.split(".")[0] == "cat":
                for alias in node.names:
                    sub = f"{source}.{alias.name}"
                    add(sub if sub in known else source)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    known = set(modules) | {"cat.launcher"}
    return {m: _imports(m, p, known) for m, p in modules.items()}


def _cycles(graph: dict[str, set[str]]) -> set[frozenset[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: set[frozenset[str]] = set()
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in graph:
                    continue
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = set()
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    comp.add(m)
                    if m == node:
                        break
                if len(comp) > 1:
                    out.add(frozenset(comp))
    return out


def _upward(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    out = set()
    for importer, targets in graph.items():
        mine = _layer(importer)
        for target in targets:
            theirs = _layer(target)
            if theirs is None:
                continue
            if mine is None or _rank(theirs) > _rank(mine):
                out.add((importer, target))
    return out


def test_the_checker_sees_cycles_and_upward_imports():
    """The checker itself: a made-up graph with one cycle and one upward import is caught."""
    graph = {"cat.fields.a": {"cat.envs.b"}, "cat.envs.b": {"cat.envs.c"}, "cat.envs.c": {"cat.envs.b"}}
    assert _cycles(graph) == {frozenset({"cat.envs.b", "cat.envs.c"})}
    assert _upward(graph) == {("cat.fields.a", "cat.envs.b")}


def test_no_new_import_cycles():
    found = _cycles(_graph())
    new = sorted(sorted(c) for c in found - set(KNOWN_CYCLES))
    stale = sorted(sorted(c) for c in set(KNOWN_CYCLES) - found)
    assert not new, f"import cycles: {new}"
    assert not stale, f"KNOWN_CYCLES entries that no longer occur (remove them): {stale}"


def test_no_new_upward_imports():
    found = _upward(_graph())
    new = sorted(found - set(KNOWN_UPWARD))
    stale = sorted(set(KNOWN_UPWARD) - found)
    assert not new, "upward imports (importer -> imported):\n" + "\n".join(f"  {a} -> {b}" for a, b in new)
    assert not stale, f"KNOWN_UPWARD entries that no longer occur (remove them): {stale}"


def test_benchmarks_live_in_their_own_package():
    strays = sorted(str(p.relative_to(CAT)) for p in CAT.rglob("bench*.py") if p.parent.name != "bench")
    assert not strays, f"benchmarks inside product packages (move them to cat/bench/): {strays}"
