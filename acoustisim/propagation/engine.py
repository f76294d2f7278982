"""The two propagation engines behind one switch: ``SolverConfig(backend="reference" | "fast")``.

Both engines compute the same rows for the same scene, pose and configuration; they differ in
how. The **reference** engine (:mod:`acoustisim.propagation.reference`) has one module per
mechanism, written in plain numpy with batched Embree queries, each opening with its physics
(equations and sources), method and accuracy: read it to know what the simulator computes. The
**fast** engine (:mod:`acoustisim.propagation.fast`) computes the same rows with compiled
kernels, geometric screens that decide most occlusion queries without Embree, and reused
buffers: use it to run. The parity suite (``tests/parity``) holds them to the same answers.

:func:`engine_for` is the one place that reads the switch; :func:`acoustisim.propagation.solve`
calls it once per solve.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any, Protocol

from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.propagation.config import BACKENDS, SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.prepared import PreparedScene


class Engine(Protocol):
    """What an engine computes: each mechanism's rows, then the solve's assembled rows.

    Every method returns a structured array of
    :data:`~acoustisim.propagation.paths.PATH_DTYPE` with the geometric columns filled
    (``path_id`` from ``context.first_path_id``, ``channel``, ``kind``, ``order``,
    ``path_length_m``, ``geometric_gain``, ``phase_rad``, ``departure_dir``, ``arrival_dir``,
    ``object_ids``, ``points_m``), in any row order; :meth:`assemble_rows` fills the derived
    columns, orders the rows and applies the amplitude floor.
    """

    name: str

    def direct_rows(self, context: SolveContext) -> NDArray[Any]:
        """Unblocked transmitter-to-receiver rows."""

    def specular_rows(self, context: SolveContext, prepared: PreparedScene, max_order: int,
                      max_curved_per_path: int) -> NDArray[Any]:
        """Specular chains of 1..``max_order`` reflections on planar and curved surfaces, at most
        ``max_curved_per_path`` of them curved."""

    def edge_rows(self, context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> NDArray[Any]:
        """Edge diffraction (discretised BTM line integrals) of every sharp edge, alone and
        combined with up to ``config.edge_reflections`` reflections."""

    def diffuse_rows(self, context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> NDArray[Any]:
        """Lambert diffuse reverberation rows (Monte Carlo, counter-based random numbers)."""

    def assemble_rows(self, parts: Sequence[NDArray[Any]], context: SolveContext, config: SolverConfig
                      ) -> NDArray[Any]:
        """The solve's rows: derived columns filled, sorted by (channel, delay, order in
        ``parts``), the amplitude floor applied. May take the parts' buffers over."""


_ENGINE_CLASSES: tuple[tuple[str, str, str], ...] = (
    ("reference", "acoustisim.propagation.reference", "ReferenceEngine"),
    ("fast", "acoustisim.propagation.fast", "FastEngine"),
)
"""(backend name, module, class): imported on first use, so that choosing one engine does not
load the other (the fast engine's compiled kernels take a moment to load)."""


def engine_for(config: SolverConfig) -> Engine:
    """The engine ``config.backend`` names (one of :data:`~acoustisim.propagation.config.BACKENDS`)."""
    for name, module, cls in _ENGINE_CLASSES:
        if name == config.backend:
            return getattr(importlib.import_module(module), cls)()
    raise InputError(f"solver.backend = {config.backend!r}: must be one of {', '.join(BACKENDS)}")


__all__ = ["Engine", "engine_for"]
