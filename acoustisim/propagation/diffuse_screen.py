"""Which legs scattering point -> receiver of the diffuse tracer may be blocked, and which
the convex objects' face planes decide: the screen of :class:`ObjectScreen`.

The tank's boundaries enclose a convex box, so only objects can block a leg between two points
in the water. Each leg is tested against the objects' axis-aligned boxes, cheapest test first
(a wedge per box shared by the receivers, tested once per point: :func:`shared_wedges`; the
wedge in which each receiver sees the box: :func:`receiver_wedges`; the slab test), and a
leg crossing the box of a convex object is decided exactly by that object's face planes
(:mod:`~acoustisim.propagation.convex_occlusion`). The compiled loop is
:func:`~acoustisim.propagation.diffuse_kernels.scatter_and_pair`; this module prepares its
arguments once per solve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation import diffuse_kernels as kernels
from acoustisim.propagation.convex_occlusion import CONVEX_MAX_FACES, ConvexPlanes


@dataclass(frozen=True, eq=False)
class ObjectScreen:
    """Which legs scattering point -> receiver may be blocked: a conservative screen.

    The tank's boundaries enclose a convex box (or there are none, in free field), so a
    straight leg between two points in the water, a scattering point on a boundary or an
    object and a receiver, never crosses a boundary: only objects can block it. A leg that
    misses every object's axis-aligned box (grown by :data:`SCREEN_MARGIN_M`) is clear, and
    Embree need not test it: each leg is tested against each object's box (its wedge seen
    from the receiver, then the slab test; the union box alone beyond
    :data:`SCREEN_MAX_BOXES` objects), and a leg crossing a convex object's box is decided by
    that object's face planes. Exact: only legs Embree would report clear are skipped (up to
    legs grazing a face, where float32 Embree and the float64 plane test may differ).

    Attributes
    ----------
    receivers : ndarray, shape (n_rx, 3)
        The legs' ends (m).
    lo, hi : ndarray, shape (k, 3)
        Grown object boxes (m); row 0 the union of all, then each object's (when there are at
        most :data:`SCREEN_MAX_BOXES`). ``None`` when the screen cannot be used (a receiver
        outside the tank's water): every leg is then tested.
    own_box : ndarray of int64, shape (n_surfaces,)
        For a surface that is a convex object, its row in ``lo``, ``hi``; else -1. A leg from
        a point on a convex body towards a receiver in front of the face cannot re-enter the
        body, so that box is skipped for it.
    wedges : ndarray, shape (n_rx, k, 6)
        :func:`receiver_wedges` of the boxes: a leg outside a box's wedge does not cross it
        (tested before the box itself, at two dot products).
    shared : ndarray, shape (k, 8)
        :func:`shared_wedges`: a point outside a box's shared wedge has no leg to any receiver
        crossing the box (tested once per point, before the receivers' own wedges).
    planes : ConvexPlanes
        Face planes of the rows of ``lo``, ``hi`` (row 0, the union, has none): a leg crossing
        the box of an object with planes is decided exactly by them
        (:mod:`~acoustisim.propagation.convex_occlusion`), without Embree; only legs crossing
        the box of an object without planes (non-convex, or more than
        :data:`SCREEN_MAX_BOXES` objects) are left to Embree.
    """

    receivers: NDArray[np.float64]
    lo: NDArray[np.float64] | None
    hi: NDArray[np.float64] | None
    own_box: NDArray[np.int64]
    wedges: NDArray[np.float64] | None = None
    planes: ConvexPlanes = field(default_factory=lambda: ConvexPlanes(np.zeros(1, dtype=np.int64), np.zeros((0, 3)),
                                                                      np.zeros(0)))
    shared: NDArray[np.float64] | None = None

    @classmethod
    def create(cls, scene: Any, receivers_m: NDArray[np.float64],
               planes: ConvexPlanes | None = None) -> "ObjectScreen":
        """The screen of ``scene``'s objects for the receivers ``receivers_m`` (n_rx, 3).

        ``planes``: the convex objects' face planes
        (:attr:`~acoustisim.propagation.raycast.RayCaster.convex_planes`, one row per object);
        None: every leg crossing an object's box is left to Embree.
        """
        receivers = np.ascontiguousarray(receivers_m, dtype=float)
        own_box = np.full(len(scene.boundaries) + len(scene.objects), -1, dtype=np.int64)
        if scene.tank is not None and not np.all(scene.tank.contains(receivers)):
            return cls(receivers, None, None, own_box)
        if not scene.objects:
            empty = np.zeros((0, 3))
            return cls(receivers, empty, empty, own_box)
        bounds = np.array([obj.bounds_m for obj in scene.objects])  # (k, 2, 3)
        lo, hi = bounds[:, 0] - SCREEN_MARGIN_M, bounds[:, 1] + SCREEN_MARGIN_M
        union_lo, union_hi = lo.min(axis=0, keepdims=True), hi.max(axis=0, keepdims=True)
        if len(scene.objects) > SCREEN_MAX_BOXES:
            return cls(receivers, union_lo, union_hi, own_box)
        with_planes = np.zeros(len(scene.objects), dtype=bool) if planes is None else planes.convex
        for k, obj in enumerate(scene.objects):
            # an analytic primitive (sphere, cylinder) is convex; a small mesh is checked
            faces = len(obj.mesh.faces)
            examined = planes is not None and faces <= CONVEX_MAX_FACES  # and found convex or not
            convex = (obj.primitive is not None or bool(with_planes[k])
                      or (not examined and faces <= SCREEN_CONVEXITY_FACES and obj.mesh.is_convex))
            if convex:
                own_box[len(scene.boundaries) + k] = k + 1
        if planes is None:
            rows = ConvexPlanes(np.zeros(len(scene.objects) + 2, dtype=np.int64), np.zeros((0, 3)), np.zeros(0))
        else:  # prepend the union's empty row
            rows = ConvexPlanes(np.concatenate([[0], planes.start]).astype(np.int64), planes.normal, planes.offset)
        lo, hi = np.concatenate([union_lo, lo]), np.concatenate([union_hi, hi])
        return cls(receivers, lo, hi, own_box, receiver_wedges(lo, hi, receivers), rows, shared_wedges(lo, hi, receivers))

    def near(self, points_m: NDArray[np.float64], receiver: int | None = None,
             surface: NDArray[np.int64] | None = None) -> NDArray[np.bool_]:
        """Whether the leg from each point (n, 3) to ``receiver`` (an index; None: to any
        receiver) may cross an object (n,). With ``surface`` (n,), the surface each point lies
        on, a convex object's own box is skipped (for legs to receivers in front of the face)."""
        points = np.asarray(points_m, dtype=float).reshape(-1, 3)
        n = points.shape[0]
        if self.lo is None:
            return np.ones(n, dtype=bool)
        near = np.zeros(n, dtype=bool)
        if self.lo.shape[0] == 0:
            return near
        x, y, z = (np.ascontiguousarray(points[:, k]) for k in range(3))
        leg = np.empty(n, dtype=bool)
        own = np.full(n, -1, dtype=np.int64) if surface is None else self.own_box[np.asarray(surface)]
        for end in self.receivers if receiver is None else self.receivers[receiver:receiver + 1]:
            kernels.near_points(x, y, z, own, end, self.lo, self.hi, leg)
            near |= leg
        return near

    def kernel_arguments(self) -> tuple[Any, ...]:
        """(mode, lo, hi, own_box, wedges, point_wedges, plane_start, plane_normal, plane_offset) for
        :func:`~acoustisim.propagation.diffuse_kernels.scatter_and_pair`: mode 0 when no leg can
        be blocked, 1 to screen with the boxes and decide with the convex objects' planes, 2
        when every leg may be blocked (Embree tests each)."""
        p = self.planes
        if self.lo is None or self.lo.shape[0] == 0:
            none = np.zeros((1, 3))
            return (2 if self.lo is None else 0, none, none, self.own_box, np.zeros((1, 1, 6)), np.zeros((1, 8)),
                    np.zeros(2, dtype=np.int64), none, np.zeros(1))
        start = p.start if p.start.size == self.lo.shape[0] + 1 else np.zeros(self.lo.shape[0] + 1, dtype=np.int64)
        normal = p.normal if p.normal.shape[0] else np.zeros((1, 3))
        offset = p.offset if p.offset.shape[0] else np.zeros(1)
        wedges = self.wedges if self.wedges is not None else receiver_wedges(self.lo, self.hi, self.receivers)
        shared = self.shared if self.shared is not None else shared_wedges(self.lo, self.hi, self.receivers)
        return 1, self.lo, self.hi, self.own_box, wedges, shared, start, normal, offset


def receiver_wedges(lo: NDArray[np.float64], hi: NDArray[np.float64],
                    receivers: NDArray[np.float64]) -> NDArray[np.float64]:
    """The wedge of directions in which each receiver sees each box, in the projection along
    the box's longest side: a cheap necessary condition for a leg to cross the box.

    A segment from a receiver q to a point p crosses a box only if its projection crosses the
    box's projected rectangle, hence only if p - q, projected, lies in the wedge spanned from q
    by the rectangle's corners (its conic hull, narrower than a half-plane when q lies outside
    the rectangle). For a tall thin post seen from the side the wedge is a few degrees wide.

    Parameters
    ----------
    lo, hi : ndarray, shape (k, 3)
        Boxes (m).
    receivers : ndarray, shape (n_rx, 3)

    Returns
    -------
    ndarray, shape (n_rx, k, 6)
        Per receiver and box, the normals N1, N2 (3 each) of the wedge's two half-spaces
        through the receiver: a leg receiver -> point (direction e) can cross the box only if
        ``N1 . e >= 0`` and ``N2 . e >= 0``. In the projected coordinates (u, v) = ((a + 1) % 3,
        (a + 2) % 3), a the projection axis, with the wedge's right and left edges R and L:
        ``N1 . e = R_u e_v - R_v e_u`` and ``N2 . e = e_u L_v - e_v L_u``. Both are zero (every
        leg passes to the slab test) when the receiver lies within 1e-9 m of the projected
        rectangle.
    """
    lo, hi = np.ascontiguousarray(lo, dtype=float), np.ascontiguousarray(hi, dtype=float)
    receivers = np.ascontiguousarray(receivers, dtype=float)
    out = np.zeros((receivers.shape[0], lo.shape[0], 6))
    _wedges_into(lo, hi, receivers, out)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _wedges_into(lo: NDArray[np.float64], hi: NDArray[np.float64], receivers: NDArray[np.float64],
                 out: NDArray[np.float64]) -> None:
    """:func:`receiver_wedges` into ``out`` (n_rx, k, 6), zeroed (a compiled loop: the boxes
    and receivers are a handful, numpy's per-call cost would dominate)."""
    for b in range(lo.shape[0]):
        # the projection axis: the box's longest side (the first of equal ones)
        axis = 0
        for a in range(1, 3):
            if hi[b, a] - lo[b, a] > hi[b, axis] - lo[b, axis]:
                axis = a
        u, v = (axis + 1) % 3, (axis + 2) % 3
        cu = (lo[b, u], hi[b, u], hi[b, u], lo[b, u])  # the projected rectangle's corners
        cv = (lo[b, v], lo[b, v], hi[b, v], hi[b, v])
        for j in range(receivers.shape[0]):
            qu, qv = receivers[j, u], receivers[j, v]
            if lo[b, u] - 1e-9 <= qu <= hi[b, u] + 1e-9 and lo[b, v] - 1e-9 <= qv <= hi[b, v] + 1e-9:
                continue  # inside the projected rectangle: no wedge (zeros)
            mu_, mv = 0.0, 0.0  # the corners' mean direction from q
            for c in range(4):
                mu_ += cu[c] - qu
                mv += cv[c] - qv
            mu_, mv = 0.25 * mu_, 0.25 * mv
            # the corners of least and largest signed angle from the mean direction (all
            # within +-90 degrees: q is outside the rectangle)
            low, high = math.inf, -math.inf
            ru, rv, lu, lv = 0.0, 0.0, 0.0, 0.0
            for c in range(4):
                eu, ev = cu[c] - qu, cv[c] - qv
                angle = math.atan2(mu_ * ev - mv * eu, eu * mu_ + ev * mv)
                if angle < low:
                    low, ru, rv = angle, eu, ev
                if angle > high:
                    high, lu, lv = angle, eu, ev
            # N1 . e = R_u e_v - R_v e_u;  N2 . e = e_u L_v - e_v L_u
            out[j, b, v], out[j, b, u] = ru, -rv
            out[j, b, 3 + u], out[j, b, 3 + v] = lv, -lu


def shared_wedges(lo: NDArray[np.float64], hi: NDArray[np.float64],
                  receivers: NDArray[np.float64]) -> NDArray[np.float64]:
    """One wedge per box for all the receivers: the points from which a leg to any receiver may
    cross the box, a superset tested once per point before the receivers' own wedges.

    With c the receivers' centroid and g the largest offset |q - c| of a receiver along each
    axis: a leg from a receiver q to a point p crossing the box at x has p = q + t (x - q),
    t >= 1, so p - c = t (y - c) with y = x - (1 - 1/t)(q - c) in the box grown by g; p lies
    in the wedge seen from c of the grown box (:func:`receiver_wedges`).

    Returns
    -------
    ndarray, shape (k, 8)
        (N1, N1 . c, N2, N2 . c) per box: the point p passes iff ``N1 . p >= N1 . c`` and
        ``N2 . p >= N2 . c``.
    """
    centre = receivers.mean(axis=0)
    grow = np.max(np.abs(receivers - centre), axis=0) + 1e-9
    normals = receiver_wedges(lo - grow, hi + grow, centre[None, :])[0]  # (k, 6)
    out = np.empty((lo.shape[0], 8))
    out[:, 0:3], out[:, 4:7] = normals[:, 0:3], normals[:, 3:6]
    out[:, 3], out[:, 7] = normals[:, 0:3] @ centre, normals[:, 3:6] @ centre
    return out


SCREEN_MARGIN_M = 1e-4
"""Growth of the object boxes in :class:`ObjectScreen` (m): a hundred times the float32
rounding of a 10 m leg in Embree (the screen itself works in float64)."""

SCREEN_MAX_BOXES = 16
"""Objects screened box by box; more are screened by their union box only."""

SCREEN_CONVEXITY_FACES = 20_000
"""Largest mesh (faces) whose convexity :class:`ObjectScreen` checks; larger non-primitive
meshes are treated as non-convex (the check would cost more than it saves)."""


__all__ = [
    "ObjectScreen",
    "SCREEN_CONVEXITY_FACES",
    "SCREEN_MARGIN_M",
    "SCREEN_MAX_BOXES",
    "receiver_wedges",
    "shared_wedges",
]
