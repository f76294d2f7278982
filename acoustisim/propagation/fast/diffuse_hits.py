"""First hits of the diffuse tracer's rays in a box tank with convex objects, without Embree.

In a tank whose boundaries are the six faces of an axis-aligned box (walls, floor and free
surface, triangles lying in the faces with their normals into the water) and whose objects are
convex meshes with face planes (:class:`~acoustisim.propagation.convex_planes.ConvexPlanes`: the
prisms, posts and pipes), the first surface a ray from a point in the water meets is found
exactly in float64, without a ray-tracing query:

* the tank: the ray leaves the box through the face of the smallest exit distance (the slab
  test); a ray from inside the box meets no boundary before (every boundary triangle lies in a
  face, and the other faces' planes are crossed outside the box); the triangle is the one of
  that face containing the exit point (a 2-D edge-function test);
* a convex object: the ray, clipped against the object's face planes (Cyrus and Beck 1978, as
  :func:`~acoustisim.propagation.fast.convex_occlusion.segment_crosses_convex`), enters the
  solid at ``t_enter`` through the plane of the largest entry distance; a convex surface is
  crossed once on the way in, so the nearest object entry closer than the box exit is the first
  hit, even for objects that overlap. Only rays crossing an object's bounding box are clipped
  (and, when every ray starts at one origin, the transmitter, only those inside the cone of
  directions of the box's bounding sphere are tested against the box: one dot product); the hit
  triangle is the triangle the entering plane was taken from (same normal, offset and surface).

A ray the rules above cannot decide is left *pending*, for an Embree query: its origin outside
the box or inside an object, an object without face planes (not convex) on its way, an exit
point in no triangle of its face (a hole, or a face tiled by more than
:data:`MAX_FACE_TRIANGLES` triangles). The answers equal Embree's but for rays grazing an edge
within Embree's float32 rounding (about 1e-6 m in a 9 m tank).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.convex_planes import ConvexPlanes
from acoustisim.propagation.fast.convex_occlusion import PlaneSet, plane_set
from acoustisim.propagation.raycast import RayCaster

MAX_FACE_TRIANGLES = 64
"""Most triangles tiling one face of the tank box searched per ray; a finer face sends the
first hits back to Embree (its BVH is faster than a linear search there)."""

FACE_TOLERANCE_M = 1e-9
"""How far outside a face triangle (m) an exit point still counts as in it: a million times
below Embree's float32 rounding, far above the float64 rounding of the exit point (1e-15 m),
so a point on a shared edge or the face's border is never lost between two triangles."""

BOX_MARGIN_M = 1e-6
"""Growth (m) of the object boxes that decide which rays are clipped against an object's planes
(a conservative screen: the clipping itself is exact)."""


class BoxTank(NamedTuple):
    """What :func:`first_hits` needs of a box tank with convex objects.

    Attributes
    ----------
    bounds : ndarray, shape (2, 3)
        The tank box (lo, hi) (m).
    face_start : ndarray of int64, shape (7,)
        Face ``f = 2 axis + side`` (side 0 at lo, 1 at hi) has the triangles
        ``face_triangle[face_start[f]:face_start[f + 1]]``.
    face_triangle : ndarray of int64, shape (k,)
        Global triangle indices.
    face_edges : ndarray, shape (k, 3, 3)
        Per triangle, its three edges as ``(a, b, c)`` with ``a u + b v + c`` the signed
        distance (m) of the point (u, v) from the edge, positive inside; (u, v) are the
        coordinates ``((axis + 1) % 3, (axis + 2) % 3)`` of the face.
    boxes : ndarray, shape (n_objects, 2, 3)
        Object boxes (lo, hi) grown by :data:`BOX_MARGIN_M` (m).
    planes : PlaneSet
        The objects' face planes (none: not convex, a ray crossing its box is pending).
    plane_triangle : ndarray of int64, shape (n_planes,) (at least 1)
        The triangle each plane was taken from.
    """

    bounds: NDArray[np.float64]
    face_start: NDArray[np.int64]
    face_triangle: NDArray[np.int64]
    face_edges: NDArray[np.float64]
    boxes: NDArray[np.float64]
    planes: PlaneSet
    plane_triangle: NDArray[np.int64]


def box_tank(raycaster: RayCaster) -> BoxTank | None:
    """The description of ``raycaster``'s scene, or None when its boundaries are not the faces
    of an axis-aligned box with normals into the water (or it has none).

    The objects are the surfaces after the boundaries, one per row of
    ``raycaster.convex_planes``.
    """
    planes: ConvexPlanes = raycaster.convex_planes
    n_objects = planes.start.size - 1
    n_boundaries = len(raycaster.surface_names) - n_objects
    surface = raycaster.surface_index
    boundary = surface < n_boundaries
    if n_boundaries <= 0 or not np.any(boundary):
        return None
    faces = raycaster.faces[boundary]
    corners = raycaster.vertices[faces]  # (k, 3, 3)
    lo, hi = corners.reshape(-1, 3).min(axis=0), corners.reshape(-1, 3).max(axis=0)
    if not np.all(hi > lo):
        return None
    normal = raycaster.face_normals[boundary]
    axis = np.argmax(np.abs(normal), axis=1)
    rows = np.arange(faces.shape[0])
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
    face_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    boxes = np.zeros((n_objects, 2, 3))
    if n_objects:
        objects = np.flatnonzero(~boundary)
        points = raycaster.vertices[raycaster.faces[objects]]  # (t, 3, 3)
        owner = surface[objects] - n_boundaries  # non-decreasing: each object's triangles are one block
        starts = np.searchsorted(owner, np.arange(n_objects))
        boxes[:, 0] = np.minimum.reduceat(points.min(axis=1), starts, axis=0) - BOX_MARGIN_M
        boxes[:, 1] = np.maximum.reduceat(points.max(axis=1), starts, axis=0) + BOX_MARGIN_M
    plane_triangle = planes.triangle if planes.triangle.size else np.zeros(1, dtype=np.int64)
    return BoxTank(np.stack([lo, hi]), face_start, np.ascontiguousarray(np.flatnonzero(boundary)[order]),
                   np.ascontiguousarray(edges[order]), boxes, plane_set(planes),
                   np.ascontiguousarray(plane_triangle, dtype=np.int64))


@njit(cache=True, nogil=True, error_model="numpy")
def _in_box(ox: float, oy: float, oz: float, ix: float, iy: float, iz: float, sx: int, sy: int, sz: int,
            boxes: NDArray[np.float64], b: int, t_max: float) -> bool:
    """Whether the ray o + t d, 0 <= t <= t_max, meets box ``boxes[b]`` ((lo, hi) x 3): the slab
    test with the inverse components ``i = 1 / d`` (+-inf for a zero component, which makes that
    slab's bounds +-inf: no constraint inside the slab, an empty interval outside; a NaN, for an
    origin exactly on that slab's face, fails the comparisons and can only make the answer True:
    conservative, the face planes decide) and ``s`` = 1 where a component is negative (the near
    side is then ``hi``). No data-dependent branch."""
    enter = (boxes[b, sx, 0] - ox) * ix
    leave = (boxes[b, 1 - sx, 0] - ox) * ix
    t = (boxes[b, sy, 1] - oy) * iy
    enter = t if t > enter else enter
    t = (boxes[b, 1 - sy, 1] - oy) * iy
    leave = t if t < leave else leave
    t = (boxes[b, sz, 2] - oz) * iz
    enter = t if t > enter else enter
    t = (boxes[b, 1 - sz, 2] - oz) * iz
    leave = t if t < leave else leave
    enter = enter if enter > 0.0 else 0.0
    leave = leave if leave < t_max else t_max
    return enter <= leave


@njit(cache=True, nogil=True, error_model="numpy")
def _box_cones(boxes: NDArray[np.float64], ox: float, oy: float, oz: float) -> NDArray[np.float64]:
    """Per box (n, 4): the cone of directions from the origin o of the box's bounding sphere, as
    its unit axis and the cosine of its half angle (-2: o inside the sphere, every direction).
    A ray outside the cone misses the box: one dot product instead of the slab test."""
    cone = np.empty((boxes.shape[0], 4))
    cone[:, :3], cone[:, 3] = 0.0, -2.0
    for b in range(boxes.shape[0]):
        wx = 0.5 * (boxes[b, 0, 0] + boxes[b, 1, 0]) - ox
        wy = 0.5 * (boxes[b, 0, 1] + boxes[b, 1, 1]) - oy
        wz = 0.5 * (boxes[b, 0, 2] + boxes[b, 1, 2]) - oz
        radius = 0.5 * math.sqrt((boxes[b, 1, 0] - boxes[b, 0, 0]) ** 2 + (boxes[b, 1, 1] - boxes[b, 0, 1]) ** 2
                                 + (boxes[b, 1, 2] - boxes[b, 0, 2]) ** 2)
        distance = math.sqrt(wx * wx + wy * wy + wz * wz)
        if distance > 1.001 * radius:
            cone[b, 0], cone[b, 1], cone[b, 2] = wx / distance, wy / distance, wz / distance
            # the half angle's cosine, lowered by 1e-9 for the rounding of these few operations
            cone[b, 3] = math.sqrt(1.0 - (radius / distance) ** 2) - 1e-9
    return cone


@njit(cache=True, nogil=True, error_model="numpy")
def first_hits(origins: NDArray[np.float64], directions: NDArray[np.float64], tank: BoxTank,
               triangle: NDArray[np.int32], pending: NDArray[np.int64]) -> int:
    """The first-hit triangle of each ray (see the module docstring), or the rays left pending.

    Parameters
    ----------
    origins : ndarray, shape (3, m) or (3, 1)
        Ray origins (m); one column is shared by every ray.
    directions : ndarray, shape (3, m)
        Ray directions (any non-zero length).
    tank : BoxTank
    triangle : output of int32, shape (>= m,)
        The hit triangle (global index) of each decided ray (a ray from inside the box always
        meets a face); pending rays' entries are left unwritten.
    pending : output of int64, shape (>= m,)
        The indices of the pending rays, in ray order, from index 0.

    Returns
    -------
    int
        The number of pending rays.
    """
    one_origin = origins.shape[1] == 1
    bounds, boxes, planes = tank.bounds, tank.boxes, tank.planes
    lo, hi = bounds[0], bounds[1]
    n_objects = boxes.shape[0]
    cone = _box_cones(boxes, origins[0, 0], origins[1, 0], origins[2, 0])  # used with one origin only
    n_pending = 0
    for ray in range(directions.shape[1]):
        o = 0 if one_origin else ray
        ox, oy, oz = origins[0, o], origins[1, o], origins[2, o]
        dx, dy, dz = directions[0, ray], directions[1, ray], directions[2, ray]
        if not (lo[0] < ox < hi[0] and lo[1] < oy < hi[1] and lo[2] < oz < hi[2]) or (
                dx == 0.0 and dy == 0.0 and dz == 0.0):
            pending[n_pending] = ray
            n_pending += 1
            continue
        # the inverse components (+-inf for a zero one) and the sign of each: 1 negative
        ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
        sx, sy, sz = int(ix < 0.0), int(iy < 0.0), int(iz < 0.0)
        # the box's exit: the face of the smallest exit distance (first axis on a tie; +inf
        # along a zero component, the origin being strictly inside); face 2 axis + 1 - s
        best, face = (bounds[1 - sx, 0] - ox) * ix, 1 - sx
        t = (bounds[1 - sy, 1] - oy) * iy
        if t < best:
            best, face = t, 3 - sy
        t = (bounds[1 - sz, 2] - oz) * iz
        if t < best:
            best, face = t, 5 - sz
        hit = -2  # the box face
        undecided = False
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        for b in range(n_objects):
            if one_origin and cone[b, 0] * dx + cone[b, 1] * dy + cone[b, 2] * dz < cone[b, 3] * length:
                continue  # outside the box's cone
            if not _in_box(ox, oy, oz, ix, iy, iz, sx, sy, sz, boxes, b, best):
                continue
            first, last = planes.start[b], planes.start[b + 1]
            if first == last:  # not convex: Embree decides
                undecided = True
                break
            enter, leave, entry = -math.inf, math.inf, -1
            missed = False
            for i in range(first, last):
                nx, ny, nz = planes.normal[i, 0], planes.normal[i, 1], planes.normal[i, 2]
                along = nx * dx + ny * dy + nz * dz
                room = planes.offset[i] - (nx * ox + ny * oy + nz * oz)  # >= 0: o inside this plane
                if along < 0.0:
                    t = room / along
                    if t > enter:
                        enter, entry = t, i
                elif along > 0.0:
                    t = room / along
                    if t < leave:
                        leave = t
                elif room < 0.0:  # parallel and outside
                    missed = True
                    break
                # the entry only grows and the exit only shrinks: no hit nearer than best
                if enter > leave or enter >= best or leave < 0.0:
                    missed = True
                    break
            if missed:
                continue
            if not enter > 0.0:  # the origin inside (or on) the object
                undecided = True
                break
            best, hit = enter, tank.plane_triangle[entry]
        if not undecided and hit == -2:
            # the exit point's coordinates (u, v) = ((axis + 1) % 3, (axis + 2) % 3) in the face
            axis = face // 2
            if axis == 0:
                pu, pv = oy + best * dy, oz + best * dz
            elif axis == 1:
                pu, pv = oz + best * dz, ox + best * dx
            else:
                pu, pv = ox + best * dx, oy + best * dy
            # the triangle the point lies deepest in (the largest of the least edge
            # distances: no data-dependent branch), if it lies in it within the tolerance
            deepest, chosen = -math.inf, -1
            edges = tank.face_edges
            for s in range(tank.face_start[face], tank.face_start[face + 1]):
                e0 = edges[s, 0, 0] * pu + edges[s, 0, 1] * pv + edges[s, 0, 2]
                e1 = edges[s, 1, 0] * pu + edges[s, 1, 1] * pv + edges[s, 1, 2]
                e2 = edges[s, 2, 0] * pu + edges[s, 2, 1] * pv + edges[s, 2, 2]
                least = e0 if e0 < e1 else e1
                least = least if least < e2 else e2
                chosen = s if least > deepest else chosen
                deepest = least if least > deepest else deepest
            if deepest >= -FACE_TOLERANCE_M:
                hit = tank.face_triangle[chosen]
            undecided = hit == -2
        if undecided:
            pending[n_pending] = ray
            n_pending += 1
        else:
            triangle[ray] = hit
    return n_pending


__all__ = ("BOX_MARGIN_M", "FACE_TOLERANCE_M", "MAX_FACE_TRIANGLES", "BoxTank", "box_tank", "first_hits")
