"""Exact occlusion of straight legs by a convex object, without a ray-tracing query.

For the convex polyhedron H of face planes ``n . x <= d`` (:class:`PlaneSet`, from
:class:`~acoustisim.propagation.convex_planes.ConvexPlanes`), the line ``p + t u`` is clipped
against the planes (Cyrus and Beck 1978):

* a plane with ``n . u < 0`` is entered at ``t = (d - n . p) / (n . u)``: ``t_enter`` is the
  largest of these;
* a plane with ``n . u > 0`` is left there: ``t_exit`` is the smallest;
* a plane with ``n . u = 0`` and ``n . p > d`` keeps the whole line outside;

and the line lies inside H for ``t_enter <= t <= t_exit``. The segment ``t0 <= t <= t1`` meets
the surface, as Embree's occlusion query would report, iff that interval is not empty and
``t_enter`` or ``t_exit`` lies in ``[t0, t1]`` (a segment entirely inside the solid meets no
triangle). The answer is the exact one in float64; Embree, in float32, may differ only for
legs grazing a face, an edge or a vertex within its rounding (about 1e-6 m in a 9 m tank).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.convex_planes import ConvexPlanes


class PlaneSet(NamedTuple):
    """Face planes of a list of convex polyhedra, for the compiled loops.

    ``start`` (k + 1,) int64: polyhedron b's planes are rows ``start[b]:start[b + 1]`` (none: not
    convex); ``normal`` (n, 3) unit outward normals; ``offset`` (n,) (m). ``normal`` and
    ``offset`` have at least one row (a zero row when there are no planes), so that every
    array keeps its compiled type.
    """

    start: NDArray[np.int64]
    normal: NDArray[np.float64]
    offset: NDArray[np.float64]


def plane_set(planes: ConvexPlanes, leading_rows: int = 0) -> PlaneSet:
    """``planes`` as a :class:`PlaneSet`, with ``leading_rows`` empty polyhedra before its objects."""
    start = np.concatenate([np.zeros(leading_rows, dtype=np.int64), planes.start]).astype(np.int64)
    normal = planes.normal if planes.normal.shape[0] else np.zeros((1, 3))
    offset = planes.offset if planes.offset.shape[0] else np.zeros(1)
    return PlaneSet(start, np.ascontiguousarray(normal, dtype=float), np.ascontiguousarray(offset, dtype=float))


@njit(cache=True, nogil=True, error_model="numpy")
def segment_crosses_convex(start: tuple[float, float, float], unit: tuple[float, float, float], t0: float,
                           t1: float, planes: PlaneSet, row: int) -> bool:
    """Whether the segment ``start + t unit``, ``t0 <= t <= t1``, meets the surface of
    polyhedron ``row`` of ``planes`` (see the module docstring).

    ``start`` (m) and ``unit`` (unit for ``t`` in metres; any length works) as (x, y, z).
    """
    px, py, pz = start
    ux, uy, uz = unit
    enter = -np.inf
    leave = np.inf
    for i in range(planes.start[row], planes.start[row + 1]):
        nx, ny, nz = planes.normal[i, 0], planes.normal[i, 1], planes.normal[i, 2]
        along = nx * ux + ny * uy + nz * uz
        room = planes.offset[i] - (nx * px + ny * py + nz * pz)  # >= 0: p inside this plane
        if along < 0.0:
            t = room / along
            if t > enter:
                enter = t
        elif along > 0.0:
            t = room / along
            if t < leave:
                leave = t
        elif room < 0.0:  # parallel and outside
            return False
        if enter > leave or enter > t1 or leave < t0:
            return False
    return (t0 <= enter <= t1) or (t0 <= leave <= t1)


__all__ = ("PlaneSet", "plane_set", "segment_crosses_convex")
