"""Direct and specular paths: image sources on planar mirrors, specular points on curved objects.

Chains, for every receiver at once (the per-chain walks, the unfolding, back-tracing with its
polygon tests, the curved specular points, their amplitudes and the incidence angles, are
compiled loops in :mod:`.specular_kernels`; the loops over candidates that write the chains,
their legs, duplicate keys and rows, in :mod:`.specular_chains`):

* planar chains of 1..``max_order`` mirrors (image-source method, :mod:`.image_source`);
* mixed chains: planar mirrors, then one curved object (sphere, cylinder side), then planar
  mirrors, of total order <= ``max_order``. The transmitter is unfolded across the mirrors
  before the object, the receiver across the mirrors after it (in reverse), the specular point
  is solved on the true surface between the two images (:mod:`.curved`), and the planar
  reflection points are back-traced from it;
* first-order echoes of smooth user meshes (no primitive, not polyhedral), on their
  interpolated normals (:mod:`.smooth_mesh`), with the stationary point's phase (saddles,
  focusing concave patches).

Paths through a right-angle corner line (tank corners, a post meeting the surface or the floor)
are found in both reflection orders with coincident points and kept once.

The chains of every order and kind are written straight into one padded array
(:class:`_Merged`; the smooth-mesh chains, built in numpy, are padded and appended), so that
what follows is one pass over all of them: every leg of every valid candidate is checked for
occlusion in one batched Embree query (legs ending on a mirror or a curved object ignore that
patch, see :mod:`.raycast`), duplicates are dropped, the reflection coefficients evaluated
(one call per distinct material), the rows written.

Gains (pressure factor relative to the source at 1 m): planar chains prod(R) / L with L the
distance from the last image to the receiver; mixed chains prod(R) x the geometric-optics
factor of the curved point with the unfolded distances. Reflection coefficients come from
``Material.reflection_coefficient`` at each vertex's incidence angle; where the product is
real its sign goes into ``geometric_gain``, otherwise ``geometric_gain`` holds the magnitude
and ``phase_rad`` the phase. ``Material`` returns coefficients in the physics convention
exp(-i omega t); ``phase_rad`` is applied as exp(+j phase) on positive frequencies of the
engineering (FFT) convention, so ``phase_rad = -arg(R)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.curved import go_amplitude_general, go_factors_at, specular_points
from acoustisim.propagation.image_source import _INSIDE_TOL, _ON_PLANE_TOL_M, PlanarMirrors, backtrace, unfold
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, empty_paths_array
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.raycast import DEFAULT_EPS_M
from acoustisim.propagation.specular_chains import (chain_legs, duplicate_keys, fill_mixed, fill_planar,
                                                    mixed_candidates, occlusion_queries32,
                                                    unblocked_chains, vertex_groups, write_rows)
from acoustisim.propagation.specular_kernels import incidence_cosines, unfold_reversed

_REAL_TOL = 1e-12
"""|Im R| below this fraction of |R| counts as a real coefficient (sign kept in the gain)."""


@dataclass
class _Chains:
    """Valid candidate chains of one order (before occlusion)."""

    vertices: NDArray[np.float64]  # (n, k + 2, 3): transmitter, k interaction points, receiver
    surface: NDArray[np.int64]  # (n, k)
    patch: NDArray[np.int64]  # (n, k)
    normal: NDArray[np.float64]  # (n, k, 3) unit normals on the water side
    material: list[Any]  # k arrays (n,) of Material indices into the materials list
    length: NDArray[np.float64]  # (n,) total path length (m)
    spreading: NDArray[np.float64]  # (n,) gain without reflection coefficients
    channel: NDArray[np.int64]  # (n,)
    chain: NDArray[np.int64]  # (n,) chain id (shared across channels)
    phase: NDArray[np.float64] | None = None  # (n,) extra phase_rad of the stationary point (saddles)


def direct_rows(context: SolveContext) -> NDArray[Any]:
    """Direct transmitter -> receiver rows (skipping a receiver that is the transmitter itself).

    Gain 1/r; blocked paths are dropped.
    """
    tx = context.transmitter_m
    rx = context.receivers_m
    dist = np.linalg.norm(rx - tx, axis=1)
    channels = np.flatnonzero(dist > 1e-9)
    # the legs as RayCaster.occluded makes them (no exclusions), straight to Embree's buffers
    origins = np.tile(tx, (channels.size, 1))
    legs = rx[channels] - origins
    length = np.linalg.norm(legs, axis=1)
    raycaster = context.raycaster
    starts32, directions32, lengths32, leg = occlusion_queries32(origins, legs / length[:, None], length,
                                                                 raycaster.shift_m, DEFAULT_EPS_M)
    blocked = np.zeros(channels.size, dtype=bool)
    blocked[leg[raycaster.occluded_segments32(starts32, directions32, lengths32)]] = True
    channels = channels[~blocked]
    rows = empty_paths_array(channels.size)
    rows["path_id"] = context.first_path_id
    rows["channel"] = channels
    rows["kind"] = PathKind.DIRECT
    rows["order"] = 0
    r = dist[channels]
    rows["path_length_m"] = r
    rows["geometric_gain"] = 1.0 / r
    direction = (rx[channels] - tx) / r[:, None]
    rows["departure_dir"] = direction
    rows["arrival_dir"] = direction
    return rows


def _receivers_in_front(context: SolveContext, mirrors: PlanarMirrors) -> NDArray[np.bool_]:
    """Mirrors (m,) with at least one receiver in front of them."""
    ahead = np.einsum("rmk,mk->rm", context.receivers_m[:, None, :] - mirrors.point, mirrors.normal)
    return np.any(ahead > 0, axis=0)


@dataclass
class _Candidates:
    """Unfolded (image) ends of chains [n_before mirrors, reflector, n_after mirrors]."""

    reflector: NDArray[np.int64]  # (n,) which reflector
    channel: NDArray[np.int64]  # (n,)
    chain: NDArray[np.int64]  # (n,) chain number (before, after, reflector), from 0
    images_before: NDArray[np.float64]  # (n, n_before + 1, 3) transmitter and its images
    images_after: NDArray[np.float64]  # (n, n_after + 1, 3) receiver and its images (reversed order)
    seq_before: NDArray[np.int64]  # (n, n_before) mirrors in path order
    seq_after: NDArray[np.int64]  # (n, n_after) mirrors in path order
    n_chains: int  # number of chain numbers used


@dataclass
class _Sides:
    """The unfolded mirror sequences before and after a reflector, by length, for one pose and
    one reflector visibility table (shared by every split of a chain order)."""

    before: dict[int, tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.bool_]]]
    after: dict[int, tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.bool_]]]


def _sides(context: SolveContext, mirrors: PlanarMirrors, seen_by: NDArray[np.bool_], lengths: Iterable[int],
           first: NDArray[np.bool_], last: NDArray[np.bool_]) -> _Sides:
    """Sequences of each of ``lengths`` mirrors before a reflector (from the transmitter, with
    their images and validity) and after it (in path order, from the reflector to the
    receiver; the receiver's images once per (sequence, receiver): row ``q * r + i`` for
    sequence q and receiver i)."""
    tx = context.transmitter_m
    receivers = np.ascontiguousarray(context.receivers_m, dtype=float)
    any_seen = np.any(seen_by, axis=0)
    before, after = {}, {}
    for k in lengths:
        seq_b = mirrors.sequences(k, first, any_seen)
        images_b, ok_b = unfold(mirrors, tx, seq_b)
        before[k] = (seq_b, images_b, ok_b)
        seq_a = mirrors.sequences(k, any_seen, last)
        images_a, ok_a = unfold_reversed(mirrors.point, mirrors.normal, receivers, seq_a)
        after[k] = (seq_a, images_a, ok_a)
    return _Sides(before, after)


def _candidates(context: SolveContext, mirrors: PlanarMirrors, seen_by: NDArray[np.bool_], n_before: int,
                n_after: int, first: NDArray[np.bool_], last: NDArray[np.bool_]) -> _Candidates:
    """Every (before sequence, after sequence, receiver, reflector) whose images are valid, pruned
    by the mirror/reflector visibility table ``seen_by`` (r, m)."""
    n_refl = seen_by.shape[0]
    n_rx = context.receivers_m.shape[0]
    sides = _sides(context, mirrors, seen_by, sorted({n_before, n_after}), first, last)
    seq_b, images_b, ok_b = sides.before[n_before]
    seq_a, images_a, ok_a = sides.after[n_after]
    gb, gar, gr, _, _ = mixed_candidates(seen_by, seq_b, images_b, ok_b, seq_a, n_rx, images_a, ok_a)
    ga = gar // n_rx
    return _Candidates(
        reflector=gr, channel=gar % n_rx, chain=(gb * seq_a.shape[0] + ga) * n_refl + gr,
        images_before=images_b[gb], images_after=images_a[gar], seq_before=seq_b[gb], seq_after=seq_a[ga],
        n_chains=seq_b.shape[0] * seq_a.shape[0] * n_refl,
    )


def _assemble(context: SolveContext, mirrors: PlanarMirrors, cand: _Candidates, x: NDArray[np.float64],
              normal: NDArray[np.float64], valid: NDArray[np.bool_], surface_of: NDArray[np.int64],
              patch_of: NDArray[np.int64], source: str, chain: NDArray[np.int64]) -> tuple[_Chains, NDArray[np.int64]]:
    """Back-trace the planar points of candidates with a reflector point ``x`` and build the chains.

    Returns the chains and the candidate rows they came from (to pick the amplitudes).
    """
    n_before = cand.seq_before.shape[1]
    n_after = cand.seq_after.shape[1]
    pts_b, ok1 = backtrace(mirrors, cand.images_before, cand.seq_before, x)
    pts_a_rev, ok2 = backtrace(mirrors, cand.images_after, cand.seq_after[:, ::-1], x)
    idx = np.flatnonzero(valid & ok1 & ok2)
    n = idx.size
    tx = context.transmitter_m
    rx = context.receivers_m[cand.channel[idx]]
    vertices = np.concatenate(
        [np.broadcast_to(tx, (n, 1, 3)), pts_b[idx], x[idx][:, None, :], pts_a_rev[idx][:, ::-1], rx[:, None, :]],
        axis=1)
    a_v, b_v, x_v = cand.images_before[idx, -1], cand.images_after[idx, -1], x[idx]
    length = np.linalg.norm(x_v - a_v, axis=1) + np.linalg.norm(x_v - b_v, axis=1)
    sb_v, sa_v, refl = cand.seq_before[idx], cand.seq_after[idx], cand.reflector[idx]
    surface = np.concatenate([mirrors.surface[sb_v], surface_of[idx][:, None], mirrors.surface[sa_v]], axis=1)
    patch = np.concatenate([mirrors.patch[sb_v], patch_of[idx][:, None], mirrors.patch[sa_v]], axis=1)
    normals = np.concatenate([mirrors.normal[sb_v], normal[idx][:, None, :], mirrors.normal[sa_v]], axis=1)
    material = ([("mirror", mirrors.material[sb_v[:, j]]) for j in range(n_before)]
                + [(source, refl)]
                + [("mirror", mirrors.material[sa_v[:, j]]) for j in range(n_after)])
    chains = _Chains(vertices, surface, patch, normals, material, length, np.zeros(n), cand.channel[idx], chain[idx])
    return chains, idx


def _smooth_chains(context: SolveContext, prepared: PreparedScene, n_before: int, n_after: int,
                   chain_base: int, first: NDArray[np.bool_], last: NDArray[np.bool_]) -> tuple[_Chains, int]:
    """Chains [n_before mirrors, one smooth mesh, n_after mirrors]; a pair may have several
    specular points on a non-convex mesh, each its own path."""
    mirrors = prepared.mirrors
    seen_by = np.array([r.seen_by for r in prepared.smooth], dtype=bool).reshape(len(prepared.smooth), mirrors.count)
    cand = _candidates(context, mirrors, seen_by, n_before, n_after, first, last)
    parts = []
    for i, reflector in enumerate(prepared.smooth):  # a loop over meshes (a few), vectorised inside
        rows = np.flatnonzero(cand.reflector == i)
        a_pt = cand.images_before[rows, -1]
        b_pt = cand.images_after[rows, -1]
        pair, tri, x, normal, e1, e2, k11, k22, k12 = reflector.mesh.specular_points(a_pt, b_pt)
        sub = _Candidates(cand.reflector[rows[pair]], cand.channel[rows[pair]], cand.chain[rows[pair]],
                          cand.images_before[rows[pair]], cand.images_after[rows[pair]],
                          cand.seq_before[rows[pair]], cand.seq_after[rows[pair]], 0)
        chain = chain_base + np.arange(pair.size)  # one id per specular point
        chain_base += pair.size
        chains, idx = _assemble(context, mirrors, sub, x, normal, np.ones(pair.size, dtype=bool),
                                np.full(pair.size, reflector.surface), reflector.patch[tri], "smooth", chain)
        chains.spreading, chains.phase = go_amplitude_general(
            a_pt[pair][idx], b_pt[pair][idx], x[idx], normal[idx], e1[idx], e2[idx], k11[idx], k22[idx], k12[idx])
        parts.append(chains)
    order = n_before + 1 + n_after
    if not parts:
        parts.append(_Chains(np.zeros((0, order + 2, 3)), np.zeros((0, order), np.int64),
                             np.zeros((0, order), np.int64), np.zeros((0, order, 3)),
                             [("mirror", np.zeros(0, np.int64))] * order, np.zeros(0), np.zeros(0),
                             np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)))
    merged = _Chains(
        np.concatenate([p.vertices for p in parts]), np.concatenate([p.surface for p in parts]),
        np.concatenate([p.patch for p in parts]), np.concatenate([p.normal for p in parts]),
        [(parts[0].material[j][0], np.concatenate([p.material[j][1] for p in parts])) for j in range(order)],
        np.concatenate([p.length for p in parts]), np.concatenate([p.spreading for p in parts]),
        np.concatenate([p.channel for p in parts]), np.concatenate([p.chain for p in parts]),
        np.concatenate([p.phase for p in parts]),
    )
    return merged, chain_base


_SOURCES = ("mirror", "curved", "smooth")
"""Reflector kinds of a chain's vertices, coded by their index in the merged chains."""


@dataclass
class _Merged:
    """Chains of every order and kind in one padded array (rows in group order).

    A chain of order k < K fills slots 0..k-1; its vertices k+2.. repeat the receiver, its
    surfaces and patches are -1, its normals 0 and its reflector kind -1 beyond.
    """

    order: NDArray[np.int64]  # (n,)
    vertices: NDArray[np.float64]  # (n, K + 2, 3)
    surface: NDArray[np.int64]  # (n, K)
    patch: NDArray[np.int64]  # (n, K)
    normal: NDArray[np.float64]  # (n, K, 3)
    kind: NDArray[np.int64]  # (n, K) index into _SOURCES, -1 for padding
    material: NDArray[np.int64]  # (n, K) index into the kind's material table
    length: NDArray[np.float64]  # (n,)
    spreading: NDArray[np.float64]  # (n,)
    channel: NDArray[np.int64]  # (n,)
    chain: NDArray[np.int64]  # (n,)
    has_phase: NDArray[np.bool_]  # (n,) the chain's group has a stationary-point phase
    phase: NDArray[np.float64]  # (n,) that phase (0 elsewhere)


def _merge(groups: list[_Chains]) -> _Merged:
    """Stack the groups' chains, padded to the largest order."""
    sizes = [chains.length.shape[0] for chains in groups]
    n = sum(sizes)
    big = max((chains.surface.shape[1] for chains in groups), default=0)
    order = np.empty(n, dtype=np.int64)
    vertices = np.empty((n, big + 2, 3))
    surface = np.full((n, big), -1, dtype=np.int64)
    patch = np.full((n, big), -1, dtype=np.int64)
    normal = np.zeros((n, big, 3))
    kind = np.full((n, big), -1, dtype=np.int64)
    material = np.zeros((n, big), dtype=np.int64)
    has_phase = np.zeros(n, dtype=bool)
    phase = np.zeros(n)
    lo = 0
    for chains, size in zip(groups, sizes):
        hi = lo + size
        k = chains.surface.shape[1]
        order[lo:hi] = k
        vertices[lo:hi, :k + 2] = chains.vertices
        vertices[lo:hi, k + 2:] = chains.vertices[:, -1:]
        surface[lo:hi, :k] = chains.surface
        patch[lo:hi, :k] = chains.patch
        normal[lo:hi, :k] = chains.normal
        for j, (source, index) in enumerate(chains.material):
            kind[lo:hi, j] = _SOURCES.index(source)
            material[lo:hi, j] = index
        if chains.phase is not None:
            has_phase[lo:hi] = True
            phase[lo:hi] = chains.phase
        lo = hi
    return _Merged(order, vertices, surface, patch, normal, kind, material,
                   np.concatenate([chains.length for chains in groups]) if groups else np.zeros(0),
                   np.concatenate([chains.spreading for chains in groups]) if groups else np.zeros(0),
                   np.concatenate([chains.channel for chains in groups]) if groups else np.zeros(0, np.int64),
                   np.concatenate([chains.chain for chains in groups]) if groups else np.zeros(0, np.int64),
                   has_phase, phase)


def _allocate(capacity: int, big: int) -> _Merged:
    """Padded chain arrays for up to ``capacity`` chains of order <= ``big``, uninitialised
    (the fill kernels write every field of every row, padding included) but for the phases
    (none, 0)."""
    return _Merged(
        order=np.empty(capacity, dtype=np.int64), vertices=np.empty((capacity, big + 2, 3)),
        surface=np.empty((capacity, big), dtype=np.int64), patch=np.empty((capacity, big), dtype=np.int64),
        normal=np.empty((capacity, big, 3)), kind=np.empty((capacity, big), dtype=np.int64),
        material=np.empty((capacity, big), dtype=np.int64), length=np.empty(capacity), spreading=np.empty(capacity),
        channel=np.empty(capacity, dtype=np.int64), chain=np.empty(capacity, dtype=np.int64),
        has_phase=np.zeros(capacity, dtype=bool), phase=np.zeros(capacity))


def _head(chains: _Merged, n: int) -> _Merged:
    """The first ``n`` chains (views)."""
    return _Merged(*(getattr(chains, name)[:n] for name in chains.__dataclass_fields__))


def _concatenated(first: _Merged, second: _Merged) -> _Merged:
    """``first``'s chains, then ``second``'s (same padded order)."""
    return _Merged(*(np.concatenate([getattr(first, name), getattr(second, name)])
                     for name in first.__dataclass_fields__))


def _planar_and_mixed(context: SolveContext, prepared: PreparedScene, max_order: int, first: NDArray[np.bool_],
                      last: NDArray[np.bool_]) -> tuple[_Merged, int]:
    """Planar chains of orders 1..``max_order``, then mixed chains [n_before mirrors, one curved
    primitive, n_after mirrors] of every split with n_before + 1 + n_after <= ``max_order``
    (every primitive at once), in the padded layout; and the next free chain number.

    Rows in the order of the groups (planar by order; mixed by split (n_before, n_after)
    lexicographic), each written by a compiled loop over its candidates
    (:mod:`.specular_chains`). The candidates of all splits share one specular-point solve and
    one geometric-optics amplitude evaluation (both row-wise).
    """
    mirrors = prepared.mirrors
    frames = mirrors._barycentric_frames
    geometry = (mirrors.point, mirrors.normal, mirrors.disc_radius, *frames,
                mirrors.surface, mirrors.patch, mirrors.material)
    tx = context.transmitter_m
    receivers = np.ascontiguousarray(context.receivers_m, dtype=float)
    n_rx = receivers.shape[0]
    planar = []
    for order in range(1, max_order + 1):
        seqs = mirrors.sequences(order, first, last)
        images, ok = unfold(mirrors, tx, seqs)
        planar.append((seqs, images, ok))
    capacity = n_rx * sum(seqs.shape[0] for seqs, _, _ in planar)
    splits = [(n_before, n_after) for n_before in range(max_order) for n_after in range(max_order - n_before)]
    candidates = []
    if prepared.curved:
        seen_by = prepared.curved_seen_by
        sides = _sides(context, mirrors, seen_by, range(max_order), first, last)
        for n_before, n_after in splits:
            seq_b, images_b, ok_b = sides.before[n_before]
            seq_a, images_a, ok_a = sides.after[n_after]
            candidates.append(mixed_candidates(seen_by, seq_b, images_b, ok_b, seq_a, n_rx, images_a, ok_a))
        capacity += sum(cand[0].size for cand in candidates)
    chains = _allocate(capacity, max_order)
    out = (chains.order, chains.vertices, chains.surface, chains.patch, chains.normal, chains.kind, chains.material,
           chains.length)
    cursor = chain_base = 0
    for seqs, images, ok in planar:
        cursor = fill_planar(*geometry, images, seqs, ok, chain_base, tx, receivers, _ON_PLANE_TOL_M, _INSIDE_TOL,
                             *out, chains.spreading, chains.channel, chains.chain, cursor)
        chain_base += seqs.shape[0]
    if not candidates:
        return _head(chains, cursor), chain_base
    reflector = np.concatenate([cand[2] for cand in candidates])
    a_pt = np.concatenate([cand[3] for cand in candidates])
    b_pt = np.concatenate([cand[4] for cand in candidates])
    x, normal, valid, e1, e2, k1, k2 = specular_points(prepared.curved_set, reflector, a_pt, b_pt)
    surfaces = np.array([r.surface for r in prepared.curved], dtype=np.int64)
    patches = np.array([r.patch for r in prepared.curved], dtype=np.int64)
    picked = np.empty(capacity, dtype=np.int64)
    mixed_start = cursor
    lo = 0
    for (n_before, n_after), (before, after_row, refl, a_end, b_end) in zip(splits, candidates):
        seq_b, images_b, _ = sides.before[n_before]
        seq_a, images_a, _ = sides.after[n_after]
        hi = lo + before.size
        cursor = fill_mixed(*geometry, seq_b, images_b, seq_a, n_rx, images_a, before, after_row, refl, a_end,
                            b_end, x[lo:hi], normal[lo:hi], valid[lo:hi], surfaces, patches, chain_base, tx,
                            receivers, _ON_PLANE_TOL_M, _INSIDE_TOL, *out, chains.channel, chains.chain, picked, lo,
                            cursor)
        chain_base += seq_b.shape[0] * seq_a.shape[0] * len(prepared.curved)
        lo = hi
    chains.spreading[mixed_start:cursor] = go_factors_at(picked[mixed_start:cursor], a_pt, b_pt, x, normal, e1, e2,
                                                         k1, k2, 0.0)[0]
    return _head(chains, cursor), chain_base


def _unblocked(chains: _Merged, prepared: PreparedScene) -> NDArray[np.int64]:
    """Indices (sorted) of the chains none of whose legs is occluded: one batched Embree query
    over every leg (legs ending on a mirror or a curved object ignore that patch)."""
    n = chains.length.shape[0]
    every = np.arange(n)
    if n == 0:
        return every
    origins, directions, lengths, exclude = chain_legs(chains.vertices, chains.patch, chains.order, every)
    # Embree's OCCLUDED query first, on the float32 buffers occluded_rays would build, without
    # exclusions: a leg it finds clear has no triangle between its ends (INTERSECT, which the
    # exclusion passes use, tests the same triangles over the same span; the two agreed on 4
    # million random and grazing legs of the thesis tank), so only the legs with some hit
    # (about 1 in 10) go through occluded_rays and its exclusion passes
    raycaster = prepared.raycaster
    starts32, directions32, lengths32, leg = occlusion_queries32(origins, directions, lengths, raycaster.shift_m,
                                                                 DEFAULT_EPS_M)
    hit = leg[raycaster.occluded_segments32(starts32, directions32, lengths32)]
    blocked_legs = np.zeros(lengths.shape[0], dtype=bool)
    if hit.size:
        blocked_legs[hit] = raycaster.occluded_rays(origins[hit], directions[hit], lengths[hit],
                                                    exclude_patches=exclude[hit])
    return unblocked_chains(blocked_legs, chains.order, every)


def _reflection_products(chains: _Merged, rows: NDArray[np.int64], prepared: PreparedScene,
                         context: SolveContext) -> NDArray[np.complex128]:
    """Product over the vertices of the chains ``rows`` of R(cos theta_incidence): (c,) complex.

    One ``Material.reflection_coefficient`` call per distinct material (equal materials of
    different reflector kinds share it) over every vertex on it, then the factors multiplied
    in vertex order per chain.
    """
    rho, c = context.density_kg_m3, context.sound_speed_m_s
    tables = (prepared.mirrors.materials, tuple(r.material for r in prepared.curved),
              tuple(r.material for r in prepared.smooth))
    distinct: dict[Any, int] = {}
    code_of = np.array([distinct.setdefault(m, len(distinct)) for table in tables for m in table], dtype=np.int64)
    kind_offset = np.cumsum([0] + [len(table) for table in tables[:-1]]).astype(np.int64)
    # |cos| of the incidence angle at each vertex (a zero-length leg, two reflections on a corner
    # line, arrives along the previous direction mirrored by the previous surface)
    cosines = incidence_cosines(chains.vertices[rows], chains.normal[rows], chains.order[rows])
    cos_i = cosines.ravel()
    positions, starts = vertex_groups(rows, chains.kind, chains.material, code_of, kind_offset, len(distinct))
    factor = np.ones(cos_i.shape, dtype=complex)
    for material, code in distinct.items():
        at = positions[starts[code]:starts[code + 1]]
        if at.size:
            factor[at] = material.reflection_coefficient(cos_i[at], rho, c)
    factor = factor.reshape(cosines.shape)
    total = np.ones(rows.size, dtype=complex)
    for j in range(factor.shape[1]):
        total *= factor[:, j]
    return total


def specular_rows(context: SolveContext, prepared: PreparedScene, max_order: int) -> NDArray[Any]:
    """Every unblocked specular path of order 1..``max_order`` to every receiver.

    Parameters
    ----------
    context : SolveContext
    prepared : PreparedScene
        Mirrors and curved reflectors of ``context.scene``.
    max_order : int
        Most reflections per path (>= 1).

    Returns
    -------
    structured ndarray of PATH_DTYPE
        ``path_id`` = ``context.first_path_id`` + a chain number shared by the receivers.
    """
    mirrors = prepared.mirrors
    groups: list[_Chains] = []
    # mirrors the transmitter can reach first, and those some receiver can be reached from last
    first = mirrors.signed_distance(np.broadcast_to(context.transmitter_m, (mirrors.count, 3)),
                                    np.arange(mirrors.count)) > 0
    last = _receivers_in_front(context, mirrors)
    chains, chain_base = _planar_and_mixed(context, prepared, max_order, first, last)
    if prepared.smooth:
        for n_before in range(max_order):
            for n_after in range(max_order - n_before):
                smooth, chain_base = _smooth_chains(context, prepared, n_before, n_after, chain_base, first, last)
                groups.append(smooth)
        chains = _concatenated(chains, _merge(groups))
    live = _unblocked(chains, prepared)
    kept = live[_first_of_duplicates(chains, live)]
    reflection = _reflection_products(chains, kept, prepared, context)
    # R in the physics convention exp(-i omega t) and the stationary-point phase in the
    # engineering one: convert the latter back before multiplying
    has_phase = chains.has_phase[kept]
    if has_phase.any():
        reflection[has_phase] = reflection[has_phase] * np.exp(-1j * chains.phase[kept][has_phase])
    rows = empty_paths_array(kept.size)
    write_rows(kept, context.first_path_id, int(PathKind.SPECULAR), chains.chain, chains.channel, chains.order,
               chains.surface, chains.vertices, chains.length, rows["path_id"], rows["channel"], rows["kind"],
               rows["order"], rows["path_length_m"], rows["departure_dir"], rows["arrival_dir"], rows["object_ids"],
               rows["points_m"])
    real = np.abs(reflection.imag) <= _REAL_TOL * np.abs(reflection)
    gain = chains.spreading[kept]
    rows["geometric_gain"] = np.where(real, gain * reflection.real, gain * np.abs(reflection))
    rows["phase_rad"] = np.where(real, 0.0, -np.angle(reflection))
    return rows


def _first_of_duplicates(chains: _Merged, rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """Positions in ``rows`` (sorted) of the chains to keep: one per (channel, ordered
    interaction points, set of surfaces), the first.

    Reflections on perpendicular planes commute: [wall, floor] and [floor, wall] have the same
    image, and generically only one order is a real path. Through the corner line itself (a
    monostatic corner return, or a post meeting the free surface or the floor) both orders pass
    with coincident reflection points: they are one path, found twice (the image method is exact
    in a right-angle wedge, whose edge does not diffract). Reciprocal twins of a monostatic path
    ([wall-x0, wall-x1] and [wall-x1, wall-x0]) visit their points in opposite orders and stay.

    The key is the one the rows carry (``object_ids`` and ``points_m``, i.e. the first
    ``MAX_INTERACTIONS`` interactions; points rounded to 1 nm).
    """
    if rows.size < 2:
        return np.arange(rows.size)
    return first_distinct_rows(duplicate_keys(rows, chains.channel, chains.order, chains.surface, chains.vertices,
                                              MAX_INTERACTIONS, 1e-9))


def first_distinct_rows(key: NDArray[np.int64]) -> NDArray[np.int64]:
    """Sorted indices of the first occurrence of each distinct row of ``key`` (n, c).

    As ``np.unique(key, axis=0, return_index=True)`` (sorted), faster: one wrapping 64-bit hash
    per row (odd multipliers), unique over the hashes; exact, as every row must equal the first
    row of its hash, else (a collision) unique over the whole rows as byte strings.
    """
    key = np.ascontiguousarray(key, dtype=np.int64)
    multipliers = np.arange(1, 2 * key.shape[1], 2, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    hashes = (key.view(np.uint64) * multipliers).sum(axis=1, dtype=np.uint64)
    _, first, inverse = np.unique(hashes, return_index=True, return_inverse=True)
    if not np.array_equal(key[first[inverse]], key):
        _, first = np.unique(key.view(np.dtype((np.void, key.dtype.itemsize * key.shape[1]))).ravel(),
                             return_index=True)
    return np.sort(first)


__all__ = ["direct_rows", "first_distinct_rows", "specular_rows"]
