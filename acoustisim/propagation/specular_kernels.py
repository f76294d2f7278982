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


@njit(cache=True, nogil=True, inline="always")
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
def unfold_reversed(point: NDArray[np.float64], normal: NDArray[np.float64], starts: NDArray[np.float64],
                    sequences: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`unfold_chains` of every start point (r, 3) across every sequence (s, k) taken in
    reverse order: row ``q * r + i`` is start i across ``sequences[q, ::-1]`` (images
    (s r, k + 1, 3), validity (s r,)), without materialising the repeated rows."""
    s, k = sequences.shape
    r = starts.shape[0]
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


@njit(cache=True, nogil=True, inline="always")
def backtrace_one(point: NDArray[np.float64], normal: NDArray[np.float64], disc_radius: NDArray[np.float64],
                  a: NDArray[np.float64], v0: NDArray[np.float64], v1: NDArray[np.float64],
                  d00: NDArray[np.float64], d01: NDArray[np.float64], d11: NDArray[np.float64],
                  den: NDArray[np.float64], images: NDArray[np.float64], image_row: int,
                  sequences: NDArray[np.int64], sequence_row: int, reverse: bool, c0: float, c1: float, c2: float,
                  on_plane_tol: float, inside_tol: float, points: NDArray[np.float64], point_row: int,
                  first_slot: int, slot_step: int) -> bool:
    """One chain of :func:`backtrace_chains`, read and written in place (no array views: they
    would cost reference counting in the loops that call this).

    The chain's images are ``images[image_row]`` (k + 1, 3), its mirrors
    ``sequences[sequence_row]`` (k,) (in reverse order if ``reverse``: the chain is the
    sequence reversed); it is traced back from the end point (c0, c1, c2). The point of the
    chain's mirror j goes to ``points[point_row, first_slot + slot_step * j]``. Returns whether
    the chain is valid.
    """
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
        valid[i] = backtrace_one(point, normal, disc_radius, a, v0, v1, d00, d01, d11, den, images, i, sequences, i,
                                 False, end[i, 0], end[i, 1], end[i, 2], on_plane_tol, inside_tol, points, i, 0, 1)
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

    A row whose step left its angle unchanged has reached a fixed point: every later step
    would be the same (computed from the same angle), again leave it unchanged, and not exceed
    ``tol`` (it is below an ulp of the angle, <= 4e-15 rad for |phi| < 20), so the row is not
    computed any more. The result is bit-for-bit that of stepping every row.
    """
    active = np.arange(phi.shape[0])
    n_active = active.shape[0]
    for _ in range(max_steps):
        moving = False
        kept = 0
        for q in range(n_active):
            i = active[q]
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
            updated = phi[i] - step
            if updated != phi[i]:  # (NaN stays active)
                active[kept] = i
                kept += 1
            phi[i] = updated
            if abs(step) > tol:
                moving = True
        n_active = kept
        if not moving:
            break
    return phi


@njit(cache=True, nogil=True)
def _norm3(x0: float, x1: float, x2: float) -> float:
    return math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)


@njit(cache=True, nogil=True)
def primitive_specular_points(is_sphere: NDArray[np.bool_], centre: NDArray[np.float64], frame: NDArray[np.float64],
                              radius: NDArray[np.float64], length: NDArray[np.float64], which: NDArray[np.int64],
                              a: NDArray[np.float64], b: NDArray[np.float64], max_steps: int, tol: float
                              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_],
                                         NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                                         NDArray[np.float64]]:
    """:func:`acoustisim.propagation.curved.specular_points` on the arrays of a ``CurvedSet``
    (``is_sphere``, ``centre``, ``frame``, ``radius``, ``length``), for sources ``a`` and
    receivers ``b`` (n, 3) on primitives ``which`` (n,): the same formulas in the same order,
    the Newton steps of :func:`circle_newton` (all rows step until none moves). Returns point,
    normal, valid, e1, e2, k1, k2.
    """
    n = which.shape[0]
    ax, ay = np.empty(n), np.empty(n)
    bx, by = np.empty(n), np.empty(n)
    rad = np.empty(n)
    phi = np.empty(n)
    na, nb = np.empty(n), np.empty(n)
    degenerate = np.empty(n, dtype=np.bool_)
    p_ax, q_ax = np.empty((n, 3)), np.empty((n, 3))
    za, zb = np.empty(n), np.empty(n)
    for i in range(n):
        r = which[i]
        sph = is_sphere[r]
        rad[i] = radius[r]
        u0, u1, u2 = a[i, 0] - centre[r, 0], a[i, 1] - centre[r, 1], a[i, 2] - centre[r, 2]
        v0, v1, v2 = b[i, 0] - centre[r, 0], b[i, 1] - centre[r, 1], b[i, 2] - centre[r, 2]
        if sph:
            nu = _norm3(u0, u1, u2)
            e0, e1, e2 = u0 / nu, u1 / nu, u2 / nu
            dv = v0 * e0 + v1 * e1 + v2 * e2
            w0, w1, w2 = v0 - dv * e0, v1 - dv * e1, v2 - dv * e2
            if not _norm3(w0, w1, w2) > 1e-12 * _norm3(v0, v1, v2):
                # collinear centre, source and receiver: any plane through the line will do
                h0, h1 = (1.0, 0.0) if abs(e0) < 0.9 else (0.0, 1.0)
                w0, w1, w2 = e1 * 0.0 - e2 * h1, e2 * h0 - e0 * 0.0, e0 * h1 - e1 * h0
            nw = _norm3(w0, w1, w2)
            p_ax[i, 0], p_ax[i, 1], p_ax[i, 2] = e0, e1, e2
            q_ax[i, 0], q_ax[i, 1], q_ax[i, 2] = w0 / nw, w1 / nw, w2 / nw
        else:
            for k in range(3):
                p_ax[i, k] = frame[r, 0, k]
                q_ax[i, k] = frame[r, 1, k]
        ax[i] = u0 * p_ax[i, 0] + u1 * p_ax[i, 1] + u2 * p_ax[i, 2]
        ay[i] = u0 * q_ax[i, 0] + u1 * q_ax[i, 1] + u2 * q_ax[i, 2]
        bx[i] = v0 * p_ax[i, 0] + v1 * p_ax[i, 1] + v2 * p_ax[i, 2]
        by[i] = v0 * q_ax[i, 0] + v1 * q_ax[i, 1] + v2 * q_ax[i, 2]
        za[i] = u0 * frame[r, 2, 0] + u1 * frame[r, 2, 1] + u2 * frame[r, 2, 2]
        zb[i] = v0 * frame[r, 2, 0] + v1 * frame[r, 2, 1] + v2 * frame[r, 2, 2]
        na[i], nb[i] = math.hypot(ax[i], ay[i]), math.hypot(bx[i], by[i])
        sx, sy = ax[i] / na[i] + bx[i] / nb[i], ay[i] / na[i] + by[i] / nb[i]
        # opposite directions (forward scatter): no lit stationary point; keep phi finite
        degenerate[i] = math.hypot(sx, sy) <= 1e-12
        phi[i] = math.atan2(ay[i], ax[i]) if degenerate[i] else math.atan2(sy, sx)
    circle_newton(ax, ay, bx, by, rad, phi, max_steps, tol)
    point, normal = np.empty((n, 3)), np.empty((n, 3))
    e1_out, e2_out = np.empty((n, 3)), np.empty((n, 3))
    k1, k2 = np.empty(n), np.empty(n)
    valid = np.empty(n, dtype=np.bool_)
    for i in range(n):
        r = which[i]
        sph = is_sphere[r]
        c, s = math.cos(phi[i]), math.sin(phi[i])
        x0, x1 = rad[i] * c, rad[i] * s
        ok = ((ax[i] - x0) * c + (ay[i] - x1) * s > 0.0) and ((bx[i] - x0) * c + (by[i] - x1) * s > 0.0)
        ok = ok and (na[i] > rad[i]) and (nb[i] > rad[i]) and not degenerate[i]
        # cylinders: lift along the axis where the unrolled path is straight
        da0, da1 = ax[i] - x0, ay[i] - x1
        db0, db1 = bx[i] - x0, by[i] - x1
        rho_a = math.sqrt(da0 * da0 + da1 * da1)
        rho_b = math.sqrt(db0 * db0 + db1 * db1)
        if sph:
            z = 0.0
        else:
            z = za[i] + (zb[i] - za[i]) * rho_a / (rho_a + rho_b if rho_a + rho_b > 0 else 1.0)
            ok = ok and abs(z) <= 0.5 * length[r] + 1e-9
        valid[i] = ok
        m0 = x0 * p_ax[i, 0] + x1 * q_ax[i, 0]
        m1 = x0 * p_ax[i, 1] + x1 * q_ax[i, 1]
        m2 = x0 * p_ax[i, 2] + x1 * q_ax[i, 2]
        nm = _norm3(m0, m1, m2)
        n0, n1, n2 = m0 / nm, m1 / nm, m2 / nm
        normal[i, 0], normal[i, 1], normal[i, 2] = n0, n1, n2
        g0, g1, g2 = (0.0, 0.0, 0.0) if sph else (frame[r, 2, 0], frame[r, 2, 1], frame[r, 2, 2])
        point[i, 0] = centre[r, 0] + rad[i] * n0 + z * g0
        point[i, 1] = centre[r, 1] + rad[i] * n1 + z * g1
        point[i, 2] = centre[r, 2] + rad[i] * n2 + z * g2
        # principal directions: cylinder (around, along); sphere any tangent pair
        if sph:
            h0, h1 = (1.0, 0.0) if abs(n0) < 0.9 else (0.0, 1.0)
            t0, t1, t2 = n1 * 0.0 - n2 * h1, n2 * h0 - n0 * 0.0, n0 * h1 - n1 * h0
        else:
            f0, f1, f2 = frame[r, 2, 0], frame[r, 2, 1], frame[r, 2, 2]
            t0, t1, t2 = f1 * n2 - f2 * n1, f2 * n0 - f0 * n2, f0 * n1 - f1 * n0
        nt = _norm3(t0, t1, t2)
        t0, t1, t2 = t0 / nt, t1 / nt, t2 / nt
        e1_out[i, 0], e1_out[i, 1], e1_out[i, 2] = t0, t1, t2
        if sph:
            e2_out[i, 0], e2_out[i, 1], e2_out[i, 2] = n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0
        else:
            e2_out[i, 0], e2_out[i, 1], e2_out[i, 2] = frame[r, 2, 0], frame[r, 2, 1], frame[r, 2, 2]
        k1[i] = 1.0 / rad[i]
        k2[i] = 1.0 / rad[i] if sph else 0.0
    return point, normal, valid, e1_out, e2_out, k1, k2



@njit(cache=True, nogil=True)
def incidence_cosines(vertices: NDArray[np.float64], normals: NDArray[np.float64],
                      order: NDArray[np.int64]) -> NDArray[np.float64]:
    """|cos| of the incidence angle (n, k) at each interaction of chains of ``order`` (n,)
    (<= k) interactions with ``vertices`` (n, k + 2, 3) (transmitter, the interaction points,
    receiver, padding) and unit ``normals`` (n, k, 3); 1 at padded slots.

    A zero-length leg (<= 1e-12 m: two reflections on a corner line) arrives along the previous
    direction mirrored by the previous surface.
    """
    n, k = normals.shape[0], normals.shape[1]
    out = np.ones((n, k))
    for i in range(n):
        p0, p1, p2 = 0.0, 0.0, 0.0
        for j in range(order[i]):
            l0 = vertices[i, j + 1, 0] - vertices[i, j, 0]
            l1 = vertices[i, j + 1, 1] - vertices[i, j, 1]
            l2 = vertices[i, j + 1, 2] - vertices[i, j, 2]
            norm = _norm3(l0, l1, l2)
            scale = norm if norm > 0 else 1.0
            c0, c1, c2 = l0 / scale, l1 / scale, l2 / scale
            if j > 0 and not norm > 1e-12:
                m0, m1, m2 = normals[i, j - 1, 0], normals[i, j - 1, 1], normals[i, j - 1, 2]
                d = p0 * m0 + p1 * m1 + p2 * m2
                c0, c1, c2 = p0 - 2.0 * d * m0, p1 - 2.0 * d * m1, p2 - 2.0 * d * m2
            p0, p1, p2 = c0, c1, c2
            out[i, j] = abs(c0 * normals[i, j, 0] + c1 * normals[i, j, 1] + c2 * normals[i, j, 2])
    return out


@njit(cache=True, nogil=True, inline="always")
def _dot3(u0: float, u1: float, u2: float, v0: float, v1: float, v2: float) -> float:
    """u . v summed as ``np.einsum("ij,ij->i", u, v)`` sums 3 terms: (x + z) + y."""
    return (u0 * v0 + u2 * v2) + u1 * v1


@njit(cache=True, nogil=True)
def go_factors(rows: NDArray[np.int64], a: NDArray[np.float64], b: NDArray[np.float64], x: NDArray[np.float64],
               normal: NDArray[np.float64], e1: NDArray[np.float64], e2: NDArray[np.float64],
               k11: NDArray[np.float64], k22: NDArray[np.float64], k12: NDArray[np.float64]
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`acoustisim.propagation.curved.go_amplitude_general` (amplitude and phase (r,)) of
    the ``rows`` (r,) of (image) sources ``a``, receivers ``b``, specular points ``x``, normals
    and tangent bases (n, 3) and curvature tensors (n,): the same formulas, term for term
    (norms summed x + y + z as ``np.linalg.norm``, dot products (x + z) + y as ``np.einsum``)."""
    n = rows.shape[0]
    amplitude = np.empty(n)
    phase = np.empty(n)
    quarter = -(math.pi / 4.0)
    for out in range(n):
        i = rows[out]
        p0, p1, p2 = x[i, 0] - a[i, 0], x[i, 1] - a[i, 1], x[i, 2] - a[i, 2]
        q0, q1, q2 = x[i, 0] - b[i, 0], x[i, 1] - b[i, 1], x[i, 2] - b[i, 2]
        r1 = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        r2 = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
        s0, s1, s2 = p0 / r1, p1 / r1, p2 / r1
        t0, t1, t2 = q0 / r2, q1 / r2, q2 / r2
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        cos_i = abs(_dot3(s0, s1, s2, n0, n1, n2))
        cos_s = abs(_dot3(t0, t1, t2, n0, n1, n2))
        a1 = _dot3(e1[i, 0], e1[i, 1], e1[i, 2], s0, s1, s2)
        a2 = _dot3(e2[i, 0], e2[i, 1], e2[i, 2], s0, s1, s2)
        b1 = _dot3(e1[i, 0], e1[i, 1], e1[i, 2], t0, t1, t2)
        b2 = _dot3(e2[i, 0], e2[i, 1], e2[i, 2], t0, t1, t2)
        c = cos_i + cos_s
        h11 = (1.0 - a1 * a1) / r1 + (1.0 - b1 * b1) / r2 + c * k11[i]
        h22 = (1.0 - a2 * a2) / r1 + (1.0 - b2 * b2) / r2 + c * k22[i]
        h12 = -a1 * a2 / r1 - b1 * b2 / r2 + c * k12[i]
        det = h11 * h22 - h12 * h12
        trace = h11 + h22
        signature = 0 if det < 0 else (2 if trace > 0 else -2)
        amplitude[out] = cos_i / (r1 * r2 * math.sqrt(abs(det)))
        phase[out] = quarter * (signature - 2)
    return amplitude, phase


@njit(cache=True, nogil=True)
def sequences_between(sequences: NDArray[np.int64], first: NDArray[np.bool_],
                      last: NDArray[np.bool_]) -> NDArray[np.int64]:
    """The rows (in order) of ``sequences`` (s, k >= 1) whose first mirror is allowed by
    ``first`` (m,) and last by ``last`` (m,)."""
    s, k = sequences.shape
    out = np.empty((s, k), dtype=np.int64)
    n = 0
    for i in range(s):
        if first[sequences[i, 0]] and last[sequences[i, k - 1]]:
            for j in range(k):
                out[n, j] = sequences[i, j]
            n += 1
    return out[:n].copy()


__all__ = ["backtrace_chains", "backtrace_one", "circle_newton", "go_factors", "incidence_cosines",
           "primitive_specular_points", "sequences_between", "unfold_chains",
           "unfold_reversed"]
