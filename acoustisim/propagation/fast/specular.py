"""The fast engine's specular paths: the rows of :mod:`acoustisim.propagation.reference.specular`.

Read the reference module for the physics. Here the chains of every order and kind are written
by compiled loops (:mod:`.chain_kernels`, over :mod:`.mirror_kernels` and
:mod:`.curved_kernels`) straight into one :class:`~.chain_kernels.PaddedChains` array (the
smooth-mesh chains, built with the same kernels per mesh, are padded and appended), so that
what follows is one pass over all of them:

* occlusion: Embree's OCCLUDED query on float32 buffers built by a compiled loop, without
  exclusions; only the legs it finds blocked (about 1 in 10) go through
  :meth:`~acoustisim.propagation.raycast.RayCaster.occluded_rays` with the patches at their ends
  excluded (a leg OCCLUDED finds clear has no triangle between its ends, and INTERSECT, which
  the exclusion passes use, tests the same triangles over the same span);
* duplicates by a 64-bit hash of the reference engine's key (:func:`first_distinct_rows`);
* reflection coefficients: one ``Material.reflection_coefficient`` call per distinct material
  over every reflection on it;
* the rows written by one compiled loop.

The mixed chains of every split share one specular-point solve and one geometric-optics
evaluation; the chains through two curved primitives (:mod:`.pair_kernels`) share one joint
solve over every split, started from three batched single-surface solves.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.curved import (CYLINDER_END_TOLERANCE_M, PAIR_MIN_COSINE, PAIR_NEWTON_STEPS,
                                          PAIR_NEWTON_TOLERANCE_M, PAIR_STATIONARY_TOLERANCE, CurvedSet,
                                          SurfacePoints)
from acoustisim.propagation.fast.chain_kernels import (MIRROR_KIND, SMOOTH_KIND, ChainEnds, MaterialCodes, MirrorSide,
                                                       MixedCandidates, PaddedChains, ReflectorLabels, chain_legs,
                                                       duplicate_keys, fill_mixed, fill_planar, incidence_cosines,
                                                       mixed_candidates, occlusion_queries32, path_columns,
                                                       unblocked_chains, vertex_groups, write_rows)
from acoustisim.propagation.fast.curved_kernels import go_factors, specular_points
from acoustisim.propagation.fast.pair_kernels import (JointSettings, PairCandidates, PairLayout, PairSplit,
                                                      fill_pairs, joint_specular_points, pair_candidates)
from acoustisim.propagation.fast.mirror_kernels import (MirrorArrays, backtrace_chains, mirror_arrays, unfold_chains,
                                                        unfold_reversed)
from acoustisim.propagation.image_source import PlanarMirrors
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, empty_paths_array
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.raycast import DEFAULT_EPS_M
from acoustisim.propagation.reference.pair_chains import pair_splits
from acoustisim.propagation.reference.specular import DUPLICATE_RESOLUTION_M, REAL_TOLERANCE, receivers_in_front


class Pose(NamedTuple):
    """What every chain builder of one solve reads."""

    mirrors: PlanarMirrors
    arrays: MirrorArrays
    ends: ChainEnds
    first: NDArray[np.bool_]
    last: NDArray[np.bool_]


def unfold_from(arrays: MirrorArrays, start: NDArray[np.float64], sequences: NDArray[np.int64]
                ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The images of one start point (3,) across every sequence (s, k), and their validity."""
    starts = np.ascontiguousarray(np.broadcast_to(np.asarray(start, dtype=float), (sequences.shape[0], 3)))
    return unfold_chains(arrays, starts, np.ascontiguousarray(sequences, dtype=np.int64))


def sides(pose: Pose, seen_by: NDArray[np.bool_], lengths: range | list[int]
          ) -> tuple[dict[int, MirrorSide], dict[int, MirrorSide]]:
    """The mirror sequences of each of ``lengths`` before a reflector (from the transmitter, with
    its images) and after it (path order, each receiver's images across them read backwards),
    for reflectors with the visibility table ``seen_by`` (c, m)."""
    seen = np.any(seen_by, axis=0)
    before, after = {}, {}
    for k in lengths:
        sequences = pose.mirrors.sequences(k, pose.first, seen)
        before[k] = MirrorSide(sequences, *unfold_from(pose.arrays, pose.ends.transmitter, sequences))
        sequences = pose.mirrors.sequences(k, seen, pose.last)
        after[k] = MirrorSide(sequences, *unfold_reversed(pose.arrays, pose.ends.receivers, sequences))
    return before, after


def allocate(capacity: int, big: int) -> PaddedChains:
    """Padded chain arrays for up to ``capacity`` chains of order <= ``big``, uninitialised (the
    fill kernels write every field of every row, padding included) but for the phases (none, 0)."""
    return PaddedChains(
        order=np.empty(capacity, dtype=np.int64), vertices=np.empty((capacity, big + 2, 3)),
        surface=np.empty((capacity, big), dtype=np.int64), patch=np.empty((capacity, big), dtype=np.int64),
        normal=np.empty((capacity, big, 3)), kind=np.empty((capacity, big), dtype=np.int64),
        material=np.empty((capacity, big), dtype=np.int64), length=np.empty(capacity), spreading=np.empty(capacity),
        channel=np.empty(capacity, dtype=np.int64), chain=np.empty(capacity, dtype=np.int64),
        has_phase=np.zeros(capacity, dtype=bool), phase=np.zeros(capacity))


def head(chains: PaddedChains, n: int) -> PaddedChains:
    """The first ``n`` chains (views)."""
    return PaddedChains(*(field[:n] for field in chains))


def splits(max_order: int) -> list[tuple[int, int]]:
    """(n_before, n_after) of every chain through one reflector of order <= ``max_order``."""
    return [(n_before, n_after) for n_before in range(max_order) for n_after in range(max_order - n_before)]


def planar_and_mixed(pose: Pose, prepared: PreparedScene, max_order: int) -> tuple[PaddedChains, int]:
    """Planar chains of orders 1..``max_order``, then mixed chains [n_before mirrors, one curved
    primitive, n_after mirrors] of every split (lexicographic), in the padded layout; and the
    next free chain number."""
    mirrors, arrays, ends = pose.mirrors, pose.arrays, pose.ends
    n_receivers = ends.receivers.shape[0]
    planar = []
    for order in range(1, max_order + 1):
        sequences = mirrors.sequences(order, pose.first, pose.last)
        planar.append(MirrorSide(sequences, *unfold_from(arrays, ends.transmitter, sequences)))
    capacity = n_receivers * sum(side.sequences.shape[0] for side in planar)
    candidates: list[MixedCandidates] = []
    if prepared.curved:
        before, after = sides(pose, prepared.curved_seen_by, range(max_order))
        for n_before, n_after in splits(max_order):
            candidates.append(mixed_candidates(prepared.curved_seen_by, before[n_before], after[n_after],
                                               n_receivers))
        capacity += sum(c.before.size for c in candidates)
    chains = allocate(capacity, max_order)
    cursor = chain_base = 0
    for side in planar:
        cursor = fill_planar(arrays, side, chain_base, ends, chains, cursor)
        chain_base += side.sequences.shape[0]
    if not candidates:
        return head(chains, cursor), chain_base
    source = np.concatenate([c.source_image for c in candidates])
    receiver = np.concatenate([c.receiver_image for c in candidates])
    points = specular_points(prepared.curved_set, np.concatenate([c.reflector for c in candidates]), source, receiver)
    labels = ReflectorLabels(np.array([r.surface for r in prepared.curved], dtype=np.int64),
                             np.array([r.patch for r in prepared.curved], dtype=np.int64))
    picked = np.empty(capacity, dtype=np.int64)
    mixed_start = cursor
    lo = 0
    for (n_before, n_after), split in zip(splits(max_order), candidates):
        hi = lo + split.before.size
        cursor = fill_mixed(arrays, before[n_before], after[n_after], n_receivers, split,
                            SurfacePoints(*(field[lo:hi] for field in points)), labels, chain_base, ends, chains,
                            picked, lo, cursor)
        chain_base += before[n_before].sequences.shape[0] * after[n_after].sequences.shape[0] * len(prepared.curved)
        lo = hi
    chains.spreading[mixed_start:cursor] = go_factors(picked[mixed_start:cursor], source, receiver, points)[0]
    return head(chains, cursor), chain_base


def smooth_chains(pose: Pose, prepared: PreparedScene, max_order: int, chain_base: int) -> tuple[PaddedChains, int]:
    """Chains [n_before mirrors, one smooth mesh, n_after mirrors] of every split, in the padded
    layout (order ``max_order``): a pair may have several specular points on a non-convex mesh,
    each its own chain number. Not a hot path: per split and mesh, numpy around the kernels."""
    mirrors, arrays, ends = pose.mirrors, pose.arrays, pose.ends
    n_receivers = ends.receivers.shape[0]
    seen_by = np.array([r.seen_by for r in prepared.smooth], dtype=bool).reshape(len(prepared.smooth), mirrors.count)
    before, after = sides(pose, seen_by, range(max_order))
    parts = []
    for n_before, n_after in splits(max_order):
        order = n_before + 1 + n_after
        side_b, side_a = before[n_before], after[n_after]
        cand = mixed_candidates(seen_by, side_b, side_a, n_receivers)
        for i, reflector in enumerate(prepared.smooth):  # a loop over meshes (a few), vectorised inside
            mine = np.flatnonzero(cand.reflector == i)
            a, b = cand.source_image[mine], cand.receiver_image[mine]
            pair, triangle, x, normal, e1, e2, k11, k22, k12 = reflector.mesh.specular_points(a, b)
            chain = chain_base + np.arange(pair.size)  # one number per specular point
            chain_base += pair.size
            rows = mine[pair]
            b_row, a_row = cand.before[rows], cand.after_row[rows]
            sequence_b, sequence_a = side_b.sequences[b_row], side_a.sequences[a_row // n_receivers]
            x = np.ascontiguousarray(x)
            points_b, ok_b = backtrace_chains(arrays, side_b.images[b_row], sequence_b, x)
            points_a, ok_a = backtrace_chains(arrays, side_a.images[a_row], np.ascontiguousarray(sequence_a[:, ::-1]),
                                              x)
            keep = np.flatnonzero(ok_b & ok_a)
            n = keep.size
            sb, sa, xk = sequence_b[keep], sequence_a[keep], x[keep]
            vertices = np.concatenate([np.broadcast_to(ends.transmitter, (n, 1, 3)), points_b[keep], xk[:, None, :],
                                       points_a[keep][:, ::-1], ends.receivers[a_row[keep] % n_receivers][:, None, :]],
                                      axis=1)
            length = (np.linalg.norm(xk - cand.source_image[rows[keep]], axis=1)
                      + np.linalg.norm(xk - cand.receiver_image[rows[keep]], axis=1))
            found = (x, normal, np.ones(pair.size, bool), e1, e2, k11, k22, k12)
            surface = SurfacePoints(*(np.ascontiguousarray(v[keep]) for v in found))
            spreading, phase = go_factors(np.arange(n), np.ascontiguousarray(a[pair][keep]),
                                          np.ascontiguousarray(b[pair][keep]), surface)
            one = np.ones((n, 1), dtype=np.int64)
            parts.append((order, PaddedChains(
                order=np.full(n, order, dtype=np.int64), vertices=vertices,
                surface=np.concatenate([mirrors.surface[sb], one * reflector.surface, mirrors.surface[sa]], axis=1),
                patch=np.concatenate([mirrors.patch[sb], reflector.patch[triangle[keep]][:, None], mirrors.patch[sa]],
                                     axis=1),
                normal=np.concatenate([mirrors.normal[sb], normal[keep][:, None, :], mirrors.normal[sa]], axis=1),
                kind=np.concatenate([np.full_like(sb, MIRROR_KIND), one * SMOOTH_KIND, np.full_like(sa, MIRROR_KIND)],
                                    axis=1),
                material=np.concatenate([mirrors.material[sb], one * i, mirrors.material[sa]], axis=1),
                length=length, spreading=spreading, channel=a_row[keep] % n_receivers, chain=chain[keep],
                has_phase=np.ones(n, dtype=bool), phase=phase)))
    return pad(parts, max_order), chain_base


def pair_chains(pose: Pose, prepared: PreparedScene, max_order: int, chain_base: int) -> tuple[PaddedChains, int]:
    """Chains [n_before mirrors, C1, n_between mirrors, C2, n_after mirrors] of every split of
    order <= ``max_order`` (:func:`~acoustisim.propagation.reference.pair_chains.pair_splits`),
    in the padded layout (order ``max_order``); and the next free chain number."""
    mirrors, arrays, ends = pose.mirrors, pose.arrays, pose.ends
    n_receivers = ends.receivers.shape[0]
    curved, seen_by = prepared.curved_set, prepared.curved_seen_by
    n_reflectors = curved.radius.shape[0]
    seen = np.any(seen_by, axis=0)
    before, after = sides(pose, seen_by, range(max_order - 1))
    between = {k: mirrors.sequences(k, seen, seen) for k in range(max_order - 1)}
    splits = pair_splits(max_order)
    candidates = [pair_candidates(arrays, curved, seen_by, before[n_before], between[n_between], after[n_after],
                                  n_receivers) for n_before, n_between, n_after in splits]
    every = PairCandidates(*(np.concatenate(field) for field in zip(*candidates)))
    # C1 and the unfolded C2 of each candidate as primitives of their own; the joint solve
    # starts from the alternating single-surface solutions
    first = curved.take(every.first)
    second = CurvedSet(curved.is_sphere[every.second], every.second_centre, every.second_frame,
                       curved.radius[every.second], curved.length[every.second])
    rows = np.arange(every.first.size)
    start = specular_points(first, rows, every.source_image, second.centre).point
    second_start = specular_points(second, rows, start, every.receiver_image).point
    first_start = specular_points(first, rows, every.source_image, second_start).point
    settings = JointSettings(PAIR_NEWTON_STEPS, PAIR_NEWTON_TOLERANCE_M, PAIR_STATIONARY_TOLERANCE,
                             CYLINDER_END_TOLERANCE_M, PAIR_MIN_COSINE)
    x1, x2, valid = joint_specular_points(first, second, every, first_start, second_start, settings)
    chains = allocate(int(np.count_nonzero(valid)), max_order)
    labels = ReflectorLabels(np.array([r.surface for r in prepared.curved], dtype=np.int64),
                             np.array([r.patch for r in prepared.curved], dtype=np.int64))
    cursor = lo = 0
    for (n_before, n_between, n_after), split in zip(splits, candidates):
        hi = lo + split.first.size
        layout = PairLayout(chain_base, between[n_between].shape[0], after[n_after].sequences.shape[0], n_reflectors)
        sides_of_split = PairSplit(*before[n_before], between[n_between], *after[n_after], n_receivers)
        cursor = fill_pairs(arrays, sides_of_split, split, SurfacePoints(*(field[lo:hi] for field in x1)),
                            SurfacePoints(*(field[lo:hi] for field in x2)), labels, layout, ends, chains, cursor)
        chain_base += (before[n_before].sequences.shape[0] * between[n_between].shape[0]
                       * after[n_after].sequences.shape[0] * n_reflectors ** 2)
        lo = hi
    return head(chains, cursor), chain_base


def pad(parts: list[tuple[int, PaddedChains]], big: int) -> PaddedChains:
    """Chains of orders k <= ``big`` (each part (k, chains of that order)) stacked in the padded
    layout of order ``big``."""
    n = sum(chains.length.size for _, chains in parts)
    out = allocate(n, big)
    out.surface[:], out.patch[:], out.kind[:] = -1, -1, -1
    out.normal[:], out.material[:] = 0.0, 0
    lo = 0
    for k, chains in parts:
        hi = lo + chains.length.size
        out.vertices[lo:hi, :k + 2] = chains.vertices
        out.vertices[lo:hi, k + 2:] = chains.vertices[:, -1:]
        for name in ("surface", "patch", "normal", "kind", "material"):
            getattr(out, name)[lo:hi, :k] = getattr(chains, name)
        for name in ("order", "length", "spreading", "channel", "chain", "has_phase", "phase"):
            getattr(out, name)[lo:hi] = getattr(chains, name)
        lo = hi
    return out


def unblocked(chains: PaddedChains, prepared: PreparedScene) -> NDArray[np.int64]:
    """Indices (increasing) of the chains none of whose legs is occluded."""
    every = np.arange(chains.length.shape[0])
    if every.size == 0:
        return every
    legs = chain_legs(chains, every)
    raycaster = prepared.raycaster
    queries = occlusion_queries32(legs, raycaster.shift_m, DEFAULT_EPS_M)
    hit = queries.leg[raycaster.occluded_segments32(queries.starts32, queries.directions32, queries.lengths32)]
    blocked_legs = np.zeros(legs.lengths.shape[0], dtype=bool)
    if hit.size:
        blocked_legs[hit] = raycaster.occluded_rays(legs.origins[hit], legs.directions[hit], legs.lengths[hit],
                                                    exclude_patches=legs.exclude[hit])
    return unblocked_chains(blocked_legs, chains.order, every)


def reflection_products(chains: PaddedChains, rows: NDArray[np.int64], prepared: PreparedScene,
                        context: SolveContext) -> NDArray[np.complex128]:
    """prod over the reflections of the chains ``rows`` of R(cos theta_i): (c,) complex.

    One ``Material.reflection_coefficient`` call per distinct material (equal materials of
    different reflector kinds share it) over every reflection on it, then the factors
    multiplied in path order per chain.
    """
    tables = (prepared.mirrors.materials, tuple(r.material for r in prepared.curved),
              tuple(r.material for r in prepared.smooth))
    distinct: dict[Any, int] = {}
    code_of = np.array([distinct.setdefault(m, len(distinct)) for table in tables for m in table], dtype=np.int64)
    kind_offset = np.cumsum([0] + [len(table) for table in tables[:-1]]).astype(np.int64)
    cosines = incidence_cosines(chains.vertices[rows], chains.normal[rows], chains.order[rows])
    cos_i = cosines.ravel()
    positions, starts = vertex_groups(rows, chains, MaterialCodes(code_of, kind_offset, len(distinct)))
    factor = np.ones(cos_i.shape, dtype=complex)
    for material, code in distinct.items():
        at = positions[starts[code]:starts[code + 1]]
        if at.size:
            factor[at] = material.reflection_coefficient(cos_i[at], context.density_kg_m3, context.sound_speed_m_s)
    factor = factor.reshape(cosines.shape)
    total = np.ones(rows.size, dtype=complex)
    for j in range(factor.shape[1]):
        total *= factor[:, j]
    return total


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


def specular_rows(context: SolveContext, prepared: PreparedScene, max_order: int,
                  max_curved_per_path: int) -> NDArray[Any]:
    """:func:`acoustisim.propagation.reference.specular.specular_rows`, compiled."""
    mirrors = prepared.mirrors
    first = mirrors.signed_distance(np.broadcast_to(context.transmitter_m, (mirrors.count, 3)),
                                    np.arange(mirrors.count)) > 0
    pose = Pose(mirrors, mirror_arrays(mirrors),
                ChainEnds(context.transmitter_m, np.ascontiguousarray(context.receivers_m, dtype=float)),
                first, receivers_in_front(context, mirrors))
    chains, chain_base = planar_and_mixed(pose, prepared, max_order)
    if prepared.smooth:
        smooth, chain_base = smooth_chains(pose, prepared, max_order, chain_base)
        chains = PaddedChains(*(np.concatenate([mine, theirs]) for mine, theirs in zip(chains, smooth)))
    if prepared.curved and max_curved_per_path >= 2 and max_order >= 2:
        pairs, chain_base = pair_chains(pose, prepared, max_order, chain_base)
        chains = PaddedChains(*(np.concatenate([mine, theirs]) for mine, theirs in zip(chains, pairs)))
    live = unblocked(chains, prepared)
    kept = live[first_distinct_rows(duplicate_keys(live, chains, MAX_INTERACTIONS, DUPLICATE_RESOLUTION_M))
                ] if live.size >= 2 else live
    reflection = reflection_products(chains, kept, prepared, context)
    # R in the physics convention exp(-i omega t) and the stationary-point phase in the
    # engineering one: convert the latter back before multiplying
    has_phase = chains.has_phase[kept]
    if has_phase.any():
        reflection[has_phase] = reflection[has_phase] * np.exp(-1j * chains.phase[kept][has_phase])
    rows = empty_paths_array(kept.size)
    write_rows(kept, context.first_path_id, int(PathKind.SPECULAR), chains, path_columns(rows))
    real = np.abs(reflection.imag) <= REAL_TOLERANCE * np.abs(reflection)
    gain = chains.spreading[kept]
    rows["geometric_gain"] = np.where(real, gain * reflection.real, gain * np.abs(reflection))
    rows["phase_rad"] = np.where(real, 0.0, -np.angle(reflection))
    return rows


__all__ = ("first_distinct_rows", "pair_chains", "planar_and_mixed", "reflection_products", "smooth_chains",
           "specular_rows", "unblocked")
