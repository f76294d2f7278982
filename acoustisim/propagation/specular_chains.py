"""Compiled candidate-to-chain loops of the specular solver (numba, cached on disk, GIL released).

:func:`acoustisim.propagation.specular.specular_rows` used to build each order's planar
chains and each split's mixed chains with a few dozen numpy passes (tiling the sequences per
receiver, gathering images, back-tracing, concatenating the vertex, surface, patch, normal and
material columns, then padding every group into one array): about 1,000 candidate chains per
pose, but hundreds of small numpy calls. Here each candidate is one loop iteration that
back-traces its planar points (:func:`.specular_kernels.backtrace_one`) and, if the chain is
valid, writes its row straight into the padded chain arrays of the solve
(``specular._Merged`` layout: a chain of order k < K fills slots 0..k-1; its vertices k+2..
repeat the receiver; surfaces, patches and kinds are -1 beyond, normals 0, materials 0, all
written here):

1. :func:`fill_planar`: the chains of one mirror sequence length, every receiver;
2. :func:`mixed_candidates`: the (before sequence, after sequence and receiver, curved
   reflector) triples of one split whose images are valid and which the reflector's
   visibility table allows, with the two unfolded ends;
3. :func:`fill_mixed`: the chains of one split, from the candidates' specular points on the
   curved reflectors (solved for all splits at once by
   :func:`.specular_kernels.primitive_specular_points`);
4. then, over the chains: :func:`chain_legs` and :func:`occlusion_queries32` (the legs and
   their Embree buffers), :func:`unblocked_chains`, :func:`duplicate_keys`,
   :func:`vertex_groups` (interactions grouped by material) and :func:`write_rows`.

Rows come out in the order (and with the chain numbers) of the numpy code they replace, and the
arithmetic is the same, term for term (lengths sqrt(dx^2 + dy^2 + dz^2) summed x + y + z,
as ``np.linalg.norm`` of a row): the rows are bit-for-bit the old ones. No ``fastmath``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.specular_kernels import backtrace_one

MIRROR_KIND = 0
"""Reflector-kind code of a planar mirror vertex (index of "mirror" in ``specular._SOURCES``)."""
CURVED_KIND = 1
"""Reflector-kind code of a curved-primitive vertex (index of "curved" in ``specular._SOURCES``)."""


@njit(cache=True, nogil=True, inline="always")
def _write_mirror_slot(row: int, slot: int, m: int, mirror_normal: NDArray[np.float64],
                       mirror_surface: NDArray[np.int64], mirror_patch: NDArray[np.int64],
                       mirror_material: NDArray[np.int64], out_surface: NDArray[np.int64],
                       out_patch: NDArray[np.int64], out_normal: NDArray[np.float64], out_kind: NDArray[np.int64],
                       out_material: NDArray[np.int64]) -> None:
    out_surface[row, slot] = mirror_surface[m]
    out_patch[row, slot] = mirror_patch[m]
    out_normal[row, slot, 0] = mirror_normal[m, 0]
    out_normal[row, slot, 1] = mirror_normal[m, 1]
    out_normal[row, slot, 2] = mirror_normal[m, 2]
    out_kind[row, slot] = MIRROR_KIND
    out_material[row, slot] = mirror_material[m]


@njit(cache=True, nogil=True, inline="always")
def _write_padding(row: int, first: int, out_surface: NDArray[np.int64], out_patch: NDArray[np.int64],
                   out_normal: NDArray[np.float64], out_kind: NDArray[np.int64], out_material: NDArray[np.int64]) -> None:
    """The padding values in interaction slots ``first``.. of a row."""
    for q in range(first, out_surface.shape[1]):
        out_surface[row, q] = -1
        out_patch[row, q] = -1
        out_normal[row, q, 0], out_normal[row, q, 1], out_normal[row, q, 2] = 0.0, 0.0, 0.0
        out_kind[row, q] = -1
        out_material[row, q] = 0


@njit(cache=True, nogil=True, inline="always")
def _write_receiver_tail(row: int, first: int, r0: float, r1: float, r2: float,
                         out_vertices: NDArray[np.float64]) -> None:
    """The receiver in vertex slots ``first``.. (the real one and the padding)."""
    for q in range(first, out_vertices.shape[1]):
        out_vertices[row, q, 0], out_vertices[row, q, 1], out_vertices[row, q, 2] = r0, r1, r2


@njit(cache=True, nogil=True)
def fill_planar(point: NDArray[np.float64], normal: NDArray[np.float64], disc_radius: NDArray[np.float64],
                a: NDArray[np.float64], v0: NDArray[np.float64], v1: NDArray[np.float64], d00: NDArray[np.float64],
                d01: NDArray[np.float64], d11: NDArray[np.float64], den: NDArray[np.float64],
                mirror_surface: NDArray[np.int64], mirror_patch: NDArray[np.int64],
                mirror_material: NDArray[np.int64], images: NDArray[np.float64], sequences: NDArray[np.int64],
                unfolded: NDArray[np.bool_], chain_base: int, transmitter: NDArray[np.float64],
                receivers: NDArray[np.float64], on_plane_tol: float, inside_tol: float,
                out_order: NDArray[np.int64], out_vertices: NDArray[np.float64], out_surface: NDArray[np.int64],
                out_patch: NDArray[np.int64], out_normal: NDArray[np.float64], out_kind: NDArray[np.int64],
                out_material: NDArray[np.int64], out_length: NDArray[np.float64],
                out_spreading: NDArray[np.float64], out_channel: NDArray[np.int64], out_chain: NDArray[np.int64],
                cursor: int) -> int:
    """Planar chains of ``sequences`` (s, k) of mirrors, to every receiver, from row ``cursor``.

    Parameters
    ----------
    point, normal, disc_radius, a, v0, v1, d00, d01, d11, den
        The mirrors' planes and barycentric frames (as :func:`.specular_kernels.backtrace_chains`).
    mirror_surface, mirror_patch, mirror_material : ndarray of int64, shape (m,)
    images : ndarray, shape (s, k + 1, 3)
        The transmitter's images across each sequence (``image_source.unfold``).
    sequences : ndarray of int64, shape (s, k)
    unfolded : ndarray of bool, shape (s,)
        Validity of the images; sequences with invalid images are skipped.
    chain_base : int
        Chain number of sequence 0 (sequence j is chain ``chain_base + j`` on every receiver).
    transmitter : ndarray, shape (3,); receivers : ndarray, shape (r, 3)
        Positions (m).
    on_plane_tol, inside_tol : float
        The back-trace tolerances (``image_source``).
    out_* : the padded chain arrays (capacity rows), written from row ``cursor``.

    Returns
    -------
    int
        The next free row. Rows: receiver by receiver, sequences in order; length (m) the
        distance from the last image to the receiver, spreading 1 / length.
    """
    s, k = sequences.shape
    for rx in range(receivers.shape[0]):
        r0, r1, r2 = receivers[rx, 0], receivers[rx, 1], receivers[rx, 2]
        for j in range(s):
            if not unfolded[j]:
                continue
            row = cursor
            ok = backtrace_one(point, normal, disc_radius, a, v0, v1, d00, d01, d11, den, images, j, sequences, j,
                               False, r0, r1, r2, on_plane_tol, inside_tol, out_vertices, row, 1, 1)
            if not ok:
                continue
            cursor += 1
            out_order[row] = k
            out_vertices[row, 0, 0] = transmitter[0]
            out_vertices[row, 0, 1] = transmitter[1]
            out_vertices[row, 0, 2] = transmitter[2]
            _write_receiver_tail(row, k + 1, r0, r1, r2, out_vertices)
            for q in range(k):
                _write_mirror_slot(row, q, sequences[j, q], normal, mirror_surface, mirror_patch, mirror_material,
                                   out_surface, out_patch, out_normal, out_kind, out_material)
            _write_padding(row, k, out_surface, out_patch, out_normal, out_kind, out_material)
            e0, e1, e2 = images[j, k, 0] - r0, images[j, k, 1] - r1, images[j, k, 2] - r2
            length = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            out_length[row] = length
            out_spreading[row] = 1.0 / length
            out_channel[row] = rx
            out_chain[row] = chain_base + j
    return cursor


@njit(cache=True, nogil=True)
def mixed_candidates(seen_by: NDArray[np.bool_], sequences_before: NDArray[np.int64],
                     images_before: NDArray[np.float64], unfolded_before: NDArray[np.bool_],
                     sequences_after: NDArray[np.int64], n_receivers: int, images_after: NDArray[np.float64],
                     unfolded_after: NDArray[np.bool_]
                     ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float64],
                                NDArray[np.float64]]:
    """The candidates of one split [n_before mirrors, a curved reflector, n_after mirrors].

    Parameters
    ----------
    seen_by : ndarray of bool, shape (c, m)
        Mirrors each curved reflector may be reached from / reach.
    sequences_before : ndarray of int64, shape (sb, n_before)
        Mirror sequences from the transmitter; ``images_before`` (sb, n_before + 1, 3) its
        images across them, ``unfolded_before`` (sb,) their validity.
    sequences_after : ndarray of int64, shape (sa, n_after)
        Mirror sequences from the reflector to a receiver, in path order.
    n_receivers : int
        r; row ``q * r + i`` of ``images_after`` (sa r, n_after + 1, 3) is receiver i's images
        across the reversed sequence q (``specular_kernels.unfold_reversed``), with validity
        ``unfolded_after`` (sa r,).

    Returns
    -------
    before, after_row, reflector : ndarray of int64, shape (n,)
        Every (before, after row, reflector) triple with valid images on both sides and allowed
        by ``seen_by`` at the mirrors next to the reflector, in that nesting order.
    a, b : ndarray, shape (n, 3)
        The last images of the transmitter and of the receiver (m).
    """
    n_refl = seen_by.shape[0]
    n_before, n_after = sequences_before.shape[1], sequences_after.shape[1]
    capacity = 0
    for gb in range(unfolded_before.shape[0]):
        if unfolded_before[gb]:
            capacity += 1
    n_after_ok = 0
    for gar in range(unfolded_after.shape[0]):
        if unfolded_after[gar]:
            n_after_ok += 1
    capacity *= n_after_ok * n_refl
    before = np.empty(capacity, dtype=np.int64)
    after_row = np.empty(capacity, dtype=np.int64)
    reflector = np.empty(capacity, dtype=np.int64)
    a_end = np.empty((capacity, 3))
    b_end = np.empty((capacity, 3))
    n = 0
    for gb in range(unfolded_before.shape[0]):
        if not unfolded_before[gb]:
            continue
        for gar in range(unfolded_after.shape[0]):
            if not unfolded_after[gar]:
                continue
            for r in range(n_refl):
                if n_before > 0 and not seen_by[r, sequences_before[gb, n_before - 1]]:
                    continue
                if n_after > 0 and not seen_by[r, sequences_after[gar // n_receivers, 0]]:
                    continue
                before[n], after_row[n], reflector[n] = gb, gar, r
                for q in range(3):
                    a_end[n, q] = images_before[gb, n_before, q]
                    b_end[n, q] = images_after[gar, n_after, q]
                n += 1
    return before[:n], after_row[:n], reflector[:n], a_end[:n], b_end[:n]


@njit(cache=True, nogil=True)
def fill_mixed(point: NDArray[np.float64], normal: NDArray[np.float64], disc_radius: NDArray[np.float64],
               a: NDArray[np.float64], v0: NDArray[np.float64], v1: NDArray[np.float64], d00: NDArray[np.float64],
               d01: NDArray[np.float64], d11: NDArray[np.float64], den: NDArray[np.float64],
               mirror_surface: NDArray[np.int64], mirror_patch: NDArray[np.int64],
               mirror_material: NDArray[np.int64], sequences_before: NDArray[np.int64],
               images_before: NDArray[np.float64], sequences_after: NDArray[np.int64], n_receivers: int,
               images_after: NDArray[np.float64], before: NDArray[np.int64], after_row: NDArray[np.int64],
               reflector: NDArray[np.int64], a_end: NDArray[np.float64], b_end: NDArray[np.float64],
               x: NDArray[np.float64], x_normal: NDArray[np.float64], x_valid: NDArray[np.bool_],
               reflector_surface: NDArray[np.int64], reflector_patch: NDArray[np.int64], chain_base: int,
               transmitter: NDArray[np.float64], receivers: NDArray[np.float64], on_plane_tol: float,
               inside_tol: float, out_order: NDArray[np.int64], out_vertices: NDArray[np.float64],
               out_surface: NDArray[np.int64], out_patch: NDArray[np.int64], out_normal: NDArray[np.float64],
               out_kind: NDArray[np.int64], out_material: NDArray[np.int64], out_length: NDArray[np.float64],
               out_channel: NDArray[np.int64], out_chain: NDArray[np.int64], out_candidate: NDArray[np.int64],
               candidate_base: int, cursor: int) -> int:
    """Mixed chains of one split's candidates (:func:`mixed_candidates`), from row ``cursor``.

    Parameters
    ----------
    point ... mirror_material
        As in :func:`fill_planar`.
    sequences_before, images_before, sequences_after, n_receivers, images_after
        As in :func:`mixed_candidates`.
    before, after_row, reflector, a_end, b_end
        The candidates (:func:`mixed_candidates`).
    x, x_normal : ndarray, shape (n, 3); x_valid : ndarray of bool, shape (n,)
        Their specular points on the reflectors (m), unit normals and validity.
    reflector_surface, reflector_patch : ndarray of int64, shape (c,)
        Surface index and patch label of each curved reflector.
    chain_base : int
        Chain number of the split's (0, 0, 0) triple: a candidate's chain is
        ``chain_base + (before * sa + after_row // r) * c + reflector``.
    out_candidate : ndarray of int64, shape (capacity,)
        Receives ``candidate_base`` + the candidate of each row written (to pick amplitudes).

    Returns
    -------
    int
        The next free row. A candidate becomes a chain if its specular point is valid and
        both back-traces (to the transmitter, and to the receiver along the reversed after
        sequence) are; its length (m) is |x - a| + |x - b|. The spreading is left to the
        caller (``curved.go_amplitude``).
    """
    n_refl = reflector_surface.shape[0]
    n_before, n_after = sequences_before.shape[1], sequences_after.shape[1]
    order = n_before + 1 + n_after
    n_seq_after = sequences_after.shape[0]
    for i in range(before.shape[0]):
        if not x_valid[i]:
            continue
        row = cursor
        gb, gar, r = before[i], after_row[i], reflector[i]
        ga = gar // n_receivers
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        ok = backtrace_one(point, normal, disc_radius, a, v0, v1, d00, d01, d11, den, images_before, gb,
                           sequences_before, gb, False, x0, x1, x2, on_plane_tol, inside_tol, out_vertices, row, 1, 1)
        if not ok:
            continue
        # the after side, traced from the receiver along the reversed sequence: its j-th point is
        # the path's vertex order - j
        ok = backtrace_one(point, normal, disc_radius, a, v0, v1, d00, d01, d11, den, images_after, gar,
                           sequences_after, ga, True, x0, x1, x2, on_plane_tol, inside_tol, out_vertices, row, order,
                           -1)
        if not ok:
            continue
        cursor += 1
        rx = gar % n_receivers
        out_order[row] = order
        out_vertices[row, 0, 0] = transmitter[0]
        out_vertices[row, 0, 1] = transmitter[1]
        out_vertices[row, 0, 2] = transmitter[2]
        out_vertices[row, n_before + 1, 0] = x0
        out_vertices[row, n_before + 1, 1] = x1
        out_vertices[row, n_before + 1, 2] = x2
        _write_receiver_tail(row, order + 1, receivers[rx, 0], receivers[rx, 1], receivers[rx, 2], out_vertices)
        for q in range(n_before):
            _write_mirror_slot(row, q, sequences_before[gb, q], normal, mirror_surface, mirror_patch,
                               mirror_material, out_surface, out_patch, out_normal, out_kind, out_material)
        out_surface[row, n_before] = reflector_surface[r]
        out_patch[row, n_before] = reflector_patch[r]
        out_normal[row, n_before, 0] = x_normal[i, 0]
        out_normal[row, n_before, 1] = x_normal[i, 1]
        out_normal[row, n_before, 2] = x_normal[i, 2]
        out_kind[row, n_before] = CURVED_KIND
        out_material[row, n_before] = r
        for q in range(n_after):
            _write_mirror_slot(row, n_before + 1 + q, sequences_after[ga, q], normal, mirror_surface, mirror_patch,
                               mirror_material, out_surface, out_patch, out_normal, out_kind, out_material)
        _write_padding(row, order, out_surface, out_patch, out_normal, out_kind, out_material)
        e0, e1, e2 = x0 - a_end[i, 0], x1 - a_end[i, 1], x2 - a_end[i, 2]
        f0, f1, f2 = x0 - b_end[i, 0], x1 - b_end[i, 1], x2 - b_end[i, 2]
        out_length[row] = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) + math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        out_channel[row] = rx
        out_chain[row] = chain_base + (gb * n_seq_after + ga) * n_refl + r
        out_candidate[row] = candidate_base + i
    return cursor


@njit(cache=True, nogil=True, error_model="numpy")
def chain_legs(vertices: NDArray[np.float64], patch: NDArray[np.int64], order: NDArray[np.int64],
               chains: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                                                   NDArray[np.int64]]:
    """The legs of ``chains`` (c,) (rows of the padded arrays ``vertices`` (n, K + 2, 3),
    ``patch`` (n, K), ``order`` (n,)) as occlusion segments, chain by chain, leg by leg.

    Returns
    -------
    origins, directions : ndarray, shape (L, 3)
        Start (m) and unit direction of each leg (``(end - start) / |end - start|``: NaN for a
        zero-length leg, which ``RayCaster.occluded_rays`` never casts).
    lengths : ndarray, shape (L,)
        Leg lengths (m), ``sqrt(dx^2 + dy^2 + dz^2)`` summed x + y + z (as ``np.linalg.norm``).
    exclude : ndarray of int64, shape (L, 2)
        The patches at the leg's start and end (-1 at the transmitter and the receiver).
    """
    n_legs = 0
    for i in range(chains.shape[0]):
        n_legs += order[chains[i]] + 1
    origins = np.empty((n_legs, 3))
    directions = np.empty((n_legs, 3))
    lengths = np.empty(n_legs)
    exclude = np.empty((n_legs, 2), dtype=np.int64)
    leg = 0
    for i in range(chains.shape[0]):
        c = chains[i]
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
    return origins, directions, lengths, exclude


@njit(cache=True, nogil=True)
def unblocked_chains(blocked_legs: NDArray[np.bool_], order: NDArray[np.int64],
                     chains: NDArray[np.int64]) -> NDArray[np.int64]:
    """The entries of ``chains`` (in order) none of whose legs (``blocked_legs`` (L,), in the
    order of :func:`chain_legs`) is blocked."""
    out = np.empty(chains.shape[0], dtype=np.int64)
    n = 0
    leg = 0
    for i in range(chains.shape[0]):
        c = chains[i]
        clear = True
        for _ in range(order[c] + 1):
            clear = clear and not blocked_legs[leg]
            leg += 1
        if clear:
            out[n] = c
            n += 1
    return out[:n]


@njit(cache=True, nogil=True)
def duplicate_keys(chains: NDArray[np.int64], channel: NDArray[np.int64], order: NDArray[np.int64],
                   surface: NDArray[np.int64], vertices: NDArray[np.float64], slots: int,
                   resolution_m: float) -> NDArray[np.int64]:
    """The duplicate key (c, 2 + 4 ``slots``) of ``chains`` (c,): channel, order, the surfaces of
    the first ``slots`` interactions sorted (-1 padding), then their points in units of
    ``resolution_m``, rounded half to even (0 for padding).

    As ``np.round(points / resolution_m)`` on float64 columns cast to int64 (the integer
    columns are exact as floats).
    """
    n = chains.shape[0]
    big = surface.shape[1]
    key = np.zeros((n, 2 + 4 * slots), dtype=np.int64)
    ids = np.empty(slots, dtype=np.int64)
    for i in range(n):
        c = chains[i]
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


@njit(cache=True, nogil=True)
def write_rows(chains: NDArray[np.int64], path_id_base: int, kind: int, chain: NDArray[np.int64],
               channel: NDArray[np.int64], order: NDArray[np.int64], surface: NDArray[np.int64],
               vertices: NDArray[np.float64], length: NDArray[np.float64], out_path_id: NDArray[np.int64],
               out_channel: NDArray[np.int8], out_kind: NDArray[np.int8], out_order: NDArray[np.int8],
               out_length: NDArray[np.float64], out_departure: NDArray[np.float64],
               out_arrival: NDArray[np.float64], out_object_ids: NDArray[np.int16],
               out_points: NDArray[np.float64]) -> None:
    """The geometric columns of the path rows of ``chains`` (c,), written into the fields
    ``out_*`` of a fresh ``empty_paths_array(c)`` (object ids and points of the padding slots
    are left at -1 and NaN): path id ``path_id_base`` + chain number, channel, ``kind``,
    order, length, the unit departure and arrival directions (as ``d / np.linalg.norm(d)``)
    and the first ``out_points.shape[1]`` interactions' surfaces and points."""
    slots = out_points.shape[1]
    big = surface.shape[1]
    for i in range(chains.shape[0]):
        c = chains[i]
        k = order[c]
        out_path_id[i] = path_id_base + chain[c]
        out_channel[i] = channel[c]
        out_kind[i] = kind
        out_order[i] = k
        out_length[i] = length[c]
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
            out_object_ids[i, q] = surface[c, q]
        for q in range(min(k, big, slots)):
            for d in range(3):
                out_points[i, q, d] = vertices[c, q + 1, d]



@njit(cache=True, nogil=True)
def vertex_groups(chains: NDArray[np.int64], kind: NDArray[np.int64], material: NDArray[np.int64],
                  code_of: NDArray[np.int64], kind_offset: NDArray[np.int64], n_codes: int
                  ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The interactions of ``chains`` (c,) grouped by reflection code, by a counting sort.

    Parameters
    ----------
    chains : ndarray of int64, shape (c,)
        Rows of the padded ``kind`` and ``material`` (n, K).
    code_of : ndarray of int64, shape (t,)
        Code (0..``n_codes`` - 1) of each entry of the concatenated material tables of the
        reflector kinds; kind k's entry j is ``kind_offset[k] + j``.

    Returns
    -------
    positions : ndarray of int64, shape (v,)
        Flat positions ``i * K + j`` (slot j of the i-th chain) of the real interactions,
        grouped by code, in increasing position within a group.
    starts : ndarray of int64, shape (n_codes + 1,)
        Group q is ``positions[starts[q]:starts[q + 1]]``.
    """
    big = kind.shape[1]
    counts = np.zeros(n_codes + 1, dtype=np.int64)
    for i in range(chains.shape[0]):
        c = chains[i]
        for j in range(big):
            if kind[c, j] >= 0:
                counts[code_of[kind_offset[kind[c, j]] + material[c, j]] + 1] += 1
    starts = np.cumsum(counts)
    fill = starts[:-1].copy()
    positions = np.empty(starts[-1], dtype=np.int64)
    for i in range(chains.shape[0]):
        c = chains[i]
        for j in range(big):
            if kind[c, j] >= 0:
                q = code_of[kind_offset[kind[c, j]] + material[c, j]]
                positions[fill[q]] = i * big + j
                fill[q] += 1
    return positions, starts


@njit(cache=True, nogil=True)
def occlusion_queries32(origins: NDArray[np.float64], directions: NDArray[np.float64], lengths: NDArray[np.float64],
                        shift: NDArray[np.float64], eps: float
                        ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32], NDArray[np.int64]]:
    """The legs (:func:`chain_legs`) as Embree's float32 buffers, as
    ``RayCaster.occluded_rays`` builds them, with the same operations in the same order (so the
    same buffers): start ``eps d + o`` minus ``shift`` rounded once to float32, direction
    rounded to float32, length ``L - 2 eps``; legs with ``L <= 2 eps`` are never blocked and
    get no query.

    Returns
    -------
    starts32, directions32 : ndarray of float32, shape (q, 3)
    lengths32 : ndarray of float32, shape (q,)
        The queries (for ``RayCaster.occluded_segments32``).
    leg : ndarray of int64, shape (q,)
        The leg of each query.
    """
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
    return starts32, directions32, lengths32, leg


__all__ = ["CURVED_KIND", "MIRROR_KIND", "chain_legs", "duplicate_keys", "fill_mixed", "fill_planar",
           "mixed_candidates", "occlusion_queries32", "unblocked_chains", "vertex_groups",
           "write_rows"]
