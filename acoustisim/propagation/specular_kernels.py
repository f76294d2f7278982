"""Compiled per-chain loops of the image-source method (numba, cached on disk, GIL released).

:func:`acoustisim.propagation.image_source.unfold` and
:func:`~acoustisim.propagation.image_source.backtrace` walk every candidate chain mirror by
mirror; in numpy each step is a dozen passes over temporary arrays (signed distances,
reflections, the barycentric polygon test over every triangle of every mirror), i.e. hundreds
of small calls per pose. Here each chain is one loop iteration:

1. :func:`unfold_chains`: the successive images of a start point across a mirror sequence,
   and whether each image lies in front of the next mirror;
2. :func:`backtrace_chains`: the reflection points from the last image back to an end point,
   with the water-side checks of every leg and the polygon (or disc) test of every point.

The arithmetic is numpy's, term for term and in the same order (dot products summed
x + y + z, the barycentric formula of :meth:`PlanarMirrors.contains` with its precomputed
pose-independent frame), so the results equal the numpy expressions' to the last bit or
within an ulp; no ``fastmath`` (it would reassociate sums). ``cache=True`` stores the compiled
code beside this file: the first call in a fresh checkout compiles for a few seconds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True)
def _signed_distance(p0: float, p1: float, p2: float, point: NDArray[np.float64], normal: NDArray[np.float64],
                     m: int) -> float:
    return (p0 - point[m, 0]) * normal[m, 0] + (p1 - point[m, 1]) * normal[m, 1] + (p2 - point[m, 2]) * normal[m, 2]


@njit(cache=True, nogil=True)
def unfold_chains(point: NDArray[np.float64], normal: NDArray[np.float64], start: NDArray[np.float64],
                  sequences: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Images (n, k + 1, 3) of ``start`` (n, 3) across ``sequences`` (n, k) of mirrors with
    planes (``point``, unit ``normal``) (m, 3), and validity (n,): each image strictly in front
    of the next mirror. See :func:`acoustisim.propagation.image_source.unfold`."""
    n, k = sequences.shape
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


@njit(cache=True, nogil=True)
def _contains(x0: float, x1: float, x2: float, m: int, point: NDArray[np.float64],
              disc_radius: NDArray[np.float64], a: NDArray[np.float64], v0: NDArray[np.float64],
              v1: NDArray[np.float64], d00: NDArray[np.float64], d01: NDArray[np.float64],
              d11: NDArray[np.float64], den: NDArray[np.float64], tol: float) -> bool:
    """:meth:`PlanarMirrors.contains` of one point on mirror ``m``."""
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


@njit(cache=True, nogil=True)
def backtrace_chains(point: NDArray[np.float64], normal: NDArray[np.float64], disc_radius: NDArray[np.float64],
                     a: NDArray[np.float64], v0: NDArray[np.float64], v1: NDArray[np.float64],
                     d00: NDArray[np.float64], d01: NDArray[np.float64], d11: NDArray[np.float64],
                     den: NDArray[np.float64], images: NDArray[np.float64], sequences: NDArray[np.int64],
                     end: NDArray[np.float64], on_plane_tol: float, inside_tol: float
                     ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Reflection points (n, k, 3) of chains from their images (n, k + 1, 3) back to ``end``
    (n, 3), and validity (n,). See :func:`acoustisim.propagation.image_source.backtrace`
    (same tests in the same order; the points of a chain found invalid are still computed,
    as there, but its polygon tests are skipped).

    ``a``, ``v0``, ``v1`` (m, t, 3) and ``d00``, ``d01``, ``d11``, ``den`` (m, t): the
    barycentric frames of the mirrors' triangles (``PlanarMirrors._barycentric_frames``).
    """
    n, k = sequences.shape
    points = np.empty((n, k, 3))
    valid = np.ones(n, dtype=np.bool_)
    for i in range(n):
        c0, c1, c2 = end[i, 0], end[i, 1], end[i, 2]
        ok = True
        for j in range(k - 1, -1, -1):
            m = sequences[i, j]
            s0, s1, s2 = images[i, j + 1, 0], images[i, j + 1, 1], images[i, j + 1, 2]
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
            points[i, j, 0], points[i, j, 1], points[i, j, 2] = c0, c1, c2
        valid[i] = ok
    return points, valid





@njit(cache=True, nogil=True)
def circle_newton(ax: NDArray[np.float64], ay: NDArray[np.float64], bx: NDArray[np.float64],
                  by: NDArray[np.float64], rad: NDArray[np.float64], phi: NDArray[np.float64],
                  max_steps: int, tol: float) -> NDArray[np.float64]:
    """Newton's method on the angle ``phi`` (n,) of the specular point on circles of radius
    ``rad`` (n,) centred at the origin, for sources (ax, ay) and receivers (bx, by) (n,), in
    place and returned.

    The loop of :func:`acoustisim.propagation.curved.circle_specular_point`, step for step:
    every row takes every step until no row's step exceeds ``tol`` (rad), at most
    ``max_steps`` steps; each step clipped to +-0.5 rad.
    """
    n = phi.shape[0]
    for _ in range(max_steps):
        moving = False
        for i in range(n):
            r = rad[i]
            c, s = math.cos(phi[i]), math.sin(phi[i])
            xx, xy = r * c, r * s
            dax, day, dbx, dby = ax[i] - xx, ay[i] - xy, bx[i] - xx, by[i] - xy
            ra, rb = math.hypot(dax, day), math.hypot(dbx, dby)
            rpa = -r * (-dax * s + day * c) / ra
            rpb = -r * (-dbx * s + dby * c) / rb
            d1 = rpa + rpb
            r2 = r * r
            d2 = (r2 + dax * xx + day * xy - rpa * rpa) / ra + (r2 + dbx * xx + dby * xy - rpb * rpb) / rb
            step = d1 / (d2 if abs(d2) > 1e-300 else 1e-300)
            if step < -0.5:
                step = -0.5
            elif step > 0.5:
                step = 0.5
            phi[i] = phi[i] - step
            if abs(step) > tol:
                moving = True
        if not moving:
            break
    return phi

__all__ = ["backtrace_chains", "circle_newton", "unfold_chains"]
