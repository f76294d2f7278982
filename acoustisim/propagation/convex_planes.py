"""The face planes of a scene's convex objects: a description for exact geometric tests.

A closed triangle mesh whose every vertex lies on the inner side of every face plane bounds the
intersection of the face planes' inner half-spaces, a convex polyhedron (the prism of the thesis
tank, the tessellated posts and pipe). Its unique face planes describe it completely: a point
is inside iff ``n . x <= d`` for every plane, and a line enters and leaves it where it crosses
the planes (Cyrus and Beck 1978). The fast engine uses them to decide occlusion and first hits
without Embree (:mod:`acoustisim.propagation.fast.convex_occlusion`,
:mod:`acoustisim.propagation.fast.diffuse_hits`, the edge-visibility screen);
:attr:`~acoustisim.propagation.raycast.RayCaster.convex_planes` holds them per scene.

:func:`convex_object_planes` extracts them from a ray caster's triangle soup; a non-convex, open
or very large mesh gets no planes (its queries go to Embree).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

CONVEX_MAX_FACES = 4096
"""Largest object mesh (triangles) examined for convexity: larger meshes get no planes (the
check costs faces x vertices, and a per-query test over thousands of planes is no faster than
Embree's BVH)."""

CONVEX_MAX_PLANES = 512
"""Most unique face planes of an object; more: the object gets none."""

PLANE_TOLERANCE_M = 1e-9
"""How far (m) a vertex may lie outside a face plane of a mesh still called convex, and the
rounding under which two triangles' planes are merged: a million times below the float32
rounding of Embree's coordinates, far above the float64 rounding of a tessellation's vertices
(1e-16 m), so the half-space intersection is the mesh's solid to 1e-9 m."""


@dataclass(frozen=True, eq=False)
class ConvexPlanes:
    """The unique face planes of the convex objects of a scene.

    Attributes
    ----------
    start : ndarray of int64, shape (n_objects + 1,)
        Object k's planes are rows ``start[k]:start[k + 1]``; none for an object that is not
        convex (or too large to examine).
    normal : ndarray, shape (n_planes, 3)
        Unit outward normals.
    offset : ndarray, shape (n_planes,)
        ``d`` of each plane ``{x : normal . x = d}`` (m); inside is ``normal . x <= d``.
    triangle : ndarray of int64, shape (n_planes,)
        The ray caster's triangle each plane was taken from: its normal and offset are that
        triangle's, bit for bit.
    """

    start: NDArray[np.int64]
    normal: NDArray[np.float64]
    offset: NDArray[np.float64]
    triangle: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def convex(self) -> NDArray[np.bool_]:
        """Whether each object (n_objects,) has planes (is convex)."""
        return self.start[1:] > self.start[:-1]

    @classmethod
    def none(cls, n_objects: int = 0) -> "ConvexPlanes":
        """No planes for ``n_objects`` objects."""
        return cls(np.zeros(n_objects + 1, dtype=np.int64), np.zeros((0, 3)), np.zeros(0))


def _closed(faces: NDArray[np.int64]) -> bool:
    """Whether every undirected edge of the triangles (n, 3) is shared by exactly two of them."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def mesh_planes(vertices: NDArray[np.float64], faces: NDArray[np.int64], normals: NDArray[np.float64],
                offsets: NDArray[np.float64]) -> NDArray[np.int64] | None:
    """The faces whose planes are the unique face planes of one closed convex mesh, or None if
    it is not one.

    Parameters
    ----------
    vertices : ndarray, shape (n_vertices, 3)
        Vertices (m); ``faces`` index them.
    faces : ndarray of int64, shape (n_faces, 3)
    normals : ndarray, shape (n_faces, 3)
        Unit outward face normals.
    offsets : ndarray, shape (n_faces,)
        ``normals . v0`` of each face (m).

    Returns
    -------
    ndarray of int64, shape (k,) or None
        Indices of one face per plane, in face order (coplanar faces, within
        :data:`PLANE_TOLERANCE_M`, share a plane). None when the mesh is too large
        (:data:`CONVEX_MAX_FACES`, :data:`CONVEX_MAX_PLANES`), open, has a face without a unit
        normal (degenerate), a vertex more than :data:`PLANE_TOLERANCE_M` outside a face plane
        (not convex), or inward normals.
    """
    if faces.shape[0] == 0 or faces.shape[0] > CONVEX_MAX_FACES:
        return None
    if not np.all(np.abs(np.linalg.norm(normals, axis=1) - 1.0) < 1e-9) or not _closed(faces):
        return None
    keys = np.round(np.column_stack([normals, offsets]) / PLANE_TOLERANCE_M)
    _, first = np.unique(keys, axis=0, return_index=True)
    first = np.sort(first)
    if first.size > CONVEX_MAX_PLANES:
        return None
    normal, offset = normals[first], offsets[first]
    used = vertices[np.unique(faces)]
    height = used @ normal.T - offset  # (v, k): > 0 outside a plane
    if np.max(height) > PLANE_TOLERANCE_M:
        return None
    # outward normals: the vertices' centroid lies strictly inside every plane (an inverted
    # mesh would have it outside every one)
    if not np.all(normal @ used.mean(axis=0) - offset < 0.0):
        return None
    return first.astype(np.int64)


def convex_object_planes(vertices: NDArray[np.float64], faces: NDArray[np.int64], face_normals: NDArray[np.float64],
                         plane_offset: NDArray[np.float64], surface_index: NDArray[np.int64],
                         object_surfaces: range) -> ConvexPlanes:
    """The planes of every convex object of a ray caster's triangles (see :func:`mesh_planes`).

    Parameters
    ----------
    vertices, faces, face_normals, plane_offset, surface_index
        The ray caster's arrays (:class:`~acoustisim.propagation.raycast.RayCaster`).
    object_surfaces : range
        The surface indices of the objects, in order (the boundaries come first).
        ``surface_index`` must be non-decreasing (each surface's triangles are one block, in
        surface order, as the ray caster stores them).

    Returns
    -------
    ConvexPlanes
    """
    triangles: list[NDArray[np.int64]] = []
    start = [0]
    surfaces = np.asarray(object_surfaces, dtype=np.int64)
    first = np.searchsorted(surface_index, surfaces, side="left")
    last = np.searchsorted(surface_index, surfaces, side="right")
    for a, b in zip(first.tolist(), last.tolist()):
        rows = None
        if 0 < b - a <= CONVEX_MAX_FACES:
            rows = mesh_planes(vertices, faces[a:b], face_normals[a:b], plane_offset[a:b])
        if rows is not None:
            triangles.append(a + rows)
        start.append(start[-1] + (0 if rows is None else rows.size))
    triangle = np.concatenate(triangles) if triangles else np.zeros(0, dtype=np.int64)
    return ConvexPlanes(np.asarray(start, dtype=np.int64), np.ascontiguousarray(face_normals[triangle]),
                        np.ascontiguousarray(plane_offset[triangle]), triangle)


__all__ = ("CONVEX_MAX_FACES", "CONVEX_MAX_PLANES", "PLANE_TOLERANCE_M", "ConvexPlanes", "convex_object_planes",
           "mesh_planes")
