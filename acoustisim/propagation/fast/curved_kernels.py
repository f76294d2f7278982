"""Compiled specular points on spheres and cylinders and their geometric-optics factors (numba).

The compiled twins of :func:`acoustisim.propagation.reference.curved.specular_points` and
:func:`~acoustisim.propagation.reference.curved.go_amplitude`: the same formulas in the same
order, one loop iteration per candidate (norms summed x + y + z as ``np.linalg.norm``, dot
products (x + z) + y as ``np.einsum``). :func:`circle_newton` stops stepping a row once a step
leaves its angle unchanged (every later step would be the same), which gives the result of
stepping every row until none moves. No ``fastmath``. Division follows IEEE (``error_model="numpy"``),
as in numpy: a degenerate pair (an end on a cylinder's axis line, a start on the axis of an image
of the same cylinder) gives NaN and an invalid point, not an exception.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.fast.bundles import plain_tuple_arguments
from acoustisim.propagation.curved import (CYLINDER_END_TOLERANCE_M, NEWTON_STEPS, NEWTON_TOLERANCE_RAD, CurvedSet,
                                          SurfacePoints)


@njit(cache=True, nogil=True, error_model="numpy")
def circle_newton(ax: NDArray[np.float64], ay: NDArray[np.float64], bx: NDArray[np.float64],
                  by: NDArray[np.float64], rad: NDArray[np.float64], phi: NDArray[np.float64],
                  max_steps: int, tol: float) -> NDArray[np.float64]:
    """Newton's method on the angle ``phi`` (n,) of the specular point on circles of radius
    ``rad`` (n,) centred at the origin, for sources (ax, ay) and receivers (bx, by) (n,), in
    place and returned.

    The loop of :func:`acoustisim.propagation.reference.curved.circle_specular_point`, step for step:
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


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def primitive_specular_points(curved_fields: tuple, which: NDArray[np.int64], a: NDArray[np.float64],
                              b: NDArray[np.float64], max_steps: int, tol: float, end_tolerance: float
                              ) -> SurfacePoints:
    """:func:`acoustisim.propagation.reference.curved.specular_points` of sources ``a`` and
    receivers ``b`` (n, 3) on the primitives ``which`` (n,) of ``curved``: the same formulas in
    the same order, the Newton steps of :func:`circle_newton` (at most ``max_steps``, until no
    step exceeds ``tol``); a cylinder's point may lie ``end_tolerance`` (m) beyond its ends.
    """
    curved = CurvedSet(*curved_fields)
    is_sphere, centre, frame, radius, length = curved
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
            ok = ok and abs(z) <= 0.5 * length[r] + end_tolerance
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
    return SurfacePoints(point, normal, valid, e1_out, e2_out, k1, k2, np.zeros(n))


def specular_points(curved: CurvedSet, which: NDArray[np.int64], a: NDArray[np.float64],
                    b: NDArray[np.float64]) -> SurfacePoints:
    """:func:`primitive_specular_points` with the shared Newton and end tolerances."""
    return primitive_specular_points(curved, np.ascontiguousarray(which, dtype=np.int64),
                                     np.ascontiguousarray(a, dtype=float), np.ascontiguousarray(b, dtype=float),
                                     NEWTON_STEPS, NEWTON_TOLERANCE_RAD, CYLINDER_END_TOLERANCE_M)



@njit(cache=True, nogil=True, inline="always")
def _dot3(u0: float, u1: float, u2: float, v0: float, v1: float, v2: float) -> float:
    """u . v summed as ``np.einsum("ij,ij->i", u, v)`` sums 3 terms: (x + z) + y."""
    return (u0 * v0 + u2 * v2) + u1 * v1


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def go_factors(rows: NDArray[np.int64], a: NDArray[np.float64], b: NDArray[np.float64], surface_fields: tuple
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`acoustisim.propagation.reference.curved.go_amplitude` (amplitude and phase (r,)) of
    the ``rows`` (r,) of (image) sources ``a``, receivers ``b`` (n, 3) and their specular
    points ``surface`` (n of them), without gathering them first."""
    surface = SurfacePoints(*surface_fields)
    x, normal, e1, e2 = surface.point, surface.normal, surface.e1, surface.e2
    k11, k22, k12 = surface.k11, surface.k22, surface.k12
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


__all__ = ("circle_newton", "go_factors", "primitive_specular_points", "specular_points")
