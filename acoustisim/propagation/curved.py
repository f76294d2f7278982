"""The analytic curved primitives of a scene as arrays, and what a specular point on one carries.

Shared by both engines: :class:`CurvedSet` stacks a scene's spheres and finite cylinders for
batched specular-point solves (:meth:`CurvedSet.take` one row per candidate,
:func:`reflect_primitives` their images across planar mirrors), :class:`SurfacePoints` is what
such a solve returns (the point, its normal, tangent basis and curvature tensor). The physics
(Alhazen's circle problem, the cylinder's lift along its axis, the geometric-optics amplitude)
is in :mod:`acoustisim.propagation.reference.curved`; paths reflected by two curved surfaces in
:mod:`acoustisim.propagation.reference.curved_pairs`.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
from numpy.typing import NDArray

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive

NEWTON_STEPS = 40
"""Most Newton iterations of the circle problem. From the bisector start it converges
quadratically, in under 10 steps for visible points."""

NEWTON_TOLERANCE_RAD = 1e-10
"""Newton stops once no step exceeds this (rad), leaving an error of order step^2 (~1e-20 rad)."""

CYLINDER_END_TOLERANCE_M = 1e-9
"""A specular point this far (m) beyond a cylinder's end still lies on it: a post meeting the free
surface or the floor at a right angle reflects a monostatic double bounce exactly at the
junction, which round-off may put just past the end."""


PAIR_NEWTON_STEPS = 40
"""Most Newton iterations of the joint specular points of a path reflected by two curved
surfaces. From the alternating single-surface start it converges quadratically, in a handful
of steps."""

PAIR_NEWTON_TOLERANCE_M = 1e-12
"""The joint Newton stops once no point moves by more than this (m): quadratic convergence then
leaves an error of order (1e-12 m)^2 / radius, far below round-off."""

PAIR_STATIONARY_TOLERANCE = 1e-9
"""A joint solution counts as specular only if every tangential component of the path-length
gradient (a difference of unit vectors: the reflection law's mismatch in radians) is below
this; a converged solve leaves ~1e-14."""


PAIR_MIN_COSINE = 1e-3
"""A chain through two curved surfaces is dropped if either reflection is more grazing than
this (|cos(theta)| < 1e-3, within 0.06 degrees of grazing). There the amplitude is not even
determined by the float64 geometry: the specular point's position along the grazing direction
is fixed only to ~1e-16 / (2 cos(theta) K) and the amplitude, ~sqrt(cos(theta)), moves by
~1e-16 / (2 cos^2(theta)) relative (5e-11 at the limit, 1e-8 at cos 1e-4); and geometric
optics does not hold there anyway (the reflected wave merges with the incident one passing the
object, the Fock transition region)."""


class CurvedSet(NamedTuple):
    """The analytic primitives of a scene as arrays (r of them).

    Attributes
    ----------
    is_sphere : ndarray of bool, shape (r,)
    centre : ndarray, shape (r, 3)
        Sphere centre or centre of the cylinder's axis segment (m).
    frame : ndarray, shape (r, 3, 3)
        Rows (p, q, axis) of an orthonormal frame (cylinders; identity for spheres).
    radius : ndarray, shape (r,)
        (m).
    length : ndarray, shape (r,)
        Cylinder length (m), inf for spheres.
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

    def take(self, rows: NDArray[np.int64]) -> "CurvedSet":
        """The primitives ``rows`` (n,), one row each (repeats allowed)."""
        return CurvedSet(*(field[rows] for field in self))


class SurfacePoints(NamedTuple):
    """Specular points on curved surfaces with their local geometry (n of them).

    Attributes
    ----------
    point, normal : ndarray, shape (n, 3)
        Specular point X (m) and unit outward normal.
    valid : ndarray of bool, shape (n,)
        Lit from both ends, both ends outside, and (cylinders) X within the finite length.
    e1, e2 : ndarray, shape (n, 3)
        Orthonormal tangent basis (cylinders: around, along the axis).
    k11, k22, k12 : ndarray, shape (n,)
        Curvature tensor in (e1, e2) (1/m, convex > 0).
    """

    point: NDArray[np.float64]
    normal: NDArray[np.float64]
    valid: NDArray[np.bool_]
    e1: NDArray[np.float64]
    e2: NDArray[np.float64]
    k11: NDArray[np.float64]
    k22: NDArray[np.float64]
    k12: NDArray[np.float64]


def cylinder_frame(cylinder: CylinderPrimitive) -> NDArray[np.float64]:
    """Orthonormal frame (3, 3), rows (p, q, axis), of a cylinder."""
    axis = np.asarray(cylinder.axis, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    p = np.cross(axis, helper)
    p /= np.linalg.norm(p)
    q = np.cross(axis, p)
    return np.stack([p, q, axis])


def reflect_primitives(curved: CurvedSet, plane_point: NDArray[np.float64],
                       plane_normal: NDArray[np.float64]) -> CurvedSet:
    """The mirror images of the primitives ``curved`` (n rows) across one plane each.

    Parameters
    ----------
    curved : CurvedSet
        n primitives.
    plane_point, plane_normal : ndarray, shape (n, 3)
        A point of each plane (m) and its unit normal.

    Returns
    -------
    CurvedSet
        Centres mirrored as points, frame rows as directions (the image frame is orthonormal
        and left-handed, which no solver minds: they use its rows as an in-plane basis and an
        axis); radii and lengths unchanged.
    """
    height = np.einsum("ij,ij->i", curved.centre - plane_point, plane_normal)
    centre = curved.centre - 2.0 * height[:, None] * plane_normal
    along = np.einsum("irk,ik->ir", curved.frame, plane_normal)
    frame = curved.frame - 2.0 * along[:, :, None] * plane_normal[:, None, :]
    return CurvedSet(curved.is_sphere, centre, frame, curved.radius, curved.length)


__all__ = ("CYLINDER_END_TOLERANCE_M", "CurvedSet", "NEWTON_STEPS", "NEWTON_TOLERANCE_RAD", "PAIR_MIN_COSINE",
           "PAIR_NEWTON_STEPS", "PAIR_NEWTON_TOLERANCE_M", "PAIR_STATIONARY_TOLERANCE", "SurfacePoints",
           "cylinder_frame", "reflect_primitives")
