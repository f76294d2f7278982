"""binsonar's layering: no import cycles between its modules, no private names imported across
modules (read from the source: every ``import`` statement, at module level or in a function)."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

import binsonar

ROOT = Path(binsonar.__file__).resolve().parent
EXCLUDED_PACKAGES = ("binsonar.cli",)
"""Checked by their own owners' tests (the command line's package imports its ``main``, which imports
the package back: a cycle to be removed there)."""


def _modules() -> dict[str, Path]:
    modules = {}
    for path in ROOT.rglob("*.py"):
        parts = ("binsonar",) + path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        if not name.startswith(EXCLUDED_PACKAGES):
            modules[name] = path
    return modules


def _imports(path: Path) -> list[tuple[str, str]]:
    """(module, name) of every ``from module import name``, and (module, "") of ``import module``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found += [(node.module, alias.name) for alias in node.names]
        elif isinstance(node, ast.Import):
            found += [(alias.name, "") for alias in node.names]
    return found


def _graph() -> tuple[nx.DiGraph, list[str]]:
    modules = _modules()
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    private = []
    for name, path in modules.items():
        for module, imported in _imports(path):
            target = f"{module}.{imported}" if f"{module}.{imported}" in modules else module
            if target in modules and target != name:
                graph.add_edge(name, target)
            if imported.startswith("_") and not imported.startswith("__") and module.startswith("binsonar"):
                private.append(f"{name}: from {module} import {imported}")
    return graph, private


def test_the_checker_sees_the_imports() -> None:
    # A known edge (function-level import) and a known package edge, so that an empty graph
    # cannot pass the tests below.
    graph, _ = _graph()
    assert graph.has_edge("binsonar.detection.methods", "binsonar.detection.matched")
    assert graph.has_edge("binsonar.localization.beam_refine", "binsonar.localization.beam_cue")
    assert graph.number_of_edges() > 100


def test_no_import_cycles() -> None:
    graph, _ = _graph()
    cycles = [sorted(c) for c in nx.strongly_connected_components(graph) if len(c) > 1]
    assert not cycles, cycles


def test_no_private_names_imported_across_modules() -> None:
    _, private = _graph()
    assert not private, private
