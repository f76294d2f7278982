"""Exact occlusion of straight legs by convex objects, without a ray-tracing query.

A closed triangle mesh whose every vertex lies on the inner side of every face plane bounds
the intersection H of the face planes' inner half-spaces (a convex polyhedron: the prism of the
thesis tank, the tessellated posts and pipe). Whether a segment ``p + t u``, ``t0 <= t <= t1``,
meets the mesh's surface is then decided by clipping the line against the planes (Cyrus and
Beck 1978; the slab test): with ``n . x <= d`` inside each plane,

* a plane with ``n . u < 0`` is entered at ``t = (d - n . p) / (n . u)``: ``t_enter`` is the
  largest of these;
* a plane with ``n . u > 0`` is left there: ``t_exit`` is the smallest;
* a plane with ``n . u = 0`` and ``n . p > d`` keeps the whole line outside;

and the line lies inside H for ``t_enter <= t <= t_exit``. The segment crosses the surface, as
Embree's occlusion query would report, iff that interval is not empty and ``t_enter`` or
``t_exit`` lies in ``[t0, t1]`` (a segment entirely inside the solid meets no triangle, as in
Embree). The answer is the exact one in float64 arithmetic; Embree, in float32, may differ only
for legs grazing a face, an edge or a vertex within its rounding (about 1e-6 m in a 9 m tank).

:func:`convex_object_planes` extracts the unique face planes of every convex object of a ray
caster's triangle soup once per scene (a non-convex, open or very large mesh gets no planes and
its legs go to Embree); :func:`segment_crosses_convex` is the compiled per-leg test
(``nogil``), called from the diffuse tracer's kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

CONVEX_MAX_FACES = 4096
"""Largest object mesh (triangles) examined for convexity: larger meshes go to Embree (the
check costs faces x vertices, and a per-leg test over thousands of planes is no faster than
Embree's BVH)."""

CONVEX_MAX_PLANES = 512
"""Most unique face planes of an object tested per leg; more: the object goes to Embree."""

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
        convex (or too large to examine), whose legs need Embree.
    normal : ndarray, shape (n_planes, 3)
        Unit outward normals.
    offset : ndarray, shape (n_planes,)
        ``d`` of each plane ``{x : normal . x = d}`` (m); inside is ``normal . x <= d``.
    """

    start: NDArray[np.int64]
    normal: NDArray[np.float64]
    offset: NDArray[np.float64]

    @property
    def convex(self) -> NDArray[np.bool_]:
        """Whether each object (n_objects,) is tested here (convex, with planes)."""
        return self.start[1:] > self.start[:-1]


def _closed(faces: NDArray[np.int64]) -> bool:
    """Whether every undirected edge of the triangles (n, 3) is shared by exactly two of them."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def mesh_planes(vertices: NDArray[np.float64], faces: NDArray[np.int64], normals: NDArray[np.float64],
                offsets: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The unique face planes of one closed convex mesh, or None if it is not one.

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
    (normal, offset) : ndarray, shape (k, 3) and (k,)
        The planes, duplicates (coplanar faces, within :data:`PLANE_TOLERANCE_M`) merged. None
        when the mesh is too large (:data:`CONVEX_MAX_FACES`, :data:`CONVEX_MAX_PLANES`), open,
        has a face without a unit normal (degenerate), a vertex more than
        :data:`PLANE_TOLERANCE_M` outside a face plane (not convex), or inward normals.
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
    normal, offset = np.ascontiguousarray(normals[first]), np.ascontiguousarray(offsets[first])
    used = vertices[np.unique(faces)]
    height = used @ normal.T - offset  # (v, k): > 0 outside a plane
    if np.max(height) > PLANE_TOLERANCE_M:
        return None
    # outward normals: the vertices' centroid lies strictly inside every plane (an inverted
    # mesh would have it outside every one)
    if not np.all(normal @ used.mean(axis=0) - offset < 0.0):
        return None
    return normal, offset


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
    normals: list[NDArray[np.float64]] = []
    offsets: list[NDArray[np.float64]] = []
    start = [0]
    surfaces = np.asarray(object_surfaces, dtype=np.int64)
    first = np.searchsorted(surface_index, surfaces, side="left")
    last = np.searchsorted(surface_index, surfaces, side="right")
    for a, b in zip(first.tolist(), last.tolist()):
        planes = None
        if 0 < b - a <= CONVEX_MAX_FACES:
            planes = mesh_planes(vertices, faces[a:b], face_normals[a:b], plane_offset[a:b])
        if planes is not None:
            normals.append(planes[0])
            offsets.append(planes[1])
            start.append(start[-1] + planes[1].size)
        else:
            start.append(start[-1])
    normal = np.concatenate(normals) if normals else np.zeros((0, 3))
    offset = np.concatenate(offsets) if offsets else np.zeros(0)
    return ConvexPlanes(np.asarray(start, dtype=np.int64), np.ascontiguousarray(normal), np.ascontiguousarray(offset))


@njit(cache=True, nogil=True, error_model="numpy")
def segment_crosses_convex(px: float, py: float, pz: float, ux: float, uy: float, uz: float, t0: float, t1: float,
                           normal: NDArray[np.float64], offset: NDArray[np.float64], first: int, last: int) -> bool:
    """Whether the segment ``p + t u``, ``t0 <= t <= t1``, meets the surface of the convex
    polyhedron of planes ``first:last`` (see the module docstring).

    Parameters
    ----------
    px, py, pz : float
        A point of the line (m).
    ux, uy, uz : float
        Its direction (unit for ``t`` in metres; any length works).
    t0, t1 : float
        The segment's parameter range.
    normal, offset : ndarray, shape (n_planes, 3) and (n_planes,)
        :class:`ConvexPlanes` arrays.
    first, last : int
        The polyhedron's rows.
    """
    enter = -np.inf
    leave = np.inf
    for i in range(first, last):
        nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
        along = nx * ux + ny * uy + nz * uz
        room = offset[i] - (nx * px + ny * py + nz * pz)  # >= 0: p inside this plane
        if along < 0.0:
            t = room / along
            if t > enter:
                enter = t
        elif along > 0.0:
            t = room / along
            if t < leave:
                leave = t
        elif room < 0.0:  # parallel and outside
            return False
        if enter > leave or enter > t1 or leave < t0:
            return False
    return (t0 <= enter <= t1) or (t0 <= leave <= t1)


@njit(cache=True, nogil=True, error_model="numpy")
def segments_cross_convex(starts: NDArray[np.float64], units: NDArray[np.float64], t0: NDArray[np.float64],
                          t1: NDArray[np.float64], normal: NDArray[np.float64], offset: NDArray[np.float64],
                          first: int, last: int, out: NDArray[np.bool_]) -> None:
    """:func:`segment_crosses_convex` of segments (n,) given as starts and directions (n, 3)
    and ranges (n,), against one polyhedron, into ``out`` (n,)."""
    for i in range(out.size):
        out[i] = segment_crosses_convex(starts[i, 0], starts[i, 1], starts[i, 2], units[i, 0], units[i, 1],
                                        units[i, 2], t0[i], t1[i], normal, offset, first, last)


__all__ = [
    "CONVEX_MAX_FACES",
    "CONVEX_MAX_PLANES",
    "PLANE_TOLERANCE_M",
    "ConvexPlanes",
    "convex_object_planes",
    "mesh_planes",
    "segment_crosses_convex",
    "segments_cross_convex",
]
