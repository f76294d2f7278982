"""Compiled chains through two curved primitives (numba, cached on disk, GIL released).

The compiled twins of :mod:`acoustisim.propagation.reference.pair_chains` and
:mod:`acoustisim.propagation.reference.curved_pairs`, one loop iteration per candidate:

1. :func:`pair_candidates`: the (before row, between sequence, after row, C1, C2) candidates of
   one split, with the transmitter's image A, and C2 and the receiver's image B unfolded across
   the mirrors between (the last first);
2. :func:`joint_specular_points`: the joint Newton on the four tangent coordinates from given
   starts (the alternating single-surface solves, made by the caller with
   :func:`.curved_kernels.specular_points`), its stop rule applied per candidate, and the
   validity tests;
3. :func:`fill_pairs`: X2 folded back, the planar points back-traced on the three stretches,
   the ray-tube amplitude (:func:`ray_tube_factors` evaluates it alone), each valid chain
   written into the solve's :class:`~.chain_kernels.PaddedChains`.

Same formulas as the reference, not the same operation order everywhere (4x4 systems by
Gaussian elimination, 2x2 matrices written out): the rows agree to round-off. No ``fastmath``;
IEEE division (``error_model="numpy"``): degenerate candidates give NaN and are invalid, as in
numpy.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.curved import CurvedSet, SurfacePoints
from acoustisim.propagation.fast.bundles import plain_tuple_arguments
from acoustisim.propagation.fast.chain_kernels import (CURVED_KIND, ChainEnds, MirrorSide, PaddedChains,
                                                       ReflectorLabels, write_mirror_slot, write_padding,
                                                       write_receiver_tail, write_transmitter)
from acoustisim.propagation.fast.mirror_kernels import MirrorArrays, backtrace_one


class PairCandidates(NamedTuple):
    """Candidates [before mirrors, C1, between mirrors, C2, after mirrors] of one split (n).

    Attributes
    ----------
    before : ndarray of int64, shape (n,)
        Row of the before side (a sequence from the transmitter).
    between : ndarray of int64, shape (n,)
        Row of the between sequences.
    after_row : ndarray of int64, shape (n,)
        Row of the after side (``sequence * r + receiver``).
    first, second : ndarray of int64, shape (n,)
        The curved reflectors C1 and C2.
    source_image : ndarray, shape (n, 3)
        A, the transmitter's last image (m).
    receiver_image : ndarray, shape (n, 3)
        B, the receiver's last image unfolded across the mirrors between (m).
    second_centre : ndarray, shape (n, 3)
        C2's centre unfolded across the mirrors between (m).
    second_frame : ndarray, shape (n, 3, 3)
        C2's frame rows unfolded across the mirrors between.
    """

    before: NDArray[np.int64]
    between: NDArray[np.int64]
    after_row: NDArray[np.int64]
    first: NDArray[np.int64]
    second: NDArray[np.int64]
    source_image: NDArray[np.float64]
    receiver_image: NDArray[np.float64]
    second_centre: NDArray[np.float64]
    second_frame: NDArray[np.float64]


class JointSettings(NamedTuple):
    """The joint Newton's limits: at most ``steps`` steps, stop once no point moves more than
    ``tolerance_m``; stationary if every gradient component is below ``stationary``; a
    cylinder's point may lie ``end_tolerance_m`` beyond its ends; incidence cosines at least
    ``min_cosine``."""

    steps: int
    tolerance_m: float
    stationary: float
    end_tolerance_m: float
    min_cosine: float


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _reflect_point(x: NDArray[np.float64], m: int, point: NDArray[np.float64], normal: NDArray[np.float64]) -> None:
    """``x`` (3,) mirrored across mirror ``m``, in place."""
    d = (x[0] - point[m, 0]) * normal[m, 0] + (x[1] - point[m, 1]) * normal[m, 1] + (x[2] - point[m, 2]) * normal[m, 2]
    for k in range(3):
        x[k] = x[k] - 2.0 * d * normal[m, k]


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _reflect_direction(v: NDArray[np.float64], m: int, normal: NDArray[np.float64]) -> None:
    """``v`` (3,) mirrored as a direction across mirror ``m``, in place."""
    d = v[0] * normal[m, 0] + v[1] * normal[m, 1] + v[2] * normal[m, 2]
    for k in range(3):
        v[k] = v[k] - 2.0 * d * normal[m, k]


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _coaxial(curved: CurvedSet, r: int, centre: NDArray[np.float64], axis: NDArray[np.float64]) -> bool:
    """Whether cylinder ``r``'s image (``centre``, ``axis``) lies on its own axis line (within
    1e-9 m and 1e-12 rad): an object's side and its image's face away from each other wherever
    the points are (a post across the floor or the surface), so no path joins them lit."""
    if curved.is_sphere[r]:
        return False
    g0, g1, g2 = curved.frame[r, 2, 0], curved.frame[r, 2, 1], curved.frame[r, 2, 2]
    c0, c1, c2 = g1 * axis[2] - g2 * axis[1], g2 * axis[0] - g0 * axis[2], g0 * axis[1] - g1 * axis[0]
    o0, o1, o2 = centre[0] - curved.centre[r, 0], centre[1] - curved.centre[r, 1], centre[2] - curved.centre[r, 2]
    along = o0 * g0 + o1 * g1 + o2 * g2
    o0, o1, o2 = o0 - along * g0, o1 - along * g1, o2 - along * g2
    return math.sqrt(c0 * c0 + c1 * c1 + c2 * c2) < 1e-12 and math.sqrt(o0 * o0 + o1 * o1 + o2 * o2) < 1e-9


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def pair_candidates(mirrors_fields: tuple, curved_fields: tuple, seen_by: NDArray[np.bool_], before_fields: tuple,
                    between_sequences: NDArray[np.int64], after_fields: tuple, n_receivers: int) -> PairCandidates:
    """The candidates of one split [n_before mirrors, C1, n_between mirrors, C2, n_after mirrors].

    Every (before row, between sequence, after row, C1, C2) with valid images on both ends,
    the mirrors next to each reflector allowed by ``seen_by`` (c, m), and C1 != C2 when no
    mirror lies between, nested in that order
    (:func:`acoustisim.propagation.reference.pair_chains.pair_candidates`); with B and C2
    unfolded across the mirrors between. An object unfolded onto its own axis (:func:`_coaxial`)
    is left out: the reference finds it invalid, and its degenerate start would take every
    Newton step.
    """
    mirrors = MirrorArrays(*mirrors_fields)
    curved = CurvedSet(*curved_fields)
    before, after = MirrorSide(*before_fields), MirrorSide(*after_fields)
    n_refl = seen_by.shape[0]
    n_before, n_after = before.sequences.shape[1], after.sequences.shape[1]
    n_between = between_sequences.shape[1]
    n_b = 0
    for i in range(before.unfolded.shape[0]):
        if before.unfolded[i]:
            n_b += 1
    n_a = 0
    for i in range(after.unfolded.shape[0]):
        if after.unfolded[i]:
            n_a += 1
    capacity = n_b * between_sequences.shape[0] * n_a * n_refl * n_refl
    before_row = np.empty(capacity, dtype=np.int64)
    between_row = np.empty(capacity, dtype=np.int64)
    after_row = np.empty(capacity, dtype=np.int64)
    first = np.empty(capacity, dtype=np.int64)
    second = np.empty(capacity, dtype=np.int64)
    source_image = np.empty((capacity, 3))
    receiver_image = np.empty((capacity, 3))
    second_centre = np.empty((capacity, 3))
    second_frame = np.empty((capacity, 3, 3))
    n = 0
    for b in range(before.unfolded.shape[0]):
        if not before.unfolded[b]:
            continue
        for m in range(between_sequences.shape[0]):
            for a in range(after.unfolded.shape[0]):
                if not after.unfolded[a]:
                    continue
                for r1 in range(n_refl):
                    if n_before > 0 and not seen_by[r1, before.sequences[b, n_before - 1]]:
                        continue
                    if n_between > 0 and not seen_by[r1, between_sequences[m, 0]]:
                        continue
                    for r2 in range(n_refl):
                        if n_between > 0:
                            if not seen_by[r2, between_sequences[m, n_between - 1]]:
                                continue
                        elif r1 == r2:
                            continue
                        if n_after > 0 and not seen_by[r2, after.sequences[a // n_receivers, 0]]:
                            continue
                        before_row[n], between_row[n], after_row[n], first[n], second[n] = b, m, a, r1, r2
                        for q in range(3):
                            source_image[n, q] = before.images[b, n_before, q]
                            receiver_image[n, q] = after.images[a, n_after, q]
                            second_centre[n, q] = curved.centre[r2, q]
                            for p in range(3):
                                second_frame[n, p, q] = curved.frame[r2, p, q]
                        for j in range(n_between - 1, -1, -1):
                            mirror = between_sequences[m, j]
                            _reflect_point(second_centre[n], mirror, mirrors.point, mirrors.normal)
                            for p in range(3):
                                _reflect_direction(second_frame[n, p], mirror, mirrors.normal)
                            _reflect_point(receiver_image[n], mirror, mirrors.point, mirrors.normal)
                        if r1 == r2 and _coaxial(curved, r1, second_centre[n], second_frame[n, 2]):
                            continue
                        n += 1
    return PairCandidates(before_row[:n], between_row[:n], after_row[:n], first[:n], second[:n], source_image[:n],
                          receiver_image[:n], second_centre[:n], second_frame[:n])


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _surface_frame(sphere: bool, c0: float, c1: float, c2: float, g0: float, g1: float, g2: float, x0: float,
                   x1: float, x2: float) -> tuple[float, float, float, float, float, float, float, float, float, float]:
    """The local geometry of point x on a sphere (centre c) or a cylinder (centre c, axis g):
    the outward normal, e1, e2 (sphere: any tangent pair; cylinder: around, along the axis) and
    the axial coordinate (0 on a sphere), as
    :func:`acoustisim.propagation.reference.curved_pairs.surface_frame`."""
    r0, r1, r2 = x0 - c0, x1 - c1, x2 - c2
    along = 0.0 if sphere else r0 * g0 + r1 * g1 + r2 * g2
    m0, m1, m2 = r0 - along * g0, r1 - along * g1, r2 - along * g2
    norm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    n0, n1, n2 = m0 / norm, m1 / norm, m2 / norm
    if sphere:
        h0, h1 = (1.0, 0.0) if abs(n0) < 0.9 else (0.0, 1.0)
        t0, t1, t2 = n1 * 0.0 - n2 * h1, n2 * h0 - n0 * 0.0, n0 * h1 - n1 * h0
    else:
        t0, t1, t2 = g1 * n2 - g2 * n1, g2 * n0 - g0 * n2, g0 * n1 - g1 * n0
    nt = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0, t1, t2 = t0 / nt, t1 / nt, t2 / nt
    if sphere:
        u0, u1, u2 = n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0
    else:
        u0, u1, u2 = g0, g1, g2
    return n0, n1, n2, t0, t1, t2, u0, u1, u2, along


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _project(sphere: bool, c0: float, c1: float, c2: float, g0: float, g1: float, g2: float, radius: float,
             x0: float, x1: float, x2: float) -> tuple[float, float, float]:
    """Point x moved radially onto the sphere or cylinder
    (:func:`acoustisim.propagation.reference.curved_pairs.project`)."""
    r0, r1, r2 = x0 - c0, x1 - c1, x2 - c2
    along = 0.0 if sphere else r0 * g0 + r1 * g1 + r2 * g2
    m0, m1, m2 = r0 - along * g0, r1 - along * g1, r2 - along * g2
    norm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    return (c0 + along * g0 + radius * (m0 / norm), c1 + along * g1 + radius * (m1 / norm),
            c2 + along * g2 + radius * (m2 / norm))


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _unit(v0: float, v1: float, v2: float) -> tuple[float, float, float, float]:
    """v / |v| and |v|."""
    norm = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    return v0 / norm, v1 / norm, v2 / norm, norm


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _point_terms(e: NDArray[np.float64], d_in: NDArray[np.float64], r_in: float, d_out: NDArray[np.float64],
                 r_out: float, normal: NDArray[np.float64], k11: float, k22: float, gradient: NDArray[np.float64],
                 hessian: NDArray[np.float64], offset: int) -> None:
    """One point's gradient E^T (d_in - d_out) and Hessian block
    E^T ((I - d_in d_in^T) / r_in + (I - d_out d_out^T) / r_out) E + ((d_out - d_in) . n) K
    (E = ``e`` rows e1, e2; K diagonal) into ``gradient[offset:offset + 2]`` and ``hessian``."""
    coefficient = ((d_out[0] - d_in[0]) * normal[0] + (d_out[1] - d_in[1]) * normal[1]
                   + (d_out[2] - d_in[2]) * normal[2])
    p0 = e[0, 0] * d_in[0] + e[0, 1] * d_in[1] + e[0, 2] * d_in[2]
    p1 = e[1, 0] * d_in[0] + e[1, 1] * d_in[1] + e[1, 2] * d_in[2]
    q0 = e[0, 0] * d_out[0] + e[0, 1] * d_out[1] + e[0, 2] * d_out[2]
    q1 = e[1, 0] * d_out[0] + e[1, 1] * d_out[1] + e[1, 2] * d_out[2]
    gradient[offset] = p0 - q0
    gradient[offset + 1] = p1 - q1
    both = 1.0 / r_in + 1.0 / r_out
    hessian[offset, offset] = both - p0 * p0 / r_in - q0 * q0 / r_out + coefficient * k11
    hessian[offset + 1, offset + 1] = both - p1 * p1 / r_in - q1 * q1 / r_out + coefficient * k22
    off = -p0 * p1 / r_in - q0 * q1 / r_out
    hessian[offset, offset + 1] = off
    hessian[offset + 1, offset] = off


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _solve4(a: NDArray[np.float64], step: NDArray[np.float64]) -> None:
    """``step`` <- ``a``^-1 ``step`` by Gaussian elimination with partial pivoting (``a`` (4, 4)
    overwritten); 0 if a pivot is 0 or anything is not finite (the reference's unsolvable rows)."""
    for col in range(4):
        pivot = col
        for row in range(col + 1, 4):
            if abs(a[row, col]) > abs(a[pivot, col]):
                pivot = row
        if not abs(a[pivot, col]) > 0.0 or not math.isfinite(a[pivot, col]):
            step[:] = 0.0
            return
        if pivot != col:
            for k in range(4):
                a[col, k], a[pivot, k] = a[pivot, k], a[col, k]
            step[col], step[pivot] = step[pivot], step[col]
        for row in range(col + 1, 4):
            factor = a[row, col] / a[col, col]
            for k in range(col, 4):
                a[row, k] -= factor * a[col, k]
            step[row] -= factor * step[col]
    for row in range(3, -1, -1):
        total = step[row]
        for k in range(row + 1, 4):
            total -= a[row, k] * step[k]
        step[row] = total / a[row, row]
    for i in range(4):
        if not math.isfinite(step[i]):
            step[:] = 0.0
            return


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _clip(s0: float, s1: float, limit: float) -> tuple[float, float, float]:
    """A tangent step scaled down to length <= ``limit``, and its length."""
    norm = math.sqrt(s0 * s0 + s1 * s1)
    scale = min(1.0, limit / (norm if norm > 0 else 1.0))
    s0, s1 = s0 * scale, s1 * scale
    return s0, s1, math.sqrt(s0 * s0 + s1 * s1)


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def joint_specular_points(first_fields: tuple, second_fields: tuple, candidates_fields: tuple,
                          first_start: NDArray[np.float64], second_start: NDArray[np.float64], settings_fields: tuple
                          ) -> tuple[SurfacePoints, SurfacePoints, NDArray[np.bool_]]:
    """Joint specular points X1 on C1 and X2 on the unfolded C2 of each candidate (n), from the
    starts (n, 3), as :func:`acoustisim.propagation.reference.curved_pairs.pair_specular_points`
    (each candidate stops as soon as its own points stop moving). ``first`` and ``second`` are
    :class:`CurvedSet` bundles with one row per candidate (C1, and C2 unfolded).

    One candidate at a time on scalars and small local arrays (bundle fields are unpacked once:
    reading a tuple's array field inside the loop would cost a reference count each time).
    """
    sphere1, centre1, frame1, radius1, length1 = first_fields
    sphere2, centre2, frame2, radius2, length2 = second_fields
    candidates = PairCandidates(*candidates_fields)
    source, receiver = candidates.source_image, candidates.receiver_image
    steps, tolerance, stationary, end_tolerance, min_cosine = settings_fields
    n = first_start.shape[0]
    point = np.empty((2, n, 3))
    normal = np.empty((2, n, 3))
    e1 = np.empty((2, n, 3))
    e2 = np.empty((2, n, 3))
    k11 = np.empty((2, n))
    k22 = np.empty((2, n))
    valid = np.empty(n, dtype=np.bool_)
    x = np.empty((2, 3))
    nrm = np.empty((2, 3))
    tangent = np.empty((2, 2, 3))  # point, (e1, e2), xyz
    legs = np.empty((3, 3))
    lengths = np.empty(3)
    along = np.empty(2)
    gradient = np.empty(4)
    hessian = np.empty((4, 4))
    step = np.empty(4)
    for i in range(n):
        sph = (sphere1[i], sphere2[i])
        c = ((centre1[i, 0], centre1[i, 1], centre1[i, 2]), (centre2[i, 0], centre2[i, 1], centre2[i, 2]))
        g = ((frame1[i, 2, 0], frame1[i, 2, 1], frame1[i, 2, 2]), (frame2[i, 2, 0], frame2[i, 2, 1], frame2[i, 2, 2]))
        radius = (radius1[i], radius2[i])
        k_along = (1.0 / radius[0] if sph[0] else 0.0, 1.0 / radius[1] if sph[1] else 0.0)
        a0, a1, a2 = source[i, 0], source[i, 1], source[i, 2]
        b0, b1, b2 = receiver[i, 0], receiver[i, 1], receiver[i, 2]
        for k in range(3):
            x[0, k], x[1, k] = first_start[i, k], second_start[i, k]
        for iteration in range(steps + 1):
            for p in range(2):
                (nrm[p, 0], nrm[p, 1], nrm[p, 2], tangent[p, 0, 0], tangent[p, 0, 1], tangent[p, 0, 2],
                 tangent[p, 1, 0], tangent[p, 1, 1], tangent[p, 1, 2], along[p]) = _surface_frame(
                    sph[p], c[p][0], c[p][1], c[p][2], g[p][0], g[p][1], g[p][2], x[p, 0], x[p, 1], x[p, 2])
            legs[0, 0], legs[0, 1], legs[0, 2], lengths[0] = _unit(x[0, 0] - a0, x[0, 1] - a1, x[0, 2] - a2)
            legs[1, 0], legs[1, 1], legs[1, 2], lengths[1] = _unit(x[1, 0] - x[0, 0], x[1, 1] - x[0, 1],
                                                                   x[1, 2] - x[0, 2])
            legs[2, 0], legs[2, 1], legs[2, 2], lengths[2] = _unit(b0 - x[1, 0], b1 - x[1, 1], b2 - x[1, 2])
            _point_terms(tangent[0], legs[0], lengths[0], legs[1], lengths[1], nrm[0], 1.0 / radius[0], k_along[0],
                         gradient, hessian, 0)
            _point_terms(tangent[1], legs[1], lengths[1], legs[2], lengths[2], nrm[1], 1.0 / radius[1], k_along[1],
                         gradient, hessian, 2)
            if iteration == steps:
                break  # the last pass only evaluates the gradient at the final points
            for u in range(2):
                for v in range(2):
                    h = (tangent[0, u, 0] * tangent[1, v, 0] + tangent[0, u, 1] * tangent[1, v, 1]
                         + tangent[0, u, 2] * tangent[1, v, 2])
                    along_first = (tangent[0, u, 0] * legs[1, 0] + tangent[0, u, 1] * legs[1, 1]
                                   + tangent[0, u, 2] * legs[1, 2])
                    along_second = (tangent[1, v, 0] * legs[1, 0] + tangent[1, v, 1] * legs[1, 1]
                                    + tangent[1, v, 2] * legs[1, 2])
                    h -= along_first * along_second
                    hessian[u, 2 + v] = -h / lengths[1]
                    hessian[2 + v, u] = -h / lengths[1]
            for k in range(4):
                step[k] = gradient[k]
            _solve4(hessian, step)
            moved = 0.0
            for p in range(2):
                s0, s1, length = _clip(step[2 * p], step[2 * p + 1], 0.5 * radius[p])
                moved = max(moved, length)
                x[p, 0], x[p, 1], x[p, 2] = _project(
                    sph[p], c[p][0], c[p][1], c[p][2], g[p][0], g[p][1], g[p][2], radius[p],
                    x[p, 0] - (tangent[p, 0, 0] * s0 + tangent[p, 1, 0] * s1),
                    x[p, 1] - (tangent[p, 0, 1] * s0 + tangent[p, 1, 1] * s1),
                    x[p, 2] - (tangent[p, 0, 2] * s0 + tangent[p, 1, 2] * s1))
            if not moved > tolerance:
                # re-evaluate the frames and gradient at the final points, then stop
                for p in range(2):
                    (nrm[p, 0], nrm[p, 1], nrm[p, 2], tangent[p, 0, 0], tangent[p, 0, 1], tangent[p, 0, 2],
                     tangent[p, 1, 0], tangent[p, 1, 1], tangent[p, 1, 2], along[p]) = _surface_frame(
                        sph[p], c[p][0], c[p][1], c[p][2], g[p][0], g[p][1], g[p][2], x[p, 0], x[p, 1], x[p, 2])
                legs[0, 0], legs[0, 1], legs[0, 2], lengths[0] = _unit(x[0, 0] - a0, x[0, 1] - a1, x[0, 2] - a2)
                legs[1, 0], legs[1, 1], legs[1, 2], lengths[1] = _unit(x[1, 0] - x[0, 0], x[1, 1] - x[0, 1],
                                                                       x[1, 2] - x[0, 2])
                legs[2, 0], legs[2, 1], legs[2, 2], lengths[2] = _unit(b0 - x[1, 0], b1 - x[1, 1], b2 - x[1, 2])
                _point_terms(tangent[0], legs[0], lengths[0], legs[1], lengths[1], nrm[0], 1.0 / radius[0],
                             k_along[0], gradient, hessian, 0)
                _point_terms(tangent[1], legs[1], lengths[1], legs[2], lengths[2], nrm[1], 1.0 / radius[1],
                             k_along[1], gradient, hessian, 2)
                break
        ok = (sph[0] or abs(along[0]) <= 0.5 * length1[i] + end_tolerance) and (
            sph[1] or abs(along[1]) <= 0.5 * length2[i] + end_tolerance)
        for k in range(4):
            ok = ok and abs(gradient[k]) <= stationary
        # lit from both neighbours, and not grazing (the incidence cosines of the arriving legs)
        lit_a = (a0 - x[0, 0]) * nrm[0, 0] + (a1 - x[0, 1]) * nrm[0, 1] + (a2 - x[0, 2]) * nrm[0, 2]
        lit_x2, lit_x1 = 0.0, 0.0
        for k in range(3):
            lit_x2 += (x[1, k] - x[0, k]) * nrm[0, k]
            lit_x1 += (x[0, k] - x[1, k]) * nrm[1, k]
        lit_b = (b0 - x[1, 0]) * nrm[1, 0] + (b1 - x[1, 1]) * nrm[1, 1] + (b2 - x[1, 2]) * nrm[1, 2]
        cos1 = -(legs[0, 0] * nrm[0, 0] + legs[0, 1] * nrm[0, 1] + legs[0, 2] * nrm[0, 2])
        cos2 = -(legs[1, 0] * nrm[1, 0] + legs[1, 1] * nrm[1, 1] + legs[1, 2] * nrm[1, 2])
        valid[i] = (ok and lit_a > 0.0 and lit_x2 > 0.0 and lit_x1 > 0.0 and lit_b > 0.0
                    and cos1 >= min_cosine and cos2 >= min_cosine)
        for p in range(2):
            for k in range(3):
                point[p, i, k] = x[p, k]
                normal[p, i, k] = nrm[p, k]
                e1[p, i, k] = tangent[p, 0, k]
                e2[p, i, k] = tangent[p, 1, k]
            k11[p, i] = 1.0 / radius[p]
            k22[p, i] = k_along[p]
    zero = np.zeros(n)
    first_points = SurfacePoints(point[0], normal[0], valid, e1[0], e2[0], k11[0], k22[0], zero)
    second_points = SurfacePoints(point[1], normal[1], valid, e1[1], e2[1], k11[1], k22[1], zero)
    return first_points, second_points, valid


@njit(cache=True, nogil=True, error_model="numpy")
def _reflect_tube(q: NDArray[np.float64], w: NDArray[np.float64], d: NDArray[np.float64], x: SurfacePoints, i: int,
                  leg: NDArray[np.float64]) -> float:
    """One reflection of the ray tube at specular point ``i`` of ``x`` and the leg after it:
    the incident curvature ``q`` (q00, q01, q11) in basis ``w`` (w1, w2 as six numbers) along
    unit ``d`` becomes the curvature at the leg's end in the outgoing basis (``q``, ``w``, ``d``
    updated in place); returns the spreading factor det(I + r q_r)^(-1/2) = |cos| / sqrt(det M)
    of the leg (``leg``: its vector), without inverting T_r (see the reference's Method)."""
    r = math.sqrt(leg[0] * leg[0] + leg[1] * leg[1] + leg[2] * leg[2])
    o0, o1, o2 = leg[0] / r, leg[1] / r, leg[2] / r
    e10, e11, e12 = x.e1[i, 0], x.e1[i, 1], x.e1[i, 2]
    e20, e21, e22 = x.e2[i, 0], x.e2[i, 1], x.e2[i, 2]
    # T_i = W_i^T E
    t00 = w[0] * e10 + w[1] * e11 + w[2] * e12
    t01 = w[0] * e20 + w[1] * e21 + w[2] * e22
    t10 = w[3] * e10 + w[4] * e11 + w[5] * e12
    t11 = w[3] * e20 + w[4] * e21 + w[5] * e22
    cos_theta = -(d[0] * x.normal[i, 0] + d[1] * x.normal[i, 1] + d[2] * x.normal[i, 2])
    # S = T_i^T q T_i + 2 cos(theta) K
    q00, q01, q11 = q[0], q[1], q[2]
    u00, u01 = q00 * t00 + q01 * t10, q00 * t01 + q01 * t11
    u10, u11 = q01 * t00 + q11 * t10, q01 * t01 + q11 * t11
    s00 = t00 * u00 + t10 * u10 + 2.0 * cos_theta * x.k11[i]
    s01 = t00 * u01 + t10 * u11 + 2.0 * cos_theta * x.k12[i]
    s11 = t01 * u01 + t11 * u11 + 2.0 * cos_theta * x.k22[i]
    _basis_into(w, o0, o1, o2)
    # T_r = W_r^T E (det = +-cos(theta)), and M = T_r^T T_r + r S
    v00 = w[0] * e10 + w[1] * e11 + w[2] * e12
    v01 = w[0] * e20 + w[1] * e21 + w[2] * e22
    v10 = w[3] * e10 + w[4] * e11 + w[5] * e12
    v11 = w[3] * e20 + w[4] * e21 + w[5] * e22
    m00 = (v00 * v00 + v10 * v10) + r * s00
    m01 = (v00 * v01 + v10 * v11) + r * s01
    m11 = (v01 * v01 + v11 * v11) + r * s11
    det = m00 * m11 - m01 * m01
    cos_out = abs(o0 * x.normal[i, 0] + o1 * x.normal[i, 1] + o2 * x.normal[i, 2])
    # the curvature at the leg's end, (I - T_r M^-1 T_r^T) / r
    n00, n01, n11 = m11 / det, -m01 / det, m00 / det
    a0, a1 = n00 * v00 + n01 * v01, n01 * v00 + n11 * v01
    b0, b1 = n00 * v10 + n01 * v11, n01 * v10 + n11 * v11
    q[0] = (1.0 - (v00 * a0 + v01 * a1)) / r
    q[1] = -(v00 * b0 + v01 * b1) / r
    q[2] = (1.0 - (v10 * b0 + v11 * b1)) / r
    d[0], d[1], d[2] = o0, o1, o2
    return cos_out / math.sqrt(det)


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _basis_into(w: NDArray[np.float64], d0: float, d1: float, d2: float) -> None:
    """An orthonormal basis (w1, w2) of the plane normal to the unit vector d into ``w`` (6,),
    as :func:`acoustisim.propagation.reference.curved_pairs.transverse_basis`."""
    h0, h1 = (1.0, 0.0) if abs(d0) < 0.9 else (0.0, 1.0)
    c0, c1, c2 = d1 * 0.0 - d2 * h1, d2 * h0 - d0 * 0.0, d0 * h1 - d1 * h0
    norm = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    w0, w1, w2 = c0 / norm, c1 / norm, c2 / norm
    w[0], w[1], w[2] = w0, w1, w2
    w[3], w[4], w[5] = d1 * w2 - d2 * w1, d2 * w0 - d0 * w2, d0 * w1 - d1 * w0


@njit(cache=True, nogil=True, error_model="numpy")
def _ray_tube(a: NDArray[np.float64], b: NDArray[np.float64], first: SurfacePoints, second: SurfacePoints, i: int,
              tube: NDArray[np.float64]) -> float:
    """Deschamps' ray-tube pressure factor of A -> X1 -> X2 -> B of candidate ``i`` (unfolded
    frame), as :func:`acoustisim.propagation.reference.curved_pairs.ray_tube_amplitude`;
    ``tube`` (15,) is work space."""
    q, w, d, leg = tube[0:3], tube[3:9], tube[9:12], tube[12:15]
    for k in range(3):
        d[k] = first.point[i, k] - a[k]
    r0 = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    d[0], d[1], d[2] = d[0] / r0, d[1] / r0, d[2] / r0
    _basis_into(w, d[0], d[1], d[2])
    q[0], q[1], q[2] = 1.0 / r0, 0.0, 1.0 / r0
    amplitude = 1.0 / r0
    for k in range(3):
        leg[k] = second.point[i, k] - first.point[i, k]
    amplitude *= _reflect_tube(q, w, d, first, i, leg)
    for k in range(3):
        leg[k] = b[k] - second.point[i, k]
    amplitude *= _reflect_tube(q, w, d, second, i, leg)
    return amplitude


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def ray_tube_factors(rows: NDArray[np.int64], a: NDArray[np.float64], b: NDArray[np.float64], first_fields: tuple,
                     second_fields: tuple) -> NDArray[np.float64]:
    """The ray-tube factors (r,) of candidates ``rows`` (r,) of sources ``a``, receivers ``b``
    (n, 3) and joint specular points ``first``, ``second`` (n of them): what :func:`fill_pairs`
    writes as each chain's spreading."""
    first, second = SurfacePoints(*first_fields), SurfacePoints(*second_fields)
    out = np.empty(rows.shape[0])
    tube = np.empty(15)
    for k in range(rows.shape[0]):
        i = rows[k]
        out[k] = _ray_tube(a[i], b[i], first, second, i, tube)
    return out


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _write_curved_slot(row: int, slot: int, r: int, normal: NDArray[np.float64], reflectors: ReflectorLabels,
                       out: PaddedChains) -> None:
    out.surface[row, slot] = reflectors.surface[r]
    out.patch[row, slot] = reflectors.patch[r]
    out.normal[row, slot, 0] = normal[0]
    out.normal[row, slot, 1] = normal[1]
    out.normal[row, slot, 2] = normal[2]
    out.kind[row, slot] = CURVED_KIND
    out.material[row, slot] = r


class PairSplit(NamedTuple):
    """The mirror stretches of one split: the before side (sequences from the transmitter with
    its images), the between sequences (s, n_between), the after side (sequences in path order
    with each receiver's images read backwards, ``n_receivers`` rows per sequence)."""

    before_sequences: NDArray[np.int64]
    before_images: NDArray[np.float64]
    before_unfolded: NDArray[np.bool_]
    between_sequences: NDArray[np.int64]
    after_sequences: NDArray[np.int64]
    after_images: NDArray[np.float64]
    after_unfolded: NDArray[np.bool_]
    n_receivers: int


class PairLayout(NamedTuple):
    """Chain numbering of one split: ``chain_base + (((before * between_count + between) *
    after_count + after) * reflector_count + C1) * reflector_count + C2``."""

    chain_base: int
    between_count: int
    after_count: int
    reflector_count: int


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def fill_pairs(mirrors_fields: tuple, split_fields: tuple, candidates_fields: tuple, first_fields: tuple,
               second_fields: tuple, reflectors_fields: tuple, layout_fields: tuple, ends_fields: tuple,
               out_fields: tuple, cursor: int) -> int:
    """The chains of one split's ``candidates`` through their joint specular points (``first``,
    ``second``: X1 and the unfolded X2) that are valid and whose planar points back-trace
    validly on the three stretches, written from row ``cursor`` of ``out`` with their length
    |X1 - A| + |X2 - X1| + |B - X2| and ray-tube amplitude. Returns the next free row."""
    mirrors = MirrorArrays(*mirrors_fields)
    split = PairSplit(*split_fields)
    before = MirrorSide(split.before_sequences, split.before_images, split.before_unfolded)
    after = MirrorSide(split.after_sequences, split.after_images, split.after_unfolded)
    between_sequences, n_receivers = split.between_sequences, split.n_receivers
    candidates = PairCandidates(*candidates_fields)
    first, second = SurfacePoints(*first_fields), SurfacePoints(*second_fields)
    reflectors = ReflectorLabels(*reflectors_fields)
    layout = PairLayout(*layout_fields)
    ends = ChainEnds(*ends_fields)
    out = PaddedChains(*out_fields)
    n_before, n_after = before.sequences.shape[1], after.sequences.shape[1]
    n_between = between_sequences.shape[1]
    order = n_before + n_between + n_after + 2
    slot_first, slot_second = n_before, n_before + n_between + 1
    receivers = ends.receivers
    between_images = np.empty((1, n_between + 1, 3))
    x2 = np.empty(3)
    n2 = np.empty(3)
    tube = np.empty(15)
    valid = first.valid
    for i in range(candidates.before.shape[0]):
        if not valid[i]:
            continue
        b, m, a = candidates.before[i], candidates.between[i], candidates.after_row[i]
        r1, r2 = candidates.first[i], candidates.second[i]
        sequence_after = a // n_receivers
        for k in range(3):
            x2[k] = second.point[i, k]
            n2[k] = second.normal[i, k]
        for j in range(n_between):
            _reflect_point(x2, between_sequences[m, j], mirrors.point, mirrors.normal)
            _reflect_direction(n2, between_sequences[m, j], mirrors.normal)
        row = cursor
        x10, x11, x12 = first.point[i, 0], first.point[i, 1], first.point[i, 2]
        ok = backtrace_one(mirrors, before.images, b, before.sequences, b, False, x10, x11, x12, out.vertices, row,
                           1, 1)
        if not ok:
            continue
        ok = backtrace_one(mirrors, after.images, a, after.sequences, sequence_after, True, x2[0], x2[1], x2[2],
                           out.vertices, row, order, -1)
        if not ok:
            continue
        if n_between > 0:
            # X1's images across the mirrors between, each in front of the next mirror
            between_images[0, 0, 0], between_images[0, 0, 1], between_images[0, 0, 2] = x10, x11, x12
            for j in range(n_between):
                mirror = between_sequences[m, j]
                height = ((between_images[0, j, 0] - mirrors.point[mirror, 0]) * mirrors.normal[mirror, 0]
                          + (between_images[0, j, 1] - mirrors.point[mirror, 1]) * mirrors.normal[mirror, 1]
                          + (between_images[0, j, 2] - mirrors.point[mirror, 2]) * mirrors.normal[mirror, 2])
                ok = ok and height > 0.0
                for k in range(3):
                    between_images[0, j + 1, k] = between_images[0, j, k] - 2.0 * height * mirrors.normal[mirror, k]
            if not ok:
                continue
            ok = backtrace_one(mirrors, between_images, 0, between_sequences, m, False, x2[0], x2[1], x2[2],
                               out.vertices, row, slot_first + 2, 1)
            if not ok:
                continue
        cursor += 1
        rx = a % n_receivers
        out.order[row] = order
        write_transmitter(row, ends, out)
        out.vertices[row, slot_first + 1, 0] = x10
        out.vertices[row, slot_first + 1, 1] = x11
        out.vertices[row, slot_first + 1, 2] = x12
        out.vertices[row, slot_second + 1, 0] = x2[0]
        out.vertices[row, slot_second + 1, 1] = x2[1]
        out.vertices[row, slot_second + 1, 2] = x2[2]
        write_receiver_tail(row, order + 1, receivers[rx, 0], receivers[rx, 1], receivers[rx, 2], out)
        for q in range(n_before):
            write_mirror_slot(row, q, before.sequences[b, q], mirrors, out)
        for q in range(n_between):
            write_mirror_slot(row, slot_first + 1 + q, between_sequences[m, q], mirrors, out)
        for q in range(n_after):
            write_mirror_slot(row, slot_second + 1 + q, after.sequences[sequence_after, q], mirrors, out)
        _write_curved_slot(row, slot_first, r1, first.normal[i], reflectors, out)
        _write_curved_slot(row, slot_second, r2, n2, reflectors, out)
        write_padding(row, order, out)
        src, dst = candidates.source_image[i], candidates.receiver_image[i]
        y0, y1, y2 = second.point[i, 0], second.point[i, 1], second.point[i, 2]
        e0, e1, e2 = x10 - src[0], x11 - src[1], x12 - src[2]
        f0, f1, f2 = y0 - x10, y1 - x11, y2 - x12
        g0, g1, g2 = dst[0] - y0, dst[1] - y1, dst[2] - y2
        out.length[row] = (math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) + math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
                           + math.sqrt(g0 * g0 + g1 * g1 + g2 * g2))
        out.spreading[row] = _ray_tube(src, dst, first, second, i, tube)
        out.channel[row] = rx
        out.chain[row] = layout.chain_base + (((b * layout.between_count + m) * layout.after_count + sequence_after)
                                              * layout.reflector_count + r1) * layout.reflector_count + r2
    return cursor


__all__ = ("JointSettings", "PairCandidates", "PairLayout", "PairSplit", "fill_pairs", "joint_specular_points",
           "pair_candidates", "ray_tube_factors")
