"""Which legs scattering point -> receiver of the diffuse tracer may be blocked, and which the
convex objects' face planes decide: the screen the compiled pairing loop applies per leg.

The tank's boundaries enclose a convex box (or there are none, in free field), so a straight leg
between two points in the water, a scattering point on a boundary or an object and a receiver,
never crosses a boundary: only objects can block it. Each leg is tested against the objects'
axis-aligned boxes (grown by :data:`SCREEN_MARGIN_M`), cheapest test first: a wedge per box
shared by the receivers, tested once per point (:func:`shared_wedges`); the wedge in which the
receiver sees the box (:func:`receiver_wedges`); the slab test. A leg missing every box is
clear; a leg crossing the box of a convex object is decided exactly by that object's face
planes (:func:`~acoustisim.propagation.fast.convex_occlusion.segment_crosses_convex`); only a
leg crossing the box of an object without planes is left to Embree. The box of the convex object
a point lies on is skipped: a leg towards a receiver in front of the face cannot re-enter it.
Exact: only legs Embree would report clear are skipped (up to legs grazing a face, where
float32 Embree and the float64 plane test may differ).

:func:`leg_screen` prepares the screen once per solve; the compiled loop is
:func:`~acoustisim.propagation.fast.diffuse_kernels.scatter_and_pair`.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.convex_planes import CONVEX_MAX_FACES, ConvexPlanes
from acoustisim.propagation.fast.convex_occlusion import PlaneSet, plane_set

SCREEN_MARGIN_M = 1e-4
"""Growth of the object boxes (m): a hundred times the float32 rounding of a 10 m leg in Embree
(the screen itself works in float64)."""

SCREEN_MAX_BOXES = 16
"""Objects screened box by box; more are screened by their union box only (every leg crossing
it goes to Embree)."""

SCREEN_CONVEXITY_FACES = 20_000
"""Largest mesh (faces) without face planes whose convexity is checked (for skipping its own
box); larger non-primitive meshes are treated as non-convex."""

LEGS_CLEAR = 0
"""Screen mode: no leg can be blocked (no objects)."""

LEGS_SCREENED = 1
"""Screen mode: legs are screened by the boxes and decided by the convex objects' planes."""

LEGS_TO_EMBREE = 2
"""Screen mode: every leg may be blocked (a receiver outside the water): Embree tests each."""


class LegScreen(NamedTuple):
    """The per-solve screen of the legs point -> receiver (see the module docstring).

    Attributes
    ----------
    mode : int
        :data:`LEGS_CLEAR`, :data:`LEGS_SCREENED` or :data:`LEGS_TO_EMBREE`.
    lo, hi : ndarray, shape (k, 3)
        Grown boxes (m): row 0 the union of the objects', then each object's (when there are at
        most :data:`SCREEN_MAX_BOXES`). One dummy row in the other modes.
    own_box : ndarray of int64, shape (n_surfaces,)
        For a surface that is a convex object, its box row; else -1.
    wedges : ndarray, shape (n_rx, k, 6)
        :func:`receiver_wedges` of the boxes.
    point_wedges : ndarray, shape (k, 8)
        :func:`shared_wedges` of the boxes.
    planes : PlaneSet
        Face planes of the box rows (row 0, the union, has none; an object without planes
        sends the legs crossing its box to Embree).
    uses_embree : bool
        Whether any leg may be left to Embree (mode :data:`LEGS_TO_EMBREE`, the union box alone,
        or an object without planes): else no Embree leg buffers are needed.
    """

    mode: int
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    own_box: NDArray[np.int64]
    wedges: NDArray[np.float64]
    point_wedges: NDArray[np.float64]
    planes: PlaneSet
    uses_embree: bool


def leg_screen(scene: Any, receivers_m: NDArray[np.float64], planes: ConvexPlanes) -> LegScreen:
    """The screen of ``scene``'s objects for the receivers ``receivers_m`` (n_rx, 3).

    ``planes``: the convex objects' face planes
    (:attr:`~acoustisim.propagation.raycast.RayCaster.convex_planes`, one row per object).
    """
    receivers = np.ascontiguousarray(receivers_m, dtype=float)
    n_rx, n_objects = receivers.shape[0], len(scene.objects)
    own_box = np.full(len(scene.boundaries) + n_objects, -1, dtype=np.int64)
    dummy_box = np.zeros((1, 3))
    no_planes = plane_set(ConvexPlanes.none())
    if scene.tank is not None and not np.all(scene.tank.contains(receivers)):
        return LegScreen(LEGS_TO_EMBREE, dummy_box, dummy_box, own_box, np.zeros((n_rx, 1, 6)), np.zeros((1, 8)),
                         no_planes, True)
    if not n_objects:
        return LegScreen(LEGS_CLEAR, dummy_box, dummy_box, own_box, np.zeros((n_rx, 1, 6)), np.zeros((1, 8)),
                         no_planes, False)
    bounds = np.array([obj.bounds_m for obj in scene.objects])  # (k, 2, 3)
    lo, hi = bounds[:, 0] - SCREEN_MARGIN_M, bounds[:, 1] + SCREEN_MARGIN_M
    union_lo, union_hi = lo.min(axis=0, keepdims=True), hi.max(axis=0, keepdims=True)
    if n_objects > SCREEN_MAX_BOXES:
        return LegScreen(LEGS_SCREENED, union_lo, union_hi, own_box, receiver_wedges(union_lo, union_hi, receivers),
                         shared_wedges(union_lo, union_hi, receivers), plane_set(ConvexPlanes.none(), 1), True)
    with_planes = planes.convex
    for k, obj in enumerate(scene.objects):
        # an analytic primitive (sphere, cylinder) is convex; a mesh with planes is; a larger
        # mesh than the planes examine is checked here
        faces = len(obj.mesh.faces)
        convex = (obj.primitive is not None or bool(with_planes[k])
                  or (CONVEX_MAX_FACES < faces <= SCREEN_CONVEXITY_FACES and obj.mesh.is_convex))
        if convex:
            own_box[len(scene.boundaries) + k] = k + 1
    lo, hi = np.concatenate([union_lo, lo]), np.concatenate([union_hi, hi])
    return LegScreen(LEGS_SCREENED, lo, hi, own_box, receiver_wedges(lo, hi, receivers),
                     shared_wedges(lo, hi, receivers), plane_set(planes, 1), not bool(np.all(with_planes)))


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


__all__ = ("LEGS_CLEAR", "LEGS_SCREENED", "LEGS_TO_EMBREE", "SCREEN_CONVEXITY_FACES", "SCREEN_MARGIN_M",
           "SCREEN_MAX_BOXES", "LegScreen", "leg_screen", "receiver_wedges", "shared_wedges")
