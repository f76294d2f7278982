"""Candidate specular chains of one order, before occlusion: the reference engine's working set.

A chain is transmitter -> k reflection points -> receiver. :mod:`.image_source` builds the
planar ones, :mod:`.specular` the chains through one curved surface; :mod:`.specular` then
tests their legs for occlusion, multiplies in the reflection coefficients and writes the rows.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Chains:
    """Chains of one order k (n of them).

    Attributes
    ----------
    vertices : ndarray, shape (n, k + 2, 3)
        Transmitter, the k reflection points in path order, receiver (m).
    surface : ndarray of int64, shape (n, k)
        Index into ``scene.surface_names`` of each reflection.
    patch : ndarray of int64, shape (n, k)
        The ray caster's patch label at each reflection (ignored by the legs ending there).
    normal : ndarray, shape (n, k, 3)
        Unit surface normal (water side) at each reflection.
    material : ndarray of int64, shape (n, k)
        Each reflection's material, as an index into the solve's material table
        (:func:`acoustisim.propagation.reference.specular.material_table`).
    length : ndarray, shape (n,)
        Path length (m).
    spreading : ndarray, shape (n,)
        Pressure factor without the reflection coefficients (relative to the source at 1 m).
    phase : ndarray, shape (n,)
        Extra phase of the stationary point (rad, engineering convention of ``phase_rad``):
        0 but on saddles and focusing concave patches of smooth meshes.
    channel : ndarray of int64, shape (n,)
        Receiver.
    chain : ndarray of int64, shape (n,)
        Chain number, shared by the receivers of one geometric chain (the rows' ``path_id``
        relative to the mechanism's first id).
    """

    vertices: NDArray[np.float64]
    surface: NDArray[np.int64]
    patch: NDArray[np.int64]
    normal: NDArray[np.float64]
    material: NDArray[np.int64]
    length: NDArray[np.float64]
    spreading: NDArray[np.float64]
    phase: NDArray[np.float64]
    channel: NDArray[np.int64]
    chain: NDArray[np.int64]

    @property
    def order(self) -> int:
        """Reflections per chain (k)."""
        return int(self.surface.shape[1])

    @property
    def count(self) -> int:
        """Number of chains (n)."""
        return int(self.length.shape[0])

    def select(self, rows: NDArray[np.intp] | NDArray[np.bool_]) -> "Chains":
        """The chains ``rows`` (indices or a mask)."""
        return Chains(**{f.name: getattr(self, f.name)[rows] for f in fields(self)})


__all__ = ("Chains",)
