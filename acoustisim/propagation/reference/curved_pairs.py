"""A path reflected by two curved surfaces in turn: its specular points and geometric-optics amplitude.

Physics
-------
A path A -> X1 -> X2 -> B from an (image) source A off a curved surface S1 at X1, then off a
curved surface S2 at X2, to an (image) receiver B is specular where its length

    L(X1, X2) = |X1 - A| + |X2 - X1| + |B - X2|

is stationary with respect to both points on their surfaces (Fermat): the tangential gradient
at X1, E1^T (d0 - d1), and at X2, E2^T (d1 - d2), vanish (d0, d1, d2 the unit vectors of the
three legs, E_j = (e1, e2) the tangent basis at X_j): the reflection law at both points.
Planar mirrors before, between and after the two surfaces are unfolded: A and B are the images
of the transmitter and receiver across the mirrors before S1 and after S2, and mirrors between
the surfaces are removed by replacing S2 and B with their images across them (the last mirror
first), so that the solve sees a free-field path; the mirrors keep the wavefront's curvature,
so the amplitude of the unfolded path is the amplitude of the real one.

The amplitude is that of geometric optics, by the ray-tube (wavefront curvature) method of
Deschamps (Proc. IEEE 60, 1022, 1972; the reflection law also in Kouyoumjian & Pathak,
Proc. IEEE 62, 1448, 1974). The wave's curvature is a symmetric 2x2 matrix q in an orthonormal
basis W (3x2) of the plane normal to the ray, its phase k (L + x^T q x / 2) near the ray:

* a point source at distance r: q = I / r, pressure factor 1 / r (re the source at 1 m);
* along a leg of length s: q -> q (I + s q)^-1, pressure x det(I + s q)^(-1/2);
* reflection at a surface point with normal n, tangent basis E, curvature tensor K (convex
  > 0), incidence angle theta: the phases of the incident and reflected waves agree to second
  order on the surface, which with T = W^T E gives

      T_r^T q_r T_r = T_i^T q_i T_i + 2 cos(theta) K,

  and the pressure is continuous (times the reflection coefficient, applied elsewhere).

Hence |p| = (1 / r0) prod_j det(I + r_j q_j)^(-1/2) over the legs after each reflection. For
one reflection this is cos(theta) / (r1 r2 sqrt|det H|) of :mod:`.curved` (the two agree
algebraically: det H = cos^2(theta) det(I + r2 q) / r2^2). For two spheres of radii a1, a2 on
one line with the path along it, it is the product of the single-sphere focusing factors with
the unfolded distances, (1 / r0) rho1 / (rho1 + r1) x rho2 / (rho2 + r2), rho1 = 1 / (1 / r0 +
2 / a1), rho2 = 1 / (1 / (rho1 + r1) + 2 / a2). Evaluating the iterated Kirchhoff integral over
both surfaces by stationary phase gives the same amplitude as
cos(theta1) cos(theta2) / (r0 r1 r2 sqrt|det H4|), H4 the 4x4 Hessian of L in the two tangent
planes (the tests use it, and a traced ray tube, as independent evaluations).
Convex reflectors keep q positive definite (the reflected wave diverges, no caustic), so the
path adds no phase.

Method
------
1. Start: the single-surface specular points (:func:`.curved.specular_points`) alternated:
   X1 between A and the centre of S2, X2 between X1 and B, X1 again between A and X2.
2. Joint Newton on the four tangent coordinates (u1 on S1, u2 on S2): X_j moves in its tangent
   plane and is projected back on the surface (radially: a retraction that agrees with the
   surface to second order), with the gradient above and the exact Hessian of L at the current
   points,

       H11 = E1^T (P0 / r0 + P1 / r1) E1 + ((d1 - d0) . n1) K1,
       H22 = E2^T (P1 / r1 + P2 / r2) E2 + ((d2 - d1) . n2) K2,
       H12 = -E1^T P1 E2 / r1,                      P_j = I - d_j d_j^T,

   each point's step clipped to half its surface's radius, until no point moves more than
   :data:`~acoustisim.propagation.curved.PAIR_NEWTON_TOLERANCE_M` (at most
   :data:`~acoustisim.propagation.curved.PAIR_NEWTON_STEPS` steps).
3. A solution is kept if it is stationary (every gradient component below
   :data:`~acoustisim.propagation.curved.PAIR_STATIONARY_TOLERANCE`), each point is lit from
   both of its neighbours (A and X2 in front of X1's tangent plane, X1 and B in front of X2's)
   and not grazing (incidence cosine at least
   :data:`~acoustisim.propagation.curved.PAIR_MIN_COSINE`), and a cylinder's point lies within
   its length (plus :data:`~acoustisim.propagation.curved.CYLINDER_END_TOLERANCE_M`).
4. The amplitude by the ray tube (:func:`ray_tube_amplitude`), each reflection evaluated without
   inverting T_r (whose determinant is cos(theta): near grazing its inverse would multiply
   round-off by 1 / cos^2): with S = T_r^T q_r T_r and M = T_r^T T_r + s S, the leg of length s
   after it spreads the wave by det(I + s q_r)^(-1/2) = |cos(theta)| / sqrt(det M) and leaves
   the curvature q_r (I + s q_r)^-1 = (I - T_r M^-1 T_r^T) / s at its end. For one reflection
   this is the Hessian form of :mod:`.curved` (M = s H).

Accuracy
--------
Geometric optics at each reflection, as for one reflection (:mod:`.curved`: against a Kirchhoff
integral at 500 kHz, 7e-5 for a 5 cm sphere and 1.3e-4 for a 10 cm cylinder): no creeping
waves, no diffraction by a cylinder's ends (a point within the length reflects fully, one
beyond it not at all), and only approximate within about (k a)^(-1/3) of grazing (the Fock
transition region, ~15 degrees for the thesis posts); reflections within 0.06 degrees of
grazing drop the chain (:data:`~acoustisim.propagation.curved.PAIR_MIN_COSINE`). For two convex
bodies the stationary path of a given sequence is a minimum of L (the Hessian is the sum of a
convex function's and positive curvature terms) and Newton finds it; a second stationary path
of the same sequence is not searched for. Newton leaves the points within about 1e-15 m of the
stationary ones. Only analytic primitives (spheres, cylinders) take part; a smooth user mesh
reflects at most once per path.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.curved import (CYLINDER_END_TOLERANCE_M, PAIR_MIN_COSINE, PAIR_NEWTON_STEPS,
                                          PAIR_NEWTON_TOLERANCE_M, PAIR_STATIONARY_TOLERANCE, CurvedSet,
                                          SurfacePoints)
from acoustisim.propagation.reference.curved import specular_points


def _unit(v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit vectors (n, 3) and norms (n,) of ``v`` (n, 3)."""
    norm = np.linalg.norm(v, axis=-1)
    return v / norm[:, None], norm


def _dot(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.einsum("ij,ij->i", u, v)


def _helper(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """A direction (n, 3) not parallel to the unit vectors ``v`` (n, 3)."""
    return np.where(np.abs(v[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))


def surface_frame(curved: CurvedSet, x: NDArray[np.float64]) -> SurfacePoints:
    """The local geometry of points ``x`` (n, 3) on the primitives ``curved`` (n rows).

    Returns
    -------
    SurfacePoints
        ``point`` = ``x``; outward ``normal``; ``e1``, ``e2`` (sphere: any tangent pair;
        cylinder: around, along the axis); curvatures (1/a, 1/a) or (1/a, 0), k12 = 0;
        ``valid``: a cylinder's point within its length (+ the end tolerance).
    """
    sphere = curved.is_sphere
    axis = curved.frame[:, 2]
    relative = x - curved.centre
    along = np.where(sphere, 0.0, _dot(relative, axis))
    normal, _ = _unit(relative - along[:, None] * axis)
    e1, _ = _unit(np.where(sphere[:, None], np.cross(normal, _helper(normal)), np.cross(axis, normal)))
    e2 = np.where(sphere[:, None], np.cross(normal, e1), axis)
    k11 = 1.0 / curved.radius
    k22 = np.where(sphere, k11, 0.0)
    valid = sphere | (np.abs(along) <= 0.5 * curved.length + CYLINDER_END_TOLERANCE_M)
    return SurfacePoints(x, normal, valid, e1, e2, k11, k22, np.zeros_like(k11))


def project(curved: CurvedSet, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points ``x`` (n, 3) moved radially onto the primitives ``curved`` (a sphere about its
    centre, a cylinder about its axis, keeping the axial coordinate)."""
    sphere = curved.is_sphere
    axis = curved.frame[:, 2]
    relative = x - curved.centre
    along = np.where(sphere, 0.0, _dot(relative, axis))
    radial, _ = _unit(relative - along[:, None] * axis)
    return curved.centre + along[:, None] * axis + curved.radius[:, None] * radial


def _tangent(points: SurfacePoints) -> NDArray[np.float64]:
    """The tangent bases E (n, 3, 2)."""
    return np.stack([points.e1, points.e2], axis=2)


def _curvature(points: SurfacePoints) -> NDArray[np.float64]:
    """The curvature tensors K (n, 2, 2)."""
    return np.stack([np.stack([points.k11, points.k12], axis=1), np.stack([points.k12, points.k22], axis=1)], axis=1)


def _projector(d: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
    """(I - d d^T) / r (n, 3, 3) of unit vectors ``d`` (n, 3) and lengths ``r`` (n,)."""
    return (np.eye(3) - d[:, :, None] * d[:, None, :]) / r[:, None, None]


def path_gradient_and_hessian(a: NDArray[np.float64], first: SurfacePoints, second: SurfacePoints,
                              b: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gradient (n, 4) and Hessian (n, 4, 4) of L = |X1 - A| + |X2 - X1| + |B - X2| in the
    tangent coordinates (u1 at X1 = ``first``, u2 at X2 = ``second``) of the radial retraction
    (the module's Method, step 2)."""
    d0, r0 = _unit(first.point - a)
    d1, r1 = _unit(second.point - first.point)
    d2, r2 = _unit(b - second.point)
    e_first, e_second = _tangent(first), _tangent(second)
    gradient = np.concatenate([np.einsum("nki,nk->ni", e_first, d0 - d1),
                               np.einsum("nki,nk->ni", e_second, d1 - d2)], axis=1)
    p0, p1, p2 = _projector(d0, r0), _projector(d1, r1), _projector(d2, r2)
    h11 = (np.einsum("nki,nkl,nlj->nij", e_first, p0 + p1, e_first)
           + _dot(d1 - d0, first.normal)[:, None, None] * _curvature(first))
    h22 = (np.einsum("nki,nkl,nlj->nij", e_second, p1 + p2, e_second)
           + _dot(d2 - d1, second.normal)[:, None, None] * _curvature(second))
    h12 = -np.einsum("nki,nkl,nlj->nij", e_first, p1, e_second)
    hessian = np.concatenate([np.concatenate([h11, h12], axis=2),
                              np.concatenate([np.swapaxes(h12, 1, 2), h22], axis=2)], axis=1)
    return gradient, hessian


def _clip(step: NDArray[np.float64], limit: NDArray[np.float64]) -> NDArray[np.float64]:
    """Tangent steps (n, 2) scaled down to length <= ``limit`` (n,)."""
    norm = np.linalg.norm(step, axis=1)
    return step * np.minimum(1.0, limit / np.where(norm > 0, norm, 1.0))[:, None]


def pair_specular_points(first: CurvedSet, second: CurvedSet, a: NDArray[np.float64],
                         b: NDArray[np.float64]) -> tuple[SurfacePoints, SurfacePoints, NDArray[np.bool_]]:
    """The specular points of paths a -> ``first`` -> ``second`` -> b.

    Parameters
    ----------
    first, second : CurvedSet
        One primitive per path (n rows each), the second already unfolded across any mirrors
        between the two.
    a, b : ndarray, shape (n, 3)
        The (image) source and the (image) receiver (m), ``b`` unfolded with ``second``.

    Returns
    -------
    first_points, second_points : SurfacePoints
        X1 and X2 with their local geometry (``valid`` set as below in both).
    valid : ndarray of bool, shape (n,)
        Stationary, each point lit from both neighbours, cylinder points within their lengths.
    """
    # degenerate pairs (an image coaxial with its object) give NaN here and are invalid below
    with np.errstate(invalid="ignore", divide="ignore"):
        start = specular_points(first, np.arange(first.radius.size), a, second.centre).point
        x2 = specular_points(second, np.arange(second.radius.size), start, b).point
        x1 = specular_points(first, np.arange(first.radius.size), a, x2).point
        for _ in range(PAIR_NEWTON_STEPS):
            p1, p2 = surface_frame(first, x1), surface_frame(second, x2)
            gradient, hessian = path_gradient_and_hessian(a, p1, p2, b)
            solvable = np.isfinite(hessian).all(axis=(1, 2)) & (np.abs(np.linalg.det(hessian)) > 0)
            step = np.zeros_like(gradient)
            step[solvable] = np.linalg.solve(hessian[solvable], gradient[solvable][:, :, None])[:, :, 0]
            s1, s2 = _clip(step[:, :2], 0.5 * first.radius), _clip(step[:, 2:], 0.5 * second.radius)
            x1 = project(first, x1 - np.einsum("nki,ni->nk", _tangent(p1), s1))
            x2 = project(second, x2 - np.einsum("nki,ni->nk", _tangent(p2), s2))
            moved = np.maximum(np.linalg.norm(s1, axis=1), np.linalg.norm(s2, axis=1))
            if not np.any(moved > PAIR_NEWTON_TOLERANCE_M):
                break
        p1, p2 = surface_frame(first, x1), surface_frame(second, x2)
        gradient, _ = path_gradient_and_hessian(a, p1, p2, b)
        stationary = np.all(np.abs(gradient) <= PAIR_STATIONARY_TOLERANCE, axis=1)
        lit = ((_dot(a - x1, p1.normal) > 0.0) & (_dot(x2 - x1, p1.normal) > 0.0)
               & (_dot(x1 - x2, p2.normal) > 0.0) & (_dot(b - x2, p2.normal) > 0.0))
        # not grazing: the incidence cosines (the leg arriving at each point)
        d0, _ = _unit(x1 - a)
        d1, _ = _unit(x2 - x1)
        lit &= (-_dot(d0, p1.normal) >= PAIR_MIN_COSINE) & (-_dot(d1, p2.normal) >= PAIR_MIN_COSINE)
    valid = stationary & lit & p1.valid & p2.valid
    return p1._replace(valid=valid), p2._replace(valid=valid), valid


def transverse_basis(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """An orthonormal basis W (n, 3, 2) of the plane normal to each unit vector ``d`` (n, 3)."""
    w1, _ = _unit(np.cross(d, _helper(d)))
    return np.stack([w1, np.cross(d, w1)], axis=2)


def ray_tube_amplitude(source: NDArray[np.float64], reflections: Sequence[SurfacePoints],
                       receiver: NDArray[np.float64]) -> NDArray[np.float64]:
    """Geometric-optics pressure factor (n,) of paths from a point ``source`` (n, 3) reflected
    by curved surfaces at ``reflections`` (specular points with their local geometry, in path
    order) to ``receiver`` (n, 3), by Deschamps' ray tube (the module's Physics): without the
    reflection coefficients, relative to the source's pressure at 1 m, for convex reflectors
    (positive: no caustic)."""
    points = [source] + [x.point for x in reflections] + [receiver]
    legs = [_unit(end - start) for start, end in zip(points[:-1], points[1:])]
    d, r = legs[0]
    basis = transverse_basis(d)
    curvature = np.eye(2) / r[:, None, None]
    amplitude = 1.0 / r
    for x, (d_out, r_out) in zip(reflections, legs[1:]):
        tangent = _tangent(x)
        incident = np.einsum("nki,nkj->nij", basis, tangent)  # T_i = W_i^T E
        matched = (np.einsum("nki,nkl,nlj->nij", incident, curvature, incident)
                   - 2.0 * _dot(d, x.normal)[:, None, None] * _curvature(x))  # S = T_r^T q_r T_r
        basis = transverse_basis(d_out)
        outgoing = np.einsum("nki,nkj->nij", basis, tangent)  # T_r = W_r^T E, det = +-cos(theta)
        m = np.einsum("nki,nkj->nij", outgoing, outgoing) + r_out[:, None, None] * matched
        amplitude = amplitude * np.abs(_dot(d_out, x.normal)) / np.sqrt(np.linalg.det(m))
        curvature = (np.eye(2) - outgoing @ np.linalg.solve(m, np.swapaxes(outgoing, 1, 2))) / r_out[:, None, None]
        d = d_out
    return amplitude


__all__ = ("pair_specular_points", "path_gradient_and_hessian", "project", "ray_tube_amplitude", "surface_frame",
           "transverse_basis")
