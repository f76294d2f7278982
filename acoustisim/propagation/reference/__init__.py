"""The reference engine: one plain-numpy module per mechanism, each reading like its equations.

Modules, each opening with its Physics (equations and sources), Method and Accuracy:

* :mod:`.direct`: the direct path;
* :mod:`.specular`: specular chains of planar mirrors and up to two curved surfaces, their
  occlusion, duplicates and reflection coefficients, built on :mod:`.image_source` (image
  sources, unfolding and back-tracing on planar mirrors), :mod:`.curved` (specular points on
  spheres and cylinders, the geometric-optics amplitude), :mod:`.curved_pairs` and
  :mod:`.pair_chains` (paths reflected by two curved primitives: joint specular points,
  ray-tube amplitude, the candidate chains) and :mod:`.chains` (the candidate chains);
* :mod:`.edges`: edge diffraction (Biot-Tolstoy-Medwin line integral; the wedge formulas and
  the quadrature in :mod:`.btm`, the discretisation in :mod:`.edge_elements`), and with
  :mod:`.edge_reflections` the edges combined with reflections (image method, curved
  reflectors at each element's specular point), the two joined under one floor by
  :mod:`.edge_paths`;
* :mod:`.diffuse`: Lambert diffuse reverberation (Monte Carlo, counter-based random numbers);
* :mod:`.floor`: the amplitude floor;
* :mod:`.columns`: the derived columns and the solve's assembled rows.

The shadows of smooth obstacles (:mod:`acoustisim.propagation.shadows`) are one
engine-independent step after the mechanisms.

Occlusion is asked of Embree in batches (:class:`~acoustisim.propagation.raycast.RayCaster`);
everything else is numpy. The fast engine (:mod:`acoustisim.propagation.fast`) computes the
same rows; the parity suite (``tests/parity``) holds it to this one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from numpy.typing import NDArray

from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.prepared import PreparedScene


class ReferenceEngine:
    """The readable engine (``SolverConfig(backend="reference")``)."""

    name = "reference"

    def direct_rows(self, context: SolveContext) -> NDArray[Any]:
        from acoustisim.propagation.reference.direct import direct_rows

        return direct_rows(context)

    def specular_rows(self, context: SolveContext, prepared: PreparedScene, max_order: int,
                      max_curved_per_path: int) -> NDArray[Any]:
        from acoustisim.propagation.reference.specular import specular_rows

        return specular_rows(context, prepared, max_order, max_curved_per_path)

    def edge_rows(self, context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> NDArray[Any]:
        from acoustisim.propagation.reference.edge_paths import edge_rows

        return edge_rows(context, config, prepared)

    def diffuse_rows(self, context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> NDArray[Any]:
        from acoustisim.propagation.reference.diffuse import diffuse_rows

        return diffuse_rows(context, config, prepared)

    def assemble_rows(self, parts: Sequence[NDArray[Any]], context: SolveContext, config: SolverConfig
                      ) -> NDArray[Any]:
        from acoustisim.propagation.reference.columns import assemble_rows

        return assemble_rows(parts, context, config.amplitude_floor_db, config.amplitude_floor_band_hz)


__all__ = ["ReferenceEngine"]
