"""The project's layering, read from the source (:mod:`support.layering`).

- No import cycles between the modules of ``acoustisim``, ``scenes`` and ``binsonar`` (every
  import counts: module level, in a function, under ``TYPE_CHECKING``, by string for
  ``importlib``).
- No private name (``_x``) imported across modules, nor by the tests, benchmarks and examples.
- No compatibility re-exports: a module's ``__all__`` names only what it defines.
- ``binsonar`` never imports ``acoustisim`` or ``scenes``; the reference engine never imports
  the fast one; only ``propagation.engine`` imports an engine.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from support.layering import PACKAGES, Layering, imports_of, layering, private_imports_into, reexports

TOLERATED_CYCLES: tuple[tuple[str, ...], ...] = ()
"""Cycles in files other engineers are editing, each named with its owner; the lead removes an
entry once its owner's branch has merged. Empty while the packages have none."""

TOLERATED_PRIVATE: tuple[str, ...] = ()
"""Private imports in files other engineers are editing (``importer:line: statement``), as
:data:`TOLERATED_CYCLES`. Empty while the packages have none."""


@pytest.fixture(scope="module")
def graph() -> Layering:
    return layering()


def test_the_checker_sees_every_kind_of_import(graph: Layering) -> None:
    # One known edge of each kind, so that a checker that misses imports cannot pass the tests
    # below: module level, function level, under TYPE_CHECKING, named by string for
    # importlib.import_module, and an edge between packages.
    edges = graph.graph
    assert edges.has_edge("acoustisim.propagation.roughness", "acoustisim.propagation.paths")  # module level
    assert edges.has_edge("binsonar.detection.methods", "binsonar.detection.matched")  # in a function
    assert edges.has_edge("acoustisim.simulation", "acoustisim.propagation.paths")  # TYPE_CHECKING
    assert edges.has_edge("acoustisim.propagation.engine", "acoustisim.propagation.fast")  # by string
    assert edges.has_edge("acoustisim.cli.main", "binsonar.cli.verbs")
    assert {name.split(".")[0] for name in edges} == set(PACKAGES)
    assert edges.number_of_nodes() > 200 and edges.number_of_edges() > 700


def test_the_checker_finds_cycles_and_private_names(tmp_path: Path) -> None:
    # A miniature package with each violation the checker must report.
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text(textwrap.dedent("""
        from typing import TYPE_CHECKING
        if TYPE_CHECKING:
            from pkg.b import Thing
        def f():
            from . import b
            return b._hidden
        """))
    (package / "b.py").write_text("from pkg.a import _helper, f\nimport pkg.a as alias\nx = alias._y\n")
    known = ("pkg", "pkg.a", "pkg.b")
    a = [imp.describe() for imp in imports_of("pkg.a", package / "a.py", known)]
    b = [imp.describe() for imp in imports_of("pkg.b", package / "b.py", known)]
    assert "pkg.a:4: from pkg.b import Thing" in a  # TYPE_CHECKING
    assert "pkg.a:6: from pkg import b" in a  # relative, in a function
    assert "pkg.a:7: pkg.b._hidden" in a  # private name through a module object
    assert "pkg.b:1: from pkg.a import _helper" in b
    assert "pkg.b:3: pkg.a._y" in b
    mini = layering(("pkg",), tmp_path)
    assert mini.cycles() == [["pkg.a", "pkg.b"]]
    assert mini.private == ("pkg.a:7: pkg.b._hidden", "pkg.b:1: from pkg.a import _helper", "pkg.b:3: pkg.a._y")


def test_no_import_cycles(graph: Layering) -> None:
    cycles = [c for c in graph.cycles() if tuple(c) not in TOLERATED_CYCLES]
    assert not cycles, (cycles, graph.cycle_edges())


def test_no_private_names_imported_across_modules(graph: Layering) -> None:
    found = [entry for entry in graph.private if entry not in TOLERATED_PRIVATE]
    assert not found, found


@pytest.mark.parametrize("folder", ["tests", "benchmarks", "examples"])
def test_tests_benchmarks_and_examples_use_public_names_only(folder: str) -> None:
    found = private_imports_into(folder)
    assert not found, found


DOCUMENTED_REEXPORTS = ("acoustisim.errors: InputError (from binsonar.errors)",
                        "acoustisim.errors: InputTypeError (from binsonar.errors)")
"""The one error hierarchy lives in ``binsonar.errors``; ``acoustisim.errors`` re-exports it so
that simulator users catch ``acoustisim.errors.InputError`` (a documented contract)."""


def test_no_compatibility_reexports() -> None:
    # A module's __all__ lists what it defines; a name has one home (packages' __init__ aside).
    found = [entry for entry in reexports() if entry not in DOCUMENTED_REEXPORTS]
    assert not found, found


@pytest.mark.parametrize("other", ["acoustisim", "scenes"])
def test_binsonar_never_imports_the_simulator(graph: Layering, other: str) -> None:
    found = graph.imports_between("binsonar", other)
    assert not found, found


def test_the_reference_engine_never_imports_the_fast_one(graph: Layering) -> None:
    # The reference engine is the plain path: it must run (and be read) without the kernels.
    found = graph.imports_between("acoustisim.propagation.reference", "acoustisim.propagation.fast")
    assert not found, found


def test_only_the_switch_imports_an_engine(graph: Layering) -> None:
    # The modules both engines share (paths, context, prepared scene, config, ...) stay below
    # them; engine.engine_for is the one place that picks an engine.
    engines = ("acoustisim.propagation.reference", "acoustisim.propagation.fast")
    found = [entry for engine in engines for entry in graph.imports_between("acoustisim.propagation", engine)
             if not entry.startswith(engines + ("acoustisim.propagation.engine:",))]
    assert not found, found


def test_every_tolerated_case_still_exists(graph: Layering) -> None:
    # A tolerated case that is gone should leave the lists, so that it cannot come back unseen.
    assert set(TOLERATED_CYCLES) <= {tuple(c) for c in graph.cycles()}
    assert set(TOLERATED_PRIVATE) <= set(graph.private)
