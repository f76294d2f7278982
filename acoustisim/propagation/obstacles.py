"""The smooth convex obstacles of a scene: what casts a diffracted (not a hard) shadow.

Spheres and circular cylinders (the objects with an analytic primitive: posts, pipes, balls)
are smooth and convex. A leg passing them within a few Fresnel zones, or blocked by them, is
not cut off but weighted by the field diffracted around them
(:mod:`acoustisim.propagation.shadows`); every other surface (the tank's boundaries, prisms,
plates, user meshes) still blocks a leg outright.

A cylinder whose two ends lie in tank boundary planes perpendicular to its axis (a post from
the floor to the free surface) is continued by its images in those planes: for the image
method it is an infinite cylinder, and its silhouette an infinite strip.

:class:`SmoothObstacles` is built once per prepared scene
(:attr:`~acoustisim.propagation.prepared.PreparedScene.smooth_obstacles`) and shared by every
pose and both engines. It holds the obstacles as arrays and a ray caster of the scene without
them (:meth:`~acoustisim.propagation.raycast.RayCaster.without_surfaces`), with which the
specular mechanism finds every chain the other surfaces leave open.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.propagation.raycast import RayCaster
from acoustisim.scene import Boundary

SPANNING_TOLERANCE_M = 1e-6
"""A cylinder's end lies in a tank boundary plane when its centre is within this of it (m)."""

PARALLEL_TOLERANCE = 1e-9
"""A cylinder's axis is perpendicular to a boundary plane when |axis . normal| is within this of 1."""


@dataclass(frozen=True, eq=False)
class SmoothObstacles:
    """The smooth convex obstacles of a scene (n of them), as arrays.

    Attributes
    ----------
    surface : ndarray of int64, shape (n,)
        Index into ``scene.surface_names``.
    centre_m : ndarray, shape (n, 3)
        Centre of the sphere or of the cylinder's axis segment (m).
    axis : ndarray, shape (n, 3)
        Unit axis of a cylinder; (0, 0, 1) for a sphere (unused).
    radius_m : ndarray, shape (n,)
    half_length_m : ndarray, shape (n,)
        Half the cylinder's length (m); 0 for a sphere.
    sphere : ndarray of bool, shape (n,)
    infinite : ndarray of bool, shape (n,)
        A cylinder both of whose ends lie in tank boundary planes perpendicular to its axis
        (continued by its images: see the module docstring).
    raycaster : RayCaster
        The scene's ray caster without the obstacles' triangles (the same object as the
        scene's when there are none).
    """

    surface: NDArray[np.int64] = field(repr=False)
    centre_m: NDArray[np.float64] = field(repr=False)
    axis: NDArray[np.float64] = field(repr=False)
    radius_m: NDArray[np.float64] = field(repr=False)
    half_length_m: NDArray[np.float64] = field(repr=False)
    sphere: NDArray[np.bool_] = field(repr=False)
    infinite: NDArray[np.bool_] = field(repr=False)
    raycaster: RayCaster = field(repr=False)

    @property
    def count(self) -> int:
        """Number of obstacles."""
        return int(self.surface.size)

    @classmethod
    def build(cls, boundaries: Sequence[Boundary],
              reflectors: Sequence[tuple[int, SpherePrimitive | CylinderPrimitive]],
              raycaster: RayCaster) -> "SmoothObstacles":
        """The obstacles of a scene.

        Parameters
        ----------
        boundaries : sequence of Boundary
            The tank's boundary planes (for the cylinders spanning the tank).
        reflectors : sequence of (int, SpherePrimitive or CylinderPrimitive)
            Each curved reflector's surface index and primitive.
        raycaster : RayCaster
            The scene's ray caster.
        """
        planes = [(np.asarray(b.plane.point_m, dtype=float), np.asarray(b.plane.normal, dtype=float))
                  for b in boundaries]
        surface, centre, axis, radius, half, sphere, infinite = [], [], [], [], [], [], []
        for index, primitive in reflectors:  # a handful of objects
            surface.append(index)
            centre.append(np.asarray(primitive.center_m, dtype=float))
            radius.append(float(primitive.radius_m))
            if not isinstance(primitive, CylinderPrimitive):  # a sphere (prepare() keeps only the two)
                axis.append(np.array([0.0, 0.0, 1.0]))
                half.append(0.0)
                sphere.append(True)
                infinite.append(False)
                continue
            a = np.asarray(primitive.axis, dtype=float)
            axis.append(a)
            half.append(0.5 * float(primitive.length_m))
            sphere.append(False)
            ends = centre[-1] + np.outer([-half[-1], half[-1]], a)
            infinite.append(all(any(abs(abs(float(a @ n)) - 1.0) < PARALLEL_TOLERANCE
                                    and abs(float((end - p) @ n)) < SPANNING_TOLERANCE_M for p, n in planes)
                                for end in ends))
        n = len(surface)
        surfaces = np.asarray(surface, dtype=np.int64)
        return cls(surfaces, np.asarray(centre, dtype=float).reshape(n, 3), np.asarray(axis, dtype=float).reshape(n, 3),
                   np.asarray(radius, dtype=float), np.asarray(half, dtype=float), np.asarray(sphere, dtype=bool),
                   np.asarray(infinite, dtype=bool),
                   raycaster.without_surfaces(surfaces) if n else raycaster)


__all__ = ("PARALLEL_TOLERANCE", "SPANNING_TOLERANCE_M", "SmoothObstacles")
