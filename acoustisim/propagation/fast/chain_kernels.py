"""Compiled candidate-to-chain loops of the fast specular engine (numba, cached on disk, GIL released).

Each candidate chain is one loop iteration that back-traces its planar points
(:func:`.mirror_kernels.backtrace_one`) and, if the chain is valid, writes its row straight
into the solve's :class:`PaddedChains` (a chain of order k < K fills slots 0..k-1; its vertices
k+2.. repeat the receiver; surfaces, patches and kinds are -1 beyond, normals 0, materials 0,
all written here):

1. :func:`fill_planar`: the chains of one mirror sequence length, every receiver;
2. :func:`mixed_candidates`: the (before row, after row, curved reflector) triples of one split
   whose images are valid and which the reflector's visibility table allows, with the two
   unfolded ends;
3. :func:`fill_mixed`: the chains of one split, from the candidates' specular points;
4. then, over the chains: :func:`chain_legs` and :func:`occlusion_queries32` (the legs and
   their Embree buffers), :func:`unblocked_chains`, :func:`duplicate_keys`,
   :func:`incidence_cosines`, :func:`vertex_groups` (reflections grouped by material) and
   :func:`write_rows`.

Rows come out in the order (and with the chain numbers) of
:mod:`acoustisim.propagation.reference.specular`, with the same arithmetic (lengths
sqrt(dx^2 + dy^2 + dz^2) summed x + y + z, as ``np.linalg.norm`` of a row). No ``fastmath``.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.fast.bundles import plain_tuple_arguments
from acoustisim.propagation.curved import SurfacePoints
from acoustisim.propagation.fast.mirror_kernels import MirrorArrays, backtrace_one

MIRROR_KIND = 0
"""Reflector-kind code of a planar-mirror reflection in :attr:`PaddedChains.kind`."""
CURVED_KIND = 1
"""Reflector-kind code of a curved-primitive reflection."""
SMOOTH_KIND = 2
"""Reflector-kind code of a smooth-mesh reflection."""


class PaddedChains(NamedTuple):
    """Chains of every order and kind in one padded array (n rows, orders up to K).

    A chain of order k < K fills slots 0..k-1; its vertices k+2.. repeat the receiver, its
    surfaces, patches and kinds are -1 beyond, its normals 0 and materials 0.

    Attributes
    ----------
    order : ndarray of int64, shape (n,)
    vertices : ndarray, shape (n, K + 2, 3)
        Transmitter, reflection points, receiver (m).
    surface, patch : ndarray of int64, shape (n, K)
        Surface index and ray-caster patch label of each reflection.
    normal : ndarray, shape (n, K, 3)
        Unit normal (water side) at each reflection.
    kind : ndarray of int64, shape (n, K)
        :data:`MIRROR_KIND`, :data:`CURVED_KIND` or :data:`SMOOTH_KIND`; -1 for padding.
    material : ndarray of int64, shape (n, K)
        Index into the kind's material table.
    length, spreading : ndarray, shape (n,)
        Path length (m) and pressure factor without reflection coefficients.
    channel, chain : ndarray of int64, shape (n,)
        Receiver and chain number.
    has_phase : ndarray of bool, shape (n,)
        The chain carries a stationary-point phase (smooth meshes).
    phase : ndarray, shape (n,)
        That phase (rad, engineering convention), 0 elsewhere.
    """

    order: NDArray[np.int64]
    vertices: NDArray[np.float64]
    surface: NDArray[np.int64]
    patch: NDArray[np.int64]
    normal: NDArray[np.float64]
    kind: NDArray[np.int64]
    material: NDArray[np.int64]
    length: NDArray[np.float64]
    spreading: NDArray[np.float64]
    channel: NDArray[np.int64]
    chain: NDArray[np.int64]
    has_phase: NDArray[np.bool_]
    phase: NDArray[np.float64]


class ChainEnds(NamedTuple):
    """The transmitter (3,) and receivers (r, 3) of a pose (m)."""

    transmitter: NDArray[np.float64]
    receivers: NDArray[np.float64]


class MirrorSide(NamedTuple):
    """Mirror sequences with a start point's images across them.

    Attributes
    ----------
    sequences : ndarray of int64, shape (s, k)
        Mirrors in path order.
    images : ndarray, shape (rows, k + 1, 3)
        The transmitter's images across each sequence (rows = s), or each receiver's across
        each sequence read backwards (rows = s r, row ``q * r + i`` for sequence q, receiver i).
    unfolded : ndarray of bool, shape (rows,)
        Each image in front of the next mirror.
    """

    sequences: NDArray[np.int64]
    images: NDArray[np.float64]
    unfolded: NDArray[np.bool_]


class MixedCandidates(NamedTuple):
    """Candidates [before mirrors, curved reflector, after mirrors] of one split (n of them).

    Attributes
    ----------
    before : ndarray of int64, shape (n,)
        Row of the before side (a sequence from the transmitter).
    after_row : ndarray of int64, shape (n,)
        Row of the after side (``sequence * r + receiver``).
    reflector : ndarray of int64, shape (n,)
    source_image, receiver_image : ndarray, shape (n, 3)
        The last images of the transmitter and of the receiver (m).
    """

    before: NDArray[np.int64]
    after_row: NDArray[np.int64]
    reflector: NDArray[np.int64]
    source_image: NDArray[np.float64]
    receiver_image: NDArray[np.float64]


class ReflectorLabels(NamedTuple):
    """Surface index and ray-caster patch label (c,) of each curved reflector."""

    surface: NDArray[np.int64]
    patch: NDArray[np.int64]


class ChainLegs(NamedTuple):
    """The legs of some chains as segments (L of them).

    Attributes
    ----------
    origins, directions : ndarray, shape (L, 3)
        Start (m) and unit direction (NaN for a zero-length leg, never cast).
    lengths : ndarray, shape (L,)
        (m).
    exclude : ndarray of int64, shape (L, 2)
        The patches at the leg's start and end (-1 at the transmitter and the receiver).
    """

    origins: NDArray[np.float64]
    directions: NDArray[np.float64]
    lengths: NDArray[np.float64]
    exclude: NDArray[np.int64]


class OcclusionQueries(NamedTuple):
    """Embree's float32 buffers of the legs long enough to be blocked (q of them).

    ``starts32``, ``directions32`` (q, 3) and ``lengths32`` (q,) for
    :meth:`~acoustisim.propagation.raycast.RayCaster.occluded_segments32`; ``leg`` (q,) the leg
    of each query.
    """

    starts32: NDArray[np.float32]
    directions32: NDArray[np.float32]
    lengths32: NDArray[np.float32]
    leg: NDArray[np.int64]


class MaterialCodes(NamedTuple):
    """Reflection codes of materials shared across reflector kinds: kind k's material j has code
    ``code_of[kind_offset[k] + j]`` (0 .. ``count`` - 1)."""

    code_of: NDArray[np.int64]
    kind_offset: NDArray[np.int64]
    count: int


class PathColumns(NamedTuple):
    """The geometric fields of a fresh ``empty_paths_array`` that :func:`write_rows` fills (views)."""

    path_id: NDArray[np.int64]
    channel: NDArray[np.int8]
    kind: NDArray[np.int8]
    order: NDArray[np.int8]
    path_length_m: NDArray[np.float64]
    departure_dir: NDArray[np.float64]
    arrival_dir: NDArray[np.float64]
    object_ids: NDArray[np.int16]
    points_m: NDArray[np.float64]


def path_columns(rows: NDArray[Any]) -> PathColumns:
    """The :class:`PathColumns` views of PATH_DTYPE ``rows``."""
    return PathColumns(*(rows[name] for name in PathColumns._fields))


@njit(cache=True, nogil=True, inline="always")
def write_mirror_slot(row: int, slot: int, m: int, mirrors: MirrorArrays, out: PaddedChains) -> None:
    out.surface[row, slot] = mirrors.surface[m]
    out.patch[row, slot] = mirrors.patch[m]
    out.normal[row, slot, 0] = mirrors.normal[m, 0]
    out.normal[row, slot, 1] = mirrors.normal[m, 1]
    out.normal[row, slot, 2] = mirrors.normal[m, 2]
    out.kind[row, slot] = MIRROR_KIND
    out.material[row, slot] = mirrors.material[m]


@njit(cache=True, nogil=True, inline="always")
def write_padding(row: int, first: int, out: PaddedChains) -> None:
    """The padding values in reflection slots ``first``.. of a row."""
    for q in range(first, out.surface.shape[1]):
        out.surface[row, q] = -1
        out.patch[row, q] = -1
        out.normal[row, q, 0], out.normal[row, q, 1], out.normal[row, q, 2] = 0.0, 0.0, 0.0
        out.kind[row, q] = -1
        out.material[row, q] = 0


@njit(cache=True, nogil=True, inline="always")
def write_receiver_tail(row: int, first: int, r0: float, r1: float, r2: float, out: PaddedChains) -> None:
    """The receiver in vertex slots ``first``.. (the real one and the padding)."""
    vertices = out.vertices
    for q in range(first, vertices.shape[1]):
        vertices[row, q, 0], vertices[row, q, 1], vertices[row, q, 2] = r0, r1, r2


@njit(cache=True, nogil=True, inline="always")
def write_transmitter(row: int, ends: ChainEnds, out: PaddedChains) -> None:
    out.vertices[row, 0, 0] = ends.transmitter[0]
    out.vertices[row, 0, 1] = ends.transmitter[1]
    out.vertices[row, 0, 2] = ends.transmitter[2]


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def fill_planar(mirrors_fields: tuple, side_fields: tuple, chain_base: int, ends_fields: tuple, out_fields: tuple,
                cursor: int) -> int:
    """Planar chains of ``side`` (the transmitter's images across s sequences of k mirrors), to
    every receiver, written from row ``cursor`` of ``out``.

    Sequence j is chain ``chain_base + j`` on every receiver; sequences with invalid images are
    skipped. Rows: receiver by receiver, sequences in order; length (m) the distance from the
    last image to the receiver, spreading 1 / length. Returns the next free row.
    """
    mirrors = MirrorArrays(*mirrors_fields)
    side = MirrorSide(*side_fields)
    ends = ChainEnds(*ends_fields)
    out = PaddedChains(*out_fields)
    sequences, images, unfolded = side
    receivers = ends.receivers
    s, k = sequences.shape
    for rx in range(receivers.shape[0]):
        r0, r1, r2 = receivers[rx, 0], receivers[rx, 1], receivers[rx, 2]
        for j in range(s):
            if not unfolded[j]:
                continue
            row = cursor
            ok = backtrace_one(mirrors, images, j, sequences, j, False, r0, r1, r2, out.vertices, row, 1, 1)
            if not ok:
                continue
            cursor += 1
            out.order[row] = k
            write_transmitter(row, ends, out)
            write_receiver_tail(row, k + 1, r0, r1, r2, out)
            for q in range(k):
                write_mirror_slot(row, q, sequences[j, q], mirrors, out)
            write_padding(row, k, out)
            e0, e1, e2 = images[j, k, 0] - r0, images[j, k, 1] - r1, images[j, k, 2] - r2
            length = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            out.length[row] = length
            out.spreading[row] = 1.0 / length
            out.channel[row] = rx
            out.chain[row] = chain_base + j
    return cursor


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def mixed_candidates(seen_by: NDArray[np.bool_], before_fields: tuple, after_fields: tuple,
                     n_receivers: int) -> MixedCandidates:
    """The candidates of one split [n_before mirrors, a curved reflector, n_after mirrors].

    ``seen_by`` (c, m): the mirrors each curved reflector may be reached from / reach.
    ``before``: sequences from the transmitter with its images; ``after``: sequences from the
    reflector to a receiver (path order), with each receiver's images across them read
    backwards (``n_receivers`` rows per sequence). Every (before row, after row, reflector)
    triple with valid images on both sides, allowed by ``seen_by`` at the mirrors next to the
    reflector, nested in that order.
    """
    before, after = MirrorSide(*before_fields), MirrorSide(*after_fields)
    n_refl = seen_by.shape[0]
    n_before, n_after = before.sequences.shape[1], after.sequences.shape[1]
    capacity = 0
    for b in range(before.unfolded.shape[0]):
        if before.unfolded[b]:
            capacity += 1
    n_after_ok = 0
    for a in range(after.unfolded.shape[0]):
        if after.unfolded[a]:
            n_after_ok += 1
    capacity *= n_after_ok * n_refl
    before_row = np.empty(capacity, dtype=np.int64)
    after_row = np.empty(capacity, dtype=np.int64)
    reflector = np.empty(capacity, dtype=np.int64)
    source_image = np.empty((capacity, 3))
    receiver_image = np.empty((capacity, 3))
    n = 0
    for b in range(before.unfolded.shape[0]):
        if not before.unfolded[b]:
            continue
        for a in range(after.unfolded.shape[0]):
            if not after.unfolded[a]:
                continue
            for r in range(n_refl):
                if n_before > 0 and not seen_by[r, before.sequences[b, n_before - 1]]:
                    continue
                if n_after > 0 and not seen_by[r, after.sequences[a // n_receivers, 0]]:
                    continue
                before_row[n], after_row[n], reflector[n] = b, a, r
                for q in range(3):
                    source_image[n, q] = before.images[b, n_before, q]
                    receiver_image[n, q] = after.images[a, n_after, q]
                n += 1
    return MixedCandidates(before_row[:n], after_row[:n], reflector[:n], source_image[:n], receiver_image[:n])


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def fill_mixed(mirrors_fields: tuple, before_fields: tuple, after_fields: tuple, n_receivers: int,
               candidates_fields: tuple, points_fields: tuple, reflectors_fields: tuple, chain_base: int,
               ends_fields: tuple, out_fields: tuple, out_candidate: NDArray[np.int64], candidate_base: int,
               cursor: int) -> int:
    """Mixed chains of one split's ``candidates`` (:func:`mixed_candidates`) through their
    specular ``points`` on the curved reflectors, written from row ``cursor`` of ``out``.

    A candidate becomes a chain if its specular point is valid and both back-traces (to the
    transmitter, and to the receiver along the reversed after sequence) are; its chain number
    is ``chain_base + (before * sa + after_row // r) * c + reflector`` and its length (m)
    |x - a| + |x - b|. ``out_candidate`` receives ``candidate_base`` + the candidate of each row
    written (to pick the amplitudes, left to the caller). Returns the next free row.
    """
    mirrors = MirrorArrays(*mirrors_fields)
    before = MirrorSide(*before_fields)
    after = MirrorSide(*after_fields)
    candidates = MixedCandidates(*candidates_fields)
    points = SurfacePoints(*points_fields)
    reflectors = ReflectorLabels(*reflectors_fields)
    ends = ChainEnds(*ends_fields)
    out = PaddedChains(*out_fields)
    n_refl = reflectors.surface.shape[0]
    n_before, n_after = before.sequences.shape[1], after.sequences.shape[1]
    order = n_before + 1 + n_after
    n_seq_after = after.sequences.shape[0]
    x, x_normal, x_valid = points.point, points.normal, points.valid
    a_end, b_end = candidates.source_image, candidates.receiver_image
    receivers = ends.receivers
    for i in range(candidates.before.shape[0]):
        if not x_valid[i]:
            continue
        row = cursor
        b, a, r = candidates.before[i], candidates.after_row[i], candidates.reflector[i]
        sequence_after = a // n_receivers
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        ok = backtrace_one(mirrors, before.images, b, before.sequences, b, False, x0, x1, x2, out.vertices, row, 1, 1)
        if not ok:
            continue
        # the after side, traced from the receiver along the reversed sequence: its j-th point is
        # the path's vertex order - j
        ok = backtrace_one(mirrors, after.images, a, after.sequences, sequence_after, True, x0, x1, x2, out.vertices,
                           row, order, -1)
        if not ok:
            continue
        cursor += 1
        rx = a % n_receivers
        out.order[row] = order
        write_transmitter(row, ends, out)
        out.vertices[row, n_before + 1, 0] = x0
        out.vertices[row, n_before + 1, 1] = x1
        out.vertices[row, n_before + 1, 2] = x2
        write_receiver_tail(row, order + 1, receivers[rx, 0], receivers[rx, 1], receivers[rx, 2], out)
        for q in range(n_before):
            write_mirror_slot(row, q, before.sequences[b, q], mirrors, out)
        out.surface[row, n_before] = reflectors.surface[r]
        out.patch[row, n_before] = reflectors.patch[r]
        out.normal[row, n_before, 0] = x_normal[i, 0]
        out.normal[row, n_before, 1] = x_normal[i, 1]
        out.normal[row, n_before, 2] = x_normal[i, 2]
        out.kind[row, n_before] = CURVED_KIND
        out.material[row, n_before] = r
        for q in range(n_after):
            write_mirror_slot(row, n_before + 1 + q, after.sequences[sequence_after, q], mirrors, out)
        write_padding(row, order, out)
        e0, e1, e2 = x0 - a_end[i, 0], x1 - a_end[i, 1], x2 - a_end[i, 2]
        f0, f1, f2 = x0 - b_end[i, 0], x1 - b_end[i, 1], x2 - b_end[i, 2]
        out.length[row] = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) + math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        out.channel[row] = rx
        out.chain[row] = chain_base + (b * n_seq_after + sequence_after) * n_refl + r
        out_candidate[row] = candidate_base + i
    return cursor


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def chain_legs(chains_fields: tuple, rows: NDArray[np.int64]) -> ChainLegs:
    """The legs of the chains ``rows`` (c,) as occlusion segments, chain by chain, leg by leg
    (directions ``(end - start) / |end - start|``, lengths summed x + y + z as
    ``np.linalg.norm``)."""
    chains = PaddedChains(*chains_fields)
    vertices, patch, order = chains.vertices, chains.patch, chains.order
    n_legs = 0
    for i in range(rows.shape[0]):
        n_legs += order[rows[i]] + 1
    origins = np.empty((n_legs, 3))
    directions = np.empty((n_legs, 3))
    lengths = np.empty(n_legs)
    exclude = np.empty((n_legs, 2), dtype=np.int64)
    leg = 0
    for i in range(rows.shape[0]):
        c = rows[i]
        k = order[c]
        for j in range(k + 1):
            o0, o1, o2 = vertices[c, j, 0], vertices[c, j, 1], vertices[c, j, 2]
            s0, s1, s2 = vertices[c, j + 1, 0] - o0, vertices[c, j + 1, 1] - o1, vertices[c, j + 1, 2] - o2
            length = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
            origins[leg, 0], origins[leg, 1], origins[leg, 2] = o0, o1, o2
            directions[leg, 0], directions[leg, 1], directions[leg, 2] = s0 / length, s1 / length, s2 / length
            lengths[leg] = length
            exclude[leg, 0] = patch[c, j - 1] if j > 0 else -1
            exclude[leg, 1] = patch[c, j] if j < k else -1
            leg += 1
    return ChainLegs(origins, directions, lengths, exclude)


@njit(cache=True, nogil=True)
def unblocked_chains(blocked_legs: NDArray[np.bool_], order: NDArray[np.int64],
                     rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """The entries of ``rows`` (in order) none of whose legs (``blocked_legs`` (L,), in the
    order of :func:`chain_legs`) is blocked."""
    out = np.empty(rows.shape[0], dtype=np.int64)
    n = 0
    leg = 0
    for i in range(rows.shape[0]):
        c = rows[i]
        clear = True
        for _ in range(order[c] + 1):
            clear = clear and not blocked_legs[leg]
            leg += 1
        if clear:
            out[n] = c
            n += 1
    return out[:n]


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def duplicate_keys(rows: NDArray[np.int64], chains_fields: tuple, slots: int, resolution_m: float) -> NDArray[np.int64]:
    """The duplicate key (c, 2 + 4 ``slots``) of the chains ``rows`` (c,): channel, order, the
    surfaces of the first ``slots`` reflections sorted (-1 padding), then their points in units
    of ``resolution_m``, rounded half to even (0 for padding): the key of
    :func:`acoustisim.propagation.reference.specular.first_distinct`."""
    chains = PaddedChains(*chains_fields)
    channel, order, surface, vertices = chains.channel, chains.order, chains.surface, chains.vertices
    n = rows.shape[0]
    big = surface.shape[1]
    key = np.zeros((n, 2 + 4 * slots), dtype=np.int64)
    ids = np.empty(slots, dtype=np.int64)
    for i in range(n):
        c = rows[i]
        k = order[c]
        key[i, 0] = channel[c]
        key[i, 1] = k
        for q in range(slots):
            ids[q] = surface[c, q] if q < big else -1
        for q in range(1, slots):  # insertion sort of a few values
            value = ids[q]
            p = q - 1
            while p >= 0 and ids[p] > value:
                ids[p + 1] = ids[p]
                p -= 1
            ids[p + 1] = value
        for q in range(slots):
            key[i, 2 + q] = ids[q]
        for q in range(min(k, big, slots)):
            for d in range(3):
                key[i, 2 + slots + 3 * q + d] = np.int64(np.rint(vertices[c, q + 1, d] / resolution_m))
    return key


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def write_rows(rows: NDArray[np.int64], path_id_base: int, kind: int, chains_fields: tuple, out_fields: tuple) -> None:
    """The geometric columns of the path rows of the chains ``rows`` (c,), written into ``out``
    (views of a fresh ``empty_paths_array(c)``; object ids and points of the padding slots are
    left at -1 and NaN): path id ``path_id_base`` + chain number, channel, ``kind``, order,
    length, the unit departure and arrival directions (as ``d / np.linalg.norm(d)``) and the
    first ``out.points_m.shape[1]`` reflections' surfaces and points."""
    chains, out = PaddedChains(*chains_fields), PathColumns(*out_fields)
    chain, channel, order, surface = chains.chain, chains.channel, chains.order, chains.surface
    vertices, length = chains.vertices, chains.length
    out_departure, out_arrival = out.departure_dir, out.arrival_dir
    slots = out.points_m.shape[1]
    big = surface.shape[1]
    for i in range(rows.shape[0]):
        c = rows[i]
        k = order[c]
        out.path_id[i] = path_id_base + chain[c]
        out.channel[i] = channel[c]
        out.kind[i] = kind
        out.order[i] = k
        out.path_length_m[i] = length[c]
        d0 = vertices[c, 1, 0] - vertices[c, 0, 0]
        d1 = vertices[c, 1, 1] - vertices[c, 0, 1]
        d2 = vertices[c, 1, 2] - vertices[c, 0, 2]
        norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        out_departure[i, 0], out_departure[i, 1], out_departure[i, 2] = d0 / norm, d1 / norm, d2 / norm
        d0 = vertices[c, k + 1, 0] - vertices[c, k, 0]
        d1 = vertices[c, k + 1, 1] - vertices[c, k, 1]
        d2 = vertices[c, k + 1, 2] - vertices[c, k, 2]
        norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        out_arrival[i, 0], out_arrival[i, 1], out_arrival[i, 2] = d0 / norm, d1 / norm, d2 / norm
        for q in range(min(big, slots)):
            out.object_ids[i, q] = surface[c, q]
        for q in range(min(k, big, slots)):
            for d in range(3):
                out.points_m[i, q, d] = vertices[c, q + 1, d]


@njit(cache=True, nogil=True)
def incidence_cosines(vertices: NDArray[np.float64], normals: NDArray[np.float64],
                      order: NDArray[np.int64]) -> NDArray[np.float64]:
    """|cos| of the incidence angle (n, k) at each reflection of chains of ``order`` (n,)
    (<= k) reflections with ``vertices`` (n, k + 2, 3) and unit ``normals`` (n, k, 3); 1 at
    padded slots (:func:`acoustisim.propagation.reference.specular.incidence_cosines`).

    A zero-length leg (<= 1e-12 m: two reflections on a corner line) arrives along the previous
    direction mirrored by the previous surface.
    """
    n, k = normals.shape[0], normals.shape[1]
    out = np.ones((n, k))
    for i in range(n):
        p0, p1, p2 = 0.0, 0.0, 0.0
        for j in range(order[i]):
            l0 = vertices[i, j + 1, 0] - vertices[i, j, 0]
            l1 = vertices[i, j + 1, 1] - vertices[i, j, 1]
            l2 = vertices[i, j + 1, 2] - vertices[i, j, 2]
            norm = math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
            scale = norm if norm > 0 else 1.0
            c0, c1, c2 = l0 / scale, l1 / scale, l2 / scale
            if j > 0 and not norm > 1e-12:
                m0, m1, m2 = normals[i, j - 1, 0], normals[i, j - 1, 1], normals[i, j - 1, 2]
                d = p0 * m0 + p1 * m1 + p2 * m2
                c0, c1, c2 = p0 - 2.0 * d * m0, p1 - 2.0 * d * m1, p2 - 2.0 * d * m2
            p0, p1, p2 = c0, c1, c2
            out[i, j] = abs(c0 * normals[i, j, 0] + c1 * normals[i, j, 1] + c2 * normals[i, j, 2])
    return out


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def vertex_groups(rows: NDArray[np.int64], chains_fields: tuple, codes_fields: tuple
                  ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The reflections of the chains ``rows`` (c,) grouped by material code, by a counting sort.

    Returns
    -------
    positions : ndarray of int64, shape (v,)
        Flat positions ``i * K + j`` (slot j of the i-th chain of ``rows``) of the real
        reflections, grouped by code, increasing within a group.
    starts : ndarray of int64, shape (codes.count + 1,)
        Group q is ``positions[starts[q]:starts[q + 1]]``.
    """
    chains, codes = PaddedChains(*chains_fields), MaterialCodes(*codes_fields)
    kind, material = chains.kind, chains.material
    code_of, kind_offset = codes.code_of, codes.kind_offset
    big = kind.shape[1]
    counts = np.zeros(codes.count + 1, dtype=np.int64)
    for i in range(rows.shape[0]):
        c = rows[i]
        for j in range(big):
            if kind[c, j] >= 0:
                counts[code_of[kind_offset[kind[c, j]] + material[c, j]] + 1] += 1
    starts = np.cumsum(counts)
    fill = starts[:-1].copy()
    positions = np.empty(starts[-1], dtype=np.int64)
    for i in range(rows.shape[0]):
        c = rows[i]
        for j in range(big):
            if kind[c, j] >= 0:
                q = code_of[kind_offset[kind[c, j]] + material[c, j]]
                positions[fill[q]] = i * big + j
                fill[q] += 1
    return positions, starts


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def occlusion_queries32(legs_fields: tuple, shift: NDArray[np.float64], eps: float) -> OcclusionQueries:
    """The ``legs`` as Embree's float32 buffers, as ``RayCaster.occluded_rays`` builds them, with
    the same operations in the same order (so the same buffers): start ``eps d + o`` minus
    ``shift`` rounded once to float32, direction rounded to float32, length ``L - 2 eps``; legs
    with ``L <= 2 eps`` are never blocked and get no query."""
    legs = ChainLegs(*legs_fields)
    origins, directions, lengths = legs.origins, legs.directions, legs.lengths
    n = lengths.shape[0]
    q = 0
    for i in range(n):
        if lengths[i] > 2.0 * eps:
            q += 1
    starts32 = np.empty((q, 3), dtype=np.float32)
    directions32 = np.empty((q, 3), dtype=np.float32)
    lengths32 = np.empty(q, dtype=np.float32)
    leg = np.empty(q, dtype=np.int64)
    q = 0
    for i in range(n):
        if not lengths[i] > 2.0 * eps:
            continue
        for k in range(3):
            start = eps * directions[i, k]
            start += origins[i, k]
            starts32[q, k] = np.float32(start - shift[k])
            directions32[q, k] = np.float32(directions[i, k])
        lengths32[q] = np.float32(lengths[i] - 2.0 * eps)
        leg[q] = i
        q += 1
    return OcclusionQueries(starts32, directions32, lengths32, leg)


__all__ = ("CURVED_KIND", "ChainEnds", "ChainLegs", "MIRROR_KIND", "MaterialCodes", "MirrorSide", "MixedCandidates",
           "OcclusionQueries", "PaddedChains", "PathColumns", "ReflectorLabels", "SMOOTH_KIND", "chain_legs",
           "duplicate_keys", "fill_mixed", "fill_planar", "incidence_cosines", "mixed_candidates",
           "occlusion_queries32", "path_columns", "unblocked_chains", "vertex_groups", "write_mirror_slot",
           "write_padding", "write_receiver_tail", "write_rows", "write_transmitter")
