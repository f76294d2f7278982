"""Compiled per-element loops of edge diffraction (numba, cached on disk, GIL released).

:func:`acoustisim.propagation.edges.edge_paths` turns some 8 000 visible edge elements of a
pose into 16 000 rows; in numpy, the quadrature of :func:`~acoustisim.propagation.btm.element_gains`
at the Gauss points, the points themselves and their path lengths, the amplitude floor and the
filling of the ``PATH_DTYPE`` rows are dozens of passes over temporary arrays. Here each
element (each row) is one loop iteration:

1. :func:`visibility_segments`: the occlusion segments of every element's centre (one Embree
   batch, :meth:`~acoustisim.propagation.raycast.SceneRaycaster.occluded`, between the kernels);
2. :func:`gauss_point_gains`: per element, the Gauss points along the edge, their path lengths
   m + l, and their gains (the element's BTM integral split between them);
3. :func:`fill_edge_rows`: the rows above the amplitude floor, with dense path ids per
   (chain, channel), the points and the unit leg directions, and the padding conventions of
   :func:`~acoustisim.propagation.paths.empty_paths_array`.

The per-pair constants (the angular factors of the four beta terms, the apex model's
constants) stay in numpy (:func:`~acoustisim.propagation.btm.pair_constants`, a few hundred
pairs). The arithmetic is :func:`~acoustisim.propagation.btm.element_gains`' term for term and
in the same order (the four terms summed 0 + t0 + t1 + t2 + t3, squares as products), so the
gains agree with the numpy reference to round-off of the elementary functions (libm here,
numpy's own SIMD loops there): ``tests/test_edges_kernels.py`` holds them to 1e-12 relative.
No ``fastmath`` (it would reassociate sums). ``cache=True`` stores the compiled code beside
this file: the first call in a fresh checkout compiles for a few seconds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True, error_model="numpy")
def gauss_point_gains(
    pair: NDArray[np.int64], z_start: NDArray[np.float64], z_end: NDArray[np.float64],
    nu: NDArray[np.float64], r_s: NDArray[np.float64], z_s: NDArray[np.float64], r_r: NDArray[np.float64],
    z_r: NDArray[np.float64], nk: NDArray[np.float64], ml_star: NDArray[np.float64], z_star: NDArray[np.float64],
    num: NDArray[np.float64], gap: NDArray[np.float64], coef: NDArray[np.float64], s_gap: NDArray[np.float64],
    gauss_x: NDArray[np.float64], gauss_w: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Gains, points and path lengths of every element's Gauss points.

    Parameters
    ----------
    pair : ndarray of int64, shape (n,)
        Pair of each element.
    z_start, z_end : ndarray, shape (n,)
        Element ends along the edge (m).
    nu, r_s, z_s, r_r, z_r, nk, ml_star, z_star : ndarray, shape (p,)
        Per pair: wedge index, source and receiver coordinates (m), and the apex model's
        nu kappa (1/m), m l at the apex (m^2) and least-time point (m).
    num, gap, coef, s_gap : ndarray, shape (p, 4)
        Per pair and term: s_i sin(nu phi_i), 2 sin^2(nu phi_i / 2), the apex model's
        coefficient and 2 |sin(nu phi_i / 2)|.
    gauss_x, gauss_w : ndarray, shape (g,)
        Gauss-Legendre abscissae and weights on [-1, 1].

    Returns
    -------
    gains, z, path_length : ndarray, shape (n, g)
        Each point's gain (1/m, signed; their sum is the element's integral), its position
        along the edge (m) and its m + l (m). See
        :func:`~acoustisim.propagation.btm.element_gains` with ``per_point=True``.
    """
    n = pair.size
    n_g = gauss_x.size
    gains = np.empty((n, n_g))
    zs_out = np.empty((n, n_g))
    paths = np.empty((n, n_g))
    exact_part = np.empty(n_g)
    for e in range(n):
        p = pair[e]
        nu_, rs, zs, rr, zr = nu[p], r_s[p], z_s[p], r_r[p], z_r[p]
        nk_, mls, zst = nk[p], ml_star[p], z_star[p]
        z0, z1 = z_start[e], z_end[e]
        half_len = 0.5 * (z1 - z0)
        centre = 0.5 * (z0 + z1)
        apex_sum = 0.0
        for g in range(n_g):
            z = centre + gauss_x[g] * half_len
            a = z - zs
            b = z - zr
            m = math.hypot(rs, a)
            l_ = math.hypot(rr, b)
            ml = m * l_
            rsr = rs * rr
            t = rs * b + rr * a
            c1 = max(t * t / ((ml + rsr - a * b) * rsr), 0.0)
            eta = math.log1p(c1 + math.sqrt(c1 * (c1 + 2.0)))
            sh = math.sinh(0.5 * nu_ * eta)
            hyperbolic = 2.0 * (sh * sh)
            mk = nk_ * (z - zst)
            model = 0.5 * (mk * mk)
            exact = 0.0
            apex = 0.0
            for i in range(4):
                den = hyperbolic + gap[p, i]
                exact += num[p, i] / den if den > 0.0 else 0.0
            for i in range(4):
                den = model + gap[p, i]
                apex += num[p, i] / den if den > 0.0 else 0.0
            exact_part[g] = gauss_w[g] * exact / ml
            apex_sum += gauss_w[g] * apex / mls
            # the point and its m + l: the same z, legs and hypot as the gain's (x h = h x exactly)
            zs_out[e, g] = z
            paths[e, g] = m + l_
        a0 = nk_ * (z0 - zst)
        a1 = nk_ * (z1 - zst)
        da = nk_ * (z1 - z0)
        prod = a0 * a1
        model_integral = 0.0
        for i in range(4):
            s = s_gap[p, i]
            model_integral += coef[p, i] * math.atan2(da * s, s * s + prod)
        scale = -(nu_ / (4.0 * np.pi))
        correction = (model_integral - apex_sum * half_len) / n_g
        for g in range(n_g):
            gains[e, g] = scale * (exact_part[g] * half_len + correction)
    return gains, zs_out, paths


@njit(cache=True, nogil=True, error_model="numpy")
def visibility_segments(
    pair: NDArray[np.int64], z_start: NDArray[np.float64], z_end: NDArray[np.float64],
    pair_edge: NDArray[np.int64], pair_rx: NDArray[np.int64], start: NDArray[np.float64],
    direction: NDArray[np.float64], offset: NDArray[np.float64], tx: NDArray[np.float64],
    rx: NDArray[np.float64], own_leg_rx: NDArray[np.bool_],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """The occlusion segments of every element: its centre's probe to the transmitter, and to
    its receiver where that is not the transmitter.

    Parameters
    ----------
    pair : ndarray of int64, shape (n,)
    z_start, z_end : ndarray, shape (n,)
        Element ends along the edge (m).
    pair_edge, pair_rx : ndarray of int64, shape (p,)
    start, direction : ndarray, shape (edges, 3)
        Each edge's start (m) and unit direction.
    offset : ndarray, shape (edges, 3)
        Each edge's probe offset (m): the probe is the element's centre plus it.
    tx : ndarray, shape (3,)
    rx : ndarray, shape (n_rx, 3)
    own_leg_rx : ndarray of bool, shape (n_rx,)
        Whether a receiver has its own leg (is not at the transmitter).

    Returns
    -------
    origins, targets : ndarray, shape (n + k, 3)
        The n probe -> transmitter segments, then the k probe -> receiver ones.
    own_leg : ndarray of int64, shape (k,)
        The elements of the k receiver legs, increasing.
    """
    n = pair.size
    k = 0
    for i in range(n):
        if own_leg_rx[pair_rx[pair[i]]]:
            k += 1
    origins = np.empty((n + k, 3))
    targets = np.empty((n + k, 3))
    own_leg = np.empty(k, dtype=np.int64)
    j = n
    for i in range(n):
        p = pair[i]
        e = pair_edge[p]
        z = 0.5 * (z_start[i] + z_end[i])
        for c in range(3):
            origins[i, c] = start[e, c] + z * direction[e, c] + offset[e, c]
            targets[i, c] = tx[c]
        ch = pair_rx[p]
        if own_leg_rx[ch]:
            for c in range(3):
                origins[j, c] = origins[i, c]
                targets[j, c] = rx[ch, c]
            own_leg[j - n] = i
            j += 1
    return origins, targets, own_leg


@njit(cache=True, nogil=True, error_model="numpy")
def fill_edge_rows(
    rows_path_id: NDArray[np.int64], rows_channel: NDArray[np.int64], rows_kind: NDArray[np.int64],
    rows_order: NDArray[np.int64], rows_path_length: NDArray[np.float64], rows_gain: NDArray[np.float64],
    rows_departure: NDArray[np.float64], rows_arrival: NDArray[np.float64], rows_objects: NDArray[np.int16],
    rows_points: NDArray[np.float64],
    keep: NDArray[np.int64], point_pair: NDArray[np.int64], gains: NDArray[np.float64],
    path_length: NDArray[np.float64], z_point: NDArray[np.float64],
    pair_edge: NDArray[np.int64], pair_rx: NDArray[np.int64], chain: NDArray[np.int64],
    surface: NDArray[np.int64], start: NDArray[np.float64], direction: NDArray[np.float64],
    tx: NDArray[np.float64], rx: NDArray[np.float64], first_path_id: int, kind: int,
) -> None:
    """Fill zeroed ``PATH_DTYPE`` field views with the kept points' rows.

    Parameters
    ----------
    rows_* : ndarray views of a zeroed row array's fields, first axis (k,)
        ``path_id``, ``channel``, ``kind``, ``order``, ``path_length_m``, ``geometric_gain``,
        ``departure_dir`` (k, 3), ``arrival_dir`` (k, 3), ``object_ids`` (k, I) and
        ``points_m`` (k, I, 3), written in place.
    keep : ndarray of int64, shape (k,)
        Indices of the kept points, increasing.
    point_pair, gains, path_length, z_point : ndarray, shape (n,)
        Every point's pair, gain (1/m), m + l (m) and position along its edge (m).
    pair_edge, pair_rx : ndarray of int64, shape (p,)
        Each pair's edge and receiver.
    chain, surface : ndarray of int64, shape (edges,)
        Each edge's chain and surface index.
    start, direction : ndarray, shape (edges, 3)
        Each edge's start (m) and unit direction.
    tx : ndarray, shape (3,)
    rx : ndarray, shape (n_rx, 3)
    first_path_id : int
        Path ids are numbered densely from it in (chain, channel) order.
    kind : int
        ``PathKind.EDGE``.
    """
    k = keep.size
    n_rx = rx.shape[0]
    max_key = 0
    for r in range(k):
        p = point_pair[keep[r]]
        max_key = max(max_key, chain[pair_edge[p]] * n_rx + pair_rx[p])
    rank = np.zeros(max_key + 1, dtype=np.int64)
    for r in range(k):
        p = point_pair[keep[r]]
        rank[chain[pair_edge[p]] * n_rx + pair_rx[p]] = 1
    count = 0
    for key in range(max_key + 1):  # cumsum - 1: the dense rank of each present key
        count += rank[key]
        rank[key] = count - 1
    n_int = rows_objects.shape[1]
    for r in range(k):
        i = keep[r]
        p = point_pair[i]
        e = pair_edge[p]
        ch = pair_rx[p]
        rows_path_id[r] = first_path_id + rank[chain[e] * n_rx + ch]
        rows_channel[r] = ch
        rows_kind[r] = kind
        rows_order[r] = 1
        rows_path_length[r] = path_length[i]
        rows_gain[r] = gains[i]
        z = z_point[i]
        x0 = start[e, 0] + z * direction[e, 0]
        x1 = start[e, 1] + z * direction[e, 1]
        x2 = start[e, 2] + z * direction[e, 2]
        l0, l1, l2 = x0 - tx[0], x1 - tx[1], x2 - tx[2]
        norm = math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        rows_departure[r, 0], rows_departure[r, 1], rows_departure[r, 2] = l0 / norm, l1 / norm, l2 / norm
        m0, m1, m2 = rx[ch, 0] - x0, rx[ch, 1] - x1, rx[ch, 2] - x2
        norm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        rows_arrival[r, 0], rows_arrival[r, 1], rows_arrival[r, 2] = m0 / norm, m1 / norm, m2 / norm
        rows_objects[r, 0] = surface[e]
        rows_points[r, 0, 0], rows_points[r, 0, 1], rows_points[r, 0, 2] = x0, x1, x2
        for j in range(1, n_int):
            rows_objects[r, j] = -1
            rows_points[r, j, 0] = np.nan
            rows_points[r, j, 1] = np.nan
            rows_points[r, j, 2] = np.nan


__all__ = ["fill_edge_rows", "gauss_point_gains", "visibility_segments"]
