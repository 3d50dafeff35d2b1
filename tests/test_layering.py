"""Module boundaries: data flows problems -> solvers -> bench, never back, and no
two modules import each other, directly or around a loop (every import counted,
those inside functions too, and ``importlib.import_module`` calls: see :func:`_imports`)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"hikbench": "hikbench", "hikbench.bench": "bench", "hikbench.solvers": "solvers",
           "hikbench.problems": "problems"}


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg, folder in FOLDERS.items():
        paths = (ROOT / folder).glob("*.py") if pkg == "hikbench" else (ROOT / folder).rglob("*.py")
        for p in paths:
            parts = [x for x in p.relative_to(ROOT / folder).with_suffix("").parts if x != "__init__"]
            mods[".".join([pkg, *parts])] = p
    return mods


MODULES = _modules()


def _is_import_module(call: ast.Call) -> bool:
    f = call.func
    return (isinstance(f, ast.Attribute) and f.attr == "import_module") or \
        (isinstance(f, ast.Name) and f.id == "import_module")


def _dynamic_imports(tree: ast.AST) -> list[str]:
    """What ``importlib.import_module`` calls of a module import: a literal argument
    (``import_module("hikbench.solvers.hcod")``); for a computed one (``import_module(
    f"hikbench.bench.commands.{name}")``, ``import_module(modname)``), every project module's
    full name written in a table of the module (a tuple, list or set entry, a dict value:
    ``COMMANDS``, ``_BUILTIN_MODULES``), alone or as ``module:attribute`` (``PROVIDERS``)."""
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and _is_import_module(n) and n.args]
    literal = [c.args[0].value for c in calls
               if isinstance(c.args[0], ast.Constant) and isinstance(c.args[0].value, str)]
    if len(literal) == len(calls):
        return literal
    tables = [n.elts if isinstance(n, (ast.Tuple, ast.List, ast.Set)) else n.values for n in ast.walk(tree)
              if isinstance(n, (ast.Tuple, ast.List, ast.Set, ast.Dict))]
    named = [e.value.partition(":")[0] for t in tables for e in t
             if isinstance(e, ast.Constant) and isinstance(e.value, str) and e.value.partition(":")[0] in MODULES]
    return literal + named


def _imports(name: str, path: Path) -> set[str]:
    """The project modules that ``name`` imports (``from pkg import mod`` counts mod;
    ``importlib.import_module``: :func:`_dynamic_imports`)."""
    found = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text())
    for t in _dynamic_imports(tree):
        while t and t not in MODULES:
            t = t.rpartition(".")[0]
        if t and t != name:
            found.add(t)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in MODULES:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


GRAPH = {m: _imports(m, p) for m, p in MODULES.items()}


def _cycles() -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while not comp or comp[-1] != v:
                comp.append(stack.pop())
                on.discard(comp[-1])
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in GRAPH:
        if v not in index:
            visit(v)
    return out


def test_the_graph_sees_the_packages():
    assert {"hikbench.problems.hierarchy", "hikbench.solvers.hcod._kernel", "hikbench.bench.harness.runner"} \
        <= set(GRAPH)
    assert "hikbench.problems.hierarchy" in GRAPH["hikbench.problems.verify"]


def test_no_import_cycle():
    assert _cycles() == []


def test_the_graph_sees_import_module():
    """The CLI loads its sub-commands by importlib, the registry its solver modules: both edges count."""
    assert "hikbench.bench.commands.scenario" in GRAPH["hikbench.bench.cli"]
    assert "hikbench.solvers.hcod" in GRAPH["hikbench.solvers.registry"]
    assert "hikbench.problems.robots.models" in GRAPH["hikbench.bench.commands.list_"]
    assert "hikbench.bench.scenarios.pink_ik" in GRAPH["hikbench.bench.scenarios.controllers"]
    tree = ast.parse('import importlib\nimportlib.import_module("hikbench.bench.cli")\n')
    assert _dynamic_imports(tree) == ["hikbench.bench.cli"]


@pytest.mark.parametrize("low, high", [("hikbench.problems", "hikbench.solvers"),
                                       ("hikbench.problems", "hikbench.bench"),
                                       ("hikbench.solvers", "hikbench.bench")],
                         ids=["problems-solvers", "problems-bench", "solvers-bench"])
def test_data_flows_one_way(low, high):
    back = sorted(f"{m} -> {t}" for m, ts in GRAPH.items() if m.startswith(low + ".") or m == low
                  for t in ts if t.startswith(high))
    assert back == []
