"""Compiled per-hit and per-pair loops of the fast diffuse tracer (numba, cached, GIL released).

What :mod:`acoustisim.propagation.reference.diffuse` computes with numpy passes over arrays
(``scatter``, ``receive`` and the row building) is computed here in loops that write the
tracer's output arrays directly:

* :func:`scatter_and_pair`: the rays that hit a scattering surface from its front, compacted,
  with the hit point solved on the triangle's plane in float64, the distance travelled and the
  speckle factor; then, for every hit and receiver, the leg's geometry and gain, whether the
  receiver is in front of the face, whether a convex object blocks the leg (its face planes),
  and the legs left for an Embree occlusion query (crossing the box of an object without
  planes, :mod:`~acoustisim.propagation.fast.diffuse_screen`), written as Embree's float32
  buffers;
* :func:`clear_blocked` and :func:`write_receptions`: Embree's answers applied, and the pairs in
  view written as receptions;
* :func:`copy_chunk`: a chunk written into a scratch block moved to its final place;
* :func:`pack_rows`: the receptions as rows of the arrivals table (path length, arrival
  direction and the chain of hits derived from the event and the receiver).

Every loop runs in order over its inputs (the output is deterministic); ``nogil=True`` lets the
tracer's threads run them in parallel; ``error_model="numpy"`` drops the per-division zero
checks (every divisor is guarded by the test before it).
"""

from __future__ import annotations

import cmath
import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.fast.convex_occlusion import segment_crosses_convex
from acoustisim.propagation.fast.diffuse_sampling import speckle_of
from acoustisim.propagation.fast.diffuse_screen import LEGS_CLEAR, LEGS_SCREENED, LegScreen
from acoustisim.propagation.fast.row_columns import write_path_columns


class TriangleSet(NamedTuple):
    """Per triangle of the ray caster: ``mu`` (n,) Lambert coefficient of its surface,
    ``normal`` (3, n) unit normal, ``offset`` (n,) plane offset n . v0 (m), ``surface`` (n,)
    int64 index into ``scene.surface_names``."""

    mu: NDArray[np.float64]
    normal: NDArray[np.float64]
    offset: NDArray[np.float64]
    surface: NDArray[np.int64]


class RoughTable(NamedTuple):
    """Per surface (n_surfaces,), what the Lambert strength of the coherent-roughness loss
    (:func:`acoustisim.propagation.reference.diffuse.rough_lambert_mu`) is computed from:
    ``k0h`` = k0 h (0: smooth surface); for the reflection energy |R|^2, ``constant_energy`` of
    the angle-independent models (rigid, pressure release, fixed), NaN for the angle-dependent
    ones: the fluid model's |R|^2 comes from ``impedance_ratio`` Z2 / Z1 and ``index_sq``
    (c2 / c1)^2, the elastic model's (``elastic`` True) from ``density_ratio`` rho / rho_w and the
    complex refraction indices ``index_l``, ``index_s`` (c_w / c~; 0 without shear)."""

    k0h: NDArray[np.float64]
    constant_energy: NDArray[np.float64]
    impedance_ratio: NDArray[np.float64]
    index_sq: NDArray[np.float64]
    elastic: NDArray[np.bool_]
    density_ratio: NDArray[np.float64]
    index_l: NDArray[np.complex128]
    index_s: NDArray[np.complex128]


class RayBatch(NamedTuple):
    """One bounce's m rays, as columns.

    ``triangle`` (m,) int32: the hit triangle (-1: none); ``origin`` (3, m) or (3, 1) (one
    shared) (m); ``direction`` and ``departure`` (3, m): unit direction, and the direction the
    ray left the transmitter; ``weight`` (m,) (sr); ``travelled`` (m,) or (1,) (m); ``parent``
    (m,) or (1,) int32: the event the ray leaves (-1: the transmitter).
    """

    triangle: NDArray[np.int32]
    origin: NDArray[np.float64]
    direction: NDArray[np.float64]
    departure: NDArray[np.float64]
    weight: NDArray[np.float64]
    travelled: NDArray[np.float64]
    parent: NDArray[np.int32]


class ReceiverSet(NamedTuple):
    """The receivers and how their legs are tested.

    ``position`` (n_rx, 3) (m); ``tested`` (n_rx,) bool: legs tested for occlusion; ``shared``:
    one receiver's leg decides for all ("centre" visibility); ``shift`` (3,): subtracted from
    the legs' starts for Embree (its float32 frame); ``eps``: each leg is shrunk by it (m) at
    both ends (shorter than 2 eps: never blocked).
    """

    position: NDArray[np.float64]
    tested: NDArray[np.bool_]
    shared: bool
    shift: NDArray[np.float64]
    eps: float


class SpeckleLattice(NamedTuple):
    """``per_cell`` = 1 / SPECKLE_CELL_M (1/m) and ``seed_hash`` = splitmix64(seed)."""

    per_cell: float
    seed_hash: np.uint64


class EventArrays(NamedTuple):
    """Event and reception arrays a chunk writes into (the solve's output or a scratch block).

    Events (M,): ``point`` and ``departure`` (M, 3), ``surface``, ``parent``, ``bounce``
    (int32), ``travelled`` (m), ``phase`` (rad). Receptions (N,): ``event`` (int32),
    ``channel`` (int8, int32 beyond 127 receivers), ``gain``.
    """

    point: NDArray[np.float64]
    departure: NDArray[np.float64]
    surface: NDArray[np.int32]
    parent: NDArray[np.int32]
    bounce: NDArray[np.int32]
    travelled: NDArray[np.float64]
    phase: NDArray[np.float64]
    event: NDArray[np.int32]
    channel: NDArray[np.int8]
    gain: NDArray[np.float64]


class Continuation(NamedTuple):
    """What a continuing hit needs beyond its event, from index 0: ``normal`` (3, m), ``weight``
    and ``mu`` (m,). Size 0 when the rays end at this bounce."""

    normal: NDArray[np.float64]
    weight: NDArray[np.float64]
    mu: NDArray[np.float64]


class PairBuffers(NamedTuple):
    """Per (hit, receiver) pair, point-major: ``state`` (int8: 0 not heard, 1 heard, 2 leg
    queued for Embree) and ``gain``; the queued legs as Embree's buffers: ``leg_start`` and
    ``leg_unit`` (L, 3) float32 (the start in Embree's frame, shrunk by eps), ``leg_length``
    (L,) float32, ``leg_pair`` (L,) int64 (L = 0 when no leg can be queued)."""

    state: NDArray[np.int8]
    gain: NDArray[np.float64]
    leg_start: NDArray[np.float32]
    leg_unit: NDArray[np.float32]
    leg_length: NDArray[np.float32]
    leg_pair: NDArray[np.int64]


class BounceCursor(NamedTuple):
    """Where one bounce writes: ``bounce`` its number (1 = first hits); ``event_row`` the row of
    its first event; ``reception_row`` the row of its first reception when no leg can be left
    to Embree (receptions written as soon as a point is decided), -1 otherwise (written by
    :func:`write_receptions` after Embree's answers); ``continues``: another bounce follows
    (write the :class:`Continuation`)."""

    bounce: int
    event_row: int
    reception_row: int
    continues: bool


class BounceCounts(NamedTuple):
    """What :func:`scatter_and_pair` did: ``hits`` (events written), ``embree_legs`` (legs
    queued), ``convex_legs`` (legs decided by convex objects' planes), ``in_view`` (pairs heard
    or queued)."""

    hits: int
    embree_legs: int
    convex_legs: int
    in_view: int


@njit(cache=True, nogil=True, error_model="numpy")
def _slab(px: float, py: float, pz: float, ix: float, iy: float, iz: float, lx: float, ly: float, lz: float,
          hx: float, hy: float, hz: float) -> bool:
    """Whether the segment p + s t, 0 <= t <= 1, meets the box [l, h], given the inverses
    ``ix, iy, iz`` = 1 / s of the segment's components (+-inf for a 0: then the slab's bounds
    give +-inf, or NaN when p lies on the slab's face, which the comparisons ignore, a
    grazing contact). Scalar arguments only: array arguments would cost reference-count
    updates at every call."""
    t1 = (lx - px) * ix
    t2 = (hx - px) * ix
    enter = min(t1, t2)
    leave = max(t1, t2)
    t1 = (ly - py) * iy
    t2 = (hy - py) * iy
    enter = max(enter, min(t1, t2))
    leave = min(leave, max(t1, t2))
    t1 = (lz - pz) * iz
    t2 = (hz - pz) * iz
    enter = max(enter, min(t1, t2))
    leave = min(leave, max(t1, t2))
    return max(enter, 0.0) <= min(leave, 1.0)


@njit(cache=True, nogil=True, error_model="numpy")
def upper_root(value: complex) -> complex:
    """The square root with Im >= 0 (``acoustisim.materials.upper_root`` for one value)."""
    root = cmath.sqrt(value)
    return -root if root.imag < 0.0 else root


@njit(cache=True, nogil=True, error_model="numpy")
def elastic_energy(rough: RoughTable, s: int, c1: float) -> float:
    """|R|^2 of the elastic model of surface ``s`` at incidence cosine ``c1``: the formula of
    ``Material``'s ``elastic`` model (``acoustisim.materials``), operation for operation."""
    sin_sq = 1.0 - c1 * c1
    n_l, n_s = rough.index_l[s], rough.index_s[s]
    a_l = upper_root(n_l * n_l - sin_sq)
    solid = complex(rough.density_ratio[s] * c1)
    if n_s != 0.0:
        inverse_sq = 1.0 / (n_s * n_s)
        a_s = upper_root(n_s * n_s - sin_sq)
        x = sin_sq * inverse_sq
        rayleigh = 1.0 - 2.0 * x
        rayleigh = rayleigh * rayleigh + 4.0 * inverse_sq * x * a_s * a_l
        solid = solid * rayleigh
    r = (solid - a_l) / (solid + a_l)
    return r.real * r.real + r.imag * r.imag


@njit(cache=True, nogil=True, error_model="numpy")
def rough_lambert_mu(rough: RoughTable, s: int, sin_grazing: float) -> float:
    """|R|^2 (1 - exp(-4 (k0 h sin g)^2)) / pi of a hit on rough surface ``s`` at incidence grazing
    sine ``sin_grazing``: the reference's (3), |R|^2 of the fluid model without complex numbers
    (real below the critical angle, |R| = 1 beyond), of the elastic one by :func:`elastic_energy`."""
    c1 = min(max(sin_grazing, 0.0), 1.0)  # the cosine of the incidence angle
    phase = rough.k0h[s] * c1
    energy = rough.constant_energy[s]
    if rough.elastic[s]:
        energy = elastic_energy(rough, s, c1)
    elif math.isnan(energy):
        q = 1.0 - rough.index_sq[s] * (1.0 - c1 * c1)  # cos^2 of the transmitted angle
        if q <= 0.0:
            energy = 1.0
        else:
            c2 = math.sqrt(q)
            z = rough.impedance_ratio[s] * c1
            r = (z - c2) / (z + c2)
            energy = r * r
    return energy * -math.expm1(-4.0 * phase * phase) / math.pi


@njit(cache=True, nogil=True, error_model="numpy")
def scatter_and_pair(rays: RayBatch, triangles: TriangleSet, rough: RoughTable, lattice: SpeckleLattice,
                     receivers: ReceiverSet, screen: LegScreen, cursor: BounceCursor, out: EventArrays,
                     continuation: Continuation, pairs: PairBuffers) -> BounceCounts:
    """Compact the rays that scatter, solve their hits, and decide every (hit, receiver) pair:
    its geometry and gain, exact occlusion by the convex objects, and the legs Embree must test.

    A ray scatters when it hits a triangle with mu > 0 from its front (its surface's mu plus, on
    a rough surface, :func:`rough_lambert_mu` at the ray's grazing angle); its hit point is solved
    on the triangle's plane (t = (n . v0 - n . o) / (n . d)) and written, with the ray's
    departure, path length, parent, surface, bounce and speckle phase, to the events of ``out``
    from row ``cursor.event_row``, in ray order (h of them); with ``cursor.continues`` its
    normal, weight and mu go to ``continuation`` from index 0.

    Pair (i, j) of hit i and receiver j gets ``pairs.state[i n_rx + j]``: 0 when the receiver
    is behind the face or the leg is blocked by a convex object, 2 when its leg is queued for
    Embree (``pairs.leg_*`` from index 0), 1 otherwise; and, when in front, its gain
    |X| sqrt(mu weight sin(g_s)) / r2, computed as |X| sqrt(mu weight) sqrt(c / r2^3) with
    c = r2 sin(g_s). Only legs of ``receivers.tested`` receivers longer than 2 eps are tested:
    with one box (the union of too many objects) a leg crossing it is queued; otherwise each
    object's box (skipping the convex object the point lies on) is tested: the point against
    the box's shared wedge (once per point), the leg's direction against the receiver's wedge,
    the slab test; a leg crossing a convex object's box is decided on the leg shrunk by eps at
    both ends by its planes; one crossing the box of an object without planes, unless a convex
    one blocks it, is queued. With ``receivers.shared``, a leg blocked by a convex object hides
    the point from every receiver.

    With ``cursor.reception_row`` >= 0 (no leg can be queued) each point's heard pairs are
    written as receptions (event row, channel, gain) into ``out`` from that row, in order.
    """
    origin, direction = rays.origin, rays.direction
    one_origin = origin.shape[1] == 1
    one_parent = rays.parent.size == 1
    position = receivers.position
    n_rx = position.shape[0]
    eps = receivers.eps
    lo, hi, planes = screen.lo, screen.hi, screen.planes
    wedges, point_wedges = screen.wedges, screen.point_wedges
    n_boxes = lo.shape[0]
    screened = screen.mode == LEGS_SCREENED
    state, pair_gain = pairs.state, pairs.gain
    reception_row = cursor.reception_row
    n_legs = 0
    n_exact = 0
    in_view = 0
    h = 0
    for ray in range(rays.triangle.size):
        t = rays.triangle[ray]
        if t < 0:
            continue
        m = triangles.mu[t]
        s = triangles.surface[t]
        rough_surface = rough.k0h[s] > 0.0
        if not (m > 0.0 or rough_surface):
            continue
        nx, ny, nz = triangles.normal[0, t], triangles.normal[1, t], triangles.normal[2, t]
        dx, dy, dz = direction[0, ray], direction[1, ray], direction[2, ray]
        cos_in = dx * nx + dy * ny + dz * nz
        if not cos_in < 0.0:
            continue
        if rough_surface:  # sin(g_i) = -cos_in
            m = m + rough_lambert_mu(rough, s, -cos_in)
            if not m > 0.0:
                continue
        o = 0 if one_origin else ray
        ox, oy, oz = origin[0, o], origin[1, o], origin[2, o]
        distance = (triangles.offset[t] - (nx * ox + ny * oy + nz * oz)) / cos_in
        px, py, pz = ox + distance * dx, oy + distance * dy, oz + distance * dz
        row = cursor.event_row + h
        out.point[row, 0], out.point[row, 1], out.point[row, 2] = px, py, pz
        for k in range(3):
            out.departure[row, k] = rays.departure[k, ray]
        w = rays.weight[ray]
        magnitude, angle = speckle_of(px, py, pz, lattice.per_cell, lattice.seed_hash)
        out.phase[row] = angle
        point_amplitude = magnitude * math.sqrt(w * m)  # |X| sqrt(mu dOmega)
        out.travelled[row] = (rays.travelled[0] if rays.travelled.size == 1 else rays.travelled[ray]) + distance
        out.parent[row] = rays.parent[0] if one_parent else rays.parent[ray]
        out.bounce[row] = cursor.bounce
        out.surface[row] = s
        if cursor.continues:
            continuation.normal[0, h], continuation.normal[1, h], continuation.normal[2, h] = nx, ny, nz
            continuation.weight[h] = w
            continuation.mu[h] = m
        own = screen.own_box[s]
        hidden = False  # a leg of this point blocked by a convex object
        # the boxes a leg from this point to some receiver may cross, as a bit mask (not the
        # convex object the point lies on)
        candidates = 0
        if screened:
            for b in range(1, n_boxes):
                if (b != own
                        and point_wedges[b, 0] * px + point_wedges[b, 1] * py + point_wedges[b, 2] * pz
                        >= point_wedges[b, 3]
                        and point_wedges[b, 4] * px + point_wedges[b, 5] * py + point_wedges[b, 6] * pz
                        >= point_wedges[b, 7]):
                    candidates |= np.int64(1) << b
        for j in range(n_rx):
            pair = h * n_rx + j
            qx, qy, qz = position[j, 0], position[j, 1], position[j, 2]
            dx, dy, dz = qx - px, qy - py, qz - pz
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            c = dx * nx + dy * ny + dz * nz
            if not c > 0.0:
                state[pair] = 0
                continue
            state[pair] = 1
            pair_gain[pair] = point_amplitude * math.sqrt(c / (length * length * length))
            in_view += 1
            if not receivers.tested[j] or screen.mode == LEGS_CLEAR or not length > 2.0 * eps:
                continue
            if screened:
                # 0: clear (no box crossed); 1: blocked by a convex object; 2: Embree must test
                # it; 3: clear, found so by the planes of the convex objects whose boxes it crosses
                verdict = 0
                if n_boxes == 1:  # the union of too many objects only
                    if _slab(px, py, pz, 1.0 / dx, 1.0 / dy, 1.0 / dz, lo[0, 0], lo[0, 1], lo[0, 2], hi[0, 0],
                             hi[0, 1], hi[0, 2]):  # +-inf for a zero component
                        verdict = 2
                for b in range(1, n_boxes if candidates else 1):
                    if not (candidates >> b) & 1:
                        continue
                    # the wedge seen from the receiver: e = -(dx, dy, dz), receiver -> point
                    if (wedges[j, b, 0] * dx + wedges[j, b, 1] * dy + wedges[j, b, 2] * dz > 0.0
                            or wedges[j, b, 3] * dx + wedges[j, b, 4] * dy + wedges[j, b, 5] * dz > 0.0):
                        continue
                    if not _slab(px, py, pz, 1.0 / dx, 1.0 / dy, 1.0 / dz, lo[b, 0], lo[b, 1], lo[b, 2], hi[b, 0],
                                 hi[b, 1], hi[b, 2]):
                        continue
                    if planes.start[b] == planes.start[b + 1]:
                        verdict = 2
                    elif segment_crosses_convex((px, py, pz), (dx / length, dy / length, dz / length), eps,
                                                length - eps, planes, b):
                        verdict = 1
                        break
                    elif verdict == 0:
                        verdict = 3
                if verdict == 0:
                    continue
                if verdict != 2:  # decided by the convex objects' planes
                    n_exact += 1
                    if verdict == 1:
                        state[pair] = 0
                        in_view -= 1
                        hidden = True
                    continue
            state[pair] = 2
            if n_legs == pairs.leg_pair.size:  # the caller allocated no room: an internal error
                raise RuntimeError("scatter_and_pair: a leg left to Embree without a buffer for it")
            inverse = 1.0 / length
            ux, uy, uz = dx * inverse, dy * inverse, dz * inverse
            pairs.leg_start[n_legs, 0] = px + eps * ux - receivers.shift[0]
            pairs.leg_start[n_legs, 1] = py + eps * uy - receivers.shift[1]
            pairs.leg_start[n_legs, 2] = pz + eps * uz - receivers.shift[2]
            pairs.leg_unit[n_legs, 0], pairs.leg_unit[n_legs, 1], pairs.leg_unit[n_legs, 2] = ux, uy, uz
            pairs.leg_length[n_legs] = length - 2.0 * eps
            pairs.leg_pair[n_legs] = pair
            n_legs += 1
        if receivers.shared and hidden:
            for j in range(n_rx):
                if state[h * n_rx + j] != 0:
                    state[h * n_rx + j] = 0
                    in_view -= 1
        if reception_row >= 0:  # every pair of this point is decided: its receptions
            for j in range(n_rx):
                pair = h * n_rx + j
                if state[pair] != 0:
                    out.event[reception_row] = row
                    out.channel[reception_row] = j
                    out.gain[reception_row] = pair_gain[pair]
                    reception_row += 1
        h += 1
    return BounceCounts(h, n_legs, n_exact, in_view)


@njit(cache=True, nogil=True, error_model="numpy")
def clear_blocked(state: NDArray[np.int8], leg_pair: NDArray[np.int64], blocked: NDArray[np.bool_], shared: bool,
                  n_rx: int) -> None:
    """Apply Embree's occlusion answers to the pair states: a queued leg found ``blocked``
    clears its pair (state 0), or with ``shared`` (one receiver's leg decides for all) every
    pair of its point."""
    for leg in range(blocked.size):
        if blocked[leg]:
            pair = leg_pair[leg]
            if shared:
                point = pair // n_rx
                for j in range(n_rx):
                    state[point * n_rx + j] = 0
            else:
                state[pair] = 0


@njit(cache=True, nogil=True, error_model="numpy")
def write_receptions(hits: int, n_rx: int, pairs: PairBuffers, event_row: int, reception_row: int,
                     out: EventArrays) -> int:
    """The pairs of the first ``hits`` points still heard (state > 0), point-major, as receptions
    of ``out`` from row ``reception_row``: event ``event_row + point``, channel, gain. Returns
    the row after the last one written."""
    k = reception_row
    for i in range(hits):
        for j in range(n_rx):
            pair = i * n_rx + j
            if pairs.state[pair] == 0:
                continue
            out.event[k] = event_row + i
            out.channel[k] = j
            out.gain[k] = pairs.gain[pair]
            k += 1
    return k


@njit(cache=True, nogil=True, error_model="numpy")
def copy_chunk(events: int, receptions: int, source: EventArrays, first_event: int, first_reception: int,
               target: EventArrays) -> None:
    """Copy one chunk's events (rows 0 to ``events``) and receptions (0 to ``receptions``),
    written into a scratch block ``source``, to rows ``first_event`` and ``first_reception``
    onwards of ``target``, shifting the event indices they hold (parents >= 0, the receptions'
    events) by ``first_event``."""
    for i in range(events):
        b = first_event + i
        for k in range(3):
            target.point[b, k] = source.point[i, k]
            target.departure[b, k] = source.departure[i, k]
        target.surface[b] = source.surface[i]
        p = source.parent[i]
        target.parent[b] = p + first_event if p >= 0 else p
        target.bounce[b] = source.bounce[i]
        target.travelled[b] = source.travelled[i]
        target.phase[b] = source.phase[i]
    for i in range(receptions):
        b = first_reception + i
        target.event[b] = source.event[i] + first_event
        target.channel[b] = source.channel[i]
        target.gain[b] = source.gain[i]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _leg(px: float, py: float, pz: float, qx: float, qy: float, qz: float) -> tuple[float, float, float, float]:
    """The length r2 (m) and unit direction of the leg p -> q."""
    dx, dy, dz = qx - px, qy - py, qz - pz
    r = math.sqrt(dx * dx + dy * dy + dz * dz)
    inverse = 1.0 / r
    return r, dx * inverse, dy * inverse, dz * inverse


@njit(cache=True, nogil=True, error_model="numpy")
def pack_rows(events: EventArrays, receivers: NDArray[np.float64], first_path_id: int, kind: int, start: int,
              stop: int, rows: NDArray) -> None:
    """Write receptions ``start:stop`` of ``events`` as rows of the arrivals table
    (``paths.PATH_DTYPE``, ``rows`` of at least ``stop`` rows).

    Every field of each row is written once, row after row (a numpy assignment per field would
    stream over the 243-byte rows a dozen times): ``path_id`` = ``first_path_id`` + event,
    channel, ``kind``, ``order`` = the event's bounce, the path length, gain, phase, departure
    and arrival directions, and the interaction chain (the surfaces and points of the event and
    its parents, first hit first, -1 / NaN padded); the derived columns are zeroed.
    """
    slots = rows[0].object_ids.size if rows.size else 0
    for i in range(start, stop):
        row = rows[i]
        e = events.event[i]
        j = events.channel[i]
        order = events.bounce[e]
        r, ax, ay, az = _leg(events.point[e, 0], events.point[e, 1], events.point[e, 2], receivers[j, 0],
                             receivers[j, 1], receivers[j, 2])
        write_path_columns(row, first_path_id + e, j, kind, order, events.travelled[e] + r, events.gain[i],
                           events.phase[e])
        row.arrival_dir[0], row.arrival_dir[1], row.arrival_dir[2] = ax, ay, az
        for k in range(3):
            row.departure_dir[k] = events.departure[e, k]
        for slot in range(slots):
            row.object_ids[slot] = -1
            for k in range(3):
                row.points_m[slot, k] = np.nan
        current, level = e, order - 1
        while current >= 0 and level >= 0:  # walk back to the first hit
            if level < slots:
                row.object_ids[level] = events.surface[current]
                for k in range(3):
                    row.points_m[level, k] = events.point[current, k]
            current = events.parent[current]
            level -= 1


__all__ = ("BounceCounts", "BounceCursor", "Continuation", "EventArrays", "PairBuffers", "RayBatch", "ReceiverSet",
           "RoughTable", "SpeckleLattice", "TriangleSet", "clear_blocked", "copy_chunk", "pack_rows",
           "elastic_energy", "rough_lambert_mu", "scatter_and_pair", "upper_root", "write_receptions")
