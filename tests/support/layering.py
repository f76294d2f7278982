"""The import graph of the project's packages, read from the source with :mod:`ast`.

Every import counts: at module level, inside a function, under ``if TYPE_CHECKING:``, and the
modules named by string in a module that imports them with :func:`importlib.import_module`
(the engine switch, the lazy package attributes). The graph has one node per module (a package
is its ``__init__``) and an edge from each module to each module it imports; the parent packages
that Python initialises on the way are not edges (every package's ``__init__`` would otherwise
be in a cycle with the modules it re-exports).

Used by the per-package layering tests (``tests/unit/test_*_layering.py``): no import cycles
between modules, no private names (``_x``) imported across modules, and the rules between
packages (``binsonar`` never imports ``acoustisim`` or ``scenes``).
"""

from __future__ import annotations

import ast
import importlib.util
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import networkx as nx

PACKAGES = ("acoustisim", "scenes", "binsonar")
"""The project's top-level packages, each a directory under the repository root."""

REPOSITORY = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Import:
    """One imported name: ``from module import name`` in ``importer`` at ``line`` (``name`` empty
    for ``import module``); ``attribute`` when the name is read as ``module.name`` through an
    imported module object."""

    importer: str
    module: str
    name: str
    line: int
    attribute: bool = False

    def describe(self) -> str:
        if self.attribute:
            what = f"{self.module}.{self.name}"
        else:
            what = f"from {self.module} import {self.name}" if self.name else f"import {self.module}"
        return f"{self.importer}:{self.line}: {what}"


@dataclass(frozen=True)
class Layering:
    """The import graph of some packages and what it breaks.

    Attributes
    ----------
    graph
        Module-to-module import edges (each edge's ``imports`` attribute lists its
        :class:`Import` statements).
    private
        Imports of a private name (``_x``, not a dunder) from another module of the packages,
        and reads of ``module._x`` through an imported module object, as ``importer:line:
        statement`` strings.
    """

    graph: nx.DiGraph
    private: tuple[str, ...]

    def cycles(self) -> list[list[str]]:
        """The strongly connected components of more than one module, each sorted."""
        return sorted(sorted(c) for c in nx.strongly_connected_components(self.graph) if len(c) > 1)

    def cycle_edges(self) -> list[str]:
        """The import statements that close the cycles: every edge inside a cycle's component,
        as ``importer:line: statement`` (what to read when a cycle appears)."""
        found = []
        for component in self.cycles():
            sub = self.graph.subgraph(component)
            for a, b in sorted(sub.edges):
                found += [imp.describe() for imp in sub.edges[a, b]["imports"]]
        return found

    def imports_between(self, importer_package: str, imported_package: str) -> list[str]:
        """Every import of a module of ``imported_package`` by a module of ``importer_package``."""
        found = []
        for a, b, data in self.graph.edges(data=True):
            if _in_package(a, importer_package) and _in_package(b, imported_package):
                found += [imp.describe() for imp in data["imports"]]
        return sorted(found)


def _in_package(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def module_files(packages: Iterable[str] = PACKAGES, root: Path = REPOSITORY) -> dict[str, Path]:
    """Dotted module name -> source file of every module of ``packages`` (folders of ``root``)."""
    modules = {}
    top = root
    for package in packages:
        root = top / package
        for path in sorted(root.rglob("*.py")):
            parts = (package,) + path.relative_to(root).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def _absolute(module: str | None, level: int, importer: str, is_package: bool) -> str:
    """The absolute module of a possibly relative ``from`` import."""
    if level == 0:
        return module or ""
    base = importer if is_package else importer.rpartition(".")[0]
    return importlib.util.resolve_name("." * level + (module or ""), base)


def _uses_import_module(tree: ast.AST) -> bool:
    return any(isinstance(node, ast.Attribute) and node.attr == "import_module"
               or isinstance(node, ast.alias) and node.name == "import_module"
               for node in ast.walk(tree))


def imports_of(importer: str, path: Path, known: Iterable[str] = ()) -> Iterator[Import]:
    """Every import in one module's source; ``known`` (module names) are the modules a string
    constant may name in a module that calls :func:`importlib.import_module`."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"
    module_aliases: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = _absolute(node.module, node.level, importer, is_package)
            for alias in node.names:
                yield Import(importer, module, alias.name, node.lineno)
                module_aliases[alias.asname or alias.name] = f"{module}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield Import(importer, alias.name, "", node.lineno)
                if alias.asname:
                    module_aliases[alias.asname] = alias.name
    known = frozenset(known)
    if known and _uses_import_module(tree):
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in known:
                yield Import(importer, node.value, "", node.lineno)
    # ``module._x``: a private name read through a module object of the packages.
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            module = _dotted(node.value, module_aliases)
            if module in known:
                yield Import(importer, module, node.attr, node.lineno, attribute=True)


def _dotted(node: ast.AST, aliases: dict[str, str]) -> str:
    """``a.b.c`` of a chain of attribute reads on a name (the name resolved through the
    module's import aliases), or "" for any other expression."""
    if isinstance(node, ast.Name):
        return aliases.get(node.id, node.id)
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value, aliases)
        return f"{base}.{node.attr}" if base else ""
    return ""


def private_imports_into(folder: str, packages: Iterable[str] = PACKAGES, root: Path = REPOSITORY) -> list[str]:
    """Private names of ``packages`` imported (or read through a module) by the scripts under
    ``folder`` of the repository (``tests``, ``benchmarks``): a test or benchmark that needs one
    makes it a contract, so it should be public."""
    modules = module_files(packages, root)
    found = []
    for path in sorted((root / folder).rglob("*.py")):
        name = ".".join(path.relative_to(root).with_suffix("").parts)
        for imp in imports_of(name, path, modules):
            private_name = imp.name.startswith("_") and not imp.name.startswith("__")
            if private_name and (imp.module in modules or f"{imp.module}.{imp.name}" in modules):
                found.append(imp.describe())
    return sorted(set(found))


def _exported(tree: ast.Module) -> set[str]:
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets) and node.value is not None:
            return {c.value for c in ast.walk(node.value) if isinstance(c, ast.Constant) and isinstance(c.value, str)}
    return set()


def reexports(packages: Iterable[str] = PACKAGES, root: Path = REPOSITORY) -> list[str]:
    """Names a module (not a package's ``__init__``) imports and lists in ``__all__``: a second
    address for a name whose home is elsewhere (a "compatibility" re-export), as
    ``module: name (from home)``."""
    found = []
    for name, path in module_files(packages, root).items():
        if path.name == "__init__.py":
            continue
        tree = ast.parse(path.read_text(), filename=str(path))
        exported = _exported(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                found += [f"{name}: {alias.asname or alias.name} (from {node.module})" for alias in node.names
                          if (alias.asname or alias.name) in exported]
    return sorted(found)


def layering(packages: Iterable[str] = PACKAGES, root: Path = REPOSITORY) -> Layering:
    """The import graph of ``packages`` (folders of ``root``; modules from :func:`module_files`)."""
    modules = module_files(packages, root)
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    private = []
    for importer, path in modules.items():
        for imp in imports_of(importer, path, modules):
            qualified = f"{imp.module}.{imp.name}"
            target = qualified if qualified in modules else imp.module
            if target in modules and target != importer:
                if not graph.has_edge(importer, target):
                    graph.add_edge(importer, target, imports=[])
                graph.edges[importer, target]["imports"].append(imp)
            private_name = imp.name.startswith("_") and not imp.name.startswith("__")
            if private_name and target in modules and target != importer:
                private.append(imp.describe())
    return Layering(graph, tuple(sorted(set(private))))
