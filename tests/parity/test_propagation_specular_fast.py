"""The fast direct + specular solver against the frozen straightforward one it replaced.

``specular_rows`` (compiled image-source kernels, one pass over every chain length) must give
the same rows as the numpy code it replaced, kept here verbatim as the slow reference
(``reference_specular_rows`` and the ``unfold`` / ``backtrace`` / ``mirror_sequences`` /
``specular_points`` it used, as of commit 21590e5), over random poses of the thesis tank and of a tank with a
sphere, a cylinder and a prism: same rows in the same order, delays and gains equal to 1e-12
(relative; the kernels add the same terms in the same order as numpy, so only the last
bits of a dot product may differ).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.propagation import image_source
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.curved import CurvedSet, go_amplitude, go_amplitude_general
from acoustisim.propagation.image_source import PlanarMirrors
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, empty_paths_array
from acoustisim.propagation.prepared import PreparedScene, prepare
from acoustisim.propagation.solver import check_sonar
from acoustisim.propagation.specular import direct_rows, specular_rows

# ---------------------------------------------------------------- frozen reference (old code)
def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def circle_specular_point(a2: NDArray[np.float64], b2: NDArray[np.float64],
                          radius: float | NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Specular points on a circle of ``radius`` centred at the origin, in 2-D.

    Parameters
    ----------
    a2, b2 : ndarray, shape (n, 2)
        Source and receiver (outside the circle).
    radius : float or ndarray (n,)

    Returns
    -------
    points : ndarray, shape (n, 2)
        X on the circle where d/dphi (|a - X| + |b - X|) = 0 (the visible, least-length one).
    valid : ndarray of bool, shape (n,)
        Both ends outside the circle and in front of the tangent at X (lit side).
    """
    rad = np.broadcast_to(np.asarray(radius, dtype=float), (a2.shape[0],))
    ax, ay, bx, by = a2[:, 0], a2[:, 1], b2[:, 0], b2[:, 1]
    na, nb = np.hypot(ax, ay), np.hypot(bx, by)
    sx, sy = ax / na + bx / nb, ay / na + by / nb
    # opposite directions (forward scatter): no lit stationary point; keep phi finite
    degenerate = np.hypot(sx, sy) <= 1e-12
    phi = np.where(degenerate, np.arctan2(ay, ax), np.arctan2(sy, sx))
    r2 = rad * rad
    for _ in range(40):
        c, s = np.cos(phi), np.sin(phi)
        xx, xy = rad * c, rad * s
        # r(phi) = |P - X|: r' = -(P - X).X' / r, r'' = (a^2 + (P - X).X) / r - r'^2 / r, X' = a(-s, c)
        dax, day, dbx, dby = ax - xx, ay - xy, bx - xx, by - xy
        ra, rb = np.hypot(dax, day), np.hypot(dbx, dby)
        rpa = -rad * (-dax * s + day * c) / ra
        rpb = -rad * (-dbx * s + dby * c) / rb
        d1 = rpa + rpb
        d2 = (r2 + dax * xx + day * xy - rpa * rpa) / ra + (r2 + dbx * xx + dby * xy - rpb * rpb) / rb
        step = np.clip(d1 / np.where(np.abs(d2) > 1e-300, d2, 1e-300), -0.5, 0.5)
        phi = phi - step
        if not np.any(np.abs(step) > 1e-10):  # quadratic: the error left is ~ step^2
            break
    c, s = np.cos(phi), np.sin(phi)
    x = rad[:, None] * np.stack([c, s], axis=1)
    valid = ((ax - x[:, 0]) * c + (ay - x[:, 1]) * s > 0.0) & ((bx - x[:, 0]) * c + (by - x[:, 1]) * s > 0.0)
    valid &= (na > rad) & (nb > rad) & ~degenerate
    return x, valid


def _dot(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.einsum("ij,ij->i", u, v)


def specular_points(curved: CurvedSet, which: NDArray[np.int64], a: NDArray[np.float64], b: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], ...]:
    """Specular points of (image) sources ``a`` and receivers ``b`` on primitives ``which``.

    Parameters
    ----------
    curved : CurvedSet
    which : ndarray of int64, shape (n,)
        Index of the primitive of each candidate.
    a, b : ndarray, shape (n, 3)
        Source and receiver (m).

    Returns
    -------
    point, normal : ndarray, shape (n, 3)
        Specular point X (m) and unit outward normal.
    valid : ndarray of bool, shape (n,)
        Lit from both ends, both ends outside, and (cylinders) X within the finite length.
    e1, e2 : ndarray, shape (n, 3)
        Principal tangent directions (cylinders: around, along the axis).
    k1, k2 : ndarray, shape (n,)
        Principal curvatures (1/m): sphere (1/a, 1/a), cylinder (1/a, 0).
    """
    sph = curved.is_sphere[which]
    c = curved.centre[which]
    rad = curved.radius[which]
    u = a - c
    v = b - c
    # in-plane basis: spheres, the plane of (centre, a, b); cylinders, the plane normal to the axis
    frame = curved.frame[which]
    e1_s = _unit(u)
    w = v - _dot(v, e1_s)[:, None] * e1_s
    helper = np.where(np.abs(e1_s[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    # collinear centre, source and receiver: any plane through the line will do
    w = np.where(np.linalg.norm(w, axis=1, keepdims=True) > 1e-12 * np.linalg.norm(v, axis=1, keepdims=True),
                 w, np.cross(e1_s, helper))
    e2_s = _unit(w)
    p_axis = np.where(sph[:, None], e1_s, frame[:, 0])
    q_axis = np.where(sph[:, None], e2_s, frame[:, 1])
    axis = frame[:, 2]
    a2 = np.column_stack([_dot(u, p_axis), _dot(u, q_axis)])
    b2 = np.column_stack([_dot(v, p_axis), _dot(v, q_axis)])
    x2, valid = circle_specular_point(a2, b2, rad)
    # cylinders: lift along the axis where the unrolled path is straight
    za, zb = _dot(u, axis), _dot(v, axis)
    rho_a = np.linalg.norm(a2 - x2, axis=1)
    rho_b = np.linalg.norm(b2 - x2, axis=1)
    z = np.where(sph, 0.0, za + (zb - za) * rho_a / np.where(rho_a + rho_b > 0, rho_a + rho_b, 1.0))
    # inclusive (1e-9 m of round-off): a post meeting the free surface or the floor at a right
    # angle reflects a monostatic double bounce exactly at the junction
    valid &= sph | (np.abs(z) <= 0.5 * curved.length[which] + 1e-9)
    normal = _unit(x2[:, :1] * p_axis + x2[:, 1:] * q_axis)
    point = c + rad[:, None] * normal + z[:, None] * np.where(sph[:, None], 0.0, axis)
    # principal directions: cylinder (around, along); sphere any tangent pair
    helper_n = np.where(np.abs(normal[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    e1 = _unit(np.where(sph[:, None], np.cross(normal, helper_n), np.cross(axis, normal)))
    e2 = np.where(sph[:, None], np.cross(normal, e1), axis)
    k1 = 1.0 / rad
    k2 = np.where(sph, 1.0 / rad, 0.0)
    return point, normal, valid, e1, e2, k1, k2


def mirror_sequences(sees: NDArray[np.bool_], length: int, first: NDArray[np.bool_] | None = None,
                     last: NDArray[np.bool_] | None = None) -> NDArray[np.int64]:
    """Candidate mirror sequences (k, length) along which a wave could travel.

    Parameters
    ----------
    sees : ndarray of bool, shape (m, m)
        Mirror-to-mirror visibility (:attr:`PlanarMirrors.sees`); consecutive mirrors must see
        each other (this also excludes a mirror twice in a row).
    length : int
        Number of mirrors (0 gives one empty sequence).
    first, last : ndarray of bool, shape (m,), optional
        Mirrors allowed first / last (e.g. those the transmitter is in front of).
    """
    m = sees.shape[0]
    if length == 0:
        return np.zeros((1, 0), dtype=np.int64)
    allowed = np.ones(m, dtype=bool) if first is None else np.asarray(first, dtype=bool)
    seqs = np.flatnonzero(allowed)[:, None]
    for _ in range(length - 1):
        rows, nxt = np.nonzero(sees[seqs[:, -1]])
        seqs = np.concatenate([seqs[rows], nxt[:, None]], axis=1)
    if last is not None:
        seqs = seqs[np.asarray(last, dtype=bool)[seqs[:, -1]]]
    return seqs.astype(np.int64)


def unfold(mirrors: PlanarMirrors, start: NDArray[np.float64],
           sequences: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Successive images of ``start`` across the mirrors of each sequence.

    Parameters
    ----------
    start : ndarray, shape (n, 3)
        The real point (transmitter, or receiver for a reversed sequence).
    sequences : ndarray of int64, shape (n, k)
        Mirror indices in the order the wave meets them from ``start``.

    Returns
    -------
    images : ndarray, shape (n, k + 1, 3)
        ``images[:, 0] = start``, ``images[:, j]`` the image across the first j mirrors.
    valid : ndarray of bool, shape (n,)
        Each image lies strictly in front of the next mirror (the wave can reach its face).
    """
    n, k = sequences.shape
    images = np.empty((n, k + 1, 3))
    images[:, 0] = start
    valid = np.ones(n, dtype=bool)
    for j in range(k):
        m = sequences[:, j]
        valid &= mirrors.signed_distance(images[:, j], m) > 0.0
        images[:, j + 1] = mirrors.reflect(images[:, j], m)
    return images, valid


def backtrace(mirrors: PlanarMirrors, images: NDArray[np.float64], sequences: NDArray[np.int64],
              end: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Reflection points of the chains start -> mirrors -> ``end``.

    Parameters
    ----------
    images : ndarray, shape (n, k + 1, 3)
        From :func:`unfold`.
    sequences : ndarray of int64, shape (n, k)
    end : ndarray, shape (n, 3)
        The point the chain arrives at (receiver, or a curved object's specular point).

    Returns
    -------
    points : ndarray, shape (n, k, 3)
        Reflection points in the order met from the start.
    valid : ndarray of bool, shape (n,)
        Every point lies inside its polygon, between its neighbours on the unfolded line, and
        every leg leaves and reaches the mirrors on their water side.
    """
    n, k = sequences.shape
    points = np.empty((n, k, 3))
    valid = np.ones(n, dtype=bool)
    current = np.asarray(end, dtype=float)
    for j in range(k - 1, -1, -1):
        m = sequences[:, j]
        source = images[:, j + 1]
        d_cur = mirrors.signed_distance(current, m)
        d_src = mirrors.signed_distance(source, m)
        # the segment current -> image must cross the plane: current in front (or on the plane,
        # within round-off: a path through a right-angle corner line, where the two reflection
        # points coincide), image behind
        valid &= (d_cur > -image_source._ON_PLANE_TOL_M) & (d_src < 0.0)
        denom = np.where(valid, d_cur - d_src, 1.0)
        t = np.maximum(d_cur, 0.0) / denom
        x = current + t[:, None] * (source - current)
        live = np.flatnonzero(valid)  # the polygon test only where the chain is still alive
        valid[live] = mirrors.contains(x[live], m[live])
        points[:, j] = x
        current = x
    return points, valid



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


def reference_direct_rows(context: SolveContext) -> NDArray[Any]:
    """Direct transmitter -> receiver rows (skipping a receiver that is the transmitter itself).

    Gain 1/r; blocked paths are dropped.
    """
    tx = context.transmitter_m
    rx = context.receivers_m
    dist = np.linalg.norm(rx - tx, axis=1)
    channels = np.flatnonzero(dist > 1e-9)
    blocked = context.raycaster.occluded(np.tile(tx, (channels.size, 1)), rx[channels])
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
    ids = np.arange(mirrors.count)
    return np.any(
        [mirrors.signed_distance(np.broadcast_to(r, (mirrors.count, 3)), ids) > 0 for r in context.receivers_m], axis=0)


def _planar_chains(context: SolveContext, mirrors: PlanarMirrors, order: int, chain_base: int,
                   first: NDArray[np.bool_], last: NDArray[np.bool_]) -> tuple[_Chains, int]:
    tx = context.transmitter_m
    seqs = mirror_sequences(mirrors.sees, order, first, last)
    images, ok = unfold(mirrors, np.broadcast_to(tx, (seqs.shape[0], 3)), seqs)
    chain_ids = np.flatnonzero(ok)
    seqs, images = seqs[ok], images[ok]
    n_rx = context.receivers_m.shape[0]
    s = seqs.shape[0]
    seqs_all = np.tile(seqs, (n_rx, 1))
    images_all = np.tile(images, (n_rx, 1, 1))
    channel = np.repeat(np.arange(n_rx), s)
    rx = context.receivers_m[channel]
    points, valid = backtrace(mirrors, images_all, seqs_all, rx)
    seqs_all, images_all, points, rx, channel = (
        seqs_all[valid], images_all[valid], points[valid], rx[valid], channel[valid])
    length = np.linalg.norm(images_all[:, -1] - rx, axis=1)
    vertices = np.concatenate([np.broadcast_to(tx, (len(rx), 1, 3)), points, rx[:, None, :]], axis=1)
    chains = _Chains(
        vertices=vertices,
        surface=mirrors.surface[seqs_all],
        patch=mirrors.patch[seqs_all],
        normal=mirrors.normal[seqs_all],
        material=[("mirror", mirrors.material[seqs_all[:, j]]) for j in range(order)],
        length=length,
        spreading=1.0 / length,
        channel=channel,
        chain=chain_base + np.tile(chain_ids, n_rx)[valid],
    )
    return chains, chain_base + len(ok)


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


def _candidates(context: SolveContext, mirrors: PlanarMirrors, seen_by: NDArray[np.bool_], n_before: int,
                n_after: int, first: NDArray[np.bool_], last: NDArray[np.bool_]) -> _Candidates:
    """Every (before sequence, after sequence, receiver, reflector) whose images are valid, pruned
    by the mirror/reflector visibility table ``seen_by`` (r, m)."""
    n_refl = seen_by.shape[0]
    tx = context.transmitter_m
    n_rx = context.receivers_m.shape[0]
    any_seen = np.any(seen_by, axis=0)
    seq_b = mirror_sequences(mirrors.sees, n_before, first, any_seen)
    # in path order, from the object to the receiver
    seq_a = mirror_sequences(mirrors.sees, n_after, any_seen, last)
    images_b, ok_b = unfold(mirrors, np.broadcast_to(tx, (seq_b.shape[0], 3)), seq_b)
    # receiver-side images, once per (after sequence, receiver)
    ra = np.repeat(np.arange(seq_a.shape[0]), n_rx)
    rr = np.tile(np.arange(n_rx), seq_a.shape[0])
    images_a, ok_a = unfold(mirrors, context.receivers_m[rr], seq_a[ra][:, ::-1])
    ib = np.flatnonzero(ok_b)
    iar = np.flatnonzero(ok_a)
    gb, gar, gr = (g.ravel() for g in np.meshgrid(ib, iar, np.arange(n_refl), indexing="ij"))
    keep = np.ones(gb.size, dtype=bool)
    if n_before:
        keep &= seen_by[gr, seq_b[gb, -1]]
    if n_after:
        keep &= seen_by[gr, seq_a[ra[gar], 0]]
    gb, gar, gr = gb[keep], gar[keep], gr[keep]
    ga = ra[gar]
    return _Candidates(
        reflector=gr, channel=rr[gar], chain=(gb * seq_a.shape[0] + ga) * n_refl + gr,
        images_before=images_b[gb], images_after=images_a[gar], seq_before=seq_b[gb], seq_after=seq_a[ga],
        n_chains=seq_b.shape[0] * seq_a.shape[0] * n_refl,
    )


def _assemble(context: SolveContext, mirrors: PlanarMirrors, cand: _Candidates, x: NDArray[np.float64],
              normal: NDArray[np.float64], valid: NDArray[np.bool_], surface_of: NDArray[np.int64],
              patch_of: NDArray[np.int64], source: str, chain: NDArray[np.int64],
              traced: tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64], NDArray[np.bool_]] | None = None
              ) -> tuple[_Chains, NDArray[np.int64]]:
    """Back-trace the planar points of candidates with a reflector point ``x`` and build the chains.

    ``traced``: the back-traces (points before, valid, reversed points after, valid) when the
    caller has them already (:func:`_backtrace_batched`). Returns the chains and the candidate
    rows they came from (to pick the amplitudes).
    """
    n_before = cand.seq_before.shape[1]
    n_after = cand.seq_after.shape[1]
    if traced is None:
        pts_b, ok1 = backtrace(mirrors, cand.images_before, cand.seq_before, x)
        pts_a_rev, ok2 = backtrace(mirrors, cand.images_after, cand.seq_after[:, ::-1], x)
    else:
        pts_b, ok1, pts_a_rev, ok2 = traced
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


def _backtrace_batched(mirrors: PlanarMirrors, jobs: list[tuple[NDArray[np.float64], NDArray[np.int64],
                                                                  NDArray[np.float64]]]
                       ) -> list[tuple[NDArray[np.float64], NDArray[np.bool_]]]:
    """:func:`backtrace` of several (images, sequences, end) jobs, one call per sequence length.

    ``backtrace`` is row-wise, so jobs with sequences of equal length are concatenated and
    traced together, then split back (in the order of ``jobs``).
    """
    results: list[tuple[NDArray[np.float64], NDArray[np.bool_]] | None] = [None] * len(jobs)
    for k in sorted({seq.shape[1] for _, seq, _ in jobs}):
        members = [i for i, (_, seq, _) in enumerate(jobs) if seq.shape[1] == k]
        sizes = [jobs[i][1].shape[0] for i in members]
        if k == 0:  # nothing to trace: no points, every chain valid
            for i, size in zip(members, sizes):
                results[i] = (np.zeros((size, 0, 3)), np.ones(size, dtype=bool))
            continue
        points, valid = backtrace(mirrors, np.concatenate([jobs[i][0] for i in members]),
                                  np.concatenate([jobs[i][1] for i in members]),
                                  np.concatenate([jobs[i][2] for i in members]))
        bounds = np.cumsum([0] + sizes)
        for i, lo, hi in zip(members, bounds[:-1], bounds[1:]):
            results[i] = (points[lo:hi], valid[lo:hi])
    return results  # type: ignore[return-value]


def _mixed_chains(context: SolveContext, prepared: PreparedScene, max_order: int, chain_base: int,
                  first: NDArray[np.bool_], last: NDArray[np.bool_]) -> tuple[list[_Chains], int]:
    """Chains [n_before mirrors, one curved primitive, n_after mirrors] of every split with
    n_before + 1 + n_after <= ``max_order``, every primitive at once.

    The candidates of all splits share one specular-point solve and one geometric-optics
    amplitude evaluation (both row-wise), instead of one per split.
    """
    mirrors = prepared.mirrors
    splits = [(n_before, n_after) for n_before in range(max_order) for n_after in range(max_order - n_before)]
    cands, bases = [], []
    for n_before, n_after in splits:
        cand = _candidates(context, mirrors, prepared.curved_seen_by, n_before, n_after, first, last)
        cands.append(cand)
        bases.append(chain_base)
        chain_base += cand.n_chains
    sizes = [cand.reflector.size for cand in cands]
    bounds = np.cumsum([0] + sizes)
    reflector = np.concatenate([cand.reflector for cand in cands])
    a_pt = np.concatenate([cand.images_before[:, -1] for cand in cands])
    b_pt = np.concatenate([cand.images_after[:, -1] for cand in cands])
    x, normal, valid, e1, e2, k1, k2 = specular_points(prepared.curved_set, reflector, a_pt, b_pt)
    surfaces = np.array([r.surface for r in prepared.curved], dtype=np.int64)[reflector]
    patches = np.array([r.patch for r in prepared.curved], dtype=np.int64)[reflector]
    # the planar points on both sides of every split, one back-trace per sequence length
    jobs = []
    for cand, lo, hi in zip(cands, bounds[:-1], bounds[1:]):
        jobs.append((cand.images_before, cand.seq_before, x[lo:hi]))
        jobs.append((cand.images_after, cand.seq_after[:, ::-1], x[lo:hi]))
    traced = _backtrace_batched(mirrors, jobs)
    groups, picked = [], []
    for s, (cand, base, lo, hi) in enumerate(zip(cands, bases, bounds[:-1], bounds[1:])):
        part = slice(lo, hi)
        chains, idx = _assemble(context, mirrors, cand, x[part], normal[part], valid[part], surfaces[part],
                                patches[part], "curved", base + cand.chain, traced[2 * s] + traced[2 * s + 1])
        groups.append(chains)
        picked.append(lo + idx)
    rows = np.concatenate(picked)
    spreading = go_amplitude(a_pt[rows], b_pt[rows], x[rows], normal[rows], e1[rows], e2[rows], k1[rows], k2[rows])
    counts = np.cumsum([0] + [p.size for p in picked])
    for chains, lo, hi in zip(groups, counts[:-1], counts[1:]):
        chains.spreading = spreading[lo:hi]
    return groups, chain_base


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


def _incidence_cosines(chains: _Chains) -> list[NDArray[np.float64]]:
    """|cos| of the incidence angle at each vertex j of the chains: k arrays (n,)."""
    n = chains.length.shape[0]
    cosines = []
    previous = np.zeros((n, 3))
    for j in range(len(chains.material)):
        leg = chains.vertices[:, j + 1] - chains.vertices[:, j]
        norm = np.linalg.norm(leg, axis=1, keepdims=True)
        incoming = leg / np.where(norm > 0, norm, 1.0)
        if j > 0:
            # a zero-length leg (two reflections on a corner line): the wave arrives along the
            # previous direction mirrored by the previous surface
            n_prev = chains.normal[:, j - 1]
            mirrored = previous - 2.0 * np.einsum("ij,ij->i", previous, n_prev)[:, None] * n_prev
            incoming = np.where(norm > 1e-12, incoming, mirrored)
        previous = incoming
        cosines.append(np.abs(np.einsum("ij,ij->i", incoming, chains.normal[:, j])))
    return cosines


def _reflection_products(groups: list[_Chains], prepared: PreparedScene, context: SolveContext
                         ) -> list[NDArray[np.complex128]]:
    """Product over each chain's vertices of R(cos theta_incidence), for every group: (n_g,) complex.

    The coefficients of every vertex of every group are evaluated together, one
    ``Material.reflection_coefficient`` call per (reflector kind, material), then multiplied in
    vertex order per chain.
    """
    rho, c = context.density_kg_m3, context.sound_speed_m_s
    tables = {"mirror": prepared.mirrors.materials, "curved": tuple(r.material for r in prepared.curved),
              "smooth": tuple(r.material for r in prepared.smooth)}
    cosines = [_incidence_cosines(chains) for chains in groups]
    # every (group, vertex) slot, by reflector kind: its material indices and cosines concatenated
    slots: dict[str, list[tuple[int, int]]] = {}
    for g, chains in enumerate(groups):
        for j, (source, _) in enumerate(chains.material):
            slots.setdefault(source, []).append((g, j))
    factors: dict[tuple[int, int], NDArray[np.complex128]] = {}
    for source, where in slots.items():
        index = np.concatenate([groups[g].material[j][1] for g, j in where])
        cos_i = np.concatenate([cosines[g][j] for g, j in where])
        r = np.ones(index.size, dtype=complex)
        for m in np.unique(index):
            sel = index == m
            r[sel] = tables[source][int(m)].reflection_coefficient(cos_i[sel], rho, c)
        bounds = np.cumsum([0] + [cosines[g][j].size for g, j in where])
        for (g, j), lo, hi in zip(where, bounds[:-1], bounds[1:]):
            factors[(g, j)] = r[lo:hi]
    products = []
    for g, chains in enumerate(groups):
        total = np.ones(chains.length.shape[0], dtype=complex)
        for j in range(len(chains.material)):
            total *= factors[(g, j)]
        products.append(total)
    return products


def _select(chains: _Chains, keep: NDArray[np.bool_]) -> _Chains:
    """The chains where ``keep`` is true."""
    return _Chains(
        chains.vertices[keep], chains.surface[keep], chains.patch[keep], chains.normal[keep],
        [(source, index[keep]) for source, index in chains.material], chains.length[keep],
        chains.spreading[keep], chains.channel[keep], chains.chain[keep],
        None if chains.phase is None else chains.phase[keep],
    )


def _rows_from_chains(chains: _Chains, reflection: NDArray[np.complex128], path_id_base: int) -> NDArray[Any]:
    k = chains.surface.shape[1]
    n = chains.length.shape[0]
    rows = empty_paths_array(n)
    if n == 0:
        return rows
    v = chains.vertices
    r = reflection
    real = np.abs(r.imag) <= _REAL_TOL * np.abs(r)
    gain = chains.spreading
    rows["path_id"] = path_id_base + chains.chain
    rows["channel"] = chains.channel
    rows["kind"] = PathKind.SPECULAR
    rows["order"] = k
    rows["path_length_m"] = chains.length
    rows["geometric_gain"] = np.where(real, gain * r.real, gain * np.abs(r))
    rows["phase_rad"] = np.where(real, 0.0, -np.angle(r))
    dep = v[:, 1] - v[:, 0]
    arr = v[:, -1] - v[:, -2]
    rows["departure_dir"] = dep / np.linalg.norm(dep, axis=1, keepdims=True)
    rows["arrival_dir"] = arr / np.linalg.norm(arr, axis=1, keepdims=True)
    m = min(k, MAX_INTERACTIONS)
    rows["object_ids"][:, :m] = chains.surface[:, :m]
    rows["points_m"][:, :m] = v[:, 1:1 + m]
    return rows


def reference_specular_rows(context: SolveContext, prepared: PreparedScene, max_order: int) -> NDArray[Any]:
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
    chain_base = 0
    # mirrors the transmitter can reach first, and those some receiver can be reached from last
    first = mirrors.signed_distance(np.broadcast_to(context.transmitter_m, (mirrors.count, 3)),
                                    np.arange(mirrors.count)) > 0
    last = _receivers_in_front(context, mirrors)
    for order in range(1, max_order + 1):
        chains, chain_base = _planar_chains(context, mirrors, order, chain_base, first, last)
        groups.append(chains)
    if prepared.curved:
        mixed, chain_base = _mixed_chains(context, prepared, max_order, chain_base, first, last)
        groups.extend(mixed)
    if prepared.smooth:
        for n_before in range(max_order):
            for n_after in range(max_order - n_before):
                chains, chain_base = _smooth_chains(context, prepared, n_before, n_after, chain_base, first, last)
                groups.append(chains)
    # one batched occlusion query over every leg of every candidate
    origins, targets, excludes = [], [], []
    for chains in groups:
        n, legs = chains.vertices.shape[0], chains.vertices.shape[1] - 1
        if n == 0:
            continue
        origins.append(chains.vertices[:, :-1].reshape(-1, 3))
        targets.append(chains.vertices[:, 1:].reshape(-1, 3))
        pad = np.full((n, 1), -1, dtype=np.int64)
        start_patch = np.concatenate([pad, chains.patch], axis=1)  # patch at each leg's start
        end_patch = np.concatenate([chains.patch, pad], axis=1)
        excludes.append(np.stack([start_patch, end_patch], axis=2).reshape(-1, 2))
    if origins:
        blocked_legs = prepared.raycaster.occluded(
            np.concatenate(origins), np.concatenate(targets), exclude_patches=np.concatenate(excludes))
    live: list[_Chains] = []
    offset = 0
    for chains in groups:
        n, legs = chains.vertices.shape[0], chains.vertices.shape[1] - 1
        if n == 0:
            continue
        blocked = blocked_legs[offset:offset + n * legs].reshape(n, legs).any(axis=1)
        offset += n * legs
        live.append(_select(chains, ~blocked))
    out = [empty_paths_array(0)]
    for chains, reflection in zip(live, _reflection_products(live, prepared, context)):
        if chains.phase is not None:
            # R in the physics convention exp(-i omega t) and the stationary-point phase in the
            # engineering one: convert the latter back before multiplying
            reflection = reflection * np.exp(-1j * chains.phase)
        out.append(_rows_from_chains(chains, reflection, context.first_path_id))
    return _deduplicate_rows(np.concatenate(out))


def _deduplicate_rows(rows: NDArray[Any]) -> NDArray[Any]:
    """Keep one row per (channel, ordered interaction points, set of surfaces).

    Reflections on perpendicular planes commute: [wall, floor] and [floor, wall] have the same
    image, and generically only one order is a real path. Through the corner line itself (a
    monostatic corner return, or a post meeting the free surface or the floor) both orders pass
    with coincident reflection points: they are one path, found twice (the image method is exact
    in a right-angle wedge, whose edge does not diffract). Reciprocal twins of a monostatic path
    ([wall-x0, wall-x1] and [wall-x1, wall-x0]) visit their points in opposite orders and stay.
    """
    if rows.size < 2:
        return rows
    points = np.nan_to_num(rows["points_m"], nan=0.0).reshape(rows.size, -1)
    ids = np.sort(rows["object_ids"].astype(np.int64), axis=1)
    key = np.column_stack([rows["channel"], rows["order"], ids, np.round(points / 1e-9)]).astype(np.int64)
    # unique over whole rows as one opaque byte string each (np.unique(axis=0) does the same
    # through a structured dtype, with more overhead); return_index gives first occurrences
    key = np.ascontiguousarray(key)
    _, first = np.unique(key.view(np.dtype((np.void, key.dtype.itemsize * key.shape[1]))).ravel(),
                         return_index=True)
    return rows[np.sort(first)]



# ---------------------------------------------------------------- tests


def _random_poses(prepared: PreparedScene, n: int, seed: int) -> list[Any]:
    """``n`` random sonar poses (position in the tank's water, any yaw, some pitch and roll)
    that ``solve`` accepts (not touching or inside an object)."""
    rng = np.random.default_rng(seed)
    poses = []
    while len(poses) < n:
        sonar = replace(prepared.scene.sonar, position_m=tuple(rng.uniform((0.3, 0.3, 0.15), (8.7, 2.7, 0.85))),
                        yaw_deg=float(rng.uniform(-180, 180)), pitch_deg=float(rng.uniform(-20, 20)),
                        roll_deg=float(rng.uniform(-10, 10)))
        try:
            check_sonar(prepared, sonar)
        except InputError:
            continue
        poses.append(sonar)
    return poses


def _assert_same_rows(new: NDArray[Any], old: NDArray[Any]) -> None:
    """Same rows in the same order: integer columns equal, floats to 1e-12 relative (lengths:
    1e-12 m absolute on top, a few ulps of a 10 m path; 1e-12 s of delay is 1.5e-9 m)."""
    assert new.dtype == old.dtype and new.shape == old.shape
    for name in ("path_id", "channel", "kind", "order", "object_ids"):
        np.testing.assert_array_equal(new[name], old[name], err_msg=name)
    np.testing.assert_allclose(new["path_length_m"], old["path_length_m"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(new["geometric_gain"], old["geometric_gain"], rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(new["phase_rad"], old["phase_rad"], rtol=0.0, atol=1e-12)
    for name in ("departure_dir", "arrival_dir", "points_m"):
        np.testing.assert_allclose(new[name], old[name], rtol=0.0, atol=1e-12, err_msg=name)


@pytest.fixture(scope="module")
def thesis_tank() -> PreparedScene:
    from scenes.builtin import builtin_scene

    return prepare(builtin_scene("thesis-tank"))


def test_thesis_tank_rows_equal_the_reference_over_random_poses(thesis_tank: PreparedScene) -> None:
    poses = [thesis_tank.scene.sonar] + _random_poses(thesis_tank, 8, seed=3)
    total = 0
    for sonar in poses:
        context = SolveContext.build(thesis_tank.scene, sonar, thesis_tank.raycaster, first_path_id=7)
        new = specular_rows(context, thesis_tank, 3)
        old = reference_specular_rows(context, thesis_tank, 3)
        _assert_same_rows(new, old)
        _assert_same_rows(direct_rows(context), reference_direct_rows(context))
        total += old.size
    assert total > 8 * 100  # the poses do exercise many chains (each has hundreds of paths)


def test_smooth_mesh_and_primitives_rows_equal_the_reference() -> None:
    """A tank with a smooth mesh (Newton on interpolated normals), a sphere, a cylinder and a
    prism: every chain kind (planar, mixed with primitives, mixed with a smooth mesh)."""
    import trimesh

    from acoustisim.materials import get_material
    from acoustisim.medium import Medium
    from acoustisim.scene import Scene, SceneObject, Tank
    from acoustisim.sonar import SonarHead
    from scenes.builders import cylinder, edge_prism, sphere

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.08)
    mesh.apply_translation((5.0, 1.2, 0.5))
    blob = SceneObject("blob", "mesh", get_material("rigid"), mesh)
    objects = (blob, sphere("ball", (3.0, 2.0, 0.4), 0.1, "steel"),
               cylinder("pipe", (6.5, 1.0, 0.5), (0.0, 1.0, 0.0), 0.05, 0.6, "pvc"),
               edge_prism("prism", (2.0, 1.0), 60.0, 180.0, 0.1, 1.0, "steel"))
    prepared = prepare(Scene("mix", Medium(), SonarHead(), Tank(9.0, 3.0, 1.0), objects))
    assert prepared.smooth and prepared.curved
    for sonar in _random_poses(prepared, 4, seed=5):
        context = SolveContext.build(prepared.scene, sonar, prepared.raycaster)
        _assert_same_rows(specular_rows(context, prepared, 2), reference_specular_rows(context, prepared, 2))


def test_first_distinct_rows_equals_numpy_unique_even_on_hash_collisions() -> None:
    from acoustisim.propagation.specular import first_distinct_rows

    rng = np.random.default_rng(11)
    key = rng.integers(-3, 3, (500, 6))  # many duplicate rows
    expected = np.sort(np.unique(key, axis=0, return_index=True)[1])
    np.testing.assert_array_equal(first_distinct_rows(key), expected)
    # two different rows with the same wrapping hash: the second column offsets the first's
    # change (m0 + d1 m1 = 0 mod 2^64 with d1 = -m0 / m1, m1 odd hence invertible)
    m0, m1 = (np.arange(1, 5, 2, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)).tolist()
    d1 = (-m0 * pow(m1, -1, 2 ** 64)) % 2 ** 64
    a = np.array([[5, 7]], dtype=np.int64)
    b = a.view(np.uint64) + np.array([[1, d1]], dtype=np.uint64)
    collide = np.concatenate([a, b.view(np.int64), a])
    assert (collide.view(np.uint64) * np.array([m0, m1], dtype=np.uint64)).sum(axis=1, dtype=np.uint64)[0] == \
        (collide.view(np.uint64) * np.array([m0, m1], dtype=np.uint64)).sum(axis=1, dtype=np.uint64)[1]
    np.testing.assert_array_equal(first_distinct_rows(collide), [0, 1])
