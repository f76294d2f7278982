"""Biot-Tolstoy-Medwin edge diffraction: the pure mathematics, no scene and no visibility.

Frame of one wedge (``physics.md`` section 4): the edge is the z axis, the water-side
(exterior) wedge angle is ``theta_w`` and ``nu = pi / theta_w``; cylindrical coordinates
(r, theta, z) with theta measured from one face *through the water* (0 <= theta <= theta_w).

First-order diffraction from a straight edge between z = 0 and z = L is the line integral of
Svensson, Fred & Vanderkooy (1999), relative to the source's pressure at 1 m::

    h(t) = -(nu / 4 pi) Int_0^L delta(t - (m + l) / c) beta(z) / (m l) dz
    m = sqrt(rS^2 + (z - zS)^2),  l = sqrt(rR^2 + (z - zR)^2)
    beta = sum_i s_i sin(nu phi_i) / (cosh(nu eta) - cos(nu phi_i)),
    phi_i in (pi + thS + thR, pi + thS - thR, pi - thS + thR, pi - thS - thR)
    cosh(eta) = (m l + (z - zS)(z - zR)) / (rS rR)

with signs s = (+, +, +, +) for a rigid wedge and (-, +, +, -) for a pressure-release one.

Discretisation (:func:`discretise_edges`): each edge is split at the least-time ("apex")
point into two branches on which the delay is monotonic, and each branch is cut at nodes of
equal *path-length* increments (an exact root of a quadratic: the nodes are where the line
meets the prolate spheroids m + l = const), so that neighbouring elements differ in delay by
one step, whatever their length; long elements are further split to a maximum length. The
first element of each branch is made very short (1/128 of a step), so that the earliest
element's delay is the least time to within a nanosecond. The per-branch loops (nodes, roots,
splitting) are compiled (:func:`acoustisim.propagation.edge_kernels.branch_elements`).

Integration (:func:`element_gains`): two-point Gauss-Legendre per element, after
subtracting, for each of the four terms of beta, its apex approximation, which is integrated
exactly (Svensson & Calamia 2006, "Edge-diffraction impulse responses near specular-zone and
shadow-zone boundaries"). Near the least-time point, with z' = z - z*,
``cosh(nu eta) - cos(nu phi) ~ nu^2 kappa^2 z'^2 / 2 + 2 sin^2(nu phi / 2)``, which is singular
when the receiver lies on a shadow or reflection boundary (``nu phi`` a multiple of 2 pi) and
has a peak of width ``|sin(nu phi / 2)| / (nu kappa)`` nearby. Its integral is an arctangent,
finite on both sides of the boundary and zero exactly on it (half the jump, matching the
geometrical-optics field's half value there); the remainder is smooth and bounded, so the
quadrature never sees the peak and never produces NaN or inf.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.propagation.edge_kernels import branch_elements, branch_setup

ONSET_FRACTION = 1.0 / 128.0
"""Length of the first element of each branch, as a fraction of the path-length step."""

_GAUSS_X = np.array([-1.0, 1.0]) / np.sqrt(3.0)
_GAUSS_W = np.array([1.0, 1.0])


def btm_signs(pressure_release: ArrayLike) -> NDArray[np.float64]:
    """Signs of the four beta terms.

    Parameters
    ----------
    pressure_release : array_like of bool, shape (...)

    Returns
    -------
    ndarray, shape (..., 4)
        (+1, +1, +1, +1) for a rigid wedge, (-1, +1, +1, -1) for a pressure-release wedge, in
        the order (pi + thS + thR, pi + thS - thR, pi - thS + thR, pi - thS - thR).
    """
    soft = np.asarray(pressure_release, dtype=bool)[..., None]
    return np.where(soft, np.array([-1.0, 1.0, 1.0, -1.0]), np.ones(4))


def wedge_phis(theta_s: ArrayLike, theta_r: ArrayLike) -> NDArray[np.float64]:
    """The four angles phi_i (rad), shape (..., 4), in the order of :func:`btm_signs`."""
    ts = np.asarray(theta_s, dtype=float)[..., None]
    tr = np.asarray(theta_r, dtype=float)[..., None]
    return np.pi + np.array([1.0, 1.0, -1.0, -1.0]) * ts + np.array([1.0, -1.0, 1.0, -1.0]) * tr


def cosh_eta_minus_one(
    z: ArrayLike, r_s: ArrayLike, z_s: ArrayLike, r_r: ArrayLike, z_r: ArrayLike
) -> NDArray[np.float64]:
    """``cosh(eta) - 1`` along the edge, without cancellation near the least-time point.

    ``m l + a b - rS rR = (rS b + rR a)^2 / (m l + rS rR - a b)`` with a = z - zS, b = z - zR
    (both sides have the same square difference), exact and >= 0.

    Parameters
    ----------
    z : array_like
        Positions along the edge (m).
    r_s, z_s, r_r, z_r : array_like
        Source and receiver cylindrical coordinates (m), broadcast against ``z``.
    """
    a = np.asarray(z, dtype=float) - z_s
    b = np.asarray(z, dtype=float) - z_r
    r_s, r_r = np.asarray(r_s, dtype=float), np.asarray(r_r, dtype=float)
    return _cosh_eta_minus_one(a, b, r_s, r_r, np.hypot(r_s, a) * np.hypot(r_r, b))


def _cosh_eta_minus_one(
    a: NDArray[np.float64], b: NDArray[np.float64], r_s: NDArray[np.float64], r_r: NDArray[np.float64],
    ml: NDArray[np.float64],
) -> NDArray[np.float64]:
    """:func:`cosh_eta_minus_one` from a = z - zS, b = z - zR and m l (already computed)."""
    rsr = r_s * r_r
    return (r_s * b + r_r * a) ** 2 / ((ml + rsr - a * b) * rsr)


def beta(
    nu: ArrayLike, cosh_eta_m1: ArrayLike, theta_s: ArrayLike, theta_r: ArrayLike, pressure_release: ArrayLike
) -> NDArray[np.float64]:
    """The BTM angular factor beta.

    Parameters
    ----------
    nu : array_like
        Wedge index pi / theta_w.
    cosh_eta_m1 : array_like
        ``cosh(eta) - 1`` (>= 0), see :func:`cosh_eta_minus_one`.
    theta_s, theta_r : array_like
        Source and receiver angles from face 1 through the water (rad).
    pressure_release : array_like of bool

    Returns
    -------
    ndarray
        beta, broadcast shape of the inputs. A term exactly on a shadow or reflection boundary
        at eta = 0 (0 / 0) is given the value 0 (its principal value).
    """
    nu_ = np.asarray(nu, dtype=float)[..., None]
    x = np.maximum(np.asarray(cosh_eta_m1, dtype=float), 0.0)
    eta = np.log1p(x + np.sqrt(x * (x + 2.0)))[..., None]
    phi = wedge_phis(theta_s, theta_r)
    # cosh(nu eta) - cos(nu phi) = 2 sinh^2(nu eta / 2) + 2 sin^2(nu phi / 2), both >= 0.
    den = 2.0 * np.sinh(0.5 * nu_ * eta) ** 2 + 2.0 * np.sin(0.5 * nu_ * phi) ** 2
    num = btm_signs(pressure_release) * np.sin(nu_ * phi)
    safe = den > 0.0
    return np.sum(np.where(safe, num / np.where(safe, den, 1.0), 0.0), axis=-1)


def least_time(
    r_s: ArrayLike, z_s: ArrayLike, r_r: ArrayLike, z_r: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least-time point on the infinite edge line and the least path length.

    Returns
    -------
    z_apex : ndarray
        z* = zS + (zR - zS) rS / (rS + rR) (m).
    length : ndarray
        sqrt((rS + rR)^2 + (zR - zS)^2) (m).
    """
    r_s, z_s, r_r, z_r = (np.asarray(v, dtype=float) for v in (r_s, z_s, r_r, z_r))
    return z_s + (z_r - z_s) * r_s / (r_s + r_r), np.hypot(r_s + r_r, z_r - z_s)


def infinite_wedge_impulse_response(
    t_s: ArrayLike,
    *,
    nu: float,
    r_s: float,
    theta_s: float,
    z_s: float,
    r_r: float,
    theta_r: float,
    z_r: float,
    sound_speed_m_s: float,
    pressure_release: bool = False,
) -> NDArray[np.float64]:
    """Medwin's (1981) closed form for an infinite wedge (1/(m s), relative to 1 m).

    ``h(t) = -(c nu / 2 pi) beta(eta) / (rS rR sinh eta)`` for t > tau0, 0 before, with
    ``cosh eta = (c^2 t^2 - rS^2 - rR^2 - (zR - zS)^2) / (2 rS rR)``.

    Parameters
    ----------
    t_s : array_like
        Times (s).
    nu, r_s, theta_s, z_s, r_r, theta_r, z_r, sound_speed_m_s, pressure_release
        Wedge index, source and receiver cylindrical coordinates (m, rad), sound speed (m/s)
        and the boundary condition.

    Returns
    -------
    ndarray, shape of ``t_s``
        h(t) (1/(m s)); 0 at and before the onset tau0.
    """
    t = np.asarray(t_s, dtype=float)
    c = float(sound_speed_m_s)
    d2 = (c * t) ** 2
    x = (d2 - (r_s + r_r) ** 2 - (z_r - z_s) ** 2) / (2.0 * r_s * r_r)  # cosh(eta) - 1
    after = x > 0.0
    xs = np.where(after, x, 1.0)
    sinh_eta = np.sqrt(xs * (xs + 2.0))
    b = beta(nu, xs, theta_s, theta_r, pressure_release)
    return np.where(after, -(c * nu / (2.0 * np.pi)) * b / (r_s * r_r * sinh_eta), 0.0)


@dataclass(frozen=True)
class EdgeElements:
    """Elements of discretised edges, one row each, for many (edge, receiver) pairs.

    Attributes
    ----------
    pair : ndarray of int64, shape (n,)
        Index of the (edge, source, receiver) pair each element belongs to.
    z_start_m, z_end_m : ndarray, shape (n,)
        Ends of the element along its edge (m), z_start < z_end.
    path_length_m : ndarray, shape (n,)
        m + l of the element: the mean of its ends' path lengths (m).
    """

    pair: NDArray[np.int64]
    z_start_m: NDArray[np.float64]
    z_end_m: NDArray[np.float64]
    path_length_m: NDArray[np.float64]

    @property
    def z_mid_m(self) -> NDArray[np.float64]:
        """Element centres along the edge (m), shape (n,)."""
        return 0.5 * (self.z_start_m + self.z_end_m)


def _graded_intervals(
    span_steps: NDArray[np.float64], has: NDArray[np.bool_], levels: int, grading: int,
    start_steps: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
    """Interior node offsets of each branch, in units of the fine step, graded by level.

    A node m (an integer number of fine steps from the branch's start, 0 <= m < span) belongs
    to level j = min(levels, the largest j with grading 2^j <= min(m0 + m, span - m)); it is a
    node when m is a multiple of 2^j. The elements are therefore 1 step long within ``grading``
    steps of either end of the branch and double in length every ``grading`` elements away from
    both ends, up to 2^levels steps; every node lies on the uniform grid of the fine step.
    m0 (``start_steps``, default 0) counts the steps from a virtual apex before the branch's
    start (a branch starting at a joint of a chain, whose apex lies beyond it).

    Returns
    -------
    first : ndarray, shape (nb, q)
        Per branch and interval (levels 0..J from the start, then J - 1..0 towards the end,
        q = 2 J + 1): its first node, in units of the interval's spacing.
    count : ndarray of int64, shape (nb, q)
        Its number of nodes.
    spacing : ndarray, shape (q,)
        The intervals' node spacings (fine steps): node k of interval i of branch b is at
        ``(first[b, i] + k) spacing[i]``.
    """
    nb = span_steps.size
    span = np.where(has, span_steps, 0.0)
    j = np.arange(levels + 1)
    f = grading * (2.0 ** j)  # F_j: level j needs at least F_j steps to both ends
    f[0] = 0.0
    m0 = np.zeros(nb) if start_steps is None else np.where(has, start_steps, 0.0)
    fs = np.maximum(f[None, :] - m0[:, None], 0.0)  # from the start, (nb, J + 1)
    fs[:, 0] = 0.0
    fe = np.broadcast_to(f, (nb, levels + 1))
    fs_next = np.concatenate([fs[:, 1:], np.full((nb, 1), np.inf)], axis=1)  # none above the top
    fe_next = np.concatenate([fe[:, 1:], np.full((nb, 1), np.inf)], axis=1)
    d = 2.0 ** j
    s = span[:, None]
    # level j's nodes: multiples of 2^j in A_j = [Fs_j, min(Fs_{j+1}, span - Fe_j)) and in
    # B_j = [max(span - Fe_{j+1}, Fs_{j+1}), span - Fe_j); A_0 < A_1 < ... < B_1 < B_0
    a_lo = fs
    a_hi = np.minimum(fs_next, s - fe)
    b_lo = np.maximum(s - fe_next, fs_next)
    b_hi = s - fe
    lo = np.concatenate([a_lo, b_lo[:, ::-1][:, 1:]], axis=1)
    hi = np.concatenate([a_hi, b_hi[:, ::-1][:, 1:]], axis=1)
    dd = np.concatenate([d, d[::-1][1:]])
    first = np.ceil(lo / dd)
    count = np.maximum(np.ceil(hi / dd) - first, 0.0).astype(np.int64)
    count[~has] = 0
    return first, count, dd


def discretise_edges(
    length_m: ArrayLike,
    r_s: ArrayLike,
    z_s: ArrayLike,
    r_r: ArrayLike,
    z_r: ArrayLike,
    path_step_m: float,
    max_element_m: float,
    max_elements: int | None = None,
    *,
    coarsening_levels: int = 0,
    grading: int = 4,
    cap_growth: float = 0.0,
    onset_nodes: int = 1,
    path_lengths: bool = True,
    open_start: ArrayLike | None = None,
    open_end: ArrayLike | None = None,
) -> EdgeElements:
    """Cut edges into elements of graded path-length increments about the least-time point.

    Parameters
    ----------
    length_m : array_like, shape (p,)
        Edge lengths L (m); the edge spans 0 <= z <= L.
    r_s, z_s, r_r, z_r : array_like, shape (p,)
        Source and receiver cylindrical coordinates for each pair (m), r > 0.
    path_step_m : float
        Finest path-length (m + l) increment between neighbouring element boundaries (m): the
        delay step times c.
    max_element_m : float
        Longest element along the edge (m); longer ones are split evenly.
    max_elements : int, optional
        Refuse (``ValueError``) to make more elements than this.
    coarsening_levels : int, optional
        0 (default): every element spans one ``path_step_m``. J > 0: elements are one step
        long within ``grading`` steps of a branch's ends (the onset singularity and the end
        step) and double every ``grading`` elements away from them, up to ``2^J`` steps, all
        their boundaries on the uniform grid (see :func:`_graded_intervals`).
    grading : int, optional
        Elements per level of the graded discretisation (>= 1).
    onset_nodes : int, optional
        Nodes between a branch's start and its first step: at ``ONSET_FRACTION`` steps and
        (when > 1) at that times 2, 4, ... below one step, so that the elements resolve the
        onset's 1 / sqrt(t - tau0) singularity geometrically.
    open_start, open_end : array_like of bool, shape (p,), optional
        With ``coarsening_levels``: the edge continues past z = 0 (z = L) into a neighbouring
        edge of its chain, so that the summed response has no step there. A branch starting
        at such a joint (its apex beyond it) grades from the apex of its edge's line, not from
        the joint, and gets no onset nodes beyond the first.
    path_lengths : bool, optional
        False: leave ``path_length_m`` NaN (for callers placing impulses at their own points,
        as :func:`gauss_points`), saving its evaluation.
    cap_growth : float, optional
        The length cap of an element is ``max_element_m + cap_growth * d``, d its distance
        from the apex along the edge (m); 0 (default): ``max_element_m`` everywhere.

    Returns
    -------
    EdgeElements
        Elements ordered by pair, then branch (z decreasing from the apex, then increasing).

    Raises
    ------
    ValueError
        Non-positive steps, or more than ``max_elements`` elements.
    """
    if not (path_step_m > 0.0 and max_element_m > 0.0):
        raise ValueError(f"path_step_m and max_element_m must be > 0, got {path_step_m!r}, {max_element_m!r}")
    if coarsening_levels < 0 or grading < 1:
        raise ValueError(f"coarsening_levels must be >= 0 and grading >= 1, got {coarsening_levels!r}, {grading!r}")
    length, rs, zs, rr, zr = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (length_m, r_s, z_s, r_r, z_r))
    p = length.size
    # per branch (branch 2 k runs from pair k's apex, its least-time point clipped to the edge,
    # down to z = 0, branch 2 k + 1 up to z = L): its ends and their path lengths, span,
    # whether it has a length and starts at a joint of its chain, and the element count's
    # lower bound, in one compiled loop (:func:`~acoustisim.propagation.edge_kernels.branch_setup`).
    # A branch starting at a joint: branch 0 starts at z = L when the apex lies beyond L,
    # branch 1 at z = 0 when the apex lies before 0. (Not refining towards a joint at a
    # branch's end as well would save another 5 % of the thesis tank's rows, but it costs 7 dB
    # of band-limited accuracy on its polygonal pipe rim, where neighbouring segments'
    # integrands differ at the joint.)
    joints = coarsening_levels > 0 and (open_start is not None or open_end is not None)
    o_start = np.ascontiguousarray(np.broadcast_to(np.asarray(False if open_start is None else open_start, dtype=bool),
                                                   (p,)))
    o_end = np.ascontiguousarray(np.broadcast_to(np.asarray(False if open_end is None else open_end, dtype=bool), (p,)))
    b_start, b_end, d_start, d_end, span, has, span_steps, joint_start, start_steps, estimate = branch_setup(
        length, rs, zs, rr, zr, o_start, o_end, bool(joints), float(path_step_m), int(coarsening_levels),
        float(max_element_m),
    )
    # onset nodes: ONSET_FRACTION step, then (graded) doubling up to half a step
    onsets = ONSET_FRACTION * path_step_m * 2.0 ** np.arange(onset_nodes)
    onsets = onsets[onsets < path_step_m]
    # a lower bound on the element count before allocating: the graded nodes (at least
    # span / (2^J step)), and the length cap
    if max_elements is not None and estimate > max_elements:
        raise ValueError(f"the edges need at least {estimate:.3g} elements (limit {max_elements})")
    # nodes of each branch: its start (offset 0), the onset node, the graded grid nodes below
    # the span, and its end
    # (a branch with a zero span, up to round-off, still gets its start node)
    if not joints:
        start_steps = None
    first, count, spacing = _graded_intervals(span_steps, has, coarsening_levels, grading, start_steps)
    # per branch, the onset nodes below its span, after its start (m = 0)
    # (only the first where the branch starts at a joint: no singularity there)
    wanted = (onsets[None, :] < span[:, None]) & (~joint_start[:, None] | (np.arange(onsets.size) == 0)[None, :])
    # the nodes of each branch (its start, the onset nodes, the graded grid below the span and
    # its end, roots on the spheroids m + l = const kept on their own branch) and the elements
    # between consecutive nodes, split evenly where longer than the cap (growing with the
    # distance from the apex): one compiled loop per branch
    sub_pair, lo, hi, mean_path = branch_elements(
        rs, zs, rr, zr, b_start, b_end, d_start, d_end, span, has, np.ascontiguousarray(first), count, spacing,
        onsets, has[:, None] & wanted, float(path_step_m), float(max_element_m), float(cap_growth), bool(path_lengths),
    )
    return EdgeElements(sub_pair, lo, hi, mean_path)


@dataclass(frozen=True)
class PairConstants:
    """Per-pair constants of the BTM quadrature (:func:`pair_constants`).

    Attributes
    ----------
    nu, r_s, z_s, r_r, z_r : ndarray, shape (p,)
        Wedge index and source and receiver coordinates (m).
    nk : ndarray, shape (p,)
        nu kappa of the apex model, nu eta ~ nu kappa |z - z*| (1/m).
    ml_star : ndarray, shape (p,)
        m l at the least-time point (m^2).
    z_star : ndarray, shape (p,)
        Least-time point on the edge line (m).
    num, gap, coef, s_gap : ndarray, shape (p, 4)
        Per term of beta: s_i sin(nu phi_i), 2 sin^2(nu phi_i / 2), the apex model integral's
        coefficient and 2 |sin(nu phi_i / 2)|.
    """

    nu: NDArray[np.float64]
    r_s: NDArray[np.float64]
    z_s: NDArray[np.float64]
    r_r: NDArray[np.float64]
    z_r: NDArray[np.float64]
    nk: NDArray[np.float64]
    ml_star: NDArray[np.float64]
    z_star: NDArray[np.float64]
    num: NDArray[np.float64]
    gap: NDArray[np.float64]
    coef: NDArray[np.float64]
    s_gap: NDArray[np.float64]


def pair_constants(
    nu: ArrayLike, r_s: ArrayLike, theta_s: ArrayLike, z_s: ArrayLike, r_r: ArrayLike, theta_r: ArrayLike,
    z_r: ArrayLike, pressure_release: ArrayLike,
) -> PairConstants:
    """Per (edge, receiver) pair, what :func:`element_gains` needs besides the elements.

    Parameters
    ----------
    nu, r_s, theta_s, z_s, r_r, theta_r, z_r, pressure_release : array_like, shape (p,)
        Per pair: wedge index, source and receiver cylindrical coordinates (m, rad), boundary
        condition.

    Returns
    -------
    PairConstants
    """
    nu_p, rs_p, ts_p, zs_p, rr_p, tr_p, zr_p = (
        np.atleast_1d(np.asarray(v, dtype=float)) for v in (nu, r_s, theta_s, z_s, r_r, theta_r, z_r)
    )
    soft_p = np.atleast_1d(np.asarray(pressure_release, dtype=bool))
    half_p = 0.5 * nu_p[:, None] * wedge_phis(ts_p, tr_p)  # nu phi_i / 2, (p, 4)
    sin_half_p = np.sin(half_p)
    signs_p = btm_signs(soft_p)
    num_p = signs_p * np.sin(2.0 * half_p)  # s_i sin(nu phi_i)
    gap_p = 2.0 * sin_half_p**2  # 1 - cos(nu phi_i) >= 0
    z_star_p, _ = least_time(rs_p, zs_p, rr_p, zr_p)
    q2_p = ((zr_p - zs_p) / (rs_p + rr_p)) ** 2
    nk_p = nu_p * (rs_p + rr_p) / (rs_p * rr_p * np.sqrt(1.0 + q2_p))  # nu eta ~ nu kappa |z - z*|
    ml_star_p = rs_p * rr_p * (1.0 + q2_p)  # m l at the apex
    # Int model dz' = sum_i s_i (2 / (nu kappa)) sgn(sin(nu phi/2)) cos(nu phi/2) atan(nu kappa z' / s);
    # exactly on a boundary (sin(nu phi / 2) = 0 up to round-off) the term is 0: half the jump
    sgn_p = np.where(np.abs(sin_half_p) > 1e-12, np.sign(sin_half_p), 0.0)
    coef_p = signs_p * sgn_p * np.cos(half_p) * 2.0 / (nk_p[:, None] * ml_star_p[:, None])
    s_gap_p = 2.0 * np.abs(sin_half_p)
    return PairConstants(nu_p, rs_p, zs_p, rr_p, zr_p, nk_p, ml_star_p, z_star_p, num_p, gap_p, coef_p, s_gap_p)


def gauss_rule(points: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gauss-Legendre abscissae and weights on [-1, 1] (the module's two-point rule for 2)."""
    if points == 2:
        return _GAUSS_X, _GAUSS_W
    return np.polynomial.legendre.leggauss(points)


def gauss_points(elements: EdgeElements, points: int = 2) -> NDArray[np.float64]:
    """The Gauss-Legendre points of each element along its edge (m), shape (n, points)."""
    x, _ = gauss_rule(points)
    centre = 0.5 * (elements.z_start_m + elements.z_end_m)
    half = 0.5 * (elements.z_end_m - elements.z_start_m)
    return centre[:, None] + half[:, None] * x[None, :]


def element_gains(
    elements: EdgeElements,
    nu: ArrayLike,
    r_s: ArrayLike,
    theta_s: ArrayLike,
    z_s: ArrayLike,
    r_r: ArrayLike,
    theta_r: ArrayLike,
    z_r: ArrayLike,
    pressure_release: ArrayLike,
    *,
    per_point: bool = False,
    points: int = 2,
) -> NDArray[np.float64]:
    """Integral of the BTM integrand over each element (1/m, relative to 1 m).

    ``-(nu / 4 pi) Int_element beta / (m l) dz``: the weight of the element's impulse, so that
    the sum over the elements of an edge is the time integral of h(t).

    Parameters
    ----------
    elements : EdgeElements
    nu, r_s, theta_s, z_s, r_r, theta_r, z_r, pressure_release : array_like, shape (p,)
        Per pair: wedge index, source and receiver cylindrical coordinates (m, rad), boundary
        condition.

    per_point : bool, optional
        False (default): one gain per element. True: the element's gain split between its
        Gauss points (:func:`gauss_points`), so that an element becomes two impulses at those
        points' delays: a quadrature of the band-limited response exact to third order in the
        phase across the element, where one impulse per element is exact to first order.
    points : int, optional
        Gauss-Legendre points per element (2 by default; n points integrate polynomials of
        degree 2n - 1 exactly).

    Returns
    -------
    ndarray, shape (n,) or (n, points)
        Signed gains; with ``per_point``, the points' gains (their sum is the element's).
    """
    # per pair: the angular factors of the four terms and the apex model's constants
    k = pair_constants(nu, r_s, theta_s, z_s, r_r, theta_r, z_r, pressure_release)
    nu_p, rs_p, zs_p, rr_p, zr_p, nk_p, ml_star_p, z_star_p = (
        k.nu, k.r_s, k.z_s, k.r_r, k.z_r, k.nk, k.ml_star, k.z_star
    )
    num_p, gap_p, coef_p, s_gap_p = k.num, k.gap, k.coef, k.s_gap

    idx = elements.pair
    nu_, rs, zs, rr, zr = nu_p[idx], rs_p[idx], zs_p[idx], rr_p[idx], zr_p[idx]
    nk, ml_star, z_star = nk_p[idx], ml_star_p[idx], z_star_p[idx]
    # the four terms as contiguous per-element rows (4, n): 1-D passes, no (n, 4) reductions
    num, gap = num_p.T.copy()[:, idx], gap_p.T.copy()[:, idx]
    coef, s_gap = coef_p.T.copy()[:, idx], s_gap_p.T.copy()[:, idx]

    def terms(den: NDArray[np.float64], i: int) -> NDArray[np.float64]:
        return np.divide(num[i], den, out=np.zeros_like(den), where=den > 0.0)

    z0, z1 = elements.z_start_m, elements.z_end_m
    half_len = 0.5 * (z1 - z0)
    centre = 0.5 * (z0 + z1)
    gauss_x, gauss_w = gauss_rule(points)
    exact_part = np.zeros((gauss_x.size, z0.size))  # w_g beta / (m l) at the Gauss points
    apex_part = np.zeros((gauss_x.size, z0.size))  # w_g (apex model) at the Gauss points
    for g, (x, w) in enumerate(zip(gauss_x, gauss_w)):  # the Gauss points
        z = centre + x * half_len
        a, b = z - zs, z - zr
        ml = np.hypot(rs, a) * np.hypot(rr, b)
        c1 = np.maximum(_cosh_eta_minus_one(a, b, rs, rr, ml), 0.0)
        eta = np.log1p(c1 + np.sqrt(c1 * (c1 + 2.0)))
        # cosh(nu eta) - cos(nu phi) = 2 sinh^2(nu eta / 2) + 2 sin^2(nu phi / 2)
        hyperbolic = 2.0 * np.sinh(0.5 * nu_ * eta) ** 2
        model = 0.5 * (nk * (z - z_star)) ** 2
        exact = np.zeros(z0.size)
        apex = np.zeros(z0.size)
        for i in range(4):  # the four terms of beta (row by row: faster than one (4, n) pass)
            exact += terms(hyperbolic + gap[i], i)
            apex += terms(model + gap[i], i)
        exact_part[g] = w * exact / ml
        apex_part[g] = w * apex / ml_star
    # Int of the apex model: sum_i coef_i (atan(A1 / s_i) - atan(A0 / s_i)), A = nu kappa (z - z*),
    # as one atan2((A1 - A0) s, s^2 + A0 A1) per term (exact for s > 0; coef_i = 0 where s_i
    # is 0, on a boundary)
    a0, a1 = nk * (z0 - z_star), nk * (z1 - z_star)
    da, prod = nk * (z1 - z0), a0 * a1
    model_integral = np.zeros(z0.size)
    for i in range(4):  # the four terms of beta
        model_integral += coef[i] * np.arctan2(da * s_gap[i], s_gap[i] ** 2 + prod)
    scale = -(nu_ / (4.0 * np.pi))
    if not per_point:
        total = (np.sum(exact_part, axis=0) - np.sum(apex_part, axis=0)) * half_len + model_integral
        return scale * total
    # each Gauss point: its share of the quadrature of the exact integrand, plus half of the
    # apex model's correction (exact integral minus its own quadrature): the model is peaked
    # only where elements are short, so the split barely moves weight in delay
    correction = (model_integral - np.sum(apex_part, axis=0) * half_len) / gauss_x.size
    return (scale * (exact_part * half_len + correction)).T


__all__ = [
    "EdgeElements",
    "beta",
    "btm_signs",
    "cosh_eta_minus_one",
    "discretise_edges",
    "element_gains",
    "gauss_points",
    "gauss_rule",
    "infinite_wedge_impulse_response",
    "least_time",
    "pair_constants",
    "PairConstants",
    "wedge_phis",
]
