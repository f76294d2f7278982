"""The stored arrival tables of the built-in scenes: what is solved, and how to regenerate them.

Run ``python tests/regression/arrival_tables.py`` to rewrite ``tests/regression/data/*.npz``
after a deliberate change of the physics (say why in the commit message); the regression test
compares every solve against them.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

DATA = Path(__file__).resolve().parent / "data"

MECHANISMS: tuple[str, ...] = ("direct", "specular", "edge")
"""The deterministic mechanisms (the diffuse tracer's rows are compared by energy elsewhere)."""


VARIANTS: tuple[tuple[str, str, tuple[tuple[str, Any], ...]], ...] = (
    ("thesis-tank-hard-shadows", "thesis-tank", (("shadows", False), ("edge_reflections", 0))),
)
"""Stored tables of a built-in scene solved with other settings: (table, scene, SolverConfig
options). ``thesis-tank-hard-shadows`` is the thesis tank with the smooth obstacles' shadows and
the edges combined with reflections off, the table as it was before they existed: the knobs off
reproduce those rows."""


def table_names() -> tuple[str, ...]:
    """Every stored table: the built-in scenes', then the variants'."""
    from scenes.builtin import builtin_scene_names

    return builtin_scene_names() + tuple(name for name, _, _ in VARIANTS)


def solve_arrivals(name: str, backend: str = "fast") -> NDArray[Any]:
    """The arrivals (:meth:`Paths.arrivals`) of table ``name`` (a built-in scene, or a
    :data:`VARIANTS` entry) at the scene's default pose, with the default solver settings but for
    the mechanisms (:data:`MECHANISMS`), the variant's options, and without the elastic-echo
    step (the tables hold the mechanisms' geometric rows; the elastic echoes' amplitudes are
    checked against the exact series in ``tests/physics``)."""
    from acoustisim.propagation import SolverConfig, solve
    from scenes.builtin import builtin_scene

    scene, options = name, ()
    for table, variant_scene, variant_options in VARIANTS:
        if table == name:
            scene, options = variant_scene, variant_options
    config = SolverConfig(mechanisms=MECHANISMS, backend=backend, elastic_echoes=False, **dict(options))
    return solve(builtin_scene(scene), config=config).arrivals()


def stored_arrivals(name: str) -> NDArray[Any]:
    """The stored arrivals of built-in scene ``name``."""
    with np.load(DATA / f"{name}.npz") as data:
        return data["arrivals"]


def regenerate() -> None:
    """Rewrite every stored table from the fast engine."""
    DATA.mkdir(exist_ok=True)
    for name in table_names():
        np.savez_compressed(DATA / f"{name}.npz", arrivals=solve_arrivals(name))
        print(f"{name}: written")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    regenerate()
