"""Specular points on the true curved surfaces and their geometric-optics amplitude.

Sphere
    The specular point of a source A and receiver B lies in the plane of the centre, A and B
    (by symmetry); in that plane it is the stationary point of |A - X| + |X - B| over the
    circle (Alhazen's problem), solved by Newton's method on the angle from the bisector.
Cylinder (finite, axis e_z of its own frame)
    In the plane normal to the axis the problem is the circle problem of the projected A, B;
    the point then lifts along the axis where the unrolled path is straight:
    z_X = z_A + (z_B - z_A) rho_A / (rho_A + rho_B). It must lie within the finite length.
    (The same horizontal specular point serves transmitter and receiver at different heights
    for a vertical cylinder, ``physics.md`` section 3.)
Amplitude (``physics.md`` section 3, Kirchhoff stationary phase)
    |p| = |R| cos(theta_i) / (r1 r2 sqrt|det H|),
    H = (I - a a^T)/r1 + (I - b b^T)/r2 + (cos theta_i + cos theta_s) K
    in a tangent basis (e1, e2) at X, a_j = e_j . s1, b_j = e_j . s2 (unit vectors A -> X and
    B -> X), K the curvature tensor (sphere I/a, cylinder diag(1/a, 0) across / along the axis).
    For a plane (K = 0) at normal incidence it reduces to 1/(r1 + r2) (the image source). With
    planar mirrors earlier or later in a chain, A and B are the unfolded images: plane mirrors
    keep the wavefront's curvature, so r1, r2 are the unfolded lengths.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive

_NEWTON_STEPS = 40
"""Most Newton iterations on the circle (vectorised; stops once every step is below 1e-10 rad,
leaving an error of order step^2, i.e. ~1e-20 rad, by quadratic convergence).
From the bisector start it converges quadratically, in under 10 steps for visible points."""


def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def circle_specular_point(a2: NDArray[np.float64], b2: NDArray[np.float64],
                          radius: float | NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Specular points on a circle of ``radius`` centred at the origin, in 2-D.

    Parameters
    ----------
    a2, b2 : ndarray, shape (n, 2)
        Source and receiver (outside the circle).
    radius : float or ndarray (n,)

    Returns
    -------
    points : ndarray, shape (n, 2)
        X on the circle where d/dphi (|a - X| + |b - X|) = 0 (the visible, least-length one).
    valid : ndarray of bool, shape (n,)
        Both ends outside the circle and in front of the tangent at X (lit side).
    """
    rad = np.broadcast_to(np.asarray(radius, dtype=float), (a2.shape[0],))
    ax, ay, bx, by = a2[:, 0], a2[:, 1], b2[:, 0], b2[:, 1]
    na, nb = np.hypot(ax, ay), np.hypot(bx, by)
    sx, sy = ax / na + bx / nb, ay / na + by / nb
    # opposite directions (forward scatter): no lit stationary point; keep phi finite
    degenerate = np.hypot(sx, sy) <= 1e-12
    phi = np.where(degenerate, np.arctan2(ay, ax), np.arctan2(sy, sx))
    r2 = rad * rad
    for _ in range(_NEWTON_STEPS):
        c, s = np.cos(phi), np.sin(phi)
        xx, xy = rad * c, rad * s
        # r(phi) = |P - X|: r' = -(P - X).X' / r, r'' = (a^2 + (P - X).X) / r - r'^2 / r, X' = a(-s, c)
        dax, day, dbx, dby = ax - xx, ay - xy, bx - xx, by - xy
        ra, rb = np.hypot(dax, day), np.hypot(dbx, dby)
        rpa = -rad * (-dax * s + day * c) / ra
        rpb = -rad * (-dbx * s + dby * c) / rb
        d1 = rpa + rpb
        d2 = (r2 + dax * xx + day * xy - rpa * rpa) / ra + (r2 + dbx * xx + dby * xy - rpb * rpb) / rb
        step = np.clip(d1 / np.where(np.abs(d2) > 1e-300, d2, 1e-300), -0.5, 0.5)
        phi = phi - step
        if not np.any(np.abs(step) > 1e-10):  # quadratic: the error left is ~ step^2
            break
    c, s = np.cos(phi), np.sin(phi)
    x = rad[:, None] * np.stack([c, s], axis=1)
    valid = ((ax - x[:, 0]) * c + (ay - x[:, 1]) * s > 0.0) & ((bx - x[:, 0]) * c + (by - x[:, 1]) * s > 0.0)
    valid &= (na > rad) & (nb > rad) & ~degenerate
    return x, valid


def sphere_specular_point(sphere: SpherePrimitive, a: NDArray[np.float64],
                          b: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Specular points X (n, 3), outward normals (n, 3) and validity (n,) on a sphere.

    ``a``, ``b`` (n, 3) are the (image) source and receiver positions (m).
    """
    c = np.asarray(sphere.center_m, dtype=float)
    u = a - c
    v = b - c
    e1 = _unit(u)
    w = v - np.einsum("ij,ij->i", v, e1)[:, None] * e1
    wn = np.linalg.norm(w, axis=1)
    # collinear centre, source and receiver: any plane through the line will do
    helper = np.where(np.abs(e1[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    fallback = np.cross(e1, helper)
    e2 = np.where(wn[:, None] > 1e-12 * np.linalg.norm(v, axis=1, keepdims=True), w, fallback)
    e2 = _unit(e2)
    a2 = np.stack([np.einsum("ij,ij->i", u, e1), np.einsum("ij,ij->i", u, e2)], axis=1)
    b2 = np.stack([np.einsum("ij,ij->i", v, e1), np.einsum("ij,ij->i", v, e2)], axis=1)
    x2, valid = circle_specular_point(a2, b2, sphere.radius_m)
    normal = x2[:, :1] * e1 + x2[:, 1:] * e2
    normal = _unit(normal)
    return c + sphere.radius_m * normal, normal, valid


def cylinder_frame(cylinder: CylinderPrimitive) -> NDArray[np.float64]:
    """Orthonormal frame (3, 3), rows (p, q, axis), of a cylinder."""
    axis = np.asarray(cylinder.axis, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    p = np.cross(axis, helper)
    p /= np.linalg.norm(p)
    q = np.cross(axis, p)
    return np.stack([p, q, axis])


def cylinder_specular_point(cylinder: CylinderPrimitive, a: NDArray[np.float64],
                            b: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Specular points X (n, 3), outward normals (n, 3) and validity (n,) on a finite cylinder's side.

    Valid where both ends are outside the cylinder on the lit side and X lies within the
    length (strictly inside the caps' planes).
    """
    c = np.asarray(cylinder.center_m, dtype=float)
    frame = cylinder_frame(cylinder)
    la = (a - c) @ frame.T
    lb = (b - c) @ frame.T
    x2, valid = circle_specular_point(la[:, :2], lb[:, :2], cylinder.radius_m)
    rho_a = np.linalg.norm(la[:, :2] - x2, axis=1)
    rho_b = np.linalg.norm(lb[:, :2] - x2, axis=1)
    z = la[:, 2] + (lb[:, 2] - la[:, 2]) * rho_a / np.where(rho_a + rho_b > 0, rho_a + rho_b, 1.0)
    valid &= np.abs(z) < 0.5 * cylinder.length_m
    local = np.column_stack([x2, z])
    point = c + local @ frame
    normal = _unit(np.column_stack([x2, np.zeros_like(z)]) @ frame)
    return point, normal, valid


def go_amplitude(a: NDArray[np.float64], b: NDArray[np.float64], x: NDArray[np.float64],
                 normal: NDArray[np.float64], e1: NDArray[np.float64], e2: NDArray[np.float64],
                 k11: NDArray[np.float64] | float, k22: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """Geometric-optics factor cos(theta_i) / (r1 r2 sqrt|det H|) of a curved specular point.

    Parameters
    ----------
    a, b : ndarray, shape (n, 3)
        (Image) source and receiver (m).
    x, normal : ndarray, shape (n, 3)
        Specular points (m) and unit outward normals.
    e1, e2 : ndarray, shape (n, 3)
        Principal directions (unit, tangent) with curvatures ``k11``, ``k22`` (1/m, convex > 0).

    Returns
    -------
    ndarray, shape (n,)
        The pressure factor without the reflection coefficient (positive).
    """
    d1 = x - a
    d2 = x - b
    r1 = np.linalg.norm(d1, axis=1)
    r2 = np.linalg.norm(d2, axis=1)
    s1 = d1 / r1[:, None]
    s2 = d2 / r2[:, None]
    cos_i = np.abs(np.einsum("ij,ij->i", s1, normal))
    cos_s = np.abs(np.einsum("ij,ij->i", s2, normal))
    a1, a2 = np.einsum("ij,ij->i", e1, s1), np.einsum("ij,ij->i", e2, s1)
    b1, b2 = np.einsum("ij,ij->i", e1, s2), np.einsum("ij,ij->i", e2, s2)
    h11 = (1.0 - a1 * a1) / r1 + (1.0 - b1 * b1) / r2 + (cos_i + cos_s) * k11
    h22 = (1.0 - a2 * a2) / r1 + (1.0 - b2 * b2) / r2 + (cos_i + cos_s) * k22
    h12 = -a1 * a2 / r1 - b1 * b2 / r2
    det = h11 * h22 - h12 * h12
    return cos_i / (r1 * r2 * np.sqrt(np.abs(det)))


def principal_directions(primitive: SpherePrimitive | CylinderPrimitive, normal: NDArray[np.float64]
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
    """Tangent principal directions (n, 3) x 2 and curvatures (1/m) of a primitive at normals (n, 3)."""
    if isinstance(primitive, CylinderPrimitive):
        axis = np.broadcast_to(np.asarray(primitive.axis, dtype=float), normal.shape)
        e1 = _unit(np.cross(axis, normal))
        return e1, np.array(axis), 1.0 / primitive.radius_m, 0.0
    helper = np.where(np.abs(normal[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    e1 = _unit(np.cross(normal, helper))
    e2 = np.cross(normal, e1)
    k = 1.0 / primitive.radius_m
    return e1, e2, k, k


def primitive_specular_point(primitive: SpherePrimitive | CylinderPrimitive, a: NDArray[np.float64],
                             b: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Dispatch to :func:`sphere_specular_point` or :func:`cylinder_specular_point`."""
    if isinstance(primitive, SpherePrimitive):
        return sphere_specular_point(primitive, a, b)
    if isinstance(primitive, CylinderPrimitive):
        return cylinder_specular_point(primitive, a, b)
    raise TypeError(f"no specular solver for {type(primitive).__name__}")


__all__ = [
    "circle_specular_point",
    "cylinder_frame",
    "cylinder_specular_point",
    "go_amplitude",
    "primitive_specular_point",
    "principal_directions",
    "sphere_specular_point",
]
