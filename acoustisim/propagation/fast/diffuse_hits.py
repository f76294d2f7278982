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
point in no triangle of its face (a hole). A tank whose boundaries are not such a box (or whose
faces are tiled too finely, :mod:`acoustisim.propagation.tank_box`) leaves every ray to Embree.
The answers equal Embree's but for rays grazing an edge within Embree's float32 rounding (about
1e-6 m in a 9 m tank).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.fast.convex_occlusion import PlaneSet, plane_set
from acoustisim.propagation.raycast import RayCaster

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
    bounds, face_start, face_triangle, face_edges
        As in :class:`~acoustisim.propagation.tank_box.TankBox`.
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
    """The description of ``raycaster``'s scene (its
    :attr:`~acoustisim.propagation.raycast.RayCaster.tank_box`, object boxes and convex planes),
    or None when its boundaries are not the faces of an axis-aligned box."""
    box = raycaster.tank_box
    if box is None:
        return None
    planes = raycaster.convex_planes
    boxes = raycaster.object_boxes.copy()
    boxes[:, 0] -= BOX_MARGIN_M
    boxes[:, 1] += BOX_MARGIN_M
    plane_triangle = planes.triangle if planes.triangle.size else np.zeros(1, dtype=np.int64)
    return BoxTank(box.bounds, box.face_start, box.face_triangle, box.face_edges, boxes, plane_set(planes),
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
    # local copies of the small tables (the compiler then knows the output writes leave them be)
    bounds = np.empty((2, 3))
    bounds[:] = tank.bounds
    boxes = np.empty(tank.boxes.shape)
    boxes[:] = tank.boxes
    plane_start, plane_normal, plane_offset = tank.planes.start, tank.planes.normal, tank.planes.offset
    plane_triangle, face_start, face_triangle, face_edges = (tank.plane_triangle, tank.face_start, tank.face_triangle,
                                                             tank.face_edges)
    lo_x, lo_y, lo_z = bounds[0, 0], bounds[0, 1], bounds[0, 2]
    hi_x, hi_y, hi_z = bounds[1, 0], bounds[1, 1], bounds[1, 2]
    n_objects = boxes.shape[0]
    # with one origin, each box's cone of directions from it (the cone of the box's bounding
    # sphere: axis and cosine of the half angle, -2 when the origin is inside the sphere): a
    # ray outside the cone misses the box, at one dot product instead of the slab test
    cone = np.empty((n_objects, 4))
    cone[:, :3], cone[:, 3] = 0.0, -2.0
    for b in range(n_objects if one_origin else 0):
        wx = 0.5 * (boxes[b, 0, 0] + boxes[b, 1, 0]) - origins[0, 0]
        wy = 0.5 * (boxes[b, 0, 1] + boxes[b, 1, 1]) - origins[1, 0]
        wz = 0.5 * (boxes[b, 0, 2] + boxes[b, 1, 2]) - origins[2, 0]
        radius = 0.5 * math.sqrt((boxes[b, 1, 0] - boxes[b, 0, 0]) ** 2 + (boxes[b, 1, 1] - boxes[b, 0, 1]) ** 2
                                 + (boxes[b, 1, 2] - boxes[b, 0, 2]) ** 2)
        distance = math.sqrt(wx * wx + wy * wy + wz * wz)
        if distance > 1.001 * radius:
            cone[b, 0], cone[b, 1], cone[b, 2] = wx / distance, wy / distance, wz / distance
            # the half angle's cosine, lowered by 1e-9 for the rounding of these few operations
            cone[b, 3] = math.sqrt(1.0 - (radius / distance) ** 2) - 1e-9
    n_pending = 0
    for ray in range(directions.shape[1]):
        o = 0 if one_origin else ray
        ox, oy, oz = origins[0, o], origins[1, o], origins[2, o]
        dx, dy, dz = directions[0, ray], directions[1, ray], directions[2, ray]
        if not (lo_x < ox < hi_x and lo_y < oy < hi_y and lo_z < oz < hi_z) or (
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
            if cone[b, 0] * dx + cone[b, 1] * dy + cone[b, 2] * dz < cone[b, 3] * length:
                continue  # outside the box's cone
            if not _in_box(ox, oy, oz, ix, iy, iz, sx, sy, sz, boxes, b, best):
                continue
            first, last = plane_start[b], plane_start[b + 1]
            if first == last:  # not convex: Embree decides
                undecided = True
                break
            enter, leave, entry = -math.inf, math.inf, -1
            missed = False
            for i in range(first, last):
                nx, ny, nz = plane_normal[i, 0], plane_normal[i, 1], plane_normal[i, 2]
                along = nx * dx + ny * dy + nz * dz
                room = plane_offset[i] - (nx * ox + ny * oy + nz * oz)  # >= 0: o inside this plane
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
            best, hit = enter, plane_triangle[entry]
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
            for s in range(face_start[face], face_start[face + 1]):
                e0 = face_edges[s, 0, 0] * pu + face_edges[s, 0, 1] * pv + face_edges[s, 0, 2]
                e1 = face_edges[s, 1, 0] * pu + face_edges[s, 1, 1] * pv + face_edges[s, 1, 2]
                e2 = face_edges[s, 2, 0] * pu + face_edges[s, 2, 1] * pv + face_edges[s, 2, 2]
                least = e0 if e0 < e1 else e1
                least = least if least < e2 else e2
                chosen = s if least > deepest else chosen
                deepest = least if least > deepest else deepest
            if deepest >= -FACE_TOLERANCE_M:
                hit = face_triangle[chosen]
            undecided = hit == -2
        if undecided:
            pending[n_pending] = ray
            n_pending += 1
        else:
            triangle[ray] = hit
    return n_pending


__all__ = ("BOX_MARGIN_M", "FACE_TOLERANCE_M", "BoxTank", "box_tank", "first_hits")
