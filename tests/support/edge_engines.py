"""Each propagation engine's edge-diffraction functions, by backend name, for tests that run on
both: the discretisation, the quadrature and the rows of a pose."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

from acoustisim.propagation.fast import edge_elements as fast_elements
from acoustisim.propagation.fast import edge_gains as fast_gains
from acoustisim.propagation.fast import edges as fast_edges
from acoustisim.propagation.reference import btm as reference_btm
from acoustisim.propagation.reference import edge_elements as reference_elements
from acoustisim.propagation.reference import edge_paths as reference_edge_paths


class EdgeEngine(NamedTuple):
    """One engine's ``discretise_edges(geometry, grid)``, ``element_gains(elements, constants)``,
    ``quadrature_points(elements, constants)`` and ``edge_rows(context, config, prepared)``."""

    discretise_edges: Callable[..., Any]
    element_gains: Callable[..., Any]
    quadrature_points: Callable[..., Any]
    edge_rows: Callable[..., Any]


def edge_engine(backend: str) -> EdgeEngine:
    """The edge functions of the engine ``backend`` ("fast" or "reference") names."""
    if backend == "fast":
        return EdgeEngine(fast_elements.discretise_edges, fast_gains.element_gains, fast_gains.quadrature_points,
                          fast_edges.edge_rows)
    if backend == "reference":
        return EdgeEngine(reference_elements.discretise_edges, reference_btm.element_gains,
                          reference_btm.quadrature_points, reference_edge_paths.edge_rows)
    raise ValueError(f"unknown backend {backend!r}")
