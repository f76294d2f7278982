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


def solve_arrivals(name: str, backend: str = "fast") -> NDArray[Any]:
    """The arrivals (:meth:`Paths.arrivals`) of built-in scene ``name`` at its default pose, with
    the default solver settings but for the mechanisms (:data:`MECHANISMS`) and without the
    elastic-echo step (the tables hold the mechanisms' geometric rows; the elastic echoes'
    amplitudes are checked against the exact series in ``tests/physics``)."""
    from acoustisim.propagation import SolverConfig, solve
    from scenes.builtin import builtin_scene

    config = SolverConfig(mechanisms=MECHANISMS, backend=backend, elastic_echoes=False)
    return solve(builtin_scene(name), config=config).arrivals()


def stored_arrivals(name: str) -> NDArray[Any]:
    """The stored arrivals of built-in scene ``name``."""
    with np.load(DATA / f"{name}.npz") as data:
        return data["arrivals"]


def regenerate() -> None:
    """Rewrite every stored table from the fast engine."""
    from scenes.builtin import builtin_scene_names

    DATA.mkdir(exist_ok=True)
    for name in builtin_scene_names():
        np.savez_compressed(DATA / f"{name}.npz", arrivals=solve_arrivals(name))
        print(f"{name}: written")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    regenerate()
