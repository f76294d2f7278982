"""The tank's boundaries as the faces of an axis-aligned box: a description for exact first hits.

When every boundary triangle lies in a face of the axis-aligned box that bounds them, with its
normal exactly the face's inward axis (the built-in tanks: walls, floor and free surface), a ray
from inside the box leaves it through the face of the smallest exit distance, and the triangle
it meets is the one of that face containing the exit point. :class:`TankBox` holds what that
test needs, built once per scene by the ray caster
(:attr:`~acoustisim.propagation.raycast.RayCaster.tank_box`); the fast engine's diffuse tracer
uses it (:mod:`acoustisim.propagation.fast.diffuse_hits`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

MAX_FACE_TRIANGLES = 64
"""Most triangles tiling one face of the box: a finer face gets no description (a linear search
over its triangles would be slower than Embree's BVH)."""


@dataclass(frozen=True, eq=False)
class TankBox:
    """The tank box and the boundary triangles tiling each of its faces.

    Attributes
    ----------
    bounds : ndarray, shape (2, 3)
        The box (lo, hi) (m).
    face_start : ndarray of int64, shape (7,)
        Face ``f = 2 axis + side`` (side 0 at lo, 1 at hi) has the triangles
        ``face_triangle[face_start[f]:face_start[f + 1]]``.
    face_triangle : ndarray of int64, shape (k,)
        Global triangle indices.
    face_edges : ndarray, shape (k, 3, 3)
        Per triangle, its three edges as ``(a, b, c)`` with ``a u + b v + c`` the signed distance
        (m) of the point (u, v) from the edge, positive inside; (u, v) are the coordinates
        ``((axis + 1) % 3, (axis + 2) % 3)`` of the face.
    """

    bounds: NDArray[np.float64]
    face_start: NDArray[np.int64]
    face_triangle: NDArray[np.int64]
    face_edges: NDArray[np.float64]


def tank_box(vertices: NDArray[np.float64], faces: NDArray[np.int64], face_normals: NDArray[np.float64],
             boundary: NDArray[np.bool_]) -> TankBox | None:
    """The box description of the ``boundary`` triangles of a ray caster's triangle soup, or None
    when they are not the faces of an axis-aligned box with normals into the water (or there
    are none, or a face has more than :data:`MAX_FACE_TRIANGLES` triangles).

    Parameters
    ----------
    vertices, faces, face_normals
        The ray caster's arrays (:class:`~acoustisim.propagation.raycast.RayCaster`).
    boundary : ndarray of bool, shape (n_triangles,)
        The triangles of the tank's boundaries.
    """
    if not np.any(boundary):
        return None
    corners = vertices[faces[boundary]]  # (k, 3, 3)
    lo, hi = corners.reshape(-1, 3).min(axis=0), corners.reshape(-1, 3).max(axis=0)
    if not np.all(hi > lo):
        return None
    normal = face_normals[boundary]
    axis = np.argmax(np.abs(normal), axis=1)
    rows = np.arange(corners.shape[0])
    along = normal[rows, axis]
    # each triangle in a face of the box, its normal exactly the face's inward axis
    if not np.all(np.abs(along) == 1.0) or not np.all(np.count_nonzero(normal, axis=1) == 1):
        return None
    side = (along < 0).astype(np.int64)  # +axis normal: the lo face (0); -axis: the hi face (1)
    level = np.where(side == 0, lo[axis], hi[axis])
    if not np.all(corners[rows, :, axis] == level[:, None]):
        return None
    u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
    u = corners[rows[:, None], np.arange(3)[None, :], u_axis[:, None]]  # (k, 3)
    v = corners[rows[:, None], np.arange(3)[None, :], v_axis[:, None]]
    # edge i from corner i to corner i + 1; the third corner on its positive side
    du, dv = np.roll(u, -1, axis=1) - u, np.roll(v, -1, axis=1) - v
    length = np.hypot(du, dv)
    good = np.all(length > 0.0, axis=1)
    a, b = np.zeros_like(du), np.zeros_like(dv)
    a[good], b[good] = -dv[good] / length[good], du[good] / length[good]
    c = -(a * u + b * v)
    opposite = np.roll(u, -2, axis=1) * a + np.roll(v, -2, axis=1) * b + c
    sign = np.where(np.sum(opposite, axis=1) < 0, -1.0, 1.0)[:, None]
    good &= np.all(np.abs(opposite) > 0.0, axis=1)  # degenerate (zero-area) triangles are skipped
    edges = np.stack([a * sign, b * sign, c * sign], axis=-1)  # (k, 3 edges, 3)
    face = 2 * axis + side
    keep = np.flatnonzero(good)
    order = keep[np.argsort(face[keep], kind="stable")]
    counts = np.bincount(face[order], minlength=6)
    if counts.max() > MAX_FACE_TRIANGLES:
        return None
    return TankBox(np.stack([lo, hi]), np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
                   np.ascontiguousarray(np.flatnonzero(boundary)[order]), np.ascontiguousarray(edges[order]))


def object_boxes(vertices: NDArray[np.float64], faces: NDArray[np.int64], surface_index: NDArray[np.int64],
                 object_surfaces: range) -> NDArray[np.float64]:
    """The axis-aligned box (lo, hi) of each object's triangles, shape (n_objects, 2, 3) (m).

    ``surface_index`` must be non-decreasing (each surface's triangles are one block) and give
    every object at least one triangle.
    """
    boxes = np.zeros((len(object_surfaces), 2, 3))
    if len(object_surfaces):
        objects = np.flatnonzero(surface_index >= object_surfaces.start)
        points = vertices[faces[objects]]  # (t, 3, 3)
        starts = np.searchsorted(surface_index[objects], np.asarray(object_surfaces))
        boxes[:, 0] = np.minimum.reduceat(points.min(axis=1), starts, axis=0)
        boxes[:, 1] = np.maximum.reduceat(points.max(axis=1), starts, axis=0)
    return boxes


__all__ = ("MAX_FACE_TRIANGLES", "TankBox", "object_boxes", "tank_box")
