"""Echo transfer functions of many rows from one table of modal coefficients.

:func:`acoustisim.scattering.echo.echo_transfer` solves the boundary systems for each call; the
simulator needs the transfer functions of hundreds of rows of a few bodies, so here the
coefficients are computed once per body and frequency set (:func:`~acoustisim.scattering.modal.
modal_coefficients`) and every row's modal sum is formed from them.

Physics (time dependence exp(-i w t) in the derivation; the formulas of :mod:`.echo`)
-------------------------------------------------------------------------------------
A row is a (image) source at distance rho_s from a post's axis (or r_s from a sphere's centre),
a receiver at rho_r (r_r), seen from the axis (centre) at the bistatic angle beta. For a post the
row must lie in a plane normal to the axis (no axial offset: rows of other elevations are this
"flat" row at the frequency f cos(e), :mod:`acoustisim.propagation.elastic_responses`):

    post    p = (i/2) sqrt(2 pi k / L) e^{-i pi/4} sum_n eps_n A_n H_n(k rho_s) H_n(k rho_r) cos(n beta)
    sphere  p = i k sum_n (2n + 1) A_n h_n(k r_s) h_n(k r_r) P_n(cos beta),

L the specular path length. Today's row is g = R(cos theta_i) G (geometric optics at the
specular point, :func:`~acoustisim.scattering.echo.specular_point`), and the transfer function in
the synthesiser's engineering convention is H(f) = conj(p e^{-i k L} / g).

Method
------
The Hankel functions of each row by upward recurrence over the order (stable for H), started
from H_0, H_1 (cylinder: Hankel's asymptotic expansion, 12 terms, where k rho >= 40: its
remainder is below 1e-16 there; ``scipy.special.hankel1`` below) or from the closed forms of
h_0, h_1 (sphere), and accumulated order by order up to each frequency's own truncation, in
one compiled loop (:func:`acoustisim.scattering.kernels.modal_sums`).

Accuracy
--------
The sums of :func:`~acoustisim.scattering.echo.echo_transfer` to rounding (about 1e-12
relative; ``tests/physics/test_elastic_echo_series.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import special

from acoustisim.errors import InputError
from acoustisim.scattering.bodies import Fluid
from acoustisim.scattering.echo import EchoGeometry, EchoTarget, specular_point
from acoustisim.scattering.kernels import modal_sums
from acoustisim.scattering.series import ModalCoefficients

__all__ = ("ASYMPTOTIC_FROM", "hankel_start", "series_transfer", "todays_echo")

ASYMPTOTIC_FROM = 40.0
"""Arguments from which H_0 and H_1 come from Hankel's asymptotic expansion (12 terms)."""

_ASYMPTOTIC_TERMS = 12


def hankel_start(x: NDArray[np.float64]) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """H_0^(1)(x) and H_1^(1)(x) for real x > 0, any shape.

    Where x >= :data:`ASYMPTOTIC_FROM`: H_nu(x) = sqrt(2 / (pi x)) e^{i (x - nu pi / 2 - pi / 4)}
    sum_k i^k a_k(nu) / x^k, a_k(nu) = prod_{j=1..k} (4 nu^2 - (2j - 1)^2) / (k! 8^k) (Abramowitz &
    Stegun 9.2.7-9.2.10); the terms fall until k ~ 2x, and at x = 40 the 12th is below 1e-17 of the
    first. Elsewhere ``scipy.special.hankel1``.
    """
    x = np.asarray(x, dtype=float)
    h0 = np.empty(x.shape, dtype=complex)
    h1 = np.empty(x.shape, dtype=complex)
    large = x >= ASYMPTOTIC_FROM
    if np.any(~large):
        h0[~large] = special.hankel1(0, x[~large])
        h1[~large] = special.hankel1(1, x[~large])
    if np.any(large):
        z = x[large]
        inverse = 1.0 / z
        for order, out in ((0, h0), (1, h1)):
            mu = 4.0 * order * order
            term = np.ones_like(z, dtype=complex)
            total = term.copy()
            for k in range(1, _ASYMPTOTIC_TERMS):
                term = term * (1j * (mu - (2 * k - 1) ** 2) / (8.0 * k)) * inverse
                total += term
            phase = z - 0.5 * order * math.pi - 0.25 * math.pi
            out[large] = np.sqrt(2.0 / (math.pi * z)) * np.exp(1j * phase) * total
    return h0, h1


def _starts(spherical: bool, x: NDArray[np.float64]) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """Orders 0 and 1 of H (cylinder) or h (sphere) at x > 0."""
    if spherical:
        wave = np.exp(1j * x)
        return -1j * wave / x, -wave * (x + 1j) / (x * x)
    return hankel_start(x)


def _modal_sum(spherical: bool, table: NDArray[np.complex128], tops: NDArray[np.int64], which: NDArray[np.int64],
               x_s: NDArray[np.float64], x_r: NDArray[np.float64], cos_beta: NDArray[np.float64]
               ) -> NDArray[np.complex128]:
    """sum_n w_n A_n Z_n(x_s) Z_n(x_r) X_n(beta), (R, K): element (r, k) with the coefficients of
    frequency ``which[r, k]`` (:func:`acoustisim.scattering.kernels.modal_sums`)."""
    start_s = np.stack(_starts(spherical, x_s))
    start_r = np.stack(_starts(spherical, x_r))
    return modal_sums(spherical, np.ascontiguousarray(table), tops, np.ascontiguousarray(which), start_s, start_r,
                      np.ascontiguousarray(x_s), np.ascontiguousarray(x_r), np.ascontiguousarray(cos_beta))


def todays_echo(target: EchoTarget, geometry: EchoGeometry, water: Fluid) -> tuple[NDArray[np.complex128],
                                                                                 NDArray[np.float64]]:
    """Today's row of each echo, g = R(cos theta_i) G (complex, (R,)), and its path length L (m, (R,)).

    Raises
    ------
    InputError
        A row whose g is zero (a material matching the water): it has no transfer function.
    """
    specular = specular_point(target.shape, target.radius_m, geometry)
    today = target.material.reflection_coefficient(specular.cos_incidence, water.density_kg_m3,
                                                   water.sound_speed_m_s) * specular.spreading
    if np.any(np.abs(today) == 0.0):
        raise InputError(f"material {target.material.name!r}: today's echo is zero (R = 0); no transfer function")
    return today, specular.path_length_m


def series_transfer(target: EchoTarget, geometry: EchoGeometry, water: Fluid, coefficients: ModalCoefficients,
                    row_bins: NDArray[np.int64] | None = None) -> NDArray[np.complex128]:
    """H(f) of rows from a coefficient table: every row at every frequency, or each at its own.

    Parameters
    ----------
    target : EchoTarget
        Its body and radius made ``coefficients``; its material made today's rows.
    geometry : EchoGeometry
        R rows; for a post every ``axial_offset_m`` must be 0 (a flat row).
    water : Fluid
    coefficients : ModalCoefficients
        A_n at K frequencies (:func:`~acoustisim.scattering.modal.modal_coefficients` with
        ``target.body``, ``target.radius_m`` and ``water``; shape "cylinder" for a post).
    row_bins : ndarray of int, shape (R,) or (R, J), optional
        Evaluate row r only at frequency ``row_bins[r]`` (or ``row_bins[r, j]``) of the table.

    Returns
    -------
    ndarray of complex
        (R, K); with ``row_bins`` its shape: engineering convention, multiply the row's spectrum.

    Raises
    ------
    InputError
        A post row with an axial offset, a table of another shape, or a row with no echo today.
    """
    spherical = target.shape == "sphere"
    if coefficients.shape != ("sphere" if spherical else "cylinder"):
        raise InputError(f"series_transfer: {target.shape} rows need {'sphere' if spherical else 'cylinder'} "
                         f"coefficients, got {coefficients.shape!r}")
    if not spherical and np.any(geometry.axial_offset_m != 0.0):
        raise InputError("series_transfer: post rows must be flat (axial offset 0); see elastic_responses")
    today, length = todays_echo(target, geometry, water)
    k = np.real(coefficients.wavenumber)
    table = coefficients.coefficients
    rho_s, rho_r = geometry.source_distance_m, geometry.receiver_distance_m
    cos_beta = np.cos(geometry.bistatic_angle_rad)
    tops = np.where(table != 0.0, np.arange(table.shape[1])[None, :], 0).max(axis=1).astype(np.int64)
    if row_bins is not None:
        bins = np.asarray(row_bins, dtype=np.int64)
        which = bins.reshape(geometry.n_rows, -1)
        kappa = k[which]
        series = _modal_sum(spherical, table, tops, which, kappa * rho_s[:, None], kappa * rho_r[:, None], cos_beta)
        out = _normalised(spherical, series, kappa, length[:, None], today[:, None])
        return out[:, 0] if bins.ndim == 1 else out
    which = np.broadcast_to(np.arange(k.size), (geometry.n_rows, k.size))
    series = _modal_sum(spherical, table, tops, which, rho_s[:, None] * k[None, :], rho_r[:, None] * k[None, :],
                        cos_beta)
    return _normalised(spherical, series, k[None, :], length[:, None], today[:, None])


def _normalised(spherical: bool, series: NDArray[np.complex128], k: NDArray[np.float64], length: NDArray[np.float64],
                today: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """conj(p e^{-i k L} / g) from the modal sum."""
    if spherical:
        pressure = 1j * k * series
    else:
        pressure = 0.5j * np.sqrt(2.0 * math.pi * k / length) * np.exp(-0.25j * math.pi) * series
    return np.conj(pressure * np.exp(-1j * k * length) / today)
