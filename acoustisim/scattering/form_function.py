"""Far-field form functions and cross-sections of a modal series.

Physics (time dependence exp(-i w t), unit plane wave, theta the scattering angle from the
forward direction: theta = pi is backscatter)
-----------------------------------------------------------------------------------------
Cylinder (2-D): p_s -> sqrt(2 / (pi k r)) e^{i (k r - pi/4)} g(theta), g = sum_n eps_n A_n cos(n theta);
form function f_inf = sqrt(2 r / a) p_s e^{-i k r} = (2 / sqrt(pi k a)) e^{-i pi/4} g(theta)
(|f_inf| -> 1 in backscatter for a rigid cylinder at high ka). Scattering width
sigma_s = (4 / k) sum_n eps_n |A_n|^2; extinction (optical theorem, from the forward amplitude)
sigma_e = -(4 / k) Re g(0).
Sphere: p_s -> (e^{i k r} / r) f(theta), f = -(i / k) sum_n (2n + 1) A_n P_n(cos theta); form
function f_inf = 2 f / a; sigma_s = (4 pi / k^2) sum_n (2n + 1) |A_n|^2,
sigma_e = (4 pi / k) Im f(0).
Without losses sigma_e = sigma_s (energy balance); with losses sigma_e - sigma_s is the power
absorbed, >= 0.

Method
------
Sums over orders as matrix products: (bins, orders) coefficients times (orders, angles) angular
factors (cos(n theta), or Legendre polynomials from ``scipy.special.eval_legendre``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from acoustisim.scattering.series import ModalCoefficients

__all__ = ("CrossSections", "angular_sum", "cross_sections", "form_function")


def _order_weights(coefficients: ModalCoefficients) -> NDArray[np.float64]:
    n = coefficients.orders.astype(float)
    if coefficients.shape == "sphere":
        return 2.0 * n + 1.0
    return np.where(n == 0.0, 1.0, 2.0)


def angular_sum(coefficients: ModalCoefficients, scattering_angle_rad: ArrayLike) -> NDArray[np.complex128]:
    """sum_n eps_n A_n cos(n theta) (cylinder) or sum_n (2n + 1) A_n P_n(cos theta) (sphere).

    Parameters
    ----------
    coefficients : ModalCoefficients
    scattering_angle_rad : array_like, shape (n_angles,)

    Returns
    -------
    ndarray, shape (n_bins, n_angles)
    """
    theta = np.atleast_1d(np.asarray(scattering_angle_rad, dtype=float))
    n = coefficients.orders
    if coefficients.shape == "sphere":
        angular = special.eval_legendre(n[:, None], np.cos(theta)[None, :])
    else:
        angular = np.cos(np.multiply.outer(n, theta))
    return (coefficients.coefficients * _order_weights(coefficients)) @ angular


def form_function(coefficients: ModalCoefficients, scattering_angle_rad: ArrayLike) -> NDArray[np.complex128]:
    """The complex far-field form function f_inf (module docstring), (n_bins, n_angles)."""
    total = angular_sum(coefficients, scattering_angle_rad)
    ka = (coefficients.wavenumber * coefficients.radius_m)[:, None]
    if coefficients.shape == "sphere":
        return -2j / ka * total
    return 2.0 / np.sqrt(np.pi * ka) * np.exp(-0.25j * np.pi) * total


class CrossSections(NamedTuple):
    """Per-bin cross-sections (m for the cylinder's widths, m^2 for the sphere), (n_bins,)."""

    scattering: NDArray[np.float64]
    extinction: NDArray[np.float64]

    @property
    def absorption(self) -> NDArray[np.float64]:
        """Power absorbed by the body: extinction - scattering (>= 0 for a passive body)."""
        return self.extinction - self.scattering


def cross_sections(coefficients: ModalCoefficients) -> CrossSections:
    """Scattering cross-section (from the coefficients) and extinction (from the forward amplitude)."""
    k = np.real(coefficients.wavenumber)
    weights = _order_weights(coefficients)
    power = np.sum(weights * np.abs(coefficients.coefficients) ** 2, axis=1)
    forward = angular_sum(coefficients, [0.0])[:, 0]
    if coefficients.shape == "sphere":
        return CrossSections(4.0 * np.pi / k**2 * power, -4.0 * np.pi / k**2 * forward.real)
    return CrossSections(4.0 / k * power, -4.0 / k * forward.real)
