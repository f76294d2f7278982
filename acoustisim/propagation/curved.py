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

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.propagation.specular_kernels import circle_newton, go_factors, primitive_specular_points

_NEWTON_STEPS = 40
"""Most Newton iterations on the circle (compiled, :func:`.specular_kernels.circle_newton`;
stops once every step is below 1e-10 rad,
leaving an error of order step^2, i.e. ~1e-20 rad, by quadratic convergence).
From the bisector start it converges quadratically, in under 10 steps for visible points."""


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
    phi = circle_newton(*(np.ascontiguousarray(q, dtype=float) for q in (ax, ay, bx, by, rad)),
                        np.array(phi, dtype=float), _NEWTON_STEPS, 1e-10)
    c, s = np.cos(phi), np.sin(phi)
    x = rad[:, None] * np.stack([c, s], axis=1)
    valid = ((ax - x[:, 0]) * c + (ay - x[:, 1]) * s > 0.0) & ((bx - x[:, 0]) * c + (by - x[:, 1]) * s > 0.0)
    valid &= (na > rad) & (nb > rad) & ~degenerate
    return x, valid


@dataclass(frozen=True, eq=False)
class CurvedSet:
    """The analytic primitives of a scene as arrays, for batched specular-point solves.

    Attributes
    ----------
    is_sphere : ndarray of bool, shape (r,)
    centre : ndarray, shape (r, 3)
        Sphere centre or centre of the cylinder's axis segment (m).
    frame : ndarray, shape (r, 3, 3)
        Rows (p, q, axis) of an orthonormal frame (cylinders; identity for spheres).
    radius, length : ndarray, shape (r,)
        Radius (m); cylinder length (m, inf for spheres).
    """

    is_sphere: NDArray[np.bool_]
    centre: NDArray[np.float64]
    frame: NDArray[np.float64]
    radius: NDArray[np.float64]
    length: NDArray[np.float64]

    @classmethod
    def from_primitives(cls, primitives: Sequence[SpherePrimitive | CylinderPrimitive]) -> "CurvedSet":
        """Stack the primitives (spheres and cylinders only)."""
        r = len(primitives)
        is_sphere = np.zeros(r, dtype=bool)
        centre = np.zeros((r, 3))
        frame = np.tile(np.eye(3), (r, 1, 1))
        radius = np.zeros(r)
        length = np.full(r, np.inf)
        for i, prim in enumerate(primitives):
            centre[i] = prim.center_m
            radius[i] = prim.radius_m
            if isinstance(prim, SpherePrimitive):
                is_sphere[i] = True
            elif isinstance(prim, CylinderPrimitive):
                frame[i] = cylinder_frame(prim)
                length[i] = prim.length_m
            else:
                raise TypeError(f"no specular solver for {type(prim).__name__}")
        return cls(is_sphere, centre, frame, radius, length)


def cylinder_frame(cylinder: CylinderPrimitive) -> NDArray[np.float64]:
    """Orthonormal frame (3, 3), rows (p, q, axis), of a cylinder."""
    axis = np.asarray(cylinder.axis, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    p = np.cross(axis, helper)
    p /= np.linalg.norm(p)
    q = np.cross(axis, p)
    return np.stack([p, q, axis])


def specular_points(curved: CurvedSet, which: NDArray[np.int64], a: NDArray[np.float64], b: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], ...]:
    """Specular points of (image) sources ``a`` and receivers ``b`` on primitives ``which``.

    Parameters
    ----------
    curved : CurvedSet
    which : ndarray of int64, shape (n,)
        Index of the primitive of each candidate.
    a, b : ndarray, shape (n, 3)
        Source and receiver (m).

    Returns
    -------
    point, normal : ndarray, shape (n, 3)
        Specular point X (m) and unit outward normal.
    valid : ndarray of bool, shape (n,)
        Lit from both ends, both ends outside, and (cylinders) X within the finite length.
    e1, e2 : ndarray, shape (n, 3)
        Principal tangent directions (cylinders: around, along the axis).
    k1, k2 : ndarray, shape (n,)
        Principal curvatures (1/m): sphere (1/a, 1/a), cylinder (1/a, 0).
    """
    # the formulas below in one compiled loop (specular_kernels.primitive_specular_points): in
    # the plane of (centre, a, b) for spheres, normal to the axis for cylinders, the circle
    # problem (circle_specular_point); cylinders then lift X along the axis where the unrolled
    # path is straight, inclusive of 1e-9 m at the ends (a post meeting the free surface or the
    # floor at a right angle reflects a monostatic double bounce exactly at the junction)
    return primitive_specular_points(
        curved.is_sphere, curved.centre, np.ascontiguousarray(curved.frame), curved.radius, curved.length,
        np.ascontiguousarray(which, dtype=np.int64), np.ascontiguousarray(a, dtype=float),
        np.ascontiguousarray(b, dtype=float), _NEWTON_STEPS, 1e-10)


def sphere_specular_point(sphere: SpherePrimitive, a: NDArray[np.float64],
                          b: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Specular points X (n, 3), outward normals (n, 3) and validity (n,) on one sphere."""
    point, normal, valid, *_ = specular_points(CurvedSet.from_primitives([sphere]), np.zeros(len(a), np.int64), a, b)
    return point, normal, valid


def cylinder_specular_point(cylinder: CylinderPrimitive, a: NDArray[np.float64],
                            b: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Specular points X (n, 3), outward normals (n, 3) and validity (n,) on one finite cylinder's side."""
    point, normal, valid, *_ = specular_points(CurvedSet.from_primitives([cylinder]), np.zeros(len(a), np.int64), a, b)
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
    k11 = np.broadcast_to(np.asarray(k11, dtype=float), (len(x),))
    k22 = np.broadcast_to(np.asarray(k22, dtype=float), (len(x),))
    amplitude, _ = go_amplitude_general(a, b, x, normal, e1, e2, k11, k22, np.zeros(len(x)))
    return amplitude


def go_amplitude_general(a: NDArray[np.float64], b: NDArray[np.float64], x: NDArray[np.float64],
                         normal: NDArray[np.float64], e1: NDArray[np.float64], e2: NDArray[np.float64],
                         k11: NDArray[np.float64], k22: NDArray[np.float64], k12: NDArray[np.float64]
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`go_amplitude` for a full (possibly indefinite) curvature tensor, with its phase.

    Parameters
    ----------
    a, b, x, normal, e1, e2 : ndarray, shape (n, 3)
        As in :func:`go_amplitude`; (e1, e2) any orthonormal tangent basis.
    k11, k22, k12 : ndarray, shape (n,)
        Curvature tensor in (e1, e2) (1/m, convex > 0).

    Returns
    -------
    amplitude : ndarray, shape (n,)
        cos(theta_i) / (r1 r2 sqrt|det H|).
    phase_rad : ndarray, shape (n,)
        Extra phase of the stationary point relative to a mirror, in the engineering convention
        of ``Paths.phase_rad``: the physics factor exp(i pi sig(H) / 4) (exp(-i omega t)) relative
        to sig = 2, conjugated: -(pi / 4)(sig - 2). 0 for a minimum (convex, plane), pi / 2 for a
        saddle, pi for a maximum (focusing concave patch beyond its focus).
    """
    # the formulas above in one compiled loop, term for term (specular_kernels.go_factors):
    # s1, s2 the unit vectors a -> x and b -> x at distances r1, r2, cos_i = |s1 . n|,
    # cos_s = |s2 . n|, a_j = e_j . s1, b_j = e_j . s2, c = cos_i + cos_s,
    # h11 = (1 - a1^2)/r1 + (1 - b1^2)/r2 + c k11, h22 likewise, h12 = -a1 a2/r1 - b1 b2/r2 + c k12,
    # signature 0 if det H < 0, else 2 if trace H > 0, else -2
    return go_factors_at(np.arange(len(x)), a, b, x, normal, e1, e2, k11, k22, k12)


def go_factors_at(rows: NDArray[np.int64], a: NDArray[np.float64], b: NDArray[np.float64], x: NDArray[np.float64],
                  normal: NDArray[np.float64], e1: NDArray[np.float64], e2: NDArray[np.float64],
                  k11: NDArray[np.float64] | float, k22: NDArray[np.float64] | float,
                  k12: NDArray[np.float64] | float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`go_amplitude_general` of the ``rows`` (r,) of its arguments (n, 3) and (n,) (or
    scalar curvatures), without gathering them first. Returns amplitude and phase (r,)."""
    n = len(x)
    vectors = (np.ascontiguousarray(v, dtype=float) for v in (a, b, x, normal, e1, e2))
    curvature = (np.ascontiguousarray(np.broadcast_to(np.asarray(k, dtype=float), (n,))) for k in (k11, k22, k12))
    return go_factors(np.ascontiguousarray(rows, dtype=np.int64), *vectors, *curvature)


__all__ = [
    "CurvedSet",
    "circle_specular_point",
    "cylinder_frame",
    "cylinder_specular_point",
    "go_amplitude",
    "go_amplitude_general",
    "go_factors_at",
    "specular_points",
    "sphere_specular_point",
]
