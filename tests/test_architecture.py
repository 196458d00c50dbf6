"""The layout keeps its shape: no import cycle anywhere in the project (lazy imports inside
functions count: grimp reads every import statement), and no module loose at ``twin/`` but
the leaves. The import contracts themselves (who may import MuJoCo, rerun, the plant) are
``lint-imports``'s, run by ``make test``; ``docs/ARCHITECTURE.md`` draws them."""

from __future__ import annotations

from pathlib import Path

import grimp

import twin

ROOTS = ("twin", "envs", "tuning")
LEAVES = {"__init__.py", "units.py", "errors.py", "nesting.py"}


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_the_cycle_finder_finds_a_cycle():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _cycles(edges) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_the_project_has_no_import_cycle():
    graph = grimp.build_graph(*ROOTS)
    ours = {m for m in graph.modules if m.split(".")[0] in ROOTS}
    edges = {m: {x for x in graph.find_modules_directly_imported_by(m) if x in ours}
             for m in ours}
    assert len(ours) > 150
    assert _cycles(edges) == []


def test_no_module_is_loose_at_the_top_of_twin():
    top = Path(twin.__file__).parent
    loose = sorted(p.name for p in top.glob("*.py") if p.name not in LEAVES)
    assert loose == [], f"modules belong in a package of twin/ (see docs/ARCHITECTURE.md): {loose}"
    packages = sorted(p.name for p in top.iterdir() if (p / "__init__.py").is_file())
    assert packages == ["analysis", "cli", "config", "controller", "drive", "hardware",
                        "identify", "plant", "session", "system", "telemetry"]
    for name in packages:
        assert (top / name / "__init__.py").read_text().lstrip().startswith('"""'), \
            f"twin/{name}/__init__.py says what the package is"
