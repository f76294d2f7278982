"""The Biot-Tolstoy-Medwin wedge: its impulse response and the quadrature of its line integral.

Physics
-------
Frame of one wedge (``physics.md`` section 4): the edge is the z axis, the water-side
(exterior) wedge angle is theta_w and nu = pi / theta_w; a point has cylindrical coordinates
(r, theta, z), theta measured from face 1 *through the water* (0 <= theta <= theta_w).

First-order diffraction by a straight edge from z = 0 to z = L, for a source S = (rS, thS, zS)
and a receiver R = (rR, thR, zR), is the line integral of Svensson, Fred & Vanderkooy (1999,
JASA 106, 2331), relative to the source's pressure at 1 m::

    h(t) = -(nu / 4 pi) Int_0^L delta(t - (m + l) / c) beta(z) / (m l) dz            (1)
    m = sqrt(rS^2 + (z - zS)^2),  l = sqrt(rR^2 + (z - zR)^2)
    beta = sum_i s_i sin(nu phi_i) / (cosh(nu eta) - cos(nu phi_i))
    phi_i in (pi + thS + thR, pi + thS - thR, pi - thS + thR, pi - thS - thR)
    cosh(eta) = (m l + (z - zS)(z - zR)) / (rS rR)

with signs s = (+, +, +, +) for a rigid wedge and (-, +, +, -) for a pressure-release one.
For an infinite edge, (1) integrates in closed form (Medwin 1981, JASA 69, 1060)::

    h(t) = -(c nu / 2 pi) beta(eta) / (rS rR sinh eta),   t > tau0,                  (2)
    cosh(eta) = (c^2 t^2 - rS^2 - rR^2 - (zR - zS)^2) / (2 rS rR),

zero before the onset tau0 = sqrt((rS + rR)^2 + (zR - zS)^2) / c, the delay of the
least-time ("apex") point z* = zS + (zR - zS) rS / (rS + rR). A finite edge cuts each of the
two branches of (1) (z below and above z*) where its end is reached: a step in h(t).

Near the apex, with z' = z - z* and kappa = (rS + rR) / (rS rR sqrt(1 + q^2)),
q = (zR - zS) / (rS + rR)::

    cosh(nu eta) - cos(nu phi) ~ (nu kappa z')^2 / 2 + 2 sin^2(nu phi / 2),          (3)

so a term of beta is singular at z* when the receiver lies on a shadow or reflection boundary
(nu phi a multiple of 2 pi) and sharply peaked near one. Svensson & Calamia (2006, "Edge-
diffraction impulse responses near specular-zone and shadow-zone boundaries", Acta Acustica
92, 501) subtract this apex model from each term and integrate it exactly::

    Int s sin(nu phi) / ((nu kappa z')^2 / 2 + 2 sin^2(nu phi / 2)) dz' / (m l)*
      = s (2 / (nu kappa)) sgn(sin(nu phi / 2)) cos(nu phi / 2) atan(nu kappa z' / (2 |sin(nu phi / 2)|)) / (m l)*,

with (m l)* = rS rR (1 + q^2) the product at the apex: finite on both sides of a boundary and
zero exactly on it (half the jump, as the geometrical field takes half its value there).

Method
------
:func:`pair_constants` evaluates, once per (edge, receiver) pair, the four terms' angular
factors and the apex model's constants. :func:`quadrature_points` and :func:`element_gains`
integrate (1) over elements [z0, z1] of the edge (:mod:`.edge_elements` cuts them): the
remainder beta / (m l) - model by two-point Gauss-Legendre, plus the model's exact integral,
one ``arctan2`` per term. :func:`element_gains` returns the element's integral (one impulse at
its mean delay); :func:`quadrature_points` splits it between the element's two Gauss points,
each taking its share of the remainder's quadrature and half of the model's correction, so that
the element becomes two impulses at the points' delays. ``cosh(eta) - 1`` is evaluated as
``(rS b + rR a)^2 / ((m l + rS rR - a b) rS rR)`` (a = z - zS, b = z - zR; the identity
m l + a b - rS rR = (rS b + rR a)^2 / (m l + rS rR - a b)), free of cancellation at the apex,
and cosh(nu eta) - cos(nu phi) as 2 sinh^2(nu eta / 2) + 2 sin^2(nu phi / 2), both terms >= 0.

Accuracy
--------
Against (2) integrated by adaptive quadrature over 1 us bins, the gains of the engine's
discretisation agree to 1e-4 relative in every bin from the onset on, for rigid and
pressure-release wedges, monostatic, bistatic and near-grazing geometries
(``tests/physics/test_btm.py``), and the jump of the total field across a shadow or reflection
boundary equals the geometrical field to 1e-5. The two impulses per element are a quadrature
of the band-limited response exact to third order in the phase across an element (one impulse
per element: first order, a sinc(f dt) low-pass, -0.06 dB at 500 kHz for dt = 1/(16 f0)).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.propagation.reference.edge_elements import EdgeElements

GAUSS_X = (-1.0 / np.sqrt(3.0), 1.0 / np.sqrt(3.0))
"""Abscissae of the two-point Gauss-Legendre rule on [-1, 1]."""

GAUSS_W = (1.0, 1.0)
"""Its weights."""


def btm_signs(pressure_release: ArrayLike) -> NDArray[np.float64]:
    """Signs s_i of the four terms of beta, shape (..., 4): (+1, +1, +1, +1) for a rigid wedge,
    (-1, +1, +1, -1) for a pressure-release one, in the order of :func:`wedge_phis`."""
    soft = np.asarray(pressure_release, dtype=bool)[..., None]
    return np.where(soft, np.array([-1.0, 1.0, 1.0, -1.0]), np.ones(4))


def wedge_phis(theta_s: ArrayLike, theta_r: ArrayLike) -> NDArray[np.float64]:
    """The four angles phi_i (rad), shape (..., 4): pi + thS + thR, pi + thS - thR,
    pi - thS + thR, pi - thS - thR."""
    ts = np.asarray(theta_s, dtype=float)[..., None]
    tr = np.asarray(theta_r, dtype=float)[..., None]
    return np.pi + np.array([1.0, 1.0, -1.0, -1.0]) * ts + np.array([1.0, -1.0, 1.0, -1.0]) * tr


def cosh_eta_minus_one(a: NDArray[np.float64], b: NDArray[np.float64], r_s: NDArray[np.float64],
                       r_r: NDArray[np.float64], ml: NDArray[np.float64]) -> NDArray[np.float64]:
    """cosh(eta) - 1 >= 0 at points a = z - zS, b = z - zR (m) with ``ml`` = m l (m^2), without
    cancellation near the apex (see the module's Method)."""
    rsr = r_s * r_r
    return (r_s * b + r_r * a) ** 2 / ((ml + rsr - a * b) * rsr)


def beta(nu: ArrayLike, cosh_eta_m1: ArrayLike, theta_s: ArrayLike, theta_r: ArrayLike,
         pressure_release: ArrayLike) -> NDArray[np.float64]:
    """The angular factor beta of (1), broadcast over the inputs.

    Parameters
    ----------
    nu : array_like
        Wedge index pi / theta_w.
    cosh_eta_m1 : array_like
        cosh(eta) - 1 (>= 0).
    theta_s, theta_r : array_like
        Source and receiver angles from face 1 through the water (rad).
    pressure_release : array_like of bool
        The wedge's boundary condition.

    Returns
    -------
    ndarray
        beta; a term exactly on a boundary at eta = 0 (0 / 0) is 0, its principal value.
    """
    nu_ = np.asarray(nu, dtype=float)[..., None]
    x = np.maximum(np.asarray(cosh_eta_m1, dtype=float), 0.0)
    eta = np.log1p(x + np.sqrt(x * (x + 2.0)))[..., None]
    phi = wedge_phis(theta_s, theta_r)
    denominator = 2.0 * np.sinh(0.5 * nu_ * eta) ** 2 + 2.0 * np.sin(0.5 * nu_ * phi) ** 2
    numerator = btm_signs(pressure_release) * np.sin(nu_ * phi)
    defined = denominator > 0.0
    return np.sum(np.where(defined, numerator / np.where(defined, denominator, 1.0), 0.0), axis=-1)


def least_time(r_s: ArrayLike, z_s: ArrayLike, r_r: ArrayLike, z_r: ArrayLike
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The apex z* on the infinite edge line (m) and the least path length
    sqrt((rS + rR)^2 + (zR - zS)^2) (m)."""
    r_s, z_s, r_r, z_r = (np.asarray(v, dtype=float) for v in (r_s, z_s, r_r, z_r))
    return z_s + (z_r - z_s) * r_s / (r_s + r_r), np.hypot(r_s + r_r, z_r - z_s)


def infinite_wedge_impulse_response(t_s: ArrayLike, *, nu: float, r_s: float, theta_s: float, z_s: float,
                                    r_r: float, theta_r: float, z_r: float, sound_speed_m_s: float,
                                    pressure_release: bool = False) -> NDArray[np.float64]:
    """Medwin's closed form (2) for an infinite wedge: h(t) (1/(m s), relative to 1 m), 0 at and
    before the onset tau0.

    Parameters
    ----------
    t_s : array_like
        Times (s).
    nu, r_s, theta_s, z_s, r_r, theta_r, z_r, sound_speed_m_s, pressure_release
        Wedge index, source and receiver cylindrical coordinates (m, rad), sound speed (m/s)
        and the boundary condition.
    """
    t = np.asarray(t_s, dtype=float)
    c = float(sound_speed_m_s)
    x = ((c * t) ** 2 - (r_s + r_r) ** 2 - (z_r - z_s) ** 2) / (2.0 * r_s * r_r)  # cosh(eta) - 1
    after = x > 0.0
    xs = np.where(after, x, 1.0)
    sinh_eta = np.sqrt(xs * (xs + 2.0))
    b = beta(nu, xs, theta_s, theta_r, pressure_release)
    return np.where(after, -(c * nu / (2.0 * np.pi)) * b / (r_s * r_r * sinh_eta), 0.0)


class WedgePairs(NamedTuple):
    """A wedge and a source and receiver in its frame, per (edge, receiver) pair, shape (p,) each.

    ``nu`` the wedge index, ``r_s, theta_s, z_s`` and ``r_r, theta_r, z_r`` the source's and the
    receiver's cylindrical coordinates (m, rad, m), ``pressure_release`` the boundary condition.
    """

    nu: NDArray[np.float64]
    r_s: NDArray[np.float64]
    theta_s: NDArray[np.float64]
    z_s: NDArray[np.float64]
    r_r: NDArray[np.float64]
    theta_r: NDArray[np.float64]
    z_r: NDArray[np.float64]
    pressure_release: NDArray[np.bool_]


class PairConstants(NamedTuple):
    """What the quadrature of (1) needs per (edge, receiver) pair besides the elements.

    Attributes
    ----------
    nu, r_s, z_s, r_r, z_r : ndarray, shape (p,)
        Wedge index and the source's and receiver's coordinates (m).
    nu_kappa : ndarray, shape (p,)
        nu kappa of the apex model (3) (1/m).
    ml_apex : ndarray, shape (p,)
        m l at the apex, (m l)* (m^2).
    z_apex : ndarray, shape (p,)
        The apex z* on the edge line (m).
    numerator : ndarray, shape (p, 4)
        Per term of beta, s_i sin(nu phi_i).
    gap : ndarray, shape (p, 4)
        2 sin^2(nu phi_i / 2): the denominator's part that does not vanish at the apex.
    model_coefficient : ndarray, shape (p, 4)
        s_i sgn(sin(nu phi_i / 2)) cos(nu phi_i / 2) 2 / (nu kappa (m l)*): the apex model's
        integral is this times an arctangent (0 on a boundary).
    model_width : ndarray, shape (p, 4)
        2 |sin(nu phi_i / 2)|: the arctangent's scale, atan(nu kappa z' / model_width).
    """

    nu: NDArray[np.float64]
    r_s: NDArray[np.float64]
    z_s: NDArray[np.float64]
    r_r: NDArray[np.float64]
    z_r: NDArray[np.float64]
    nu_kappa: NDArray[np.float64]
    ml_apex: NDArray[np.float64]
    z_apex: NDArray[np.float64]
    numerator: NDArray[np.float64]
    gap: NDArray[np.float64]
    model_coefficient: NDArray[np.float64]
    model_width: NDArray[np.float64]


def pair_constants(wedges: WedgePairs) -> PairConstants:
    """The per-pair constants of the quadrature (see :class:`PairConstants`)."""
    nu, r_s, z_s, r_r, z_r = (np.atleast_1d(np.asarray(v, dtype=float))
                              for v in (wedges.nu, wedges.r_s, wedges.z_s, wedges.r_r, wedges.z_r))
    half = 0.5 * nu[:, None] * wedge_phis(np.atleast_1d(wedges.theta_s), np.atleast_1d(wedges.theta_r))
    sin_half = np.sin(half)
    signs = btm_signs(np.atleast_1d(wedges.pressure_release))
    numerator = signs * np.sin(2.0 * half)
    gap = 2.0 * sin_half**2
    z_apex, _ = least_time(r_s, z_s, r_r, z_r)
    q2 = ((z_r - z_s) / (r_s + r_r)) ** 2
    nu_kappa = nu * (r_s + r_r) / (r_s * r_r * np.sqrt(1.0 + q2))
    ml_apex = r_s * r_r * (1.0 + q2)
    # exactly on a boundary (sin(nu phi / 2) = 0 up to round-off) the model's integral is 0
    sign = np.where(np.abs(sin_half) > 1e-12, np.sign(sin_half), 0.0)
    model_coefficient = signs * sign * np.cos(half) * 2.0 / (nu_kappa[:, None] * ml_apex[:, None])
    return PairConstants(nu, r_s, z_s, r_r, z_r, nu_kappa, ml_apex, z_apex, numerator, gap, model_coefficient,
                         2.0 * np.abs(sin_half))


class QuadraturePoints(NamedTuple):
    """The impulses of edge elements, shape (n, g) each (g points per element).

    ``gain`` the impulse's weight (1/m, relative to the source's pressure at 1 m; signed),
    ``z_m`` its position along the edge (m), ``path_length_m`` its m + l (m).
    """

    gain: NDArray[np.float64]
    z_m: NDArray[np.float64]
    path_length_m: NDArray[np.float64]


def _quadrature(elements: EdgeElements, constants: PairConstants
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                           NDArray[np.float64]]:
    """The parts of each element's integral (see the module's Method).

    Returns
    -------
    remainder : ndarray, shape (n, 2)
        w_g beta / (m l) at each Gauss point (1/m^2), the weight included.
    model_sum : ndarray, shape (n,)
        sum_g w_g model_g / (m l)* (1/m^2): the quadrature of the apex model.
    model_integral : ndarray, shape (n,)
        The apex model's exact integral over the element (1/m).
    z, path_length : ndarray, shape (n, 2)
        The Gauss points along the edge (m) and their m + l (m).
    """
    k = constants
    p = elements.pair
    nu, r_s, z_s, r_r, z_r = k.nu[p], k.r_s[p], k.z_s[p], k.r_r[p], k.z_r[p]
    nu_kappa, ml_apex, z_apex = k.nu_kappa[p], k.ml_apex[p], k.z_apex[p]
    numerator, gap = k.numerator[p], k.gap[p]  # (n, 4)
    z0, z1 = elements.z_start_m, elements.z_end_m
    half_length = 0.5 * (z1 - z0)
    centre = 0.5 * (z0 + z1)

    def terms(denominator: NDArray[np.float64], i: int) -> NDArray[np.float64]:
        """Term i of beta (or of the model) for its denominator; 0 where that is 0."""
        return np.divide(numerator[:, i], denominator, out=np.zeros_like(denominator), where=denominator > 0.0)

    remainder = np.empty((z0.size, 2))
    model_sum = np.zeros(z0.size)
    z = np.empty((z0.size, 2))
    path_length = np.empty((z0.size, 2))
    for g, (x, w) in enumerate(zip(GAUSS_X, GAUSS_W)):  # the two Gauss points
        zg = centre + x * half_length
        a, b = zg - z_s, zg - z_r
        m, l_ = np.hypot(r_s, a), np.hypot(r_r, b)
        ml = m * l_
        c1 = np.maximum(cosh_eta_minus_one(a, b, r_s, r_r, ml), 0.0)
        eta = np.log1p(c1 + np.sqrt(c1 * (c1 + 2.0)))
        hyperbolic = 2.0 * np.sinh(0.5 * nu * eta) ** 2  # cosh(nu eta) - cos(nu phi) - gap
        model = 0.5 * (nu_kappa * (zg - z_apex)) ** 2  # the apex model's part of it
        exact = np.zeros(z0.size)
        apex = np.zeros(z0.size)
        for i in range(4):  # the four terms of beta
            exact += terms(hyperbolic + gap[:, i], i)
            apex += terms(model + gap[:, i], i)
        remainder[:, g] = w * exact / ml
        model_sum += w * apex / ml_apex
        z[:, g] = zg
        path_length[:, g] = m + l_
    # the model's integral: sum_i coefficient_i (atan(A1 / s_i) - atan(A0 / s_i)), A = nu kappa
    # (z - z*), as one atan2((A1 - A0) s, s^2 + A0 A1) per term (exact for s > 0; the
    # coefficient is 0 where s is, on a boundary)
    a0, a1 = nu_kappa * (z0 - z_apex), nu_kappa * (z1 - z_apex)
    spread, product = nu_kappa * (z1 - z0), a0 * a1
    model_integral = np.zeros(z0.size)
    for i in range(4):
        s = k.model_width[p, i]
        model_integral += k.model_coefficient[p, i] * np.arctan2(spread * s, s * s + product)
    return remainder, model_sum, model_integral, z, path_length


def element_gains(elements: EdgeElements, constants: PairConstants) -> NDArray[np.float64]:
    """Each element's integral of (1): -(nu / 4 pi) Int_element beta / (m l) dz (1/m, signed),
    shape (n,): the weight of one impulse per element."""
    remainder, model_sum, model_integral, _, _ = _quadrature(elements, constants)
    half_length = 0.5 * (elements.z_end_m - elements.z_start_m)
    scale = -(constants.nu[elements.pair] / (4.0 * np.pi))
    return scale * ((remainder[:, 0] + remainder[:, 1] - model_sum) * half_length + model_integral)


def quadrature_points(elements: EdgeElements, constants: PairConstants) -> QuadraturePoints:
    """Each element's integral of (1) split between its two Gauss points: two impulses whose
    gains sum to :func:`element_gains`, at the points' positions and path lengths."""
    remainder, model_sum, model_integral, z, path_length = _quadrature(elements, constants)
    half_length = 0.5 * (elements.z_end_m - elements.z_start_m)
    scale = -(constants.nu[elements.pair] / (4.0 * np.pi))
    # each point: its share of the remainder's quadrature plus half of the model's correction
    # (its exact integral minus its quadrature): the model is peaked only where elements are
    # short, so the split barely moves weight in delay
    correction = 0.5 * (model_integral - model_sum * half_length)
    gain = scale[:, None] * (remainder * half_length[:, None] + correction[:, None])
    return QuadraturePoints(gain, z, path_length)


__all__ = ("GAUSS_W", "GAUSS_X", "PairConstants", "QuadraturePoints", "WedgePairs", "beta", "btm_signs",
           "cosh_eta_minus_one", "element_gains", "infinite_wedge_impulse_response", "least_time", "pair_constants",
           "quadrature_points", "wedge_phis")
