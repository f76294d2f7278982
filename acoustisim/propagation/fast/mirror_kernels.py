"""Compiled per-chain loops of the image-source method (numba, cached on disk, GIL released).

The compiled twins of :func:`acoustisim.propagation.reference.image_source.unfold` and
:func:`~acoustisim.propagation.reference.image_source.backtrace`, one loop iteration per chain:

1. :func:`unfold_chains` / :func:`unfold_reversed`: the successive images of a start point
   across a mirror sequence, and whether each image lies in front of the next mirror;
2. :func:`backtrace_one` / :func:`backtrace_chains`: the reflection points from the last image
   back to an end point, with the water-side checks of every leg and the polygon (or disc)
   test of every point (:meth:`PlanarMirrors.contains
   <acoustisim.propagation.image_source.PlanarMirrors.contains>` with its
   :class:`~acoustisim.propagation.image_source.TriangleFrames`).

Dot products are summed x + y + z as numpy sums a row of three; no ``fastmath`` (it would
reassociate sums). The kernels take :class:`MirrorArrays` and unpack it once: the private
per-chain helpers take plain arrays, because every read of a tuple's array field inside a loop
costs a reference count in numba (ten times the arithmetic of a chain).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray


from acoustisim.propagation.fast.bundles import plain_tuple_arguments
from acoustisim.propagation.image_source import INSIDE_TOLERANCE, ON_PLANE_TOLERANCE_M, PlanarMirrors


class MirrorArrays(NamedTuple):
    """The planar mirrors as the kernels read them (m mirrors, t triangles each).

    Attributes
    ----------
    point, normal : ndarray, shape (m, 3)
        A point of each plane (m) and its unit normal on the water side.
    disc_radius : ndarray, shape (m,)
        Radius (m) of a circular cap about ``point``, NaN for polygons.
    corner, edge0, edge1, d00, d01, d11, det : ndarray
        The barycentric frames of the triangles (:class:`~acoustisim.propagation.image_source.TriangleFrames`).
    surface, patch, material : ndarray of int64, shape (m,)
        Surface index, ray-caster patch label and material index of each mirror.
    on_plane_tolerance_m, inside_tolerance : float
        :data:`~acoustisim.propagation.image_source.ON_PLANE_TOLERANCE_M` and
        :data:`~acoustisim.propagation.image_source.INSIDE_TOLERANCE`.
    """

    point: NDArray[np.float64]
    normal: NDArray[np.float64]
    disc_radius: NDArray[np.float64]
    corner: NDArray[np.float64]
    edge0: NDArray[np.float64]
    edge1: NDArray[np.float64]
    d00: NDArray[np.float64]
    d01: NDArray[np.float64]
    d11: NDArray[np.float64]
    det: NDArray[np.float64]
    surface: NDArray[np.int64]
    patch: NDArray[np.int64]
    material: NDArray[np.int64]
    on_plane_tolerance_m: float
    inside_tolerance: float


def mirror_arrays(mirrors: PlanarMirrors) -> MirrorArrays:
    """The :class:`MirrorArrays` of ``mirrors``."""
    return MirrorArrays(mirrors.point, mirrors.normal, mirrors.disc_radius, *mirrors.triangle_frames, mirrors.surface,
                        mirrors.patch, mirrors.material, ON_PLANE_TOLERANCE_M, INSIDE_TOLERANCE)


@njit(cache=True, nogil=True, inline="always")
def _signed_distance(p0: float, p1: float, p2: float, point: NDArray[np.float64], normal: NDArray[np.float64],
                     m: int) -> float:
    return (p0 - point[m, 0]) * normal[m, 0] + (p1 - point[m, 1]) * normal[m, 1] + (p2 - point[m, 2]) * normal[m, 2]


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def unfold_chains(mirrors_fields: tuple, start: NDArray[np.float64], sequences: NDArray[np.int64]
                  ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Images (n, k + 1, 3) of ``start`` (n, 3) across ``sequences`` (n, k) of mirrors, and
    validity (n,): each image strictly in front of the next mirror."""
    mirrors = MirrorArrays(*mirrors_fields)
    n, k = sequences.shape
    point, normal = mirrors.point, mirrors.normal
    images = np.empty((n, k + 1, 3))
    valid = np.ones(n, dtype=np.bool_)
    for i in range(n):
        x0, x1, x2 = start[i, 0], start[i, 1], start[i, 2]
        images[i, 0, 0], images[i, 0, 1], images[i, 0, 2] = x0, x1, x2
        ok = True
        for j in range(k):
            m = sequences[i, j]
            d = _signed_distance(x0, x1, x2, point, normal, m)
            ok = ok and d > 0.0
            x0 = x0 - 2.0 * d * normal[m, 0]
            x1 = x1 - 2.0 * d * normal[m, 1]
            x2 = x2 - 2.0 * d * normal[m, 2]
            images[i, j + 1, 0], images[i, j + 1, 1], images[i, j + 1, 2] = x0, x1, x2
        valid[i] = ok
    return images, valid


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def unfold_reversed(mirrors_fields: tuple, starts: NDArray[np.float64], sequences: NDArray[np.int64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`unfold_chains` of every start point (r, 3) across every sequence (s, k) taken in
    reverse order: row ``q * r + i`` is start i across ``sequences[q, ::-1]`` (images
    (s r, k + 1, 3), validity (s r,)), without materialising the repeated rows."""
    mirrors = MirrorArrays(*mirrors_fields)
    s, k = sequences.shape
    r = starts.shape[0]
    point, normal = mirrors.point, mirrors.normal
    images = np.empty((s * r, k + 1, 3))
    valid = np.ones(s * r, dtype=np.bool_)
    for q in range(s):
        for i in range(r):
            row = q * r + i
            x0, x1, x2 = starts[i, 0], starts[i, 1], starts[i, 2]
            images[row, 0, 0], images[row, 0, 1], images[row, 0, 2] = x0, x1, x2
            ok = True
            for j in range(k):
                m = sequences[q, k - 1 - j]
                d = _signed_distance(x0, x1, x2, point, normal, m)
                ok = ok and d > 0.0
                x0 = x0 - 2.0 * d * normal[m, 0]
                x1 = x1 - 2.0 * d * normal[m, 1]
                x2 = x2 - 2.0 * d * normal[m, 2]
                images[row, j + 1, 0], images[row, j + 1, 1], images[row, j + 1, 2] = x0, x1, x2
            valid[row] = ok
    return images, valid


@njit(cache=True, nogil=True, inline="always")
def _contains(x0: float, x1: float, x2: float, m: int, point: NDArray[np.float64], disc_radius: NDArray[np.float64],
              a: NDArray[np.float64], v0: NDArray[np.float64], v1: NDArray[np.float64], d00: NDArray[np.float64],
              d01: NDArray[np.float64], d11: NDArray[np.float64], den: NDArray[np.float64], tol: float) -> bool:
    """:meth:`PlanarMirrors.contains` of one point on mirror ``m`` (the :class:`MirrorArrays`
    fields of that name)."""
    radius = disc_radius[m]
    if not math.isnan(radius):
        e0, e1, e2 = x0 - point[m, 0], x1 - point[m, 1], x2 - point[m, 2]
        return math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) <= radius * (1.0 + tol)
    for t in range(a.shape[1]):
        w0, w1, w2 = x0 - a[m, t, 0], x1 - a[m, t, 1], x2 - a[m, t, 2]
        d20 = w0 * v0[m, t, 0] + w1 * v0[m, t, 1] + w2 * v0[m, t, 2]
        d21 = w0 * v1[m, t, 0] + w1 * v1[m, t, 1] + w2 * v1[m, t, 2]
        v = (d11[m, t] * d20 - d01[m, t] * d21) / den[m, t]
        w = (d00[m, t] * d21 - d01[m, t] * d20) / den[m, t]
        u = 1.0 - v - w
        if u >= -tol and v >= -tol and w >= -tol:
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _backtrace_one(point: NDArray[np.float64], normal: NDArray[np.float64], disc_radius: NDArray[np.float64],
                   a: NDArray[np.float64], v0: NDArray[np.float64], v1: NDArray[np.float64], d00: NDArray[np.float64],
                   d01: NDArray[np.float64], d11: NDArray[np.float64], den: NDArray[np.float64], on_plane_tol: float,
                   inside_tol: float, images: NDArray[np.float64], image_row: int, sequences: NDArray[np.int64],
                   sequence_row: int, reverse: bool, c0: float, c1: float, c2: float, points: NDArray[np.float64],
                   point_row: int, first_slot: int, slot_step: int) -> bool:
    """:func:`backtrace_one` on the unpacked :class:`MirrorArrays` (``point`` .. ``inside_tol``)."""
    k = sequences.shape[1]
    ok = True
    for j in range(k - 1, -1, -1):
        m = sequences[sequence_row, k - 1 - j] if reverse else sequences[sequence_row, j]
        s0, s1, s2 = images[image_row, j + 1, 0], images[image_row, j + 1, 1], images[image_row, j + 1, 2]
        d_cur = _signed_distance(c0, c1, c2, point, normal, m)
        d_src = _signed_distance(s0, s1, s2, point, normal, m)
        ok = ok and (d_cur > -on_plane_tol) and (d_src < 0.0)
        denom = d_cur - d_src if ok else 1.0
        t = max(d_cur, 0.0) / denom
        c0 = c0 + t * (s0 - c0)
        c1 = c1 + t * (s1 - c1)
        c2 = c2 + t * (s2 - c2)
        if ok:
            ok = _contains(c0, c1, c2, m, point, disc_radius, a, v0, v1, d00, d01, d11, den, inside_tol)
        slot = first_slot + slot_step * j
        points[point_row, slot, 0], points[point_row, slot, 1], points[point_row, slot, 2] = c0, c1, c2
    return ok


@njit(cache=True, nogil=True, inline="always")
def backtrace_one(mirrors: MirrorArrays, images: NDArray[np.float64], image_row: int, sequences: NDArray[np.int64],
                  sequence_row: int, reverse: bool, c0: float, c1: float, c2: float, points: NDArray[np.float64],
                  point_row: int, first_slot: int, slot_step: int) -> bool:
    """One chain of :func:`backtrace_chains`, read and written in place.

    The chain's images are ``images[image_row]`` (k + 1, 3), its mirrors
    ``sequences[sequence_row]`` (k,) (in reverse order if ``reverse``: the chain is the
    sequence reversed); it is traced back from the end point (c0, c1, c2). The point of the
    chain's mirror j goes to ``points[point_row, first_slot + slot_step * j]``. Returns whether
    the chain is valid. (A loop over chains unpacks ``mirrors`` once and calls the private
    twin instead: see the module's note.)
    """
    (point, normal, disc_radius, a, v0, v1, d00, d01, d11, den, _, _, _, on_plane_tol, inside_tol) = mirrors
    return _backtrace_one(point, normal, disc_radius, a, v0, v1, d00, d01, d11, den, on_plane_tol, inside_tol, images,
                          image_row, sequences, sequence_row, reverse, c0, c1, c2, points, point_row, first_slot,
                          slot_step)


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def backtrace_chains(mirrors_fields: tuple, images: NDArray[np.float64], sequences: NDArray[np.int64],
                     end: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Reflection points (n, k, 3) of chains from their images (n, k + 1, 3) back to ``end``
    (n, 3), and validity (n,), as
    :func:`acoustisim.propagation.reference.image_source.backtrace` (the points of a chain
    found invalid are still computed, but its polygon tests are skipped)."""
    mirrors = MirrorArrays(*mirrors_fields)
    (point, normal, disc_radius, a, v0, v1, d00, d01, d11, den, _, _, _, on_plane_tol, inside_tol) = mirrors
    n, k = sequences.shape
    points = np.empty((n, k, 3))
    valid = np.ones(n, dtype=np.bool_)
    for i in range(n):
        valid[i] = _backtrace_one(point, normal, disc_radius, a, v0, v1, d00, d01, d11, den, on_plane_tol, inside_tol,
                                  images, i, sequences, i, False, end[i, 0], end[i, 1], end[i, 2], points, i, 0, 1)
    return points, valid


__all__ = ("MirrorArrays", "backtrace_chains", "backtrace_one", "mirror_arrays", "unfold_chains", "unfold_reversed")
