"""The fast engine: the reference engine's rows from compiled kernels, screens and reused buffers.

Every function here computes what its namesake in :mod:`acoustisim.propagation.reference`
computes (the parity suite, ``tests/parity``, holds them to it); read the reference module for
the physics. What this package adds is speed: numba kernels over rows, geometric screens that
decide most occlusion queries without Embree, and buffers reused across a solve.

Its edge modules: :mod:`.edges` (orchestration and rows, first-order and combined with
reflections), :mod:`.edge_elements`, :mod:`.edge_gains`, :mod:`.edge_visibility`,
:mod:`.edge_order` and :mod:`.edge_reflections` (the per-element kernels of the reflected paths,
a leg screen for legs touching the tank's boundaries). Its specular, direct and assembly
modules: :mod:`.direct`, :mod:`.specular` (orchestration) over :mod:`.mirror_kernels` (image
sources), :mod:`.curved_kernels` (specular points on primitives, geometric-optics factors) and
:mod:`.chain_kernels` (candidate chains, legs, duplicate keys, rows); :mod:`.columns`, :mod:`.floor` with :mod:`.floor_kernels`, and
:mod:`.assemble`. Kernels take typed bundles (NamedTuples), passed across the numba boundary
as plain tuples (:mod:`.bundles`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from numpy.typing import NDArray

from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.prepared import PreparedScene


class FastEngine:
    """The compiled engine (``SolverConfig(backend="fast")``, the default)."""

    name = "fast"

    def direct_rows(self, context: SolveContext) -> NDArray[Any]:
        from acoustisim.propagation.fast.direct import direct_rows

        return direct_rows(context)

    def specular_rows(self, context: SolveContext, prepared: PreparedScene, max_order: int,
                      max_curved_per_path: int) -> NDArray[Any]:
        from acoustisim.propagation.fast.specular import specular_rows

        return specular_rows(context, prepared, max_order, max_curved_per_path)

    def edge_rows(self, context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> NDArray[Any]:
        from acoustisim.propagation.fast.edges import edge_rows

        return edge_rows(context, config, prepared)

    def diffuse_rows(self, context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> NDArray[Any]:
        from acoustisim.propagation.fast.diffuse import diffuse_rows

        return diffuse_rows(context, config)

    def assemble_rows(self, parts: Sequence[NDArray[Any]], context: SolveContext, config: SolverConfig
                      ) -> NDArray[Any]:
        from acoustisim.propagation.fast.assemble import assemble_rows

        return assemble_rows(parts, context, config.amplitude_floor_db, config.amplitude_floor_band_hz)


__all__ = ["FastEngine"]
