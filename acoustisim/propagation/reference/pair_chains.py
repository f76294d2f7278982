"""Candidate specular chains through two curved primitives, with planar mirrors before, between and after.

A chain [n_before mirrors, curved primitive C1, n_between mirrors, curved primitive C2, n_after
mirrors] of order n_before + n_between + n_after + 2 (post to post, post via a wall to another
post or to itself, sphere to post, ...). The transmitter is unfolded across the mirrors before
C1 (image A), each receiver backwards across the mirrors after C2 (image B); C2 and B are
unfolded across the mirrors between (the last first), the joint specular points and the
ray-tube amplitude are solved in that unfolded frame (:mod:`.curved_pairs`), X2 is folded
back, and the planar points are back-traced on the three stretches (:mod:`.image_source`).
:mod:`.specular` then tests the legs for occlusion, drops duplicates, multiplies in the
reflection coefficients and writes the rows, as for every other chain.

C1 and C2 are different objects unless mirrors lie between them (a convex body cannot
reflect its own reflection directly). Mirrors next to a primitive must be allowed by its
visibility table (``PreparedScene.curved_seen_by``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.curved import CurvedSet, SurfacePoints, reflect_primitives
from acoustisim.propagation.image_source import PlanarMirrors
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.reference.chains import Chains
from acoustisim.propagation.reference.curved_pairs import pair_specular_points, ray_tube_amplitude
from acoustisim.propagation.reference.image_source import backtrace, unfold


class PairCandidates(NamedTuple):
    """Chains [before mirrors, C1, between mirrors, C2, after mirrors] of one split whose
    images are valid (n of them).

    Attributes
    ----------
    first, second : ndarray of int64, shape (n,)
        The curved reflectors C1 and C2 (indices into ``PreparedScene.curved``).
    channel : ndarray of int64, shape (n,)
        Receiver.
    chain : ndarray of int64, shape (n,)
        ``(((before * sm + between) * sa + after) * c + first) * c + second`` (sequence numbers
        of each stretch, sm and sa sequences between and after, c reflectors).
    images_before : ndarray, shape (n, n_before + 1, 3)
        The transmitter and its images across the mirrors before C1 (m).
    images_after : ndarray, shape (n, n_after + 1, 3)
        The receiver and its images across the mirrors after C2, from the receiver back (m).
    sequences_before, sequences_between, sequences_after : ndarray of int64
        The mirrors of each stretch in path order, shapes (n, n_before), (n, n_between),
        (n, n_after).
    chain_count : int
        Chain numbers this split uses (sb x sm x sa x c x c).
    """

    first: NDArray[np.int64]
    second: NDArray[np.int64]
    channel: NDArray[np.int64]
    chain: NDArray[np.int64]
    images_before: NDArray[np.float64]
    images_after: NDArray[np.float64]
    sequences_before: NDArray[np.int64]
    sequences_between: NDArray[np.int64]
    sequences_after: NDArray[np.int64]
    chain_count: int

    def select(self, rows: NDArray[np.intp]) -> "PairCandidates":
        """The candidates ``rows``."""
        return PairCandidates(*(field[rows] for field in self[:-1]), self.chain_count)


def pair_splits(max_order: int) -> list[tuple[int, int, int]]:
    """(n_before, n_between, n_after) of every chain through two curved reflectors of order
    <= ``max_order``, lexicographic."""
    mirrors = max_order - 2
    return [(n_before, n_between, n_after) for n_before in range(mirrors + 1)
            for n_between in range(mirrors + 1 - n_before) for n_after in range(mirrors + 1 - n_before - n_between)]


def pair_candidates(context: SolveContext, mirrors: PlanarMirrors, seen_by: NDArray[np.bool_],
                    split: tuple[int, int, int], first: NDArray[np.bool_], last: NDArray[np.bool_]) -> PairCandidates:
    """Every (before, between, after sequence and receiver, C1, C2) of one ``split`` with valid
    images on both ends, the mirrors next to each reflector allowed by ``seen_by`` (c, m), and
    C1 != C2 when no mirror lies between; nested in that order."""
    n_before, n_between, n_after = split
    n_reflectors = seen_by.shape[0]
    n_receivers = context.receivers_m.shape[0]
    seen = np.any(seen_by, axis=0)
    before = mirrors.sequences(n_before, first, seen)
    between = mirrors.sequences(n_between, seen, seen)
    after = mirrors.sequences(n_after, seen, last)  # in path order
    images_before, ok_before = unfold(mirrors, context.transmitter_m, before)
    after_of_row = np.repeat(np.arange(after.shape[0]), n_receivers)
    receiver_of_row = np.tile(np.arange(n_receivers), after.shape[0])
    images_after, ok_after = unfold(mirrors, context.receivers_m[receiver_of_row], after[after_of_row][:, ::-1])
    b, m, ar, r1, r2 = (g.ravel() for g in np.meshgrid(
        np.flatnonzero(ok_before), np.arange(between.shape[0]), np.flatnonzero(ok_after), np.arange(n_reflectors),
        np.arange(n_reflectors), indexing="ij"))
    a = after_of_row[ar]
    allowed = np.ones(b.size, dtype=bool)
    if n_before:
        allowed &= seen_by[r1, before[b, -1]]
    if n_between:
        allowed &= seen_by[r1, between[m, 0]] & seen_by[r2, between[m, -1]]
    else:
        allowed &= r1 != r2
    if n_after:
        allowed &= seen_by[r2, after[a, 0]]
    b, m, ar, a, r1, r2 = (v[allowed] for v in (b, m, ar, a, r1, r2))
    chain = (((b * between.shape[0] + m) * after.shape[0] + a) * n_reflectors + r1) * n_reflectors + r2
    return PairCandidates(first=r1, second=r2, channel=receiver_of_row[ar], chain=chain,
                          images_before=images_before[b], images_after=images_after[ar], sequences_before=before[b],
                          sequences_between=between[m], sequences_after=after[a],
                          chain_count=before.shape[0] * between.shape[0] * after.shape[0] * n_reflectors ** 2)


def unfold_between(mirrors: PlanarMirrors, second: CurvedSet, receiver_image: NDArray[np.float64],
                   between: NDArray[np.int64]) -> tuple[CurvedSet, NDArray[np.float64]]:
    """C2 (n rows) and the receiver's image B (n, 3) as seen from C1 through the mirrors
    ``between`` (n, k): reflected across the last mirror first."""
    for j in range(between.shape[1] - 1, -1, -1):
        m = between[:, j]
        second = reflect_primitives(second, mirrors.point[m], mirrors.normal[m])
        receiver_image = mirrors.reflect(receiver_image, m)
    return second, receiver_image


def fold_back(mirrors: PlanarMirrors, point: NDArray[np.float64], normal: NDArray[np.float64],
              between: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The real X2 and its normal (n, 3) from their unfolded images: reflected across the
    mirrors ``between`` (n, k) in path order (the inverse of :func:`unfold_between`)."""
    for j in range(between.shape[1]):
        m = between[:, j]
        point = mirrors.reflect(point, m)
        normal = normal - 2.0 * np.einsum("ij,ij->i", normal, mirrors.normal[m])[:, None] * mirrors.normal[m]
    return point, normal


def chains_through_pairs(context: SolveContext, prepared: PreparedScene, candidates: PairCandidates,
                         curved_offset: int, chain_base: int) -> Chains:
    """The chains of ``candidates`` whose joint specular points are valid and whose planar
    points back-trace validly on all three stretches; reflections on curved reflector r have
    material code ``curved_offset + r``, chain numbers start at ``chain_base``."""
    mirrors = prepared.mirrors
    c = candidates
    first = prepared.curved_set.take(c.first)
    second, b = unfold_between(mirrors, prepared.curved_set.take(c.second), c.images_after[:, -1],
                               c.sequences_between)
    a = c.images_before[:, -1]
    x1, x2, valid = pair_specular_points(first, second, a, b)
    point2, normal2 = fold_back(mirrors, x2.point, x2.normal, c.sequences_between)
    before_points, ok = backtrace(mirrors, c.images_before, c.sequences_before, x1.point)
    valid &= ok
    after_points, ok = backtrace(mirrors, c.images_after, c.sequences_after[:, ::-1], point2)
    valid &= ok
    images_between, ok = unfold(mirrors, x1.point, c.sequences_between)
    valid &= ok
    between_points, ok = backtrace(mirrors, images_between, c.sequences_between, point2)
    valid &= ok
    keep = np.flatnonzero(valid)
    c = c.select(keep)
    x1, x2 = (SurfacePoints(*(field[keep] for field in x)) for x in (x1, x2))
    a, b, point2, normal2 = a[keep], b[keep], point2[keep], normal2[keep]
    n = keep.size
    length = (np.linalg.norm(x1.point - a, axis=1) + np.linalg.norm(x2.point - x1.point, axis=1)
              + np.linalg.norm(b - x2.point, axis=1))
    spreading = ray_tube_amplitude(a, [x1, x2], b)
    vertices = np.concatenate([np.broadcast_to(context.transmitter_m, (n, 1, 3)), before_points[keep],
                               x1.point[:, None, :], between_points[keep], point2[:, None, :],
                               after_points[keep][:, ::-1], context.receivers_m[c.channel][:, None, :]], axis=1)
    sb, sm, sa = c.sequences_before, c.sequences_between, c.sequences_after
    surface_of = np.array([r.surface for r in prepared.curved], dtype=np.int64)
    patch_of = np.array([r.patch for r in prepared.curved], dtype=np.int64)

    def stretches(of_mirror: NDArray, of_first: NDArray, of_second: NDArray) -> NDArray:
        return np.concatenate([of_mirror[sb], of_first[:, None], of_mirror[sm], of_second[:, None], of_mirror[sa]],
                              axis=1)

    return Chains(
        vertices=vertices,
        surface=stretches(mirrors.surface, surface_of[c.first], surface_of[c.second]),
        patch=stretches(mirrors.patch, patch_of[c.first], patch_of[c.second]),
        normal=stretches(mirrors.normal, x1.normal, normal2),
        material=stretches(mirrors.material, curved_offset + c.first, curved_offset + c.second),
        length=length, spreading=spreading, phase=np.zeros(n), channel=c.channel, chain=chain_base + c.chain)


def pair_chains(context: SolveContext, prepared: PreparedScene, max_order: int, first: NDArray[np.bool_],
                last: NDArray[np.bool_], curved_offset: int, chain_base: int) -> tuple[list[Chains], int]:
    """Chains [n_before mirrors, C1, n_between mirrors, C2, n_after mirrors] of every split of
    order <= ``max_order`` (:func:`pair_splits`), ``first`` / ``last`` the mirrors the
    transmitter / some receiver faces; and the next free chain number."""
    groups = []
    for split in pair_splits(max_order):
        candidates = pair_candidates(context, prepared.mirrors, prepared.curved_seen_by, split, first, last)
        groups.append(chains_through_pairs(context, prepared, candidates, curved_offset, chain_base))
        chain_base += candidates.chain_count
    return groups, chain_base


__all__ = ("PairCandidates", "chains_through_pairs", "fold_back", "pair_candidates", "pair_chains", "pair_splits",
           "unfold_between")
