"""The reference's element visibility, with most legs decided exactly without Embree.

:func:`element_visibility` answers what
:func:`acoustisim.propagation.reference.edges.element_visibility` answers: whether each
element's probe sees the transmitter and its receiver, as Embree's float32 occlusion query of
the leg shrunk by ``eps`` at both ends says. On the thesis tank that is some 13 000 legs per
pose, nearly all of which a geometric screen decides without Embree:

* the tank's boundaries enclose a convex box, so a leg whose two ends lie inside the water
  at least ``tolerance`` from every boundary passes at least that far from every wall;
* a leg missing an object's axis-aligned box grown by ``tolerance`` passes at least that far
  from the object;
* per (edge, receiver) pair and leg, the legs of all its elements lie in one triangle (the
  segment of its probes and the target): an object whose box the triangle's box misses, or
  with a face plane the triangle lies outside of, is skipped for all of them, as are the walls
  when the triangle lies in the shrunk water box;
* a leg crossing the box of a convex object (a closed mesh with every vertex inside every face
  plane, :mod:`~acoustisim.propagation.convex_planes`) is clipped against the object's face
  planes moved ``tolerance`` outwards (P+) and inwards (P-) (Cyrus and Beck 1978): a segment
  missing P+ passes more than ``tolerance`` from the solid (every point within ``tolerance``
  of a convex solid lies in P+), and a segment whose ends lie outside P+ and which meets P-
  crosses the solid's surface with both ends and one inner point at least ``tolerance`` from
  it.

Embree answers in float32: vertices, ray origin, direction and length rounded to float32
(about one ulp of the scene's coordinates, 5e-7 m in the 9 m tank, after the ray caster's
shift to the centre) and an intersection test with errors of a few ulps of the distances
involved. A leg decided with the margin ``tolerance`` (:func:`screen_tolerance`,
:data:`TOLERANCE_ULPS` float32 ulps of the scene's diagonal: 2.3e-5 m in the tank, 40 times
that rounding, and below the probes' 1.4e-4 m from their own faces) therefore gets Embree's
answer; every other leg (ends near a wall, grazing an object within ``tolerance``, crossing
the box of a non-convex object) goes to Embree in one batch, as the same float32 query the
reference makes. The only leg where the two could differ is one Embree itself lets through a
solid, across the shared edge of two triangles within its float32 rounding (its intersection
test is not watertight), at both of the leg's crossings of the solid.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.convex_planes import ConvexPlanes
from acoustisim.propagation.edge_extraction import DiffractingEdges
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.raycast import DEFAULT_EPS_M
from acoustisim.propagation.reference.edge_elements import EdgeElements
from acoustisim.propagation.reference.edges import EdgePairs

TOLERANCE_ULPS = 20.0
"""The screen's margin, in float32 ulps (2^-23) of the scene's bounding-box diagonal."""

CLEAR, BLOCKED, UNDECIDED = 0, 1, 2
"""Decisions of :func:`screen_legs`."""

MASK_BITS = 62
"""Objects with an index below this are pre-screened once per (edge, receiver) pair and leg
(:func:`pair_masks`); further ones are tested on every leg."""

WALL_BIT = 62
"""The bit of a pre-screen mask saying the walls must be tested."""

OTHERS_BIT = 63
"""The bit of a pre-screen mask set when the scene has objects from :data:`MASK_BITS` on
(tested on every leg), so that the mask is never zero (a zero mask skips the leg)."""


FLOAT32_EPS = 2.0**-23
"""One float32 ulp at 1 (``np.finfo(np.float32).eps``)."""


def screen_tolerance(bounds_m: NDArray[np.float64]) -> float:
    """The screen's margin (m) for a scene within the box ``bounds_m`` (2, 3):
    :data:`TOLERANCE_ULPS` float32 ulps of the box's diagonal (2.3e-5 m in the thesis tank)."""
    diagonal = bounds_m[1] - bounds_m[0]
    return TOLERANCE_ULPS * FLOAT32_EPS * math.sqrt(float(diagonal @ diagonal))


class ScreenGeometry(NamedTuple):
    """What decides a leg without Embree.

    Attributes
    ----------
    tolerance : float
        The margin (m), :func:`screen_tolerance` of the scene's box.
    water_lo, water_hi : ndarray, shape (3,)
        The tank's water box shrunk by ``tolerance`` (m); infinite in free field (no walls).
    box_lo, box_hi : ndarray, shape (k, 3)
        Each object's axis-aligned box grown by ``tolerance`` (m).
    plane_start : ndarray of int64, shape (k + 1,)
        Object j's face planes are rows ``plane_start[j]:plane_start[j + 1]`` of the next two;
        none for a non-convex object (its legs crossing its box go to Embree).
    plane_normal : ndarray, shape (m, 3)
    plane_offset : ndarray, shape (m,)
        The planes ``normal . x = offset``, inside below (m).
    """

    tolerance: float
    water_lo: NDArray[np.float64]
    water_hi: NDArray[np.float64]
    box_lo: NDArray[np.float64]
    box_hi: NDArray[np.float64]
    plane_start: NDArray[np.int64]
    plane_normal: NDArray[np.float64]
    plane_offset: NDArray[np.float64]

    @classmethod
    def create(cls, object_bounds_m: NDArray[np.float64], tank_bounds_m: NDArray[np.float64] | None,
               planes: ConvexPlanes | None) -> "ScreenGeometry":
        """The screen of a scene: its objects' boxes (k, 2, 3), its tank's box (2, 3) (None:
        free field) and its convex objects' face planes
        (:attr:`~acoustisim.propagation.raycast.RayCaster.convex_planes`; None: every leg
        crossing an object's box goes to Embree)."""
        n_objects = object_bounds_m.shape[0]
        box_lo, box_hi = object_bounds_m[:, 0], object_bounds_m[:, 1]
        if tank_bounds_m is None:
            water_lo, water_hi = np.full(3, -np.inf), np.full(3, np.inf)
            scene_box = np.array([box_lo.min(axis=0), box_hi.max(axis=0)]) if n_objects else None
        elif n_objects:
            scene_box = np.array([np.minimum(box_lo.min(axis=0), tank_bounds_m[0]),
                                  np.maximum(box_hi.max(axis=0), tank_bounds_m[1])])
        else:
            scene_box = tank_bounds_m
        tolerance = 0.0 if scene_box is None else screen_tolerance(scene_box)
        if tank_bounds_m is not None:
            water_lo, water_hi = tank_bounds_m[0] + tolerance, tank_bounds_m[1] - tolerance
        if planes is not None and planes.start.size == n_objects + 1 and planes.normal.shape[0]:
            start, normal, offset = planes.start, planes.normal, planes.offset
        else:
            start, normal, offset = np.zeros(n_objects + 1, dtype=np.int64), np.zeros((1, 3)), np.zeros(1)
        return cls(tolerance, water_lo, water_hi, box_lo - tolerance, box_hi + tolerance, start, normal, offset)


class EdgeLines(NamedTuple):
    """Per diffracting edge: its ``start`` (m), unit ``direction``, the probes' offset from it
    ``probe_offset`` (m), each shape (e, 3); its ``chain`` and ``surface`` (index into the
    scene's surface names), shape (e,)."""

    start: NDArray[np.float64]
    direction: NDArray[np.float64]
    probe_offset: NDArray[np.float64]
    chain: NDArray[np.int64]
    surface: NDArray[np.int64]

    @classmethod
    def of(cls, scene_edges: DiffractingEdges) -> "EdgeLines":
        """The lines of a scene's diffracting edges."""
        edges = scene_edges.edges
        return cls(edges.start_m, edges.direction, scene_edges.probe_offset_m, edges.chain, edges.surface)


class LegTargets(NamedTuple):
    """Where the legs go: the ``transmitter`` (3,) and the ``receivers`` (n_rx, 3) (m), and
    ``own_leg`` (n_rx,): whether a receiver is not the transmitter (has a leg of its own)."""

    transmitter: NDArray[np.float64]
    receivers: NDArray[np.float64]
    own_leg: NDArray[np.bool_]

    @classmethod
    def of(cls, context: SolveContext) -> "LegTargets":
        """The transducers of a pose."""
        tx = np.asarray(context.transmitter_m, dtype=float)
        rx = np.asarray(context.receivers_m, dtype=float)
        return cls(tx, rx, ~np.all(rx == tx, axis=1))


class EmbreeQueries(NamedTuple):
    """Float32 occlusion queries for
    :meth:`~acoustisim.propagation.raycast.RayCaster.occluded_segments32`: ``starts32``
    (q, 3) (shifted by the ray caster's ``shift_m``), ``directions32`` (q, 3), ``lengths32``
    (q,); ``element`` (q,): the element each query belongs to."""

    starts32: NDArray[np.float32]
    directions32: NDArray[np.float32]
    lengths32: NDArray[np.float32]
    element: NDArray[np.int64]


@njit(cache=True, nogil=True, error_model="numpy")
def _inverse(x: float) -> float:
    """1 / x, 0 for 0 (a segment parallel to a slab)."""
    return 1.0 / x if x != 0.0 else 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def _slab(enter: float, leave: float, a: float, inverse: float, lo: float, hi: float) -> tuple[float, float]:
    """The part (enter, leave) of the parameter range where ``a + s / inverse`` lies in
    [lo, hi], within the given one (enter > leave: none); ``inverse`` is 1 / the component of
    the segment (0: none, the segment is parallel to the slab)."""
    if inverse == 0.0:
        return (enter, leave) if (lo <= a) & (a <= hi) else (1.0, 0.0)
    s_lo = (lo - a) * inverse
    s_hi = (hi - a) * inverse
    return max(enter, min(s_lo, s_hi)), min(leave, max(s_lo, s_hi))


@njit(cache=True, nogil=True, error_model="numpy")
def _height(p: tuple[float, float, float], normal: NDArray[np.float64], offset: NDArray[np.float64], i: int) -> float:
    """Height of p above plane i (m; > 0 outside)."""
    return (normal[i, 0] * p[0] + normal[i, 1] * p[1] + normal[i, 2] * p[2]) - offset[i]


@njit(cache=True, nogil=True, error_model="numpy")
def _convex_decision(p0: tuple[float, float, float], p1: tuple[float, float, float], normal: NDArray[np.float64],
                     offset: NDArray[np.float64], first: int, last: int, tolerance: float) -> tuple[int, int]:
    """(CLEAR, BLOCKED or UNDECIDED, a separating plane or -1) for the segment p0 -> p1 and the
    convex polyhedron of planes ``first:last``, with the margin ``tolerance`` (see the module
    docstring): the planes moved out (P+) and in (P-) by it, clipped in one pass. The
    separating plane, when found, has both ends more than ``tolerance`` outside it."""
    enter_out, leave_out = 0.0, 1.0  # the part of the segment in P+ (parameter s in [0, 1])
    enter_in, leave_in = 0.0, 1.0  # in P-
    out0, out1 = False, False  # whether the ends lie outside P+
    for i in range(first, last):
        h0 = _height(p0, normal, offset, i)
        h1 = _height(p1, normal, offset, i)
        above0, above1 = h0 > tolerance, h1 > tolerance
        if above0 & above1:
            return CLEAR, i
        out0 |= above0
        out1 |= above1
        slope = h1 - h0  # height h0 + s slope along the segment
        if slope < 0.0:
            enter_out = max(enter_out, (tolerance - h0) / slope)
            enter_in = max(enter_in, (-tolerance - h0) / slope)
        elif slope > 0.0:
            leave_out = min(leave_out, (tolerance - h0) / slope)
            leave_in = min(leave_in, (-tolerance - h0) / slope)
        elif h0 > -tolerance:  # parallel, outside P-
            enter_in = 2.0
    if enter_out > leave_out:  # misses P+
        return CLEAR, -1
    if out0 & out1 & (enter_in <= leave_in):  # ends outside P+, meets P-
        return BLOCKED, -1
    return UNDECIDED, -1


@njit(cache=True, nogil=True, error_model="numpy")
def screen_legs(p0: NDArray[np.float64], p1: NDArray[np.float64], mask: NDArray[np.int64],
                screen: ScreenGeometry) -> NDArray[np.int8]:
    """CLEAR, BLOCKED or UNDECIDED (left to Embree) for each segment p0 -> p1.

    One loop over the segments with every test written out (a call per segment passing the
    arrays would cost more than the tests themselves).

    Parameters
    ----------
    p0, p1 : ndarray, shape (n, 3)
        The segments' ends (m): the legs shrunk by Embree's ``eps`` at both ends.
    mask : ndarray of int64, shape (n,)
        What to test per segment (:func:`triangle_mask`): the walls when bit
        :data:`WALL_BIT` is set, object j < :data:`MASK_BITS` when bit j is (-1: everything;
        objects from :data:`MASK_BITS` on are always tested).
    screen : ScreenGeometry

    Returns
    -------
    ndarray of int8, shape (n,)
    """
    n = p0.shape[0]
    decisions = np.empty(n, dtype=np.int8)
    tolerance = screen.tolerance
    water_lo, water_hi = screen.water_lo, screen.water_hi
    box_lo, box_hi = screen.box_lo, screen.box_hi
    normal, offset = screen.plane_normal, screen.plane_offset
    n_boxes = box_lo.shape[0]
    hint = np.full(n_boxes, -1, dtype=np.int64)  # per object, the plane that last separated a segment
    for s in range(n):
        a = (p0[s, 0], p0[s, 1], p0[s, 2])
        b = (p1[s, 0], p1[s, 1], p1[s, 2])
        m = mask[s]
        decision = CLEAR
        if (m >> WALL_BIT) & 1 == 1:  # both ends in the shrunk water box, or Embree
            inside = ((water_lo[0] <= a[0]) & (a[0] <= water_hi[0]) & (water_lo[1] <= a[1]) & (a[1] <= water_hi[1])
                      & (water_lo[2] <= a[2]) & (a[2] <= water_hi[2]) & (water_lo[0] <= b[0]) & (b[0] <= water_hi[0])
                      & (water_lo[1] <= b[1]) & (b[1] <= water_hi[1]) & (water_lo[2] <= b[2]) & (b[2] <= water_hi[2]))
            if not inside:
                decisions[s] = UNDECIDED
                continue
        inv0, inv1, inv2 = _inverse(b[0] - a[0]), _inverse(b[1] - a[1]), _inverse(b[2] - a[2])
        for j in range(n_boxes):
            if j < MASK_BITS:
                if (m >> j) & 1 == 0:
                    continue
            # the slab test against the object's grown box
            enter, leave = _slab(0.0, 1.0, a[0], inv0, box_lo[j, 0], box_hi[j, 0])
            enter, leave = _slab(enter, leave, a[1], inv1, box_lo[j, 1], box_hi[j, 1])
            enter, leave = _slab(enter, leave, a[2], inv2, box_lo[j, 2], box_hi[j, 2])
            if enter > leave:
                continue
            first, last = screen.plane_start[j], screen.plane_start[j + 1]
            if first == last:  # not convex: Embree decides, unless another object blocks
                decision = UNDECIDED
                continue
            h = hint[j]
            if h >= 0:
                if (_height(a, normal, offset, h) > tolerance) & (_height(b, normal, offset, h) > tolerance):
                    continue
            here, separating = _convex_decision(a, b, normal, offset, first, last, tolerance)
            if separating >= 0:
                hint[j] = separating
            if here == BLOCKED:
                decision = BLOCKED
                break
            if here == UNDECIDED:
                decision = UNDECIDED
        decisions[s] = decision
    return decisions


@njit(cache=True, nogil=True, error_model="numpy")
def triangle_mask(a: NDArray[np.float64], b: NDArray[np.float64], t: NDArray[np.float64],
                  screen: ScreenGeometry) -> int:
    """What a segment within the triangle a, b, t (each shape (3,), m) must still be tested
    against, as a bit mask for :func:`screen_legs`: bit j (j < :data:`MASK_BITS`) for object j
    unless the triangle keeps at least ``tolerance`` from it (the triangle's box grown by
    ``tolerance`` apart from the object's grown box, or one of the object's face planes with
    the three corners more than twice ``tolerance`` outside), bit :data:`WALL_BIT` unless
    the three corners lie in the shrunk water box, and bit :data:`OTHERS_BIT` when there are
    objects from :data:`MASK_BITS` on (always tested)."""
    water_lo, water_hi = screen.water_lo, screen.water_hi
    box_lo, box_hi = screen.box_lo, screen.box_hi
    normal, offset = screen.plane_normal, screen.plane_offset
    tolerance = screen.tolerance
    mask = np.int64(0)
    for c in range(3):
        if not ((water_lo[c] <= a[c]) & (a[c] <= water_hi[c]) & (water_lo[c] <= b[c]) & (b[c] <= water_hi[c])
                & (water_lo[c] <= t[c]) & (t[c] <= water_hi[c])):
            mask |= np.int64(1) << WALL_BIT
    lo0 = min(min(a[0], b[0]), t[0]) - tolerance
    lo1 = min(min(a[1], b[1]), t[1]) - tolerance
    lo2 = min(min(a[2], b[2]), t[2]) - tolerance
    hi0 = max(max(a[0], b[0]), t[0]) + tolerance
    hi1 = max(max(a[1], b[1]), t[1]) + tolerance
    hi2 = max(max(a[2], b[2]), t[2]) + tolerance
    margin = 2.0 * tolerance
    if box_lo.shape[0] > MASK_BITS:  # objects beyond the mask's bits: always tested (never a zero mask)
        mask |= np.int64(1) << OTHERS_BIT
    for j in range(min(box_lo.shape[0], MASK_BITS)):
        apart = ((hi0 < box_lo[j, 0]) | (lo0 > box_hi[j, 0]) | (hi1 < box_lo[j, 1]) | (lo1 > box_hi[j, 1])
                 | (hi2 < box_lo[j, 2]) | (lo2 > box_hi[j, 2]))
        if apart:
            continue
        separated = False
        for i in range(screen.plane_start[j], screen.plane_start[j + 1]):
            ha = (normal[i, 0] * a[0] + normal[i, 1] * a[1] + normal[i, 2] * a[2]) - offset[i]
            hb = (normal[i, 0] * b[0] + normal[i, 1] * b[1] + normal[i, 2] * b[2]) - offset[i]
            ht = (normal[i, 0] * t[0] + normal[i, 1] * t[1] + normal[i, 2] * t[2]) - offset[i]
            if (ha > margin) & (hb > margin) & (ht > margin):
                separated = True
                break
        if not separated:  # (an object without planes is never separated here)
            mask |= np.int64(1) << j
    return mask


@njit(cache=True, nogil=True, error_model="numpy")
def pair_masks(elements: EdgeElements, pair_edge: NDArray[np.int64], pair_receiver: NDArray[np.int64],
               lines: EdgeLines, targets: LegTargets, screen: ScreenGeometry) -> NDArray[np.int64]:
    """Per pair and leg (0: to the transmitter, 1: to its receiver), shape (p, 2), what every
    such leg of the pair's elements must be tested against (:func:`triangle_mask`), decided
    once for the pair: the legs run from probes on the segment between the pair's first and
    last probes (along its edge) to one target, so they lie in the triangle of those three
    points (up to the probes' round-off, 1e-16 m, far inside the margins)."""
    n_pairs = pair_edge.size
    z_lo = np.full(n_pairs, np.inf)
    z_hi = np.full(n_pairs, -np.inf)
    for i in range(elements.pair.size):
        z = 0.5 * (elements.z_start_m[i] + elements.z_end_m[i])
        p = elements.pair[i]
        z_lo[p] = min(z_lo[p], z)
        z_hi[p] = max(z_hi[p], z)
    masks = np.zeros((n_pairs, 2), dtype=np.int64)
    a = np.empty(3)
    b = np.empty(3)
    t = np.empty(3)
    for p in range(n_pairs):
        if z_lo[p] > z_hi[p]:  # no element
            continue
        e = pair_edge[p]
        for c in range(3):
            a[c] = lines.start[e, c] + z_lo[p] * lines.direction[e, c] + lines.probe_offset[e, c]
            b[c] = lines.start[e, c] + z_hi[p] * lines.direction[e, c] + lines.probe_offset[e, c]
        for leg in range(2):
            for c in range(3):
                t[c] = targets.transmitter[c] if leg == 0 else targets.receivers[pair_receiver[p], c]
            masks[p, leg] = triangle_mask(a, b, t, screen)
    return masks


@njit(cache=True, nogil=True, error_model="numpy")
def screen_element_legs(elements: EdgeElements, pair_edge: NDArray[np.int64], pair_receiver: NDArray[np.int64],
                        lines: EdgeLines, targets: LegTargets, screen: ScreenGeometry, shift_m: NDArray[np.float64],
                        eps_m: float) -> tuple[NDArray[np.bool_], EmbreeQueries]:
    """Every element's legs screened (:func:`screen_legs`), and Embree's queries of the
    undecided ones.

    The legs are the reference's: from each element's probe (its centre plus its edge's probe
    offset) to the transmitter, and to its receiver where that has a leg of its own; a leg not
    longer than 2 ``eps_m`` is never blocked. An undecided leg's query is the one
    :meth:`~acoustisim.propagation.raycast.RayCaster.occluded` makes of it, with the same
    operations in the same order (the same float32 buffers): length L = sqrt((s0^2 + s1^2) +
    s2^2) of s = target - probe, unit direction d = s / L, start eps d + probe, shifted by
    ``shift_m`` and rounded once to float32, length L - 2 eps.

    Returns
    -------
    visible : ndarray of bool, shape (n,)
        Whether each element's decided legs are all clear (its undecided ones still to be asked).
    queries : EmbreeQueries
        The undecided legs of the elements no leg blocks: an element is visible iff
        ``visible[element]`` and none of its queries is blocked.
    """
    n = elements.pair.size
    masks = pair_masks(elements, pair_edge, pair_receiver, lines, targets, screen)
    # the legs to test (at most two per element): the segment Embree would be asked about, in
    # float64, its direction and length, and what to test it against
    leg_element = np.empty(2 * n, dtype=np.int64)
    p0 = np.empty((2 * n, 3))
    p1 = np.empty((2 * n, 3))
    unit = np.empty((2 * n, 3))
    length = np.empty(2 * n)
    mask = np.empty(2 * n, dtype=np.int64)
    two_eps = 2.0 * eps_m
    k = 0
    for i in range(n):
        p = elements.pair[i]
        e = pair_edge[p]
        ch = pair_receiver[p]
        z = 0.5 * (elements.z_start_m[i] + elements.z_end_m[i])
        o0 = lines.start[e, 0] + z * lines.direction[e, 0] + lines.probe_offset[e, 0]
        o1 = lines.start[e, 1] + z * lines.direction[e, 1] + lines.probe_offset[e, 1]
        o2 = lines.start[e, 2] + z * lines.direction[e, 2] + lines.probe_offset[e, 2]
        for leg in range(2):
            if masks[p, leg] == 0:  # clear of everything
                continue
            if leg == 0:
                t0, t1, t2 = targets.transmitter[0], targets.transmitter[1], targets.transmitter[2]
            elif targets.own_leg[ch]:
                t0, t1, t2 = targets.receivers[ch, 0], targets.receivers[ch, 1], targets.receivers[ch, 2]
            else:
                break
            s0, s1, s2 = t0 - o0, t1 - o1, t2 - o2
            norm = math.sqrt((s0 * s0 + s1 * s1) + s2 * s2)
            if not norm > two_eps:  # never blocked
                continue
            d0, d1, d2 = s0 / norm, s1 / norm, s2 / norm
            far = norm - eps_m
            leg_element[k] = i
            p0[k, 0], p0[k, 1], p0[k, 2] = eps_m * d0 + o0, eps_m * d1 + o1, eps_m * d2 + o2
            p1[k, 0], p1[k, 1], p1[k, 2] = o0 + far * d0, o1 + far * d1, o2 + far * d2
            unit[k, 0], unit[k, 1], unit[k, 2] = d0, d1, d2
            length[k] = norm
            mask[k] = masks[p, leg]
            k += 1
    decisions = screen_legs(p0[:k], p1[:k], mask[:k], screen)
    visible = np.ones(n, dtype=np.bool_)
    for s in range(k):
        if decisions[s] == BLOCKED:
            visible[leg_element[s]] = False
    q = 0
    for s in range(k):
        if (decisions[s] == UNDECIDED) & visible[leg_element[s]]:
            q += 1
    starts32 = np.empty((q, 3), dtype=np.float32)
    directions32 = np.empty((q, 3), dtype=np.float32)
    lengths32 = np.empty(q, dtype=np.float32)
    element = np.empty(q, dtype=np.int64)
    q = 0
    for s in range(k):
        if (decisions[s] == UNDECIDED) & visible[leg_element[s]]:
            for c in range(3):
                starts32[q, c] = np.float32(p0[s, c] - shift_m[c])
                directions32[q, c] = np.float32(unit[s, c])
            lengths32[q] = np.float32(length[s] - two_eps)
            element[q] = leg_element[s]
            q += 1
    return visible, EmbreeQueries(starts32, directions32, lengths32, element)


def scene_screen(prepared: PreparedScene) -> ScreenGeometry:
    """The screen of a prepared scene."""
    tank = prepared.scene.tank
    return ScreenGeometry.create(prepared.object_bounds, None if tank is None else np.asarray(tank.bounds_m, float),
                                 prepared.raycaster.convex_planes)


def element_visibility(context: SolveContext, prepared: PreparedScene, elements: EdgeElements,
                       pairs: EdgePairs) -> NDArray[np.bool_]:
    """The reference's :func:`~acoustisim.propagation.reference.edges.element_visibility`:
    the legs the screen decides, the others asked of Embree in one batch."""
    raycaster = context.raycaster
    lines = EdgeLines.of(prepared.diffracting_edges)
    visible, queries = screen_element_legs(elements, pairs.edge, pairs.receiver, lines, LegTargets.of(context),
                                           scene_screen(prepared), raycaster.shift_m, DEFAULT_EPS_M)
    if queries.element.size:
        blocked = raycaster.occluded_segments32(queries.starts32, queries.directions32, queries.lengths32)
        visible[queries.element[blocked]] = False
    return visible


__all__ = ("BLOCKED", "CLEAR", "EdgeLines", "EmbreeQueries", "FLOAT32_EPS", "LegTargets", "MASK_BITS", "OTHERS_BIT",
           "ScreenGeometry", "TOLERANCE_ULPS", "UNDECIDED", "WALL_BIT", "element_visibility", "pair_masks",
           "scene_screen", "screen_element_legs", "screen_legs", "screen_tolerance", "triangle_mask")
