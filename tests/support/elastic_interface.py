"""Reference for plane-wave reflection at a water / elastic-solid interface (tests only): the
boundary conditions solved numerically, independent of the closed form in
:mod:`acoustisim.materials`.

Physics
-------
Water in z > 0, the solid in z < 0, time dependence exp(-i w t), horizontal wavenumber
xi = k_w sin t. In the water the pressure is p = e^{i xi x} (e^{-i g_w z} + R e^{i g_w z}),
g_w = k_w cos t, and the displacement u = grad p / (rho_w w^2). In the solid, a compressional
and a shear (SV) plane wave leave the interface downward,

    u = A (xi, -g_L) / k_L e^{i (xi x - g_L z)} + B (g_S, xi) / k_S e^{i (xi x - g_S z)},

g = sqrt(k^2 - xi^2) with Im g >= 0 (decaying, or carrying energy, downward), complex
wavenumbers k = (w / c)(1 + i eta / 2) for losses; A and B are displacement amplitudes
(the polarisations are unit vectors for real angles). Hooke's law with the Lame moduli
mu = rho c_S^2, lambda = rho c_L^2 - 2 mu (complex speeds c = w / k) gives the stresses
sigma_zz = lambda div u + 2 mu d_z u_z and sigma_xz = mu (d_z u_x + d_x u_z). The boundary
conditions at z = 0 are: u_z continuous, sigma_zz = -p, sigma_xz = 0 (Brekhovskikh, *Waves in
Layered Media*, section 4; Aki & Richards, *Quantitative Seismology*, section 5.2), three
linear equations for (R, A, B) per angle.

Method
------
One 3 x 3 complex system per angle, rows and columns equilibrated (the entries span some
twenty decades in SI units) and solved by ``numpy.linalg.solve``. The time-averaged energy
flux through the interface of each transmitted wave, as a fraction of the incident one, is
rho c w^2 |amplitude|^2 cos(t_wave) / 2 over cos t / (2 rho_w c_w), for a real angle (lossless,
below that wave's critical angle; an evanescent wave carries none).

Accuracy
--------
Rounding of the equilibrated solve: a relative error of order 1e-14 away from the critical
angles (condition numbers of the scaled systems below 1e2), larger within about 1e-6 rad of
them, where a column degenerates. Needs c_S > 0 (a fluid leaves B undetermined).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ("ElasticHalfSpace", "InterfaceSolution", "solve_interface")

ANGULAR_FREQUENCY_RAD_S = 2.0 * np.pi * 500e3
"""Any frequency gives the same R (no length scale); the band's centre keeps the numbers usual."""


class ElasticHalfSpace(NamedTuple):
    """Water over a solid: densities (kg/m^3), speeds (m/s) and the solid's loss factors."""

    water_density_kg_m3: float
    water_speed_m_s: float
    density_kg_m3: float
    compressional_speed_m_s: float
    shear_speed_m_s: float
    compressional_loss_factor: float = 0.0
    shear_loss_factor: float = 0.0


class InterfaceSolution(NamedTuple):
    """Per incidence angle (n,): the pressure reflection coefficient ``reflection``, the
    transmitted displacement amplitudes ``compressional`` and ``shear`` (m per Pa of incident
    pressure), and the fractions of the incident normal energy flux they carry
    (``compressional_flux``, ``shear_flux``; 0 for an evanescent wave; meaningful without losses)."""

    reflection: NDArray[np.complex128]
    compressional: NDArray[np.complex128]
    shear: NDArray[np.complex128]
    compressional_flux: NDArray[np.float64]
    shear_flux: NDArray[np.float64]


def _vertical(k: complex, xi: NDArray[np.float64]) -> NDArray[np.complex128]:
    g = np.sqrt(k * k - xi * xi + 0j)
    return np.where(g.imag < 0.0, -g, g)


def solve_interface(half_space: ElasticHalfSpace, incidence_rad: ArrayLike) -> InterfaceSolution:
    """Solve the boundary conditions at each incidence angle (rad from the normal, shape (n,))."""
    theta = np.atleast_1d(np.asarray(incidence_rad, dtype=float))
    w = ANGULAR_FREQUENCY_RAD_S
    rho_w, c_w = half_space.water_density_kg_m3, half_space.water_speed_m_s
    rho = half_space.density_kg_m3
    k_w = w / c_w
    k_l = w / half_space.compressional_speed_m_s * (1.0 + 0.5j * half_space.compressional_loss_factor)
    k_s = w / half_space.shear_speed_m_s * (1.0 + 0.5j * half_space.shear_loss_factor)
    mu = rho * (w / k_s) ** 2
    lam = rho * (w / k_l) ** 2 - 2.0 * mu
    xi = k_w * np.sin(theta)
    g_w = k_w * np.cos(theta)
    g_l, g_s = _vertical(k_l, xi), _vertical(k_s, xi)

    n = theta.size
    matrix = np.zeros((n, 3, 3), dtype=complex)
    rhs = np.zeros((n, 3), dtype=complex)
    # u_z continuous: i g_w (R - 1) / (rho_w w^2) = -A g_L / k_L + B xi / k_S
    matrix[:, 0, 0] = 1j * g_w / (rho_w * w * w)
    matrix[:, 0, 1] = g_l / k_l
    matrix[:, 0, 2] = -xi / k_s
    rhs[:, 0] = 1j * g_w / (rho_w * w * w)
    # sigma_zz = -(1 + R): i A (lambda k_L + 2 mu g_L^2 / k_L) - 2 i mu B xi g_S / k_S
    matrix[:, 1, 0] = 1.0
    matrix[:, 1, 1] = 1j * (lam * k_l + 2.0 * mu * g_l * g_l / k_l)
    matrix[:, 1, 2] = -2j * mu * xi * g_s / k_s
    rhs[:, 1] = -1.0
    # sigma_xz = 0: -2 i mu A xi g_L / k_L + i mu B (xi^2 - g_S^2) / k_S
    matrix[:, 2, 1] = -2j * mu * xi * g_l / k_l
    matrix[:, 2, 2] = 1j * mu * (xi * xi - g_s * g_s) / k_s
    # Equilibrate: columns by their largest entry, then rows.
    columns = 1.0 / np.max(np.abs(matrix), axis=1)
    scaled = matrix * columns[:, None, :]
    rows = 1.0 / np.max(np.abs(scaled), axis=2)
    solution = np.linalg.solve(scaled * rows[:, :, None], (rhs * rows)[..., None])[..., 0] * columns

    reflection, a, b = solution[:, 0], solution[:, 1], solution[:, 2]
    incident = np.cos(theta) / (2.0 * rho_w * c_w)

    def flux(amplitude: NDArray[np.complex128], k: complex, g: NDArray[np.complex128]) -> NDArray[np.float64]:
        c = (w / k).real
        propagating = np.abs(g.imag) <= 1e-12 * np.abs(k)
        cos_wave = np.where(propagating, g.real / k.real, 0.0)
        return 0.5 * rho * c * w * w * np.abs(amplitude) ** 2 * cos_wave / incident

    return InterfaceSolution(reflection, a, b, flux(a, k_l, g_l), flux(b, k_s, g_s))
