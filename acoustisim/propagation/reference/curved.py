"""Specular points on curved surfaces and their geometric-optics amplitude.

Physics
-------
A curved surface reflects from its specular point X, where the path A -> X -> B from (image)
source A to (image) receiver B is stationary (Fermat): the surface normal bisects the
directions to A and B. In the Kirchhoff approximation evaluated by stationary phase
(physics.md section 3) the echo's pressure factor, relative to the source's pressure at 1 m, is

    |p| = |R| cos(theta_i) / (r1 r2 sqrt|det H|),
    H = (I - a a^T) / r1 + (I - b b^T) / r2 + (cos theta_i + cos theta_s) K,

in an orthonormal tangent basis (e1, e2) at X: r1 = |X - A|, r2 = |X - B|, s1, s2 the unit
vectors A -> X and B -> X, a_j = e_j . s1, b_j = e_j . s2, cos theta_i = |s1 . n|,
cos theta_s = |s2 . n|, K the curvature tensor (convex > 0; sphere I / a, cylinder
diag(1/a, 0) across / along the axis). For a plane (K = 0) at normal incidence it is
1 / (r1 + r2), the image source; for a sphere of radius a seen monostatically at range r,
a / (2 r (r + a)); for an infinite cylinder sqrt(a / (a + r)) / (2 r). The stationary point's
signature sig(H) adds the phase exp(i pi (sig - 2) / 4) relative to a mirror (0 for a minimum,
pi / 2 for a saddle, pi for a maximum: a concave patch beyond its focus); in the engineering
convention of ``Paths.phase_rad`` that is -(pi / 4)(sig - 2). Plane mirrors earlier or later in
a chain keep the wavefront's curvature, so A and B are the unfolded images and r1, r2 the
unfolded lengths.

Method
------
Sphere: by symmetry X lies in the plane of the centre, A and B; in that plane it is the
stationary point of |A - X| + |X - B| on a circle (Alhazen's problem), solved by Newton's
method on the angle from the centre (:func:`circle_specular_point`). Cylinder (finite, axis e_z
of its own frame): the circle problem of A and B projected on the plane normal to the axis; X
then rises along the axis where the unrolled path is straight,
z_X = z_A + (z_B - z_A) rho_A / (rho_A + rho_B), and must lie within the finite length. The
amplitude is the formula above (:func:`go_amplitude`). Smooth meshes solve for X on their
interpolated normals (:meth:`acoustisim.propagation.smooth_mesh.SmoothMesh.specular_points`)
and use the same amplitude with their full curvature tensor.

Accuracy
--------
Geometric optics neglects terms of order 1 / (k a): against a brute-force Kirchhoff integral at
500 kHz it agrees to 7e-5 (sphere, ka = 106) and 1.3e-4 (cylinder, ka = 212)
(``tests/physics/test_propagation_curved.py``); creeping waves and the cylinder's end
diffraction are not modelled. Newton stops once every step is below 1e-10 rad (quadratic
convergence leaves ~1e-20 rad). A point within 1e-9 m beyond a cylinder's end still counts as
on it (a post meeting the free surface or the floor at a right angle reflects a monostatic
double bounce exactly at the junction).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.curved import (CYLINDER_END_TOLERANCE_M, NEWTON_STEPS, NEWTON_TOLERANCE_RAD, CurvedSet,
                                          SurfacePoints)


def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _dot(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.einsum("ij,ij->i", u, v)


def circle_specular_point(a2: NDArray[np.float64], b2: NDArray[np.float64],
                          radius: float | NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Specular points on a circle of ``radius`` centred at the origin, in 2-D.

    Newton's method on the angle phi of X = radius (cos phi, sin phi), from the bisector of the
    directions to a and b, on d/dphi (|a - X| + |b - X|) = 0 with
    r' = -(P - X) . X' / r and r'' = (radius^2 + (P - X) . X - r'^2) / r for each end P,
    X' = radius (-sin phi, cos phi); steps clipped to +-0.5 rad; every row steps until no step
    exceeds :data:`~acoustisim.propagation.curved.NEWTON_TOLERANCE_RAD`.

    Parameters
    ----------
    a2, b2 : ndarray, shape (n, 2)
        Source and receiver (outside the circle) (m).
    radius : float or ndarray, shape (n,)
        (m).

    Returns
    -------
    points : ndarray, shape (n, 2)
        X (m).
    valid : ndarray of bool, shape (n,)
        Both ends outside the circle and in front of the tangent at X (the lit side).
    """
    rad = np.broadcast_to(np.asarray(radius, dtype=float), (a2.shape[0],))
    ax, ay, bx, by = a2[:, 0], a2[:, 1], b2[:, 0], b2[:, 1]
    na, nb = np.hypot(ax, ay), np.hypot(bx, by)
    sx, sy = ax / na + bx / nb, ay / na + by / nb
    # opposite directions (forward scatter): no lit stationary point; keep phi finite
    degenerate = np.hypot(sx, sy) <= 1e-12
    phi = np.where(degenerate, np.arctan2(ay, ax), np.arctan2(sy, sx))
    r2 = rad * rad
    for _ in range(NEWTON_STEPS):
        c, s = np.cos(phi), np.sin(phi)
        xx, xy = rad * c, rad * s
        dax, day, dbx, dby = ax - xx, ay - xy, bx - xx, by - xy
        ra, rb = np.hypot(dax, day), np.hypot(dbx, dby)
        rpa = -rad * (-dax * s + day * c) / ra
        rpb = -rad * (-dbx * s + dby * c) / rb
        d1 = rpa + rpb
        d2 = (r2 + dax * xx + day * xy - rpa * rpa) / ra + (r2 + dbx * xx + dby * xy - rpb * rpb) / rb
        step = np.clip(d1 / np.where(np.abs(d2) > 1e-300, d2, 1e-300), -0.5, 0.5)
        phi = phi - step
        if not np.any(np.abs(step) > NEWTON_TOLERANCE_RAD):
            break
    c, s = np.cos(phi), np.sin(phi)
    x = rad[:, None] * np.stack([c, s], axis=1)
    valid = ((ax - x[:, 0]) * c + (ay - x[:, 1]) * s > 0.0) & ((bx - x[:, 0]) * c + (by - x[:, 1]) * s > 0.0)
    valid &= (na > rad) & (nb > rad) & ~degenerate
    return x, valid


def specular_points(curved: CurvedSet, which: NDArray[np.int64], a: NDArray[np.float64],
                    b: NDArray[np.float64]) -> SurfacePoints:
    """Specular points of (image) sources ``a`` and receivers ``b`` on the primitives ``which``.

    Parameters
    ----------
    curved : CurvedSet
    which : ndarray of int64, shape (n,)
        The primitive of each pair.
    a, b : ndarray, shape (n, 3)
        Source and receiver (m).

    Returns
    -------
    SurfacePoints
        Principal curvatures: sphere (1/a, 1/a), cylinder (1/a, 0); k12 = 0.
    """
    sphere = curved.is_sphere[which]
    centre = curved.centre[which]
    radius = curved.radius[which]
    frame = curved.frame[which]
    u, v = a - centre, b - centre
    # the plane of the circle problem: spheres, the plane of (centre, a, b); cylinders, the plane
    # normal to the axis (frame rows p, q)
    p_sphere = _unit(u)
    w = v - _dot(v, p_sphere)[:, None] * p_sphere
    helper = np.where(np.abs(p_sphere[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    # collinear centre, source and receiver: any plane through the line will do
    w = np.where(np.linalg.norm(w, axis=1, keepdims=True) > 1e-12 * np.linalg.norm(v, axis=1, keepdims=True),
                 w, np.cross(p_sphere, helper))
    p_axis = np.where(sphere[:, None], p_sphere, frame[:, 0])
    q_axis = np.where(sphere[:, None], _unit(w), frame[:, 1])
    axis = frame[:, 2]
    a2 = np.column_stack([_dot(u, p_axis), _dot(u, q_axis)])
    b2 = np.column_stack([_dot(v, p_axis), _dot(v, q_axis)])
    x2, valid = circle_specular_point(a2, b2, radius)
    # cylinders: rise along the axis where the unrolled path is straight
    za, zb = _dot(u, axis), _dot(v, axis)
    rho_a = np.linalg.norm(a2 - x2, axis=1)
    rho_b = np.linalg.norm(b2 - x2, axis=1)
    z = np.where(sphere, 0.0, za + (zb - za) * rho_a / np.where(rho_a + rho_b > 0, rho_a + rho_b, 1.0))
    valid &= sphere | (np.abs(z) <= 0.5 * curved.length[which] + CYLINDER_END_TOLERANCE_M)
    normal = _unit(x2[:, :1] * p_axis + x2[:, 1:] * q_axis)
    point = centre + radius[:, None] * normal + z[:, None] * np.where(sphere[:, None], 0.0, axis)
    # principal directions: cylinder (around, along the axis); sphere any tangent pair
    helper = np.where(np.abs(normal[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    e1 = _unit(np.where(sphere[:, None], np.cross(normal, helper), np.cross(axis, normal)))
    e2 = np.where(sphere[:, None], np.cross(normal, e1), axis)
    k11 = 1.0 / radius
    k22 = np.where(sphere, 1.0 / radius, 0.0)
    return SurfacePoints(point, normal, valid, e1, e2, k11, k22, np.zeros_like(k11))


def go_amplitude(a: NDArray[np.float64], b: NDArray[np.float64], x: NDArray[np.float64],
                 normal: NDArray[np.float64], e1: NDArray[np.float64], e2: NDArray[np.float64],
                 k11: NDArray[np.float64], k22: NDArray[np.float64], k12: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Geometric-optics factor cos(theta_i) / (r1 r2 sqrt|det H|) of specular points, and their phase.

    Parameters
    ----------
    a, b : ndarray, shape (n, 3)
        (Image) source and receiver (m).
    x, normal : ndarray, shape (n, 3)
        Specular points (m) and unit normals.
    e1, e2 : ndarray, shape (n, 3)
        Orthonormal tangent basis at x.
    k11, k22, k12 : ndarray, shape (n,)
        Curvature tensor in (e1, e2) (1/m, convex > 0).

    Returns
    -------
    amplitude : ndarray, shape (n,)
        The pressure factor without the reflection coefficient (positive).
    phase_rad : ndarray, shape (n,)
        -(pi / 4)(sig(H) - 2): 0 for a minimum, pi / 2 for a saddle, pi for a maximum.
    """
    d1, d2 = x - a, x - b
    r1, r2 = np.linalg.norm(d1, axis=1), np.linalg.norm(d2, axis=1)
    s1, s2 = d1 / r1[:, None], d2 / r2[:, None]
    cos_i, cos_s = np.abs(_dot(s1, normal)), np.abs(_dot(s2, normal))
    a1, a2, b1, b2 = _dot(e1, s1), _dot(e2, s1), _dot(e1, s2), _dot(e2, s2)
    c = cos_i + cos_s
    h11 = (1.0 - a1 * a1) / r1 + (1.0 - b1 * b1) / r2 + c * k11
    h22 = (1.0 - a2 * a2) / r1 + (1.0 - b2 * b2) / r2 + c * k22
    h12 = -a1 * a2 / r1 - b1 * b2 / r2 + c * k12
    det = h11 * h22 - h12 * h12
    signature = np.where(det < 0, 0, np.where(h11 + h22 > 0, 2, -2))
    return cos_i / (r1 * r2 * np.sqrt(np.abs(det))), -(np.pi / 4.0) * (signature - 2)


__all__ = ("circle_specular_point", "go_amplitude", "specular_points")
