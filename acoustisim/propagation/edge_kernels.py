"""Compiled per-element loops of edge diffraction (numba, cached on disk, GIL released).

:func:`acoustisim.propagation.edges.edge_paths` turns some 8 000 visible edge elements of a
pose into 16 000 rows; in numpy, the graded discretisation, the quadrature of
:func:`~acoustisim.propagation.btm.element_gains` at the Gauss points, the points and their
path lengths, the amplitude floor and the filling of the ``PATH_DTYPE`` rows were dozens of
passes over temporary arrays. Here each branch, element or row is one loop iteration:

1. :func:`branch_elements` (called by :func:`~acoustisim.propagation.btm.discretise_edges`):
   the graded nodes of each branch (roots on the spheroids m + l = const) and the elements
   between them, split to the length cap;
2. :func:`visibility_rays32`: the occlusion queries of every element's centre, written as
   Embree's float32 buffers (one batch,
   :meth:`~acoustisim.propagation.raycast.RayCaster.occluded_segments32`, between the kernels);
   ``edge_paths`` first decides most legs exactly without Embree
   (:mod:`~acoustisim.propagation.edge_visibility`) and asks Embree about the others only;
3. :func:`gauss_point_gains`: per element, the Gauss points along the edge, their path lengths
   m + l, and their gains (the element's BTM integral split between them): two compiled loops
   around numpy's vectorised ``log1p``, ``sinh`` and ``arctan2``;
4. :func:`fill_edge_rows`: the rows above the amplitude floor, with dense path ids per
   (chain, channel), the points and the unit leg directions, and the padding conventions of
   :func:`~acoustisim.propagation.paths.empty_paths_array`.

The per-branch and per-pair constants (the graded grid's intervals, the angular factors of the
four beta terms, the apex model's constants) stay in numpy (a few hundred pairs). The
arithmetic is the former numpy code's term for term and in the same order (the four terms
summed 0 + t0 + t1 + t2 + t3, squares as products), so the elements, points and path lengths
are bit-identical to the numpy reference, and the gains agree with it to the round-off of the
elementary functions (``hypot`` is libm's in both; ``log1p``, ``sinh`` and ``arctan2`` are
numpy's own loops in both, which may use SIMD code within 4 ulp of libm's, so the last bits of
the gains depend on the CPU numpy dispatches to): ``tests/parity/test_edges_kernels.py`` keeps the
numpy code and holds every row to 1e-12 relative. No ``fastmath`` (it would reassociate sums).
``cache=True`` stores the compiled code beside this file: the first call in a fresh checkout
compiles for a few seconds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True, error_model="numpy")
def _path(z: float, rs: float, zs: float, rr: float, zr: float) -> float:
    return math.hypot(rs, z - zs) + math.hypot(rr, z - zr)


@njit(cache=True, nogil=True, error_model="numpy")
def _on_spheroid(d: float, r_s: float, z_s: float, r_r: float, z_r: float, upper: bool) -> float:
    """:func:`~acoustisim.propagation.btm._solve_on_spheroid` of one node."""
    mid = 0.5 * (z_s + z_r)
    zs, zr = z_s - mid, z_r - mid
    a1 = -2.0 * (zr - zs)
    a0 = d * d + r_r * r_r - r_s * r_s + zr * zr - zs * zs
    qa = 4.0 * d * d - a1 * a1
    qb = -(8.0 * d * d * zr + 2.0 * a0 * a1)
    qc = 4.0 * d * d * (r_r * r_r + zr * zr) - a0 * a0
    disc = math.sqrt(max(qb * qb - 4.0 * qa * qc, 0.0))
    root = ((-qb + disc) if upper else (-qb - disc)) / (2.0 * qa)
    return root + mid


@njit(cache=True, nogil=True, error_model="numpy")
def branch_setup(
    length: NDArray[np.float64], r_s: NDArray[np.float64], z_s: NDArray[np.float64], r_r: NDArray[np.float64],
    z_r: NDArray[np.float64], open_start: NDArray[np.bool_], open_end: NDArray[np.bool_], joints: bool,
    path_step_m: float, coarsening_levels: int, max_element_m: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.bool_], NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64], float]:
    """The per-branch quantities of :func:`~acoustisim.propagation.btm.discretise_edges`, in
    one loop (its former numpy expressions, operation for operation: the same values).

    Branch 2 k runs from pair k's apex (its least-time point clipped to the edge) down to
    z = 0, branch 2 k + 1 up to z = L.

    Parameters
    ----------
    length, r_s, z_s, r_r, z_r : ndarray, shape (p,)
        Edge lengths and source and receiver coordinates per pair (m).
    open_start, open_end : ndarray of bool, shape (p,)
        The edges continuing past z = 0 (z = L) into their chain; used when ``joints``.
    joints : bool
        Whether a branch may start at a joint (graded discretisation with joints given).
    path_step_m, coarsening_levels, max_element_m
        As :func:`~acoustisim.propagation.btm.discretise_edges`.

    Returns
    -------
    b_start, b_end, d_start, d_end, span : ndarray, shape (2 p,)
        Each branch's start and end along the edge (m), their path lengths (m) and its span
        ``max(d_end - d_start, 0)`` (m).
    has : ndarray of bool, shape (2 p,)
        Whether the branch has a length.
    span_steps : ndarray, shape (2 p,)
        ``max(span / step, 0.5)`` where it has, else 0.
    joint_start : ndarray of bool, shape (2 p,)
        Whether the branch starts at a joint of its chain (its apex beyond it).
    start_steps : ndarray, shape (2 p,)
        Steps from the line's apex to a joint start (0 elsewhere).
    estimate : float
        The lower bound on the element count (graded nodes or the length cap, per branch).
    """
    p = length.size
    nb = 2 * p
    b_start = np.empty(nb)
    b_end = np.empty(nb)
    d_start = np.empty(nb)
    d_end = np.empty(nb)
    span = np.empty(nb)
    has = np.empty(nb, dtype=np.bool_)
    span_steps = np.empty(nb)
    joint_start = np.zeros(nb, dtype=np.bool_)
    start_steps = np.zeros(nb)
    coarse_step = path_step_m * 2.0 ** coarsening_levels
    estimate = 0.0
    for k in range(p):
        rs, zs, rr, zr = r_s[k], z_s[k], r_r[k], z_r[k]
        z_star = zs + (zr - zs) * rs / (rs + rr)  # least_time
        z_apex = min(max(z_star, 0.0), length[k])  # np.clip
        d_line = math.hypot(rs + rr, zr - zs)
        for upper in range(2):
            b = 2 * k + upper
            start = z_apex
            end = length[k] if upper == 1 else 0.0
            ds = math.hypot(rs, start - zs) + math.hypot(rr, start - zr)
            de = math.hypot(rs, end - zs) + math.hypot(rr, end - zr)
            b_start[b], b_end[b], d_start[b], d_end[b] = start, end, ds, de
            sp = max(de - ds, 0.0)
            span[b] = sp
            has_b = abs(end - start) > 0.0
            has[b] = has_b
            span_steps[b] = max(sp / path_step_m, 0.5) if has_b else 0.0
            # (float ceilings: an absurd element length must give a huge count, not overflow)
            n_graded = np.ceil(sp / coarse_step) if has_b else 0.0
            estimate += max(n_graded, np.ceil(abs(end - start) / max_element_m))
            if joints:
                if upper == 1:
                    joint = (z_star < 0.0) & open_start[k]
                else:
                    joint = (z_star > length[k]) & open_end[k]
                joint_start[b] = joint
                if joint:
                    start_steps[b] = (ds - d_line) / path_step_m
    return b_start, b_end, d_start, d_end, span, has, span_steps, joint_start, start_steps, estimate


@njit(cache=True, nogil=True, error_model="numpy")
def branch_elements(
    r_s: NDArray[np.float64], z_s: NDArray[np.float64], r_r: NDArray[np.float64], z_r: NDArray[np.float64],
    b_start: NDArray[np.float64], b_end: NDArray[np.float64], d_start: NDArray[np.float64],
    d_end: NDArray[np.float64], span: NDArray[np.float64], has: NDArray[np.bool_],
    grid_first: NDArray[np.float64], grid_count: NDArray[np.int64], grid_step: NDArray[np.float64],
    onsets: NDArray[np.float64], onset_wanted: NDArray[np.bool_], path_step_m: float, max_element_m: float,
    cap_growth: float, path_lengths: bool,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The elements of every branch, from its graded nodes (the loops of
    :func:`~acoustisim.propagation.btm.discretise_edges`).

    Branch b belongs to pair b // 2 and is upper (z increasing from the apex) when b is odd.

    Parameters
    ----------
    r_s, z_s, r_r, z_r : ndarray, shape (p,)
        Source and receiver coordinates per pair (m).
    b_start, b_end, d_start, d_end, span : ndarray, shape (2 p,)
        Per branch: start (the apex) and end along the edge (m), their path lengths m + l and
        the branch's path-length span (m).
    has : ndarray of bool, shape (2 p,)
        Whether the branch has a non-zero length.
    grid_first, grid_count : ndarray, shape (2 p, q)
        Per branch and interval of the graded grid: its first node (in units of the
        interval's spacing) and its node count.
    grid_step : ndarray, shape (q,)
        Each interval's spacing (fine steps).
    onsets : ndarray, shape (o,)
        Onset node offsets (m of path length).
    onset_wanted : ndarray of bool, shape (2 p, o)
        Which onset nodes each branch gets.
    path_step_m, max_element_m, cap_growth : float
        See :func:`~acoustisim.propagation.btm.discretise_edges`.
    path_lengths : bool
        False: NaN path lengths.

    Returns
    -------
    pair : ndarray of int64, shape (n,)
    z_start, z_end, path_length : ndarray, shape (n,)
        As :class:`~acoustisim.propagation.btm.EdgeElements`.
    """
    nb = has.size
    q = grid_step.size
    n_on = onsets.size
    # nodes of every branch: grid offset 0, the onset nodes, the rest of the grid, the end
    n_nodes = np.zeros(nb, dtype=np.int64)
    for b in range(nb):
        if has[b]:
            c = 1
            for i in range(q):
                c += grid_count[b, i]
            for o in range(n_on):
                if onset_wanted[b, o]:
                    c += 1
            n_nodes[b] = c
    total = 0
    for b in range(nb):
        total += n_nodes[b]
    node_z = np.empty(total)
    node_d = np.empty(total)
    node_off = np.empty(total)
    at = 0
    for b in range(nb):
        if not has[b]:
            continue
        pr = b // 2
        upper = b % 2 == 1
        first_at = at
        placed_grid = 0
        for i in range(q):
            for kk in range(grid_count[b, i]):
                node_off[at] = (grid_first[b, i] + kk) * grid_step[i] * path_step_m
                at += 1
                placed_grid += 1
                if placed_grid == 1:
                    for o in range(n_on):
                        if onset_wanted[b, o]:
                            node_off[at] = onsets[o]
                            at += 1
        if placed_grid == 0:  # (no grid node: cannot happen for a branch with a length)
            for o in range(n_on):
                if onset_wanted[b, o]:
                    node_off[at] = onsets[o]
                    at += 1
        node_off[at] = span[b]
        at += 1
        last_at = at - 1
        lo_z = b_start[b] if upper else b_end[b]
        hi_z = b_end[b] if upper else b_start[b]
        for m in range(first_at, at):
            d = d_start[b] + node_off[m]
            z = _on_spheroid(d, r_s[pr], z_s[pr], r_r[pr], z_r[pr], upper)
            if m == first_at:
                z = b_start[b]
            elif m == last_at:
                z = b_end[b]
            node_z[m] = min(max(z, lo_z), hi_z)
            if m == first_at:
                d = d_start[b]
            elif m == last_at:
                d = d_end[b]
            node_d[m] = d
    # elements between consecutive nodes, split to the (growing) length cap: at most the sum
    # of the splits (zero-length pieces are dropped)
    n_sub = np.ones(max(total - 1, 0), dtype=np.int64)
    bound = 0
    at = 0
    for b in range(nb):
        for m in range(at, at + n_nodes[b] - 1):
            za, zb = node_z[m], node_z[m + 1]
            cap = max_element_m
            if cap_growth > 0.0:
                cap = max_element_m + cap_growth * min(abs(za - b_start[b]), abs(zb - b_start[b]))
            n_sub[m] = max(np.int64(math.ceil(abs(zb - za) / cap)), 1)
            bound += n_sub[m]
        at += n_nodes[b]
    pair = np.empty(bound, dtype=np.int64)
    lo = np.empty(bound)
    hi = np.empty(bound)
    mean_path = np.full(bound, np.nan)
    i = 0
    at = 0
    for b in range(nb):
        pr = b // 2
        for m in range(at, at + n_nodes[b] - 1):
            za, zb = node_z[m], node_z[m + 1]
            n_m = n_sub[m]
            for j in range(n_m):
                z0 = za + (zb - za) * (j / n_m)
                z1 = za + (zb - za) * ((j + 1) / n_m)
                if z1 == z0:
                    continue
                pair[i] = pr
                lo[i] = min(z0, z1)
                hi[i] = max(z0, z1)
                if path_lengths:
                    d0 = _path(z0, r_s[pr], z_s[pr], r_r[pr], z_r[pr]) if n_m > 1 and j > 0 else node_d[m]
                    d1 = _path(z1, r_s[pr], z_s[pr], r_r[pr], z_r[pr]) if n_m > 1 and j < n_m - 1 else node_d[m + 1]
                    mean_path[i] = 0.5 * (d0 + d1)
                i += 1
        at += n_nodes[b]
    return pair[:i].copy(), lo[:i].copy(), hi[:i].copy(), mean_path[:i].copy()


@njit(cache=True, nogil=True, error_model="numpy")
def _gauss_point_arguments(
    pair: NDArray[np.int64], z_start: NDArray[np.float64], z_end: NDArray[np.float64],
    nu: NDArray[np.float64], r_s: NDArray[np.float64], z_s: NDArray[np.float64], r_r: NDArray[np.float64],
    z_r: NDArray[np.float64], nk: NDArray[np.float64], ml_star: NDArray[np.float64], z_star: NDArray[np.float64],
    num: NDArray[np.float64], gap: NDArray[np.float64], s_gap: NDArray[np.float64],
    gauss_x: NDArray[np.float64], gauss_w: NDArray[np.float64], whole: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The first half of :func:`gauss_point_gains`: everything up to its elementary functions.

    Returns
    -------
    log_arg : ndarray, shape (n, g)
        ``c1 + sqrt(c1 (c1 + 2))`` at each Gauss point (eta = log1p of it).
    half_nu : ndarray, shape (n, 1)
        0.5 nu of each element's pair (sinh's argument is ``half_nu * eta``).
    ml : ndarray, shape (n, g)
        m l at each point (m^2).
    apex_sum : ndarray, shape (n,)
        The quadrature of the apex model, sum_g w_g model_g / (m l)* (1/m^2).
    atan_y, atan_x : ndarray, shape (n, 4)
        Per element and term, the arguments of the apex model integral's atan2.
    z, path_length : ndarray, shape (n, g), or (n, 0) with ``whole``
        The points and their m + l (m).
    """
    n = pair.size
    n_g = gauss_x.size
    log_arg = np.empty((n, n_g))
    half_nu = np.empty((n, 1))
    ml_out = np.empty((n, n_g))
    apex_out = np.empty(n)
    atan_y = np.empty((n, 4))
    atan_x = np.empty((n, 4))
    zs_out = np.empty((n, 0 if whole else n_g))
    paths = np.empty((n, 0 if whole else n_g))
    for e in range(n):
        p = pair[e]
        nu_, rs, zs, rr, zr = nu[p], r_s[p], z_s[p], r_r[p], z_r[p]
        nk_, mls, zst = nk[p], ml_star[p], z_star[p]
        z0, z1 = z_start[e], z_end[e]
        half_len = 0.5 * (z1 - z0)
        centre = 0.5 * (z0 + z1)
        half_nu[e, 0] = 0.5 * nu_
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
            log_arg[e, g] = c1 + math.sqrt(c1 * (c1 + 2.0))
            ml_out[e, g] = ml
            mk = nk_ * (z - zst)
            model = 0.5 * (mk * mk)
            apex = 0.0
            for i in range(4):
                den = model + gap[p, i]
                apex += num[p, i] / den if den > 0.0 else 0.0
            apex_sum += gauss_w[g] * apex / mls
            if not whole:
                # the point and its m + l: the same z, legs and hypot as the gain's (x h = h x exactly)
                zs_out[e, g] = z
                paths[e, g] = m + l_
        apex_out[e] = apex_sum
        a0 = nk_ * (z0 - zst)
        a1 = nk_ * (z1 - zst)
        da = nk_ * (z1 - z0)
        prod = a0 * a1
        for i in range(4):
            s = s_gap[p, i]
            atan_y[e, i] = da * s
            atan_x[e, i] = s * s + prod
    return log_arg, half_nu, ml_out, apex_out, atan_y, atan_x, zs_out, paths


@njit(cache=True, nogil=True, error_model="numpy")
def _gauss_point_sums(
    pair: NDArray[np.int64], z_start: NDArray[np.float64], z_end: NDArray[np.float64],
    nu: NDArray[np.float64], num: NDArray[np.float64], gap: NDArray[np.float64], coef: NDArray[np.float64],
    sh: NDArray[np.float64], ml: NDArray[np.float64], apex_sum: NDArray[np.float64], atan: NDArray[np.float64],
    gauss_w: NDArray[np.float64], whole: bool,
) -> NDArray[np.float64]:
    """The second half of :func:`gauss_point_gains`: the gains from sinh(nu eta / 2) at the
    points (``sh``, shape (n, g)) and the apex model's atan2 terms (``atan``, shape (n, 4))."""
    n = pair.size
    n_g = gauss_w.size
    gains = np.empty((n, 1 if whole else n_g))
    exact_part = np.empty(n_g)
    for e in range(n):
        p = pair[e]
        half_len = 0.5 * (z_end[e] - z_start[e])
        for g in range(n_g):
            hyperbolic = 2.0 * (sh[e, g] * sh[e, g])
            exact = 0.0
            for i in range(4):
                den = hyperbolic + gap[p, i]
                exact += num[p, i] / den if den > 0.0 else 0.0
            exact_part[g] = gauss_w[g] * exact / ml[e, g]
        model_integral = 0.0
        for i in range(4):
            model_integral += coef[p, i] * atan[e, i]
        scale = -(nu[p] / (4.0 * np.pi))
        if whole:
            exact_sum = 0.0
            for g in range(n_g):
                exact_sum += exact_part[g]
            gains[e, 0] = scale * ((exact_sum - apex_sum[e]) * half_len + model_integral)
            continue
        correction = (model_integral - apex_sum[e] * half_len) / n_g
        for g in range(n_g):
            gains[e, g] = scale * (exact_part[g] * half_len + correction)
    return gains


def gauss_point_gains(
    pair: NDArray[np.int64], z_start: NDArray[np.float64], z_end: NDArray[np.float64],
    nu: NDArray[np.float64], r_s: NDArray[np.float64], z_s: NDArray[np.float64], r_r: NDArray[np.float64],
    z_r: NDArray[np.float64], nk: NDArray[np.float64], ml_star: NDArray[np.float64], z_star: NDArray[np.float64],
    num: NDArray[np.float64], gap: NDArray[np.float64], coef: NDArray[np.float64], s_gap: NDArray[np.float64],
    gauss_x: NDArray[np.float64], gauss_w: NDArray[np.float64], whole: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Gains, points and path lengths of every element's Gauss points (or each element's gain).

    Two compiled loops around numpy's vectorised elementary functions: the arguments per point
    and element (:func:`_gauss_point_arguments`, with libm's ``hypot`` for the legs, so that
    the points and path lengths are those of the former single loop, byte for byte), then
    ``log1p``, ``sinh`` and ``arctan2`` over whole arrays (numpy's SIMD loops: some 3 to 6 ns
    per value on AVX-512, where libm's scalar calls took 30 to 40 ns and were two thirds of the
    former loop), then the sums (:func:`_gauss_point_sums`). The arithmetic is the former
    loop's in the same order; the gains differ from it only by the elementary functions'
    rounding (numpy's SIMD loops are within 4 ulp, libm within 1: a few 1e-16 relative, see
    ``tests/parity/test_edges_kernels.py``), as the numpy reference the loop replaced did.

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
    whole : bool, optional
        True: one gain per element (:func:`~acoustisim.propagation.btm.element_gains` without
        ``per_point``), shape (n, 1), and no points (``z`` and ``path_length`` of shape (n, 0)).

    Returns
    -------
    gains, z, path_length : ndarray, shape (n, g)
        Each point's gain (1/m, signed; their sum is the element's integral), its position
        along the edge (m) and its m + l (m). See
        :func:`~acoustisim.propagation.btm.element_gains` with ``per_point=True``.
    """
    log_arg, half_nu, ml, apex_sum, atan_y, atan_x, z, path_length = _gauss_point_arguments(
        pair, z_start, z_end, nu, r_s, z_s, r_r, z_r, nk, ml_star, z_star, num, gap, s_gap, gauss_x, gauss_w,
        bool(whole),
    )
    sh = np.log1p(log_arg, out=log_arg)  # eta
    np.multiply(half_nu, sh, out=sh)  # (0.5 nu) eta, as the loop's 0.5 * nu * eta
    np.sinh(sh, out=sh)
    atan = np.arctan2(atan_y, atan_x, out=atan_y)
    gains = _gauss_point_sums(pair, z_start, z_end, nu, num, gap, coef, sh, ml, apex_sum, atan, gauss_w, bool(whole))
    return gains, z, path_length


@njit(cache=True, nogil=True, error_model="numpy")
def visibility_rays32(
    pair: NDArray[np.int64], z_start: NDArray[np.float64], z_end: NDArray[np.float64],
    pair_edge: NDArray[np.int64], pair_rx: NDArray[np.int64], start: NDArray[np.float64],
    direction: NDArray[np.float64], offset: NDArray[np.float64], tx: NDArray[np.float64],
    rx: NDArray[np.float64], own_leg_rx: NDArray[np.bool_], shift: NDArray[np.float64], eps: float,
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32], NDArray[np.int64], NDArray[np.int64]]:
    """The occlusion queries of every element, as Embree's float32 buffers: its centre's probe
    to the transmitter, and to its receiver where that is not the transmitter.

    Segment s of the n + k (the n probe -> transmitter ones, then the k probe -> receiver ones)
    runs from the probe o (the element's centre plus its edge's offset) to the target t; its
    query is what :meth:`~acoustisim.propagation.raycast.RayCaster.occluded` makes of it, with
    the same operations in the same order (so the same float32 buffers and the same answers):
    length L = sqrt((s0^2 + s1^2) + s2^2) of s = t - o, unit direction d = s / L, start
    eps d + o shrunk by ``eps`` and shifted by ``shift`` (rounded once to float32), length
    L - 2 eps; segments with L <= 2 eps are never blocked and get no query.

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
    shift : ndarray, shape (3,)
        :attr:`~acoustisim.propagation.raycast.RayCaster.shift_m`.
    eps : float
        End shrink (m), :data:`~acoustisim.propagation.raycast.DEFAULT_EPS_M`.

    Returns
    -------
    starts32, directions32 : ndarray of float32, shape (q, 3)
    lengths32 : ndarray of float32, shape (q,)
        The queries (for :meth:`~acoustisim.propagation.raycast.RayCaster.occluded_segments32`).
    segment : ndarray of int64, shape (q,)
        The segment (0 .. n + k - 1) of each query, increasing.
    own_leg : ndarray of int64, shape (k,)
        The elements of the k receiver legs, increasing.
    """
    n = pair.size
    k = 0
    for i in range(n):
        if own_leg_rx[pair_rx[pair[i]]]:
            k += 1
    own_leg = np.empty(k, dtype=np.int64)
    probes = np.empty((n, 3))
    j = 0
    for i in range(n):
        p = pair[i]
        e = pair_edge[p]
        z = 0.5 * (z_start[i] + z_end[i])
        for c in range(3):
            probes[i, c] = start[e, c] + z * direction[e, c] + offset[e, c]
        if own_leg_rx[pair_rx[p]]:
            own_leg[j] = i
            j += 1
    m = n + k
    starts32 = np.empty((m, 3), dtype=np.float32)
    directions32 = np.empty((m, 3), dtype=np.float32)
    lengths32 = np.empty(m, dtype=np.float32)
    segment = np.empty(m, dtype=np.int64)
    two_eps = 2.0 * eps
    q = 0
    for s in range(m):
        i = s if s < n else own_leg[s - n]
        if s < n:
            t0, t1, t2 = tx[0], tx[1], tx[2]
        else:
            ch = pair_rx[pair[i]]
            t0, t1, t2 = rx[ch, 0], rx[ch, 1], rx[ch, 2]
        o0, o1, o2 = probes[i, 0], probes[i, 1], probes[i, 2]
        s0, s1, s2 = t0 - o0, t1 - o1, t2 - o2
        length = math.sqrt((s0 * s0 + s1 * s1) + s2 * s2)
        if not length > two_eps:
            continue
        d0, d1, d2 = s0 / length, s1 / length, s2 / length
        starts32[q, 0] = np.float32((eps * d0 + o0) - shift[0])
        starts32[q, 1] = np.float32((eps * d1 + o1) - shift[1])
        starts32[q, 2] = np.float32((eps * d2 + o2) - shift[2])
        directions32[q, 0] = np.float32(d0)
        directions32[q, 1] = np.float32(d1)
        directions32[q, 2] = np.float32(d2)
        lengths32[q] = np.float32(length - two_eps)
        segment[q] = s
        q += 1
    return starts32[:q], directions32[:q], lengths32[:q], segment[:q], own_leg


@njit(cache=True, nogil=True, error_model="numpy")
def fill_edge_rows(
    rows_path_id: NDArray[np.int64], rows_channel: NDArray[np.int64], rows_kind: NDArray[np.int64],
    rows_order: NDArray[np.int64], rows_path_length: NDArray[np.float64], rows_gain: NDArray[np.float64],
    rows_departure: NDArray[np.float64], rows_arrival: NDArray[np.float64], rows_objects: NDArray[np.int16],
    rows_points: NDArray[np.float64], rows_zero: tuple[NDArray[np.float64], ...],
    keep: NDArray[np.int64], point_pair: NDArray[np.int64], gains: NDArray[np.float64],
    path_length: NDArray[np.float64], z_point: NDArray[np.float64],
    pair_edge: NDArray[np.int64], pair_rx: NDArray[np.int64], chain: NDArray[np.int64],
    surface: NDArray[np.int64], start: NDArray[np.float64], direction: NDArray[np.float64],
    tx: NDArray[np.float64], rx: NDArray[np.float64], first_path_id: int, kind: int,
) -> None:
    """Fill a ``PATH_DTYPE`` row array (uninitialised) with the kept points' rows: every field
    written, those the mechanism leaves to the solver zero.

    Parameters
    ----------
    rows_* : ndarray views of the row array's fields, first axis (k,)
        ``path_id``, ``channel``, ``kind``, ``order``, ``path_length_m``, ``geometric_gain``,
        ``departure_dir`` (k, 3), ``arrival_dir`` (k, 3), ``object_ids`` (k, I) and
        ``points_m`` (k, I, 3), written in place.
    rows_zero : tuple of ndarray views, each shape (k,)
        The row array's other (float) fields, set to 0.
    keep : ndarray of int64, shape (k,)
        Indices of the kept points, in the order of the rows to write.
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
        for field in rows_zero:
            field[r] = 0.0
        rows_objects[r, 0] = surface[e]
        rows_points[r, 0, 0], rows_points[r, 0, 1], rows_points[r, 0, 2] = x0, x1, x2
        for j in range(1, n_int):
            rows_objects[r, j] = -1
            rows_points[r, j, 0] = np.nan
            rows_points[r, j, 1] = np.nan
            rows_points[r, j, 2] = np.nan


__all__ = ["branch_elements", "branch_setup", "fill_edge_rows", "gauss_point_gains", "visibility_rays32"]
