"""Specular points on smooth triangle meshes (user meshes without an analytic primitive).

A smooth mesh is traced through its interpolated (Phong) vertex normals, split at creases
sharper than :data:`CREASE_DEG` so that true edges stay sharp. For a source A and receiver B,
a specular point is where the interpolated normal n(u, v) equals the bisector of the
directions to A and B seen from the point X(u, v) of the flat triangle (barycentric u, v):
solved by Newton's method on every triangle whose normal cone can contain the bisector
(vectorised over candidate (pair, triangle) combinations). Several specular points per pair are
possible (non-convex meshes).

The curvature tensor at X is the gradient of the interpolated normal (the shape operator
dn = S dX, symmetrised), which feeds the general bistatic Hessian of
:func:`acoustisim.propagation.reference.curved.go_amplitude`. Position and curvature converge to
the smooth surface's as O(h^2) in the mesh spacing h.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    import trimesh

CREASE_DEG = 30.0
"""Dihedral angle (degrees) above which an edge is a crease: normals are not interpolated across it."""

_NEWTON_STEPS = 12
"""Newton iterations in barycentric coordinates (quadratic convergence; 6-8 suffice from the centroid)."""

_CHUNK = 2_000_000
"""(pair, cluster) combinations screened per vectorised block (bounds the memory to ~0.5 GB)."""

_TRIANGLES_PER_CLUSTER = 600
"""Target triangles per cluster: the voxel grid has about sqrt(t / 600) cells per axis, which
balances the two screening stages (pairs x clusters, then pairs x triangles of near clusters)."""

_BARY_TOL = 1e-9
"""Barycentric slack at the triangle's edges (points on a shared edge belong to both triangles)."""


def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True, eq=False)
class SmoothMesh:
    """A mesh traced through interpolated normals.

    Attributes
    ----------
    triangles : ndarray, shape (t, 3, 3)
        Corner positions (m).
    corner_normals : ndarray, shape (t, 3, 3)
        Unit vertex normals at the corners (outward, split at creases).
    face_normals : ndarray, shape (t, 3)
    spread : ndarray, shape (t,)
        Largest angle (rad) between a corner normal and the face normal.
    size : ndarray, shape (t,)
        Longest edge (m).
    source_face : ndarray of int64, shape (t,)
        Index of each triangle in the original mesh (crease splitting may reorder faces).
    cluster_order : ndarray of int64, shape (t,)
        Triangles sorted by cluster (a voxel grid, :data:`_TRIANGLES_PER_CLUSTER`).
    cluster_start : ndarray of int64, shape (c + 1,)
        Offsets of each cluster in ``cluster_order``.
    cluster_centre, cluster_radius, cluster_axis, cluster_cone : ndarray
        Bounding sphere (c, 3), (c,) (m) and normal cone (unit axis (c, 3), half-angle (c,) rad)
        of each cluster, for a coarse screening before the triangles.
    """

    triangles: NDArray[np.float64] = field(repr=False)
    corner_normals: NDArray[np.float64] = field(repr=False)
    face_normals: NDArray[np.float64] = field(repr=False)
    spread: NDArray[np.float64] = field(repr=False)
    size: NDArray[np.float64] = field(repr=False)
    source_face: NDArray[np.int64] = field(repr=False)
    cluster_order: NDArray[np.int64] = field(repr=False)
    cluster_start: NDArray[np.int64] = field(repr=False)
    cluster_centre: NDArray[np.float64] = field(repr=False)
    cluster_radius: NDArray[np.float64] = field(repr=False)
    cluster_axis: NDArray[np.float64] = field(repr=False)
    cluster_cone: NDArray[np.float64] = field(repr=False)

    @classmethod
    def from_mesh(cls, mesh: "trimesh.Trimesh") -> "SmoothMesh":
        """Interpolated normals of a mesh, split at creases (``source_face`` maps the faces back)."""
        import trimesh

        smooth = trimesh.graph.smooth_shade(mesh, angle=np.radians(CREASE_DEG), facet_minarea=None)
        triangles = np.asarray(smooth.triangles, dtype=float)
        faces = np.asarray(smooth.faces)
        # vertex normals with Max's (1999) weights, cross(e1, e2) / (|e1|^2 |e2|^2) per corner:
        # exact for vertices on a sphere, so the interpolated normal's gradient (the curvature)
        # converges with refinement (area weights leave an O(1) error in the gradient)
        n_vertices = len(smooth.vertices)
        summed = np.zeros((n_vertices, 3))
        for corner in range(3):
            e1 = triangles[:, (corner + 1) % 3] - triangles[:, corner]
            e2 = triangles[:, (corner + 2) % 3] - triangles[:, corner]
            weight = np.einsum("ij,ij->i", e1, e1) * np.einsum("ij,ij->i", e2, e2)
            contribution = np.cross(e1, e2) / weight[:, None]
            for k in range(3):  # bincount: a scatter-add far faster than np.add.at
                summed[:, k] += np.bincount(faces[:, corner], contribution[:, k], minlength=n_vertices)
        vertex_normals = _unit(summed)
        corner_normals = vertex_normals[faces]
        face_normals = np.asarray(smooth.face_normals, dtype=float)
        cosines = np.einsum("tjk,tk->tj", corner_normals, face_normals)
        spread = np.arccos(np.clip(cosines.min(axis=1), -1.0, 1.0))
        edges = triangles[:, [1, 2, 0]] - triangles
        size = np.linalg.norm(edges, axis=2).max(axis=1)
        from scipy.spatial import cKDTree

        _, source_face = cKDTree(np.asarray(mesh.triangles_center)).query(triangles.mean(axis=1))
        # clusters: a voxel grid over the triangle centroids
        centroid = triangles.mean(axis=1)
        lo, hi = centroid.min(axis=0), centroid.max(axis=0)
        per_axis = int(np.clip(np.sqrt(len(triangles) / _TRIANGLES_PER_CLUSTER), 4, 128))
        cell = max(float(np.max(hi - lo)) / per_axis, 1e-12)
        ijk = np.floor((centroid - lo) / cell).astype(np.int64)
        key = (ijk[:, 0] * (per_axis + 1) + ijk[:, 1]) * (per_axis + 1) + ijk[:, 2]
        _, cluster = np.unique(key, return_inverse=True)
        order = np.argsort(cluster, kind="stable")
        counts = np.bincount(cluster)
        start = np.concatenate([[0], np.cumsum(counts)])
        n_clusters = counts.size

        def per_cluster_sum(values: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.stack([np.bincount(cluster, values[:, k], minlength=n_clusters) for k in range(3)], axis=1)

        centre = per_cluster_sum(centroid) / counts[:, None]
        corner_dist = np.linalg.norm(triangles - centre[cluster][:, None, :], axis=2).max(axis=1)
        radius = np.zeros(n_clusters)
        np.maximum.at(radius, cluster, corner_dist)
        axis = per_cluster_sum(face_normals)
        axis_norm = np.linalg.norm(axis, axis=1, keepdims=True)
        axis = np.where(axis_norm > 1e-12, axis / np.where(axis_norm > 0, axis_norm, 1.0), np.array([[0.0, 0.0, 1.0]]))
        corner_angle = np.arccos(np.clip(np.einsum("tjk,tk->tj", corner_normals, axis[cluster]), -1.0, 1.0)).max(axis=1)
        cone = np.zeros(n_clusters)
        np.maximum.at(cone, cluster, corner_angle)
        return cls(triangles, corner_normals, face_normals, spread, size, np.asarray(source_face, dtype=np.int64),
                   order.astype(np.int64), start.astype(np.int64), centre, radius, axis, cone)

    def _normal(self, tri: NDArray[np.int64], u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        n = self.corner_normals[tri]
        return (1.0 - u - v)[:, None] * n[:, 0] + u[:, None] * n[:, 1] + v[:, None] * n[:, 2]

    def _point(self, tri: NDArray[np.int64], u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        p = self.triangles[tri]
        return p[:, 0] + u[:, None] * (p[:, 1] - p[:, 0]) + v[:, None] * (p[:, 2] - p[:, 0])

    def specular_points(self, a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """All specular points of pairs (a[i], b[i]).

        Parameters
        ----------
        a, b : ndarray, shape (n, 3)
            (Image) source and receiver (m).

        Returns
        -------
        pair : ndarray of int64, shape (m,)
            Which pair each solution belongs to.
        triangle : ndarray of int64, shape (m,)
        point, normal : ndarray, shape (m, 3)
            Specular point on the flat triangle (m) and the interpolated unit normal there.
        e1, e2 : ndarray, shape (m, 3)
            Orthonormal tangent basis.
        k11, k22, k12 : ndarray, shape (m,)
            Shape operator in (e1, e2) (1/m, convex > 0), symmetrised.
        """
        if a.shape[0] == 0:
            z0, e0 = np.zeros(0), np.zeros((0, 3))
            return np.zeros(0, np.int64), np.zeros(0, np.int64), e0, e0, e0, e0, z0, z0, z0
        # 1. clusters whose normal cone can hold the bisector (which turns by at most ~ 2 R / r
        #    across a cluster of radius R seen from r), vectorised over pairs x clusters in chunks
        n_clusters = self.cluster_radius.size
        pair_list, cluster_list = [], []
        chunk = max(1, _CHUNK // max(1, n_clusters))
        for start in range(0, a.shape[0], chunk):  # a loop over chunks of pairs
            da = a[start:start + chunk, None, :] - self.cluster_centre[None]
            db = b[start:start + chunk, None, :] - self.cluster_centre[None]
            ra = np.linalg.norm(da, axis=2)
            rb = np.linalg.norm(db, axis=2)
            h = da / ra[..., None] + db / rb[..., None]
            with np.errstate(invalid="ignore", divide="ignore"):  # opposite ends: no bisector, NaN fails below
                cos_h = np.einsum("pck,ck->pc", h, self.cluster_axis) / np.linalg.norm(h, axis=2)
                turn = 2.0 * self.cluster_radius[None] / np.maximum(np.minimum(ra, rb) - self.cluster_radius[None], 1e-12)
            slack = np.minimum(self.cluster_cone[None] + 2.0 * turn + 1e-3, np.pi)
            p_idx, c_idx = np.nonzero(cos_h > np.cos(slack))
            pair_list.append(p_idx + start)
            cluster_list.append(c_idx)
        pc = np.concatenate(pair_list).astype(np.int64)
        cc = np.concatenate(cluster_list).astype(np.int64)
        # 2. their triangles, screened one by one (3x margins on the bisector's turn)
        counts = self.cluster_start[cc + 1] - self.cluster_start[cc]
        first = np.repeat(self.cluster_start[cc] - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
        tri = self.cluster_order[first + np.arange(int(counts.sum()))]
        pair = np.repeat(pc, counts)
        centroid = self.triangles[tri].mean(axis=1)
        da = a[pair] - centroid
        db = b[pair] - centroid
        ra = np.linalg.norm(da, axis=1)
        rb = np.linalg.norm(db, axis=1)
        fn = self.face_normals[tri]
        with np.errstate(invalid="ignore", divide="ignore"):
            h = _unit(da / ra[:, None] + db / rb[:, None])
        slack = 3.0 * self.spread[tri] + 3.0 * self.size[tri] / np.minimum(ra, rb) + 1e-6
        lit = (np.einsum("ij,ij->i", da, fn) > 0) & (np.einsum("ij,ij->i", db, fn) > 0)
        near = lit & (np.einsum("ij,ij->i", h, fn) > np.cos(np.minimum(slack, np.pi / 2)))
        pair_list, tri_list = [pair[near]], [tri[near]]
        pair = np.concatenate(pair_list).astype(np.int64) if pair_list else np.zeros(0, np.int64)
        tri = np.concatenate(tri_list).astype(np.int64) if tri_list else np.zeros(0, np.int64)
        empty = np.zeros((0, 3))
        if tri.size == 0:
            z = np.zeros(0)
            return pair, tri, empty, empty, empty, empty, z, z, z
        p = self.triangles[tri]
        e_u = p[:, 1] - p[:, 0]
        e_v = p[:, 2] - p[:, 0]
        cn = self.corner_normals[tri]
        # Newton on the survivors only, with their data gathered once; candidates whose iterate
        # leaves the neighbourhood of their triangle are dropped as the iterations go
        live = np.arange(tri.size)
        u = np.full(tri.size, 1.0 / 3.0)
        v = np.full(tri.size, 1.0 / 3.0)

        def residual(k: NDArray[np.int64], uu: NDArray[np.float64], vv: NDArray[np.float64]) -> NDArray[np.float64]:
            x = p[k, 0] + uu[:, None] * e_u[k] + vv[:, None] * e_v[k]
            h = _unit(_unit(a[pair[k]] - x) + _unit(b[pair[k]] - x))
            nrm = _unit(cn[k, 0] + uu[:, None] * (cn[k, 1] - cn[k, 0]) + vv[:, None] * (cn[k, 2] - cn[k, 0]))
            d = h - nrm
            t1 = _unit(e_u[k])
            t2 = np.cross(self.face_normals[tri[k]], t1)
            return np.stack([np.einsum("ij,ij->i", d, t1), np.einsum("ij,ij->i", d, t2)], axis=1)

        step = 1e-7
        for iteration in range(_NEWTON_STEPS):
            uu, vv = u[live], v[live]
            f = residual(live, uu, vv)
            ju = (residual(live, uu + step, vv) - f) / step
            jv = (residual(live, uu, vv + step) - f) / step
            det = ju[:, 0] * jv[:, 1] - ju[:, 1] * jv[:, 0]
            det = np.where(np.abs(det) > 1e-300, det, 1e-300)
            du = np.clip((f[:, 0] * jv[:, 1] - f[:, 1] * jv[:, 0]) / det, -0.5, 0.5)
            dv = np.clip((ju[:, 0] * f[:, 1] - ju[:, 1] * f[:, 0]) / det, -0.5, 0.5)
            u[live] = uu - du
            v[live] = vv - dv
            if iteration >= 3:  # far outside the triangle after 4 steps: another triangle's point
                near = (u[live] > -1.0) & (v[live] > -1.0) & (u[live] + v[live] < 2.0)
                moving = np.maximum(np.abs(du), np.abs(dv)) > 1e-14
                live = live[near & moving]
            if live.size == 0:
                break
        f = residual(np.arange(tri.size), u, v)
        ok = (np.linalg.norm(f, axis=1) < 1e-10) & (u >= -_BARY_TOL) & (v >= -_BARY_TOL) & (u + v <= 1 + _BARY_TOL)
        pair, tri, u, v, e_u, e_v = pair[ok], tri[ok], u[ok], v[ok], e_u[ok], e_v[ok]
        x = self._point(tri, u, v)
        raw = self._normal(tri, u, v)
        norm = np.linalg.norm(raw, axis=1, keepdims=True)
        n = raw / norm
        # a point on an edge shared by two triangles is found twice: keep one per pair
        key = np.column_stack([pair, np.round(x / 1e-7)]).astype(np.int64)
        _, first = np.unique(key, axis=0, return_index=True)
        first = np.sort(first)
        pair, tri, x, n, norm, e_u, e_v = pair[first], tri[first], x[first], n[first], norm[first], e_u[first], e_v[first]
        # shape operator from the normal's gradient: dn = S dX on the tangent plane
        cn = self.corner_normals[tri]
        proj = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
        dn_du = np.einsum("ijk,ik->ij", proj, cn[:, 1] - cn[:, 0]) / norm
        dn_dv = np.einsum("ijk,ik->ij", proj, cn[:, 2] - cn[:, 0]) / norm
        e1 = _unit(np.einsum("ijk,ik->ij", proj, e_u))
        e2 = np.cross(n, e1)

        def in_basis(w: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.stack([np.einsum("ij,ij->i", w, e1), np.einsum("ij,ij->i", w, e2)], axis=1)

        big_n = np.stack([in_basis(dn_du), in_basis(dn_dv)], axis=1)  # rows: d/du, d/dv
        big_m = np.stack([in_basis(e_u), in_basis(e_v)], axis=1)
        shape = np.swapaxes(np.linalg.solve(big_m, big_n), 1, 2)
        shape = 0.5 * (shape + np.swapaxes(shape, 1, 2))
        return pair, tri, x, n, e1, e2, shape[:, 0, 0], shape[:, 1, 1], shape[:, 0, 1]


__all__ = ["CREASE_DEG", "SmoothMesh"]
