"""Image sources on planar mirrors: unfolding, back-tracing, and the planar specular chains.

Physics
-------
A plane wall reflects a point source's spherical wave as if it came from the source's mirror
image (the image-source method; Allen & Berkley 1979, Borish 1984; physics.md section 3). For a
chain of k mirrors the transmitter T is mirrored across each plane in turn,

    T_0 = T,   T_j = T_{j-1} - 2 ((T_{j-1} - P_j) . n_j) n_j      (plane j: point P_j, unit normal n_j),

and the path T -> mirrors -> receiver R has the length L = |T_k - R| of the straight line from
the last image, with the spreading 1 / L of a free field from the image (plane mirrors keep
the wavefront's curvature); the reflection coefficients multiply in later
(:mod:`acoustisim.propagation.reference.specular`).

Method
------
* :func:`unfold`: the images T_0 .. T_k of a start point across a sequence of mirrors; the
  chain is possible only if every image lies strictly in front of the next mirror (its wave
  can reach that mirror's water side).
* :func:`backtrace`: from the end point back toward the images, the reflection points: the
  point on mirror j is where the segment (current point -> T_j) crosses the plane. Each must
  lie inside the mirror's polygon (or disc), and each leg must run on the water side of its
  mirrors.
* :func:`planar_chains`: every sequence of ``order`` mirrors
  (:func:`~acoustisim.propagation.image_source.mirror_sequences`: consecutive mirrors must see
  each other, the first must face the transmitter, the last some receiver), unfolded and
  back-traced to every receiver.

Accuracy
--------
Exact within geometric acoustics (the image method is exact for a plane of infinite extent; a
finite mirror is used only where the specular point lies inside it: no edge diffraction, which
:mod:`acoustisim.propagation.edges` adds). Round-off: a point within
:data:`~acoustisim.propagation.image_source.ON_PLANE_TOLERANCE_M` (1e-12 m) of a plane is on it
and a point within :data:`~acoustisim.propagation.image_source.INSIDE_TOLERANCE` (1e-9,
barycentric) of a polygon's edge is inside, so that paths through a right-angle corner line
(coincident reflection points) are found.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.image_source import ON_PLANE_TOLERANCE_M, PlanarMirrors, mirror_sequences
from acoustisim.propagation.reference.chains import Chains


def unfold(mirrors: PlanarMirrors, start: NDArray[np.float64],
           sequences: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Successive images of ``start`` across the mirrors of each sequence.

    Parameters
    ----------
    mirrors : PlanarMirrors
    start : ndarray, shape (n, 3) or (3,)
        The real point (m): the transmitter, or a receiver for a sequence read backwards.
    sequences : ndarray of int64, shape (n, k)
        Mirror indices in the order the wave meets them from ``start``.

    Returns
    -------
    images : ndarray, shape (n, k + 1, 3)
        ``images[:, 0] = start``, ``images[:, j]`` the image across the first j mirrors (m).
    valid : ndarray of bool, shape (n,)
        Each image lies strictly in front of the next mirror.
    """
    n, k = sequences.shape
    images = np.empty((n, k + 1, 3))
    images[:, 0] = start
    valid = np.ones(n, dtype=bool)
    for j in range(k):  # a loop over the few mirrors of a chain, vectorised over chains
        m = sequences[:, j]
        valid &= mirrors.signed_distance(images[:, j], m) > 0.0
        images[:, j + 1] = mirrors.reflect(images[:, j], m)
    return images, valid


def backtrace(mirrors: PlanarMirrors, images: NDArray[np.float64], sequences: NDArray[np.int64],
              end: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Reflection points of the chains start -> mirrors -> ``end``.

    Parameters
    ----------
    mirrors : PlanarMirrors
    images : ndarray, shape (n, k + 1, 3)
        From :func:`unfold`.
    sequences : ndarray of int64, shape (n, k)
    end : ndarray, shape (n, 3)
        The point the chain arrives at (a receiver, or a curved surface's specular point) (m).

    Returns
    -------
    points : ndarray, shape (n, k, 3)
        Reflection points in the order met from the start (m).
    valid : ndarray of bool, shape (n,)
        Every point lies inside its polygon, and every leg leaves and reaches its mirrors on
        their water side.
    """
    n, k = sequences.shape
    points = np.empty((n, k, 3))
    valid = np.ones(n, dtype=bool)
    current = np.broadcast_to(np.asarray(end, dtype=float), (n, 3))
    for j in range(k - 1, -1, -1):
        m = sequences[:, j]
        source = images[:, j + 1]
        d_current = mirrors.signed_distance(current, m)
        d_source = mirrors.signed_distance(source, m)
        # the segment current -> image must cross the plane: current in front (or on the plane,
        # within round-off: a path through a right-angle corner line, where two reflection
        # points coincide), image behind
        valid &= (d_current > -ON_PLANE_TOLERANCE_M) & (d_source < 0.0)
        t = np.maximum(d_current, 0.0) / np.where(valid, d_current - d_source, 1.0)
        crossing = current + t[:, None] * (source - current)
        alive = np.flatnonzero(valid)  # the polygon test only where the chain is still possible
        valid[alive] = mirrors.contains(crossing[alive], m[alive])
        points[:, j] = crossing
        current = crossing
    return points, valid


def planar_chains(context: SolveContext, mirrors: PlanarMirrors, order: int, first: NDArray[np.bool_],
                  last: NDArray[np.bool_], chain_base: int) -> tuple[Chains, int]:
    """Every valid chain of ``order`` planar mirrors, to every receiver.

    Parameters
    ----------
    context : SolveContext
    mirrors : PlanarMirrors
    order : int
        Number of mirrors (>= 1).
    first, last : ndarray of bool, shape (m,)
        Mirrors the transmitter faces; mirrors some receiver faces.
    chain_base : int
        Chain number of the first sequence; sequence q is chain ``chain_base + q`` on every receiver.

    Returns
    -------
    chains : Chains
        Receiver by receiver, sequences in order; length |T_k - R|, spreading 1 / length.
    next_chain : int
        The next free chain number.
    """
    transmitter = context.transmitter_m
    sequences = mirror_sequences(mirrors.sees, order, first, last)
    images, unfolded = unfold(mirrors, transmitter, sequences)
    ids = np.flatnonzero(unfolded)
    n_receivers = context.receivers_m.shape[0]
    # every (receiver, sequence) pair, receiver by receiver
    channel = np.repeat(np.arange(n_receivers), ids.size)
    chain = np.tile(ids, n_receivers)
    receiver = context.receivers_m[channel]
    points, valid = backtrace(mirrors, images[chain], sequences[chain], receiver)
    channel, chain, points, receiver = channel[valid], chain[valid], points[valid], receiver[valid]
    seq = sequences[chain]
    length = np.linalg.norm(images[chain, -1] - receiver, axis=1)
    n = chain.size
    chains = Chains(
        vertices=np.concatenate([np.broadcast_to(transmitter, (n, 1, 3)), points, receiver[:, None, :]], axis=1),
        surface=mirrors.surface[seq], patch=mirrors.patch[seq], normal=mirrors.normal[seq],
        material=mirrors.material[seq], length=length, spreading=1.0 / length,
        phase=np.zeros(n), channel=channel, chain=chain_base + chain)
    return chains, chain_base + sequences.shape[0]


__all__ = ("backtrace", "planar_chains", "unfold")
