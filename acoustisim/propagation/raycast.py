"""Batched ray queries on a whole scene with Embree (embreex).

One Embree scene is built per :class:`~acoustisim.scene.Scene`: every object mesh and every
tank boundary rectangle, concatenated into one triangle geometry so that Embree's primitive
index is the global triangle index. Each triangle carries

* ``surface_index``: the index into ``scene.surface_names`` (boundaries first, then objects),
* ``patch_index``: a *planar patch* (a tank boundary, a coplanar facet of a polyhedral object)
  or, for an object with a convex analytic primitive (sphere, cylinder), the whole object.
  A patch cannot block a leg that ends on it from the water side (a plane cannot, nor can a
  convex body block a leg touching its own surface from outside), so legs ending on a
  reflecting patch exclude it instead of relying on a geometric epsilon alone.
* ``face_normals``: unit outward normals (into the water for boundaries), float64.

Embree works in float32; coordinates are shifted to the scene's centre before conversion so
that the round-off is about 5e-7 m in a 9 m tank. Every query is one batched call.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError
from acoustisim.propagation.convex_planes import ConvexPlanes, convex_object_planes
from acoustisim.propagation.tank_box import TankBox, object_boxes, tank_box
from acoustisim.scene import Scene

DEFAULT_EPS_M = 1e-4
"""Default shrink (m) of an occlusion segment at each end: 200 float32 ulps in a 9 m tank and
far below any object size, so a leg ending on a surface does not hit that surface."""

_MAX_EXCLUSION_PASSES = 16
"""Most re-launches of a segment past hits on excluded patches (a leg crosses a plane once and
a tessellated convex body at most twice; the cap only guards against pathological meshes)."""


@dataclass(frozen=True)
class RayHits:
    """First hits of a batch of rays.

    Attributes
    ----------
    distance_m : ndarray, shape (n,)
        Distance along the (unit) direction to the hit (m); ``inf`` where nothing was hit.
    triangle : ndarray of int64, shape (n,)
        Global triangle index, -1 where nothing was hit.
    surface : ndarray of int64, shape (n,)
        Index into ``scene.surface_names``, -1 where nothing was hit.
    normal : ndarray, shape (n, 3)
        Unit face normal of the hit triangle (outward from objects, into the water for the
        tank boundaries), NaN where nothing was hit.
    """

    distance_m: NDArray[np.float64]
    triangle: NDArray[np.int64]
    surface: NDArray[np.int64]
    normal: NDArray[np.float64]

    @property
    def hit(self) -> NDArray[np.bool_]:
        """Whether each ray hit something."""
        return self.triangle >= 0

    def points(self, origins: ArrayLike, directions: ArrayLike) -> NDArray[np.float64]:
        """Hit points (n, 3) (m), NaN where nothing was hit (directions must be the unit ones used)."""
        o = np.asarray(origins, dtype=float)
        d = np.asarray(directions, dtype=float)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        return np.where(self.hit[:, None], o + d * self.distance_m[:, None], np.nan)


def object_patches(mesh: Any, convex_whole: bool) -> NDArray[np.int64]:
    """Planar patch label per triangle of one mesh, 0..k-1.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    convex_whole : bool
        True for an object with a convex analytic primitive: the whole mesh is one patch.

    Returns
    -------
    ndarray of int64, shape (n_faces,)
        Coplanar adjacent faces (trimesh ``facets``) share a label; other faces get their own.
    """
    n = len(mesh.faces)
    if convex_whole:
        return np.zeros(n, dtype=np.int64)
    labels = np.full(n, -1, dtype=np.int64)
    facets = mesh.facets
    for k, faces in enumerate(facets):
        labels[faces] = k
    lonely = labels < 0
    labels[lonely] = len(facets) + np.arange(int(lonely.sum()))
    return labels


@dataclass(frozen=True, eq=False)
class RayCaster:
    """An Embree scene over all object meshes and tank boundaries, with per-triangle metadata.

    Build it with :meth:`from_scene` (once per scene; poses change nothing). Queries are
    vectorised: one Embree call per batch.

    Attributes
    ----------
    vertices : ndarray, shape (n_vertices, 3)
        All vertices (tank frame, m, float64).
    faces : ndarray of int64, shape (n_triangles, 3)
    face_normals : ndarray, shape (n_triangles, 3)
        Unit normals (outward / into the water).
    surface_index : ndarray of int64, shape (n_triangles,)
        Index into ``surface_names``.
    patch_index : ndarray of int64, shape (n_triangles,)
        Global planar-patch (or convex-object) label, see the module docstring.
    patch_surface : ndarray of int64, shape (n_patches,)
        Surface index of each patch.
    surface_names : tuple of str
    plane_offset : ndarray, shape (n_triangles,)
        ``face_normals . v0`` of each triangle (m): its plane is ``{x : n . x = plane_offset}``.
    convex_planes : ConvexPlanes
        The unique face planes of each convex object (none for the others), for the fast
        engine's exact geometric tests (:mod:`~acoustisim.propagation.convex_planes`).
    tank_box : TankBox or None
        The boundaries as the faces of an axis-aligned box (:mod:`~acoustisim.propagation.tank_box`),
        or None when they are not.
    object_boxes : ndarray, shape (n_objects, 2, 3)
        The axis-aligned box (lo, hi) of each object's triangles (m).
    """

    vertices: NDArray[np.float64] = field(repr=False)
    faces: NDArray[np.int64] = field(repr=False)
    face_normals: NDArray[np.float64] = field(repr=False)
    surface_index: NDArray[np.int64] = field(repr=False)
    patch_index: NDArray[np.int64] = field(repr=False)
    patch_surface: NDArray[np.int64] = field(repr=False)
    surface_names: tuple[str, ...]
    plane_offset: NDArray[np.float64] = field(repr=False)
    _shift: NDArray[np.float64] = field(repr=False)
    _embree: Any = field(repr=False)
    _buffers: tuple[Any, ...] = field(repr=False)
    convex_planes: ConvexPlanes = field(repr=False, default_factory=ConvexPlanes.none)
    tank_box: TankBox | None = field(repr=False, default=None)
    object_boxes: NDArray[np.float64] = field(repr=False, default_factory=lambda: np.zeros((0, 2, 3)))

    @classmethod
    def from_scene(cls, scene: Scene) -> "RayCaster":
        """Build the Embree scene of ``scene`` (objects and boundaries).

        Raises
        ------
        InputError
            If a mesh has no triangles or non-finite vertices.
        """
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        vertex_blocks: list[NDArray[np.float64]] = []
        face_blocks: list[NDArray[np.int64]] = []
        normal_blocks: list[NDArray[np.float64]] = []
        surface_blocks: list[NDArray[np.int64]] = []
        patch_blocks: list[NDArray[np.int64]] = []
        patch_surface: list[NDArray[np.int64]] = []
        n_vertices = 0
        n_patches = 0
        surface = 0
        for boundary in scene.boundaries:
            mesh = boundary.mesh
            faces = np.asarray(mesh.faces, dtype=np.int64)
            vertex_blocks.append(np.asarray(mesh.vertices, dtype=float))
            face_blocks.append(faces + n_vertices)
            normal_blocks.append(np.tile(np.asarray(boundary.plane.normal, dtype=float), (len(faces), 1)))
            surface_blocks.append(np.full(len(faces), surface, dtype=np.int64))
            patch_blocks.append(np.full(len(faces), n_patches, dtype=np.int64))
            patch_surface.append(np.array([surface], dtype=np.int64))
            n_vertices += len(mesh.vertices)
            n_patches += 1
            surface += 1
        for obj in scene.objects:
            mesh = obj.mesh
            vertices = np.asarray(mesh.vertices, dtype=float)
            if vertices.size == 0 or len(mesh.faces) == 0:
                raise InputError(f"object {obj.name!r}: mesh has no triangles")
            if not np.all(np.isfinite(vertices)):
                raise InputError(f"object {obj.name!r}: mesh has non-finite vertices")
            faces = np.asarray(mesh.faces, dtype=np.int64)
            labels = object_patches(mesh, obj.primitive is not None)
            k = int(labels.max()) + 1
            vertex_blocks.append(vertices)
            face_blocks.append(faces + n_vertices)
            normal_blocks.append(np.asarray(mesh.face_normals, dtype=float))
            surface_blocks.append(np.full(len(faces), surface, dtype=np.int64))
            patch_blocks.append(labels + n_patches)
            patch_surface.append(np.full(k, surface, dtype=np.int64))
            n_vertices += len(vertices)
            n_patches += k
            surface += 1
        empty = not face_blocks  # free field without objects: every query misses
        vertices = np.concatenate(vertex_blocks) if not empty else np.zeros((0, 3))
        faces = np.concatenate(face_blocks) if not empty else np.zeros((0, 3), dtype=np.int64)
        shift = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0)) if not empty else np.zeros(3)
        vertices32 = np.ascontiguousarray(vertices - shift, dtype=np.float32)
        faces32 = np.ascontiguousarray(faces, dtype=np.int32)
        embree = rtcore_scene.EmbreeScene()
        if not empty:
            TriangleMesh(embree, vertices32, faces32)
        # Embree builds its BVH lazily on the first query: do it here, once per scene, so that
        # per-pose queries (and their timings) do not pay for it
        embree.run(np.zeros((1, 3), dtype=np.float32), np.array([[1.0, 0.0, 0.0]], dtype=np.float32))

        def stack(blocks: list[NDArray[Any]], shape: tuple[int, ...], dtype: Any) -> NDArray[Any]:
            return np.concatenate(blocks) if blocks else np.zeros(shape, dtype=dtype)

        face_normals = stack(normal_blocks, (0, 3), float)
        surface_index = stack(surface_blocks, (0,), np.int64)
        plane_offset = np.einsum("ij,ij->i", face_normals, vertices[faces[:, 0]]) if not empty else np.zeros(0)
        n_boundaries = len(scene.boundaries)
        objects = range(n_boundaries, n_boundaries + len(scene.objects))
        return cls(
            vertices=vertices,
            faces=faces,
            face_normals=face_normals,
            surface_index=surface_index,
            patch_index=stack(patch_blocks, (0,), np.int64),
            patch_surface=stack(patch_surface, (0,), np.int64),
            surface_names=scene.surface_names,
            plane_offset=plane_offset,
            _shift=shift,
            _embree=embree,
            _buffers=(vertices32, faces32),
            convex_planes=convex_object_planes(vertices, faces, face_normals, plane_offset, surface_index, objects),
            tank_box=tank_box(vertices, faces, face_normals, surface_index < n_boundaries),
            object_boxes=object_boxes(vertices, faces, surface_index, objects),
        )

    def without_surfaces(self, surfaces: ArrayLike) -> "RayCaster":
        """A ray caster of the same scene without the triangles of ``surfaces``.

        Its triangles keep their metadata (surface index, patch label, normal, plane offset)
        and its patch labels stay the global ones, so that exclusion lists built for this ray
        caster mean the same here; only the Embree scene and the per-triangle arrays lose the
        triangles of ``surfaces`` (their objects are then never hit). Its ``convex_planes`` are
        none (every query a screen would decide goes to Embree), its ``tank_box`` and
        ``object_boxes`` those of the whole scene.

        Parameters
        ----------
        surfaces : array_like of int
            Indices into ``surface_names`` to leave out.
        """
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        keep = ~np.isin(self.surface_index, np.asarray(surfaces, dtype=np.int64))
        faces = self.faces[keep]
        vertices32 = self._buffers[0]
        faces32 = np.ascontiguousarray(faces, dtype=np.int32)
        embree = rtcore_scene.EmbreeScene()
        if faces.shape[0]:
            TriangleMesh(embree, vertices32, faces32)
        embree.run(np.zeros((1, 3), dtype=np.float32), np.array([[1.0, 0.0, 0.0]], dtype=np.float32))
        return RayCaster(
            vertices=self.vertices, faces=faces, face_normals=self.face_normals[keep],
            surface_index=self.surface_index[keep], patch_index=self.patch_index[keep],
            patch_surface=self.patch_surface, surface_names=self.surface_names,
            plane_offset=self.plane_offset[keep], _shift=self._shift, _embree=embree,
            _buffers=(vertices32, faces32), convex_planes=ConvexPlanes.none(self.object_boxes.shape[0]),
            tank_box=self.tank_box, object_boxes=self.object_boxes,
        )

    @property
    def triangle_count(self) -> int:
        """Number of triangles in the Embree scene."""
        return int(self.faces.shape[0])

    @property
    def shift_m(self) -> NDArray[np.float64]:
        """The offset (3,) (m) subtracted from tank coordinates before the float32 Embree scene."""
        return self._shift

    # ------------------------------------------------------------------ queries
    def first_hit_triangles32(self, origins32: NDArray[np.float32],
                              directions32: NDArray[np.float32]) -> NDArray[np.int32]:
        """Low-level batched first-hit query: the triangle index only.

        For callers that prepare Embree's buffers themselves (the diffuse tracer) and compute
        the hit distance from the triangle's plane (:attr:`plane_offset`, in float64).
        Releases the GIL: threads may query concurrently.

        Parameters
        ----------
        origins32 : ndarray of float32, shape (n, 3), C-contiguous
            Ray origins minus :attr:`shift_m` (m).
        directions32 : ndarray of float32, shape (n, 3), C-contiguous
            Unit directions.

        Returns
        -------
        ndarray of int32, shape (n,)
            Global triangle index, -1 where nothing was hit.
        """
        if origins32.shape[0] == 0 or self.triangle_count == 0:
            return np.full(origins32.shape[0], -1, dtype=np.int32)
        return self._embree.run(origins32, directions32, query="INTERSECT")

    def occluded_segments32(self, starts32: NDArray[np.float32], directions32: NDArray[np.float32],
                            lengths32: NDArray[np.float32]) -> NDArray[np.bool_]:
        """Low-level batched occlusion query on prepared float32 buffers.

        No end shrinking and no patch exclusion (see :meth:`occluded_rays` for those).
        Releases the GIL: threads may query concurrently.

        Parameters
        ----------
        starts32 : ndarray of float32, shape (n, 3), C-contiguous
            Segment starts minus :attr:`shift_m` (m).
        directions32 : ndarray of float32, shape (n, 3), C-contiguous
            Unit directions.
        lengths32 : ndarray of float32, shape (n,), C-contiguous
            Segment lengths (m).

        Returns
        -------
        ndarray of bool, shape (n,)
            Whether a triangle lies on each segment.
        """
        if starts32.shape[0] == 0 or self.triangle_count == 0:
            return np.zeros(starts32.shape[0], dtype=bool)
        return np.asarray(self._embree.run(starts32, directions32, dists=lengths32, query="OCCLUDED")) >= 0

    def _to_float32(self, points: NDArray[np.float64]) -> NDArray[np.float32]:
        """``points - shift`` as a C-contiguous float32 (n, 3) array, in one pass (the subtraction
        is done in float64 and rounded once, as ``(points - shift).astype(float32)`` would)."""
        out = np.empty(points.shape, dtype=np.float32)
        np.subtract(points, self._shift, out=out, casting="unsafe")
        return out

    def _run(self, origins32: NDArray[np.float32], directions: NDArray[np.float64],
             tfar: NDArray[np.float64] | None, query: str) -> Any:
        """One Embree call; ``origins32`` already shifted and float32 (see :meth:`_to_float32`)."""
        d32 = np.ascontiguousarray(directions, dtype=np.float32)
        output = 1 if query == "INTERSECT" else None
        if tfar is None:
            return self._embree.run(origins32, d32, query=query, output=output)
        t32 = np.ascontiguousarray(tfar, dtype=np.float32)
        return self._embree.run(origins32, d32, dists=t32, query=query, output=output)

    def intersect(self, origins: ArrayLike, directions: ArrayLike,
                  max_distance_m: ArrayLike | None = None, *, unit_directions: bool = False) -> RayHits:
        """First hit of each ray.

        Parameters
        ----------
        origins : array_like, shape (n, 3)
            Ray origins (tank frame, m). A broadcast single point (stride 0) is fine.
        directions : array_like, shape (n, 3)
            Ray directions (normalised here unless ``unit_directions``).
        max_distance_m : array_like, shape (n,) or scalar, optional
            Ignore hits farther than this (m).
        unit_directions : bool
            The caller guarantees unit directions: skip the normalisation (a pass over the rays).

        Returns
        -------
        RayHits
        """
        o = np.atleast_2d(np.asarray(origins, dtype=float))
        d = np.atleast_2d(np.asarray(directions, dtype=float))
        n = o.shape[0]
        if n == 0 or self.triangle_count == 0:
            return RayHits(np.full(n, np.inf), np.full(n, -1, np.int64), np.full(n, -1, np.int64),
                           np.full((n, 3), np.nan))
        if not unit_directions:
            d = d / np.linalg.norm(d, axis=1, keepdims=True)
        tfar = None if max_distance_m is None else np.broadcast_to(np.asarray(max_distance_m, float), (n,))
        out = self._run(self._to_float32(o), d, tfar, "INTERSECT")
        tri = out["primID"].astype(np.int64)
        hit = tri >= 0
        tfar32 = out["tfar"]
        if bool(hit.all()):  # a closed tank: no scatter/gather, every gather below is direct
            return RayHits(tfar32.astype(float), tri, self.surface_index[tri], self.face_normals[tri])
        # gather metadata of the hits only
        idx = np.flatnonzero(hit)
        tri_hit = tri[idx]
        dist = np.full(n, np.inf)
        dist[idx] = tfar32[idx]
        surface = np.full(n, -1, dtype=np.int64)
        surface[idx] = self.surface_index[tri_hit]
        normal = np.full((n, 3), np.nan)
        normal[idx] = self.face_normals[tri_hit]
        return RayHits(dist, tri, surface, normal)

    def occluded(self, origins: ArrayLike, targets: ArrayLike, eps: float = DEFAULT_EPS_M,
                 exclude_patches: ArrayLike | None = None) -> NDArray[np.bool_]:
        """Whether each segment origin -> target is blocked strictly between its ends.

        Parameters
        ----------
        origins, targets : array_like, shape (n, 3)
            Segment ends (tank frame, m).
        eps : float
            Each segment is shrunk by ``eps`` (m) at both ends, so surfaces the ends lie on do
            not count. Segments shorter than ``2 eps`` are never blocked.
        exclude_patches : array_like of int, shape (n, k), optional
            Patch labels (``patch_index`` values, -1 for none) ignored by each segment: the
            planar patches / convex objects its ends lie on.

        Returns
        -------
        ndarray of bool, shape (n,)
        """
        o = np.atleast_2d(np.asarray(origins, dtype=float))
        t = np.atleast_2d(np.asarray(targets, dtype=float))
        if o.shape != t.shape or o.ndim != 2 or o.shape[1] != 3:
            raise ValueError(f"origins and targets must both be (n, 3), got {o.shape} and {t.shape}")
        n = o.shape[0]
        if n == 0 or self.triangle_count == 0:
            return np.zeros(n, dtype=bool)
        seg = t - o
        length = np.linalg.norm(seg, axis=1)
        # (zero-length segments give NaN directions here; they are never cast, being short)
        with np.errstate(invalid="ignore", divide="ignore"):
            d = seg / length[:, None]
        return self.occluded_rays(o, d, length, eps=eps, exclude_patches=exclude_patches)

    def occluded_rays(self, origins: ArrayLike, unit_directions: ArrayLike, lengths_m: ArrayLike,
                      eps: float = DEFAULT_EPS_M, exclude_patches: ArrayLike | None = None) -> NDArray[np.bool_]:
        """:meth:`occluded` for segments given as origin, unit direction and length.

        For callers that have the directions and lengths already (the diffuse tracer's legs to
        the receivers): no target points, no norms recomputed.

        Parameters
        ----------
        origins : array_like, shape (n, 3)
            Segment starts (tank frame, m).
        unit_directions : array_like, shape (n, 3)
            Unit directions (not normalised here).
        lengths_m : array_like, shape (n,)
            Segment lengths (m).
        eps, exclude_patches
            As in :meth:`occluded`.

        Returns
        -------
        ndarray of bool, shape (n,)
        """
        o = np.atleast_2d(np.asarray(origins, dtype=float))
        d = np.atleast_2d(np.asarray(unit_directions, dtype=float))
        length = np.asarray(lengths_m, dtype=float).reshape(-1)
        n = o.shape[0]
        if d.shape != o.shape or o.shape[1:] != (3,) or length.shape != (n,):
            raise ValueError(f"origins {o.shape}, directions {d.shape} and lengths {length.shape} do not agree")
        blocked = np.zeros(n, dtype=bool)
        if n == 0 or self.triangle_count == 0:
            return blocked
        live = length > 2.0 * eps
        if bool(live.all()):
            idx = np.arange(n)
        else:
            idx = np.flatnonzero(live)
            if idx.size == 0:
                return blocked
            o, d, length = o[idx], d[idx], length[idx]
        start = eps * d
        start += o
        remaining = length - 2.0 * eps
        if exclude_patches is None:
            hits = np.asarray(self._run(self._to_float32(start), d, remaining, "OCCLUDED"))
            blocked[idx] = hits >= 0
            return blocked
        exclude = np.asarray(exclude_patches, dtype=np.int64)
        if exclude.ndim == 1:
            exclude = exclude[:, None]
        if idx.size < n:
            exclude = exclude[idx]
        for _ in range(_MAX_EXCLUSION_PASSES):
            out = self._run(self._to_float32(start), d, remaining, "INTERSECT")
            tri = out["primID"].astype(np.int64)
            hit = tri >= 0
            patch = np.where(hit, self.patch_index[np.where(hit, tri, 0)], -2)
            excluded_hit = hit & np.any(patch[:, None] == exclude, axis=1)
            blocked[idx[hit & ~excluded_hit]] = True
            again = excluded_hit
            if not np.any(again):
                return blocked
            dist = out["tfar"][again].astype(float)
            # step past the excluded triangle: float32 round-off at the hit is ~1e-6 of the
            # coordinate scale, so advance by a few of those.
            step = dist + 1e-6 * (1.0 + dist)
            idx, d, exclude = idx[again], d[again], exclude[again]
            start = start[again] + step[:, None] * d
            remaining = remaining[again] - step
            keep = remaining > 0.0
            idx, d, exclude, start, remaining = idx[keep], d[keep], exclude[keep], start[keep], remaining[keep]
            if idx.size == 0:
                return blocked
        blocked[idx] = True  # still crossing excluded patches after the cap: treat as blocked
        return blocked


__all__ = ["DEFAULT_EPS_M", "RayCaster", "RayHits", "object_patches"]
