"""The quadrature of :mod:`acoustisim.propagation.reference.btm`, compiled.

:func:`quadrature_points` and :func:`element_gains` return what their reference namesakes do
(and :func:`edge_impulses`, the impulses of the elements, what
:func:`acoustisim.propagation.reference.edges.edge_impulses` does):
the same arithmetic in the same order, in two compiled loops over the elements around numpy's
vectorised ``log1p``, ``sinh`` and ``arctan2`` (the loops compute their arguments, numpy
evaluates them over whole arrays, the second loop sums the terms). The reference calls the
same numpy functions, so the points and path lengths are identical and the gains too, up to
the CPU-dependent SIMD paths numpy may pick for different array lengths (a few ulp).
numba, cached on disk, GIL released; no ``fastmath``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.reference.btm import GAUSS_W, GAUSS_X, PairConstants, QuadraturePoints
from acoustisim.propagation.reference.edge_elements import EdgeElements
from acoustisim.propagation.reference.edges import EdgeImpulses

_RULE_X = np.array(GAUSS_X)
_RULE_X.setflags(write=False)
_RULE_W = np.array(GAUSS_W)
_RULE_W.setflags(write=False)


class TermArguments(NamedTuple):
    """What the first loop hands to numpy's elementary functions, per element.

    ``log_argument`` (n, g): exp(eta) - 1 = c1 + sqrt(c1 (c1 + 2)) at each Gauss point, with
    c1 = cosh(eta) - 1 (eta is its log1p); ``half_nu`` (n, 1):
    nu / 2; ``ml`` (n, g): m l (m^2); ``model_sum`` (n,): the apex model's quadrature (1/m^2);
    ``atan_y``, ``atan_x`` (n, 4): the model integral's arctan2 arguments per term; ``z``,
    ``path_length`` (n, g), or (n, 0) for whole elements: the points (m) and their m + l (m).
    """

    log_argument: NDArray[np.float64]
    half_nu: NDArray[np.float64]
    ml: NDArray[np.float64]
    model_sum: NDArray[np.float64]
    atan_y: NDArray[np.float64]
    atan_x: NDArray[np.float64]
    z: NDArray[np.float64]
    path_length: NDArray[np.float64]


@njit(cache=True, nogil=True, error_model="numpy")
def term_arguments(elements: EdgeElements, k: PairConstants, rule_x: NDArray[np.float64],
                   rule_w: NDArray[np.float64], whole: bool) -> TermArguments:
    """Everything of the quadrature up to its elementary functions (see :class:`TermArguments`)."""
    n = elements.pair.size
    n_points = rule_x.size
    log_argument = np.empty((n, n_points))
    half_nu = np.empty((n, 1))
    ml_out = np.empty((n, n_points))
    model_out = np.empty(n)
    atan_y = np.empty((n, 4))
    atan_x = np.empty((n, 4))
    z_out = np.empty((n, 0 if whole else n_points))
    path_out = np.empty((n, 0 if whole else n_points))
    for e in range(n):
        p = elements.pair[e]
        rs, zs, rr, zr = k.r_s[p], k.z_s[p], k.r_r[p], k.z_r[p]
        nu_kappa, z_apex = k.nu_kappa[p], k.z_apex[p]
        z0, z1 = elements.z_start_m[e], elements.z_end_m[e]
        half_length = 0.5 * (z1 - z0)
        centre = 0.5 * (z0 + z1)
        half_nu[e, 0] = 0.5 * k.nu[p]
        model_sum = 0.0
        for g in range(n_points):
            z = centre + rule_x[g] * half_length
            a = z - zs
            b = z - zr
            m = math.hypot(rs, a)
            l_ = math.hypot(rr, b)
            ml = m * l_
            rsr = rs * rr
            t = rs * b + rr * a
            c1 = max(t * t / ((ml + rsr - a * b) * rsr), 0.0)
            log_argument[e, g] = c1 + math.sqrt(c1 * (c1 + 2.0))
            ml_out[e, g] = ml
            x = nu_kappa * (z - z_apex)
            model = 0.5 * (x * x)
            apex = 0.0
            for i in range(4):
                denominator = model + k.gap[p, i]
                apex += k.numerator[p, i] / denominator if denominator > 0.0 else 0.0
            model_sum += rule_w[g] * apex / k.ml_apex[p]
            if not whole:
                z_out[e, g] = z
                path_out[e, g] = m + l_
        model_out[e] = model_sum
        a0 = nu_kappa * (z0 - z_apex)
        a1 = nu_kappa * (z1 - z_apex)
        spread = nu_kappa * (z1 - z0)
        product = a0 * a1
        for i in range(4):
            s = k.model_width[p, i]
            atan_y[e, i] = spread * s
            atan_x[e, i] = s * s + product
    return TermArguments(log_argument, half_nu, ml_out, model_out, atan_y, atan_x, z_out, path_out)


@njit(cache=True, nogil=True, error_model="numpy")
def term_sums(elements: EdgeElements, k: PairConstants, sinh_half: NDArray[np.float64], ml: NDArray[np.float64],
              model_sum: NDArray[np.float64], atan: NDArray[np.float64], rule_w: NDArray[np.float64],
              whole: bool) -> NDArray[np.float64]:
    """The gains from sinh(nu eta / 2) at the points (``sinh_half``, (n, g)) and the model's
    arctangents (``atan``, (n, 4)): shape (n, g), or (n, 1) for whole elements."""
    n = elements.pair.size
    n_points = rule_w.size
    gains = np.empty((n, 1 if whole else n_points))
    remainder = np.empty(n_points)
    for e in range(n):
        p = elements.pair[e]
        half_length = 0.5 * (elements.z_end_m[e] - elements.z_start_m[e])
        for g in range(n_points):
            hyperbolic = 2.0 * (sinh_half[e, g] * sinh_half[e, g])
            exact = 0.0
            for i in range(4):
                denominator = hyperbolic + k.gap[p, i]
                exact += k.numerator[p, i] / denominator if denominator > 0.0 else 0.0
            remainder[g] = rule_w[g] * exact / ml[e, g]
        model_integral = 0.0
        for i in range(4):
            model_integral += k.model_coefficient[p, i] * atan[e, i]
        scale = -(k.nu[p] / (4.0 * np.pi))
        if whole:
            remainder_sum = 0.0
            for g in range(n_points):
                remainder_sum += remainder[g]
            gains[e, 0] = scale * ((remainder_sum - model_sum[e]) * half_length + model_integral)
            continue
        correction = (model_integral - model_sum[e] * half_length) / n_points
        for g in range(n_points):
            gains[e, g] = scale * (remainder[g] * half_length + correction)
    return gains


def _gains(elements: EdgeElements, constants: PairConstants, whole: bool) -> tuple[NDArray[np.float64], TermArguments]:
    arguments = term_arguments(elements, constants, _RULE_X, _RULE_W, whole)
    sinh_half = np.log1p(arguments.log_argument, out=arguments.log_argument)  # eta
    np.multiply(arguments.half_nu, sinh_half, out=sinh_half)  # (nu / 2) eta
    np.sinh(sinh_half, out=sinh_half)
    atan = np.arctan2(arguments.atan_y, arguments.atan_x, out=arguments.atan_y)
    return term_sums(elements, constants, sinh_half, arguments.ml, arguments.model_sum, atan, _RULE_W, whole), arguments


def quadrature_points(elements: EdgeElements, constants: PairConstants) -> QuadraturePoints:
    """The reference's :func:`~acoustisim.propagation.reference.btm.quadrature_points`."""
    gains, arguments = _gains(elements, constants, False)
    return QuadraturePoints(gains, arguments.z, arguments.path_length)


def element_gains(elements: EdgeElements, constants: PairConstants) -> NDArray[np.float64]:
    """The reference's :func:`~acoustisim.propagation.reference.btm.element_gains`."""
    gains, _ = _gains(elements, constants, True)
    return gains[:, 0]



def edge_impulses(elements: EdgeElements, constants: PairConstants, adaptive: bool) -> EdgeImpulses:
    """The reference's :func:`~acoustisim.propagation.reference.edges.edge_impulses`."""
    if adaptive:
        points = quadrature_points(elements, constants)
        return EdgeImpulses(np.repeat(elements.pair, points.gain.shape[1]), points.gain.reshape(-1),
                            points.z_m.reshape(-1), points.path_length_m.reshape(-1))
    return EdgeImpulses(elements.pair, element_gains(elements, constants),
                        0.5 * (elements.z_start_m + elements.z_end_m), elements.path_length_m)

__all__ = ("TermArguments", "edge_impulses", "element_gains", "quadrature_points", "term_arguments", "term_sums")
