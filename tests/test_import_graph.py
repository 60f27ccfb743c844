"""The package's import graph, read from the source (every import, function-level ones
included, ``TYPE_CHECKING`` blocks left out): no circle, and the lower stages of the chain
import nothing of the higher ones (``docs/architecture.md``)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "spslidar"


def _graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (``a.b`` for ``from a import b`` where
    ``a.b`` is a module, else ``a``)."""
    files = {}
    for f in SRC.rglob("*.py"):
        parts = list(f.relative_to(SRC.parent).with_suffix("").parts)
        package = parts[:-1] if parts[-1] != "__init__" else parts[:-1]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        files[".".join(parts)] = (f, package)
    graph = {}
    for name, (f, package) in files.items():
        tree = ast.parse(f.read_text(encoding="utf-8"))
        # (the body of ``if TYPE_CHECKING:`` only: its ``else:`` runs, and so does
        # ``if not TYPE_CHECKING:``, a review)
        typing_only = {id(n) for node in ast.walk(tree)
                       if isinstance(node, ast.If)
                       and ast.unparse(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING")
                       for part in node.body for n in ast.walk(part)}
        out = set()
        for node in ast.walk(tree):
            if id(node) in typing_only:
                continue
            if isinstance(node, ast.ImportFrom):
                base = (package[:len(package) - node.level + 1] if node.level else [])
                mod = ".".join(base + ([node.module] if node.module else []))
                for alias in node.names:
                    sub = f"{mod}.{alias.name}"
                    out.add(sub if sub in files else mod)
            elif isinstance(node, ast.Import):
                out.update(alias.name for alias in node.names)
        # importing ``a.b.c`` runs the packages ``a`` and ``a.b`` first (their __init__): an
        # edge to each that is not the importer's own (a circle closed only through a
        # package's __init__ was missed, a review)
        ancestors = {".".join(name.split(".")[:i]) for i in range(1, name.count(".") + 1)}
        for target in list(out):
            parts = target.split(".")
            out.update(".".join(parts[:i]) for i in range(1, len(parts)))
        graph[name] = {m for m in out if m in files and m != name and m not in ancestors}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's, iterative)."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(root):
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            node, edges = work[-1]
            nxt = next(edges, None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter[0]
                    counter[0] += 1
                    stack.append(nxt)
                    on.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                elif nxt in on:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    top = stack.pop()
                    on.discard(top)
                    comp.append(top)
                    if top == node:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_reader_sees_every_module():
    """The graph is the package's (the test would pass on an empty one)."""
    graph = _graph()
    assert len(graph) > 100
    assert "spslidar.pipeline.calibrated" in graph["spslidar.pipeline.chain"]
    assert "spslidar.cli_common" in graph["spslidar.cli_measured"]


def test_circles_are_found():
    """The circle finder finds a planted circle (and a self-import is no circle)."""
    planted = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"d"}, "e": {"a"}}
    assert _circles(planted) == [["a", "b", "c"]]


def test_no_import_circle():
    """No module reaches itself back through the package's imports, function-level ones
    included (an audit of 2026-11-29 found three: the simulation's chain through the
    calibration and the measured-data path, ``cli`` through its sub-commands' modules, and
    the conformance checks through the fresh-process digests)."""
    assert _circles(_graph()) == []


#: the lower stages, and the higher ones they must not import
LOWER = {
    "spslidar.operators": ("pipeline", "depth", "solvers", "detectors", "forward", "cli",
                           "experiments", "config", "scenes"),
    "spslidar.solvers": ("pipeline", "depth", "detectors", "forward", "codes", "patterns",
                         "correlate", "qcr", "scenes", "cli", "experiments", "config"),
    "spslidar.depth": ("pipeline", "solvers", "cli", "experiments", "detectors"),
    "spslidar.codes": ("pipeline", "depth", "solvers", "detectors", "cli", "experiments",
                       "operators"),
}


@pytest.mark.parametrize("lower", sorted(LOWER))
def test_lower_stages_import_no_higher_one(lower):
    graph = _graph()
    higher = tuple(f"spslidar.{h}" for h in LOWER[lower])
    bad = sorted(f"{mod} -> {dep}" for mod, deps in graph.items()
                 if mod == lower or mod.startswith(lower + ".")
                 for dep in deps if dep.startswith(higher))
    assert bad == []


def _lazy_modules() -> list[str]:
    """The package's modules with a module-level ``__getattr__`` (PEP 562 lazy names)."""
    found = []
    for f in sorted(SRC.rglob("*.py")):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        if any((isinstance(n, ast.FunctionDef) and n.name == "__getattr__")
               or (isinstance(n, ast.Assign)
                   and any(getattr(t, "id", None) == "__getattr__" for t in n.targets))
               for n in tree.body):
            parts = list(f.relative_to(SRC.parent).with_suffix("").parts)
            found.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return found


def test_lazy_modules_are_found():
    assert {"spslidar", "spslidar.depth", "spslidar.codes"} <= set(_lazy_modules())


@pytest.mark.parametrize("name", _lazy_modules())
def test_lazy_names_are_listed_by_dir(name):
    """``dir()`` and a REPL's completion list a module's lazy public names (``spslidar.run``
    was missing from ``dir(spslidar)`` while ``spslidar.run`` worked: an audit of
    2026-11-30), and every name ``dir()`` lists resolves."""
    import importlib

    module = importlib.import_module(name)
    listed = dir(module)
    assert set(module.__all__) <= set(listed)
    assert all(hasattr(module, attr) for attr in listed)
