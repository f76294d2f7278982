"""Planar mirrors: the bounded planes of a scene that reflect specularly, shared by both engines.

A *mirror* is a bounded planar polygon that reflects specularly: a tank boundary, a coplanar
facet of a polyhedral object (prism, plate: trimesh ``facets``), or a flat cap of a cylinder.
The facets of spheres and of the curved side of cylinders are never mirrors (their flat
facets would give the wrong spreading; see :mod:`acoustisim.propagation.reference.curved`).
:class:`PlanarMirrors` holds their planes, polygons and materials, which mirror can see which
(:func:`mirror_sequences`), and the point-in-polygon test; the image-source method that uses
them is :mod:`acoustisim.propagation.reference.image_source` (and its compiled twin in
:mod:`acoustisim.propagation.fast`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.materials import Material
from acoustisim.propagation.raycast import RayCaster
from acoustisim.scene import Scene, SceneObject

CACHED_SEQUENCE_ROWS = 200_000
"""Mirror sequences of one length are enumerated once per scene if there are at most this many
(bounded by m x (most mirrors one sees)^(length - 1)); beyond, once per pose with the pose's end
constraints (fewer rows)."""

MAX_OBJECT_MIRRORS = 256
"""Objects (without a curved primitive) with more planar patches than this are not used as
mirrors: they are smooth or finely detailed meshes, not polyhedra (traced through their
interpolated normals instead, :mod:`acoustisim.propagation.smooth_mesh`), and order-3 chains
over their facets would explode combinatorially."""

ON_PLANE_TOLERANCE_M = 1e-12
"""A point this close (m) to a mirror's plane counts as on it (float64 round-off at tank scale)."""

INSIDE_TOLERANCE = 1e-9
"""Barycentric tolerance of the point-in-polygon test (dimensionless): points on a shared
edge of two facets' triangles, or on the tank's corner lines, count as inside."""


class TriangleFrames(NamedTuple):
    """The pose-independent parts of the barycentric point-in-triangle test of every mirror's
    triangles (m mirrors, t triangles each, padded).

    For a point p, with w = p - corner, d20 = w . edge0, d21 = w . edge1:
    v = (d11 d20 - d01 d21) / det, w = (d00 d21 - d01 d20) / det, u = 1 - v - w; p is inside
    when u, v, w >= -:data:`INSIDE_TOLERANCE`.

    Attributes
    ----------
    corner, edge0, edge1 : ndarray, shape (m, t, 3)
        First vertex a, and b - a, c - a (m).
    d00, d01, d11 : ndarray, shape (m, t)
        edge0 . edge0, edge0 . edge1, edge1 . edge1 (m^2).
    det : ndarray, shape (m, t)
        d00 d11 - d01^2 (m^4), inf for a degenerate triangle (nothing is inside it).
    """

    corner: NDArray[np.float64]
    edge0: NDArray[np.float64]
    edge1: NDArray[np.float64]
    d00: NDArray[np.float64]
    d01: NDArray[np.float64]
    d11: NDArray[np.float64]
    det: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PlanarMirrors:
    """All planar mirrors of a scene.

    Attributes
    ----------
    point : ndarray, shape (m, 3)
        A point of each plane (m).
    normal : ndarray, shape (m, 3)
        Unit normal on the reflecting (water) side.
    surface : ndarray of int64, shape (m,)
        Index into ``scene.surface_names``.
    patch : ndarray of int64, shape (m,)
        The ray caster's patch label (excluded from the occlusion of legs ending on it).
    material : ndarray of int64, shape (m,)
        Index into ``materials``.
    materials : tuple of Material
    triangles : ndarray, shape (m, t, 3, 3)
        The polygon as triangles, padded by repeating the first one.
    disc_radius : ndarray, shape (m,)
        For the circular caps of cylinders, the true radius (m) about ``point`` (the cap's
        centre), tested instead of the tessellated polygon; NaN for polygons.
    sees : ndarray of bool, shape (m, m)
        ``sees[i, j]``: some vertex of mirror j lies strictly in front of mirror i and some
        vertex of i strictly in front of j (a necessary condition for a leg i -> j).
    """

    point: NDArray[np.float64] = field(repr=False)
    normal: NDArray[np.float64] = field(repr=False)
    surface: NDArray[np.int64] = field(repr=False)
    patch: NDArray[np.int64] = field(repr=False)
    material: NDArray[np.int64] = field(repr=False)
    materials: tuple[Material, ...]
    triangles: NDArray[np.float64] = field(repr=False)
    disc_radius: NDArray[np.float64] = field(repr=False)
    sees: NDArray[np.bool_] = field(repr=False)

    @property
    def count(self) -> int:
        """Number of mirrors."""
        return int(self.point.shape[0])

    @classmethod
    def from_scene(cls, scene: Scene, raycaster: RayCaster) -> "PlanarMirrors":
        """Collect the boundaries, polyhedral facets and cylinder caps of ``scene``."""
        points: list[NDArray[np.float64]] = []
        normals: list[NDArray[np.float64]] = []
        surfaces: list[int] = []
        patches: list[int] = []
        material_of: list[int] = []
        materials: list[Material] = []
        polygons: list[NDArray[np.float64]] = []
        discs: list[float] = []

        def material_index(material: Material) -> int:
            for i, known in enumerate(materials):
                if known is material or known == material:
                    return i
            materials.append(material)
            return len(materials) - 1

        tri_all = raycaster.vertices[raycaster.faces]
        n_boundaries = len(scene.boundaries)
        for s, boundary in enumerate(scene.boundaries):
            faces = np.flatnonzero(raycaster.surface_index == s)
            points.append(np.asarray(boundary.plane.point_m, dtype=float))
            normals.append(np.asarray(boundary.plane.normal, dtype=float))
            surfaces.append(s)
            patches.append(int(raycaster.patch_index[faces[0]]))
            material_of.append(material_index(boundary.material))
            polygons.append(tri_all[faces])
            discs.append(np.nan)
        for j, obj in enumerate(scene.objects):
            s = n_boundaries + j
            faces_of_object = np.flatnonzero(raycaster.surface_index == s)
            offset = int(faces_of_object[0])
            mesh = obj.mesh
            if isinstance(obj.primitive, SpherePrimitive):
                continue  # never a mirror (and its facets are not worth computing)
            if obj.primitive is None:
                # every planar patch (coplanar facet or lonely triangle) of a polyhedron
                labels = raycaster.patch_index[faces_of_object]
                if not is_polyhedral(obj, raycaster, s):
                    continue  # a smooth mesh (see acoustisim.propagation.smooth_mesh)
                order = np.argsort(labels, kind="stable")
                bounds = np.flatnonzero(np.r_[True, np.diff(labels[order]) != 0, True])
                groups = [faces_of_object[order[b0:b1]] for b0, b1 in zip(bounds[:-1], bounds[1:])]
                for faces in groups:
                    tri = tri_all[faces]
                    normals.append(raycaster.face_normals[faces[0]])
                    surfaces.append(s)
                    patches.append(int(raycaster.patch_index[faces[0]]))
                    material_of.append(material_index(obj.material))
                    points.append(tri[0, 0])
                    polygons.append(tri)
                    discs.append(np.nan)
            elif isinstance(obj.primitive, CylinderPrimitive):
                # the flat caps, as exact discs
                cyl = obj.primitive
                axis = np.asarray(cyl.axis, dtype=float)
                facet_normals = np.asarray(mesh.facets_normal, dtype=float) if len(mesh.facets) else np.zeros((0, 3))
                for k in [k for k in range(len(mesh.facets)) if abs(facet_normals[k] @ axis) > 1.0 - 1e-9]:
                    faces = np.asarray(mesh.facets[k], dtype=np.int64) + offset
                    side = np.sign(facet_normals[k] @ axis)
                    normals.append(facet_normals[k])
                    surfaces.append(s)
                    patches.append(int(raycaster.patch_index[faces[0]]))
                    material_of.append(material_index(obj.material))
                    points.append(np.asarray(cyl.center_m) + side * 0.5 * cyl.length_m * axis)
                    polygons.append(tri_all[faces[:1]])
                    discs.append(float(cyl.radius_m))
        m = len(points)
        t = max((len(p) for p in polygons), default=1)
        triangles = np.zeros((m, t, 3, 3))
        for i, poly in enumerate(polygons):
            triangles[i, : len(poly)] = poly
            triangles[i, len(poly):] = poly[0]
        point_arr = np.array(points, dtype=float).reshape(m, 3)
        normal_arr = np.array(normals, dtype=float).reshape(m, 3)
        disc_arr = np.array(discs, dtype=float)
        corners = triangles.reshape(m, 3 * t, 3).copy()
        for i in np.flatnonzero(np.isfinite(disc_arr)):  # 8 rim points stand for a disc
            helper = np.array([1.0, 0.0, 0.0]) if abs(normal_arr[i, 0]) < 0.9 else np.array([0.0, 1.0, 0.0])
            u = np.cross(normal_arr[i], helper)
            u /= np.linalg.norm(u)
            w = np.cross(normal_arr[i], u)
            ang = np.linspace(0.0, 2.0 * np.pi, corners.shape[1], endpoint=False)
            corners[i] = point_arr[i] + disc_arr[i] * (np.outer(np.cos(ang), u) + np.outer(np.sin(ang), w))
        # front[i, j]: some corner of mirror j is in front of plane i (beyond 1e-9 m of round-off)
        offset = np.einsum("ik,ik->i", point_arr, normal_arr)
        height = np.einsum("jvk,ik->ijv", corners, normal_arr) - offset[:, None, None]
        front = np.any(height > 1e-9, axis=2)
        sees = front & front.T
        np.fill_diagonal(sees, False)
        return cls(
            point=point_arr,
            normal=normal_arr,
            surface=np.array(surfaces, dtype=np.int64),
            patch=np.array(patches, dtype=np.int64),
            material=np.array(material_of, dtype=np.int64),
            materials=tuple(materials),
            triangles=triangles,
            disc_radius=disc_arr,
            sees=sees,
        )

    # ------------------------------------------------------------------ geometry
    def signed_distance(self, points: NDArray[np.float64], mirror: NDArray[np.int64]) -> NDArray[np.float64]:
        """Distance (n,) of points (n, 3) in front of mirrors (n,) (positive on the water side)."""
        return np.einsum("ij,ij->i", points - self.point[mirror], self.normal[mirror])

    def reflect(self, points: NDArray[np.float64], mirror: NDArray[np.int64]) -> NDArray[np.float64]:
        """Images (n, 3) of points (n, 3) across the planes of mirrors (n,)."""
        return points - 2.0 * self.signed_distance(points, mirror)[:, None] * self.normal[mirror]

    @cached_property
    def triangle_frames(self) -> TriangleFrames:
        """The :class:`TriangleFrames` of the mirrors' triangles (computed once)."""
        tri = self.triangles
        a, b, c = tri[:, :, 0], tri[:, :, 1], tri[:, :, 2]
        v0, v1 = b - a, c - a
        d00 = np.einsum("ntk,ntk->nt", v0, v0)
        d01 = np.einsum("ntk,ntk->nt", v0, v1)
        d11 = np.einsum("ntk,ntk->nt", v1, v1)
        den = d00 * d11 - d01 * d01
        den = np.where(den > 0, den, np.inf)
        return TriangleFrames(*(np.ascontiguousarray(part) for part in (a, v0, v1, d00, d01, d11, den)))

    @cached_property
    def _sequence_cache(self) -> dict[int, NDArray[np.int64]]:
        """Every mirror sequence of a length, unconstrained at its ends (:meth:`sequences`)."""
        return {}

    def sequences(self, length: int, first: NDArray[np.bool_] | None = None,
                  last: NDArray[np.bool_] | None = None) -> NDArray[np.int64]:
        """:func:`mirror_sequences` of :attr:`sees` (same rows, same order).

        The sequences of a length without end constraints depend on the scene only: short ones
        (up to :data:`CACHED_SEQUENCE_ROWS` rows) are enumerated once and filtered by ``first``
        and ``last`` for each pose (the enumeration is lexicographic, so filtering keeps the
        order).
        """
        if length == 0:
            return np.zeros((1, 0), dtype=np.int64)
        cache = self._sequence_cache
        if length not in cache:
            rows_bound = self.count * int(self.sees.sum(axis=1).max(initial=0)) ** (length - 1)
            if rows_bound > CACHED_SEQUENCE_ROWS:
                return mirror_sequences(self.sees, length, first, last)
            cache[length] = mirror_sequences(self.sees, length)
        seqs = cache[length]
        keep = np.ones(seqs.shape[0], dtype=bool)
        if first is not None:
            keep &= np.asarray(first, dtype=bool)[seqs[:, 0]]
        if last is not None:
            keep &= np.asarray(last, dtype=bool)[seqs[:, -1]]
        return seqs[keep]  # a copy (the cache stays the caller's to read only)

    def contains(self, points: NDArray[np.float64], mirror: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Whether points (n, 3) on the planes of mirrors (n,) lie inside their polygons (or discs)."""
        radius = self.disc_radius[mirror]
        in_disc = np.linalg.norm(points - self.point[mirror], axis=1) <= radius * (1.0 + INSIDE_TOLERANCE)
        a, v0, v1, d00, d01, d11, den = (part[mirror] for part in self.triangle_frames)
        v2 = points[:, None, :] - a
        d20 = np.einsum("ntk,ntk->nt", v2, v0)
        d21 = np.einsum("ntk,ntk->nt", v2, v1)
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
        u = 1.0 - v - w
        inside = (u >= -INSIDE_TOLERANCE) & (v >= -INSIDE_TOLERANCE) & (w >= -INSIDE_TOLERANCE)
        return np.where(np.isnan(radius), np.any(inside, axis=1), in_disc)


def object_patch_count(raycaster: RayCaster, surface: int) -> int:
    """Number of planar patches (coplanar facets and lonely triangles) of one object's mesh."""
    labels = raycaster.patch_index[raycaster.surface_index == surface]
    return int(labels.max() - labels.min() + 1) if labels.size else 0


def is_polyhedral(obj: SceneObject, raycaster: RayCaster, surface: int) -> bool:
    """Whether an object without a primitive is traced as planar mirrors (a polyhedron).

    It is if every edge between non-coplanar faces is a crease (dihedral angle above
    ``smooth_mesh.CREASE_DEG``: the mesh does not approximate a curved surface) and it has at
    most :data:`MAX_OBJECT_MIRRORS` planar patches; otherwise it is a smooth mesh.
    """
    from acoustisim.propagation.smooth_mesh import CREASE_DEG

    if obj.primitive is not None or object_patch_count(raycaster, surface) > MAX_OBJECT_MIRRORS:
        return False
    angles = np.asarray(obj.mesh.face_adjacency_angles, dtype=float)
    # 1e-6 rad: trimesh's own coplanarity tolerance for facets is of this order
    return not bool(np.any((angles > 1e-6) & (angles < np.radians(CREASE_DEG))))


def mirror_sequences(sees: NDArray[np.bool_], length: int, first: NDArray[np.bool_] | None = None,
                     last: NDArray[np.bool_] | None = None) -> NDArray[np.int64]:
    """Candidate mirror sequences (k, length) along which a wave could travel.

    Parameters
    ----------
    sees : ndarray of bool, shape (m, m)
        Mirror-to-mirror visibility (:attr:`PlanarMirrors.sees`); consecutive mirrors must see
        each other (this also excludes a mirror twice in a row).
    length : int
        Number of mirrors (0 gives one empty sequence).
    first, last : ndarray of bool, shape (m,), optional
        Mirrors allowed first / last (e.g. those the transmitter is in front of).
    """
    m = sees.shape[0]
    if length == 0:
        return np.zeros((1, 0), dtype=np.int64)
    allowed = np.ones(m, dtype=bool) if first is None else np.asarray(first, dtype=bool)
    seqs = np.flatnonzero(allowed)[:, None]
    for _ in range(length - 1):
        rows, nxt = np.nonzero(sees[seqs[:, -1]])
        seqs = np.concatenate([seqs[rows], nxt[:, None]], axis=1)
    if last is not None:
        seqs = seqs[np.asarray(last, dtype=bool)[seqs[:, -1]]]
    return seqs.astype(np.int64)


__all__ = ("CACHED_SEQUENCE_ROWS", "INSIDE_TOLERANCE", "MAX_OBJECT_MIRRORS", "ON_PLANE_TOLERANCE_M", "PlanarMirrors",
           "TriangleFrames", "is_polyhedral", "mirror_sequences", "object_patch_count")
