"""Exact modal-series coefficients of an infinite cylinder and of a sphere in water.

Physics (time dependence exp(-i w t); derived from the boundary conditions, after Faran,
J. Acoust. Soc. Am. 23, 405 (1951) for the cylinder and sphere and Hickling, JASA 34, 1582
(1962) for the sphere)
------------------------------------------------------------------------------------------
Unit plane wave along +x. Outside (water, density rho_w, wavenumber k, x = k a):

    cylinder  p = sum_n eps_n i^n [J_n(k r) + A_n H_n(k r)] cos(n phi),    eps_0 = 1, eps_n = 2,
    sphere    p = sum_n (2n + 1) i^n [j_n(k r) + A_n h_n(k r)] P_n(cos theta),

H_n = H_n^(1), h_n = h_n^(1) (outgoing). The water's radial displacement is
u_r = (dp/dr) / (rho_w w^2). Inside a solid (density rho_s, complex k_L, k_T, x_L = k_L a,
x_T = k_T a) the displacement is u = grad Phi + curl(Psi e_z) (cylinder) or
u = grad Phi + curl curl(r Psi) (sphere), Phi = B Z_n(k_L r), Psi = C Z_n(k_T r) times the
angular factor, and the stress is sigma = lambda div(u) I + mu (grad u + grad u^T). At r = a:
the normal displacement is continuous, sigma_rr = -p, and the tangential stress is zero. With
the scaled unknowns b = rho_s w^2 B, c = rho_s w^2 C, delta = rho_w / rho_s,
gamma = mu / (rho_s w^2 a^2) = 1 / x_T^2, and m = n (cylinder) or m = n (n + 1) (sphere),
each order gives the 3 x 3 system (Z = J for the cylinder, j for the sphere; q = 2 for the
cylinder, 4 for the sphere):

    [ -x H_n'(x)   delta x_L Z'(x_L)                           delta m Z(x_T)               ] [A]   [x Z'(x)]
    [  H_n(x)      (2 m' gamma - 1) Z(x_L) - q gamma x_L Z'(x_L) 2 m gamma (x_T Z'(x_T) - Z(x_T)) ] [b] = [-Z(x) ]
    [  0           shear row (below)                                                         ] [c]   [  0   ]

with m' = n^2 (cylinder) or n (n + 1) (sphere), and the zero-tangential-stress row

    cylinder  [0, 2n (J_n(x_L) - x_L J_n'(x_L)),      (x_T^2 - 2 n^2) J_n(x_T) + 2 x_T J_n'(x_T)]
    sphere    [0, 2 (x_L j_n'(x_L) - j_n(x_L)),       (2 n (n + 1) - x_T^2 - 2) j_n(x_T) - 2 x_T j_n'(x_T)].

The same code gives the limits, each by replacing rows of the same system: a fluid (c_S = 0:
gamma = 0, no shear potential, the shear row becomes c = 0; also for n = 0, where the shear
potential does not couple to the water), a rigid body (normal displacement zero: first row
without the solid's terms, b = c = 0: A_n = -Z'(x)/H'(x)) and a pressure-release body
(pressure zero: A_n = -Z(x)/H(x)).

Far field: cylinder p_s -> sqrt(2 / (pi k r)) e^{i (k r - pi/4)} sum_n eps_n A_n cos(n theta);
sphere p_s -> (e^{i k r} / r) f(theta), f = -(i / k) sum_n (2n + 1) A_n P_n(cos theta); theta the
scattering angle from the forward direction (pi: backscatter).

Method
------
Every order n = 0..N and every frequency bin at once: the Bessel functions from one
``scipy.special`` call per kind (:mod:`.special`), the (bins, orders, 3, 3) systems solved in one
batched, equilibrated ``numpy.linalg.solve`` (:mod:`.linear_systems`). Truncation: a bin keeps
the orders n <= Re(k a) + ``extra_orders`` (30 by default); beyond it |A_n| falls faster than
exponentially (J_n(x) / H_n(x) for n > x), below 1e-20 of the largest term at n = ka + 30 in the
tank's band (``tests/physics/test_elastic_series.py`` shows the convergence).

Accuracy
--------
Rounding: the coefficients satisfy the lossless unitarity |1 + 2 A_n| = 1 to about 1e-13 and
the closed-form rigid, soft and fluid limits to the same level (tests).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError
from acoustisim.scattering.bodies import Body, Elastic, Fluid, PressureRelease, Rigid, Shell
from acoustisim.scattering.linear_systems import solve_equilibrated
from acoustisim.scattering.series import DEFAULT_EXTRA_ORDERS, ModalCoefficients, Shape, check_band, order_keep_mask
from acoustisim.scattering.shell import shell_coefficients
from acoustisim.scattering.special import bessel_pair

__all__ = ("boundary_system", "modal_coefficients")

def modal_coefficients(shape: Shape, body: Body, radius_m: float, frequencies_hz: ArrayLike, water: Fluid,
                       extra_orders: int = DEFAULT_EXTRA_ORDERS) -> ModalCoefficients:
    """Scattering coefficients A_n of a cylinder (normal incidence) or a sphere.

    Parameters
    ----------
    shape : {"cylinder", "sphere"}
    body : Rigid, PressureRelease, Elastic or Shell
        A :class:`Shell` only for a cylinder (:mod:`.shell`).
    radius_m : float
        Outer radius a (m).
    frequencies_hz : array_like, shape (n_bins,)
        Frequencies (Hz, > 0).
    water : Fluid
        The host medium.
    extra_orders : int
        Orders kept beyond Re(k a) in each bin.

    Returns
    -------
    ModalCoefficients

    Raises
    ------
    InputError
        Bad radius or frequencies, a shell sphere, an unknown shape or body.
    """
    f = check_band(radius_m, frequencies_hz)
    omega = 2.0 * np.pi * f
    k = water.wavenumber(omega)
    if shape not in ("cylinder", "sphere"):
        raise InputError(f"shape = {shape!r}: expected 'cylinder' or 'sphere'")
    if isinstance(body, Shell):
        if shape != "cylinder":
            raise InputError("a Shell body is a cylindrical pipe: shape must be 'cylinder'")
        return shell_coefficients(body, radius_m, f, water, extra_orders)
    if not isinstance(body, (Rigid, PressureRelease, Elastic)):
        raise InputError(f"body = {body!r}: expected Rigid, PressureRelease, Elastic or Shell")
    x = k * radius_m
    orders, keep = order_keep_mask(x, extra_orders)
    matrix, rhs = boundary_system(shape, body, x, omega, radius_m, water, orders, keep)
    solution = solve_equilibrated(matrix, rhs)
    coefficients = np.where(keep, solution[..., 0], 0.0)
    return ModalCoefficients(shape, orders, coefficients, k, float(radius_m))


def boundary_system(shape: Shape, body: Rigid | PressureRelease | Elastic, x: NDArray[np.complex128],
                    omega: NDArray[np.float64], radius_m: float, water: Fluid, orders: NDArray[np.int64],
                    keep: NDArray[np.bool_]) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """The (bins, orders, 3, 3) systems and (bins, orders, 3) right-hand sides of the module
    docstring, unknowns (A_n, b, c); rows of orders beyond the truncation are the identity."""
    spherical = shape == "sphere"
    n = orders[None, :].astype(float)
    m = n * (n + 1.0) if spherical else n
    m_sq = n * (n + 1.0) if spherical else n * n
    q = 4.0 if spherical else 2.0
    z_x = bessel_pair("J", orders, x, spherical=spherical, keep=keep)
    h_x = bessel_pair("H", orders, x, spherical=spherical, keep=keep)
    xx = x[:, None]
    shape_systems = keep.shape + (3, 3)
    matrix = np.zeros(shape_systems, dtype=complex)
    rhs = np.zeros(keep.shape + (3,), dtype=complex)
    rhs[..., 0] = xx * z_x.derivative
    rhs[..., 1] = -z_x.value
    if isinstance(body, Rigid):
        matrix[..., 0, 0] = -xx * h_x.derivative
        matrix[..., 1, 1] = 1.0
        matrix[..., 2, 2] = 1.0
        rhs[..., 1] = 0.0
    elif isinstance(body, PressureRelease):
        matrix[..., 1, 0] = h_x.value
        matrix[..., 0, 1] = 1.0
        matrix[..., 2, 2] = 1.0
        rhs[..., 0] = 0.0
    else:
        x_l = body.compressional_wavenumber(omega) * radius_m
        z_l = bessel_pair("J", orders, x_l, spherical=spherical, keep=keep)
        delta = water.density_kg_m3 / body.density_kg_m3
        xl = x_l[:, None]
        matrix[..., 0, 0] = -xx * h_x.derivative
        matrix[..., 1, 0] = h_x.value
        matrix[..., 0, 1] = delta * xl * z_l.derivative
        if body.is_fluid:
            matrix[..., 1, 1] = -z_l.value
            matrix[..., 2, 2] = 1.0
        else:
            x_t = body.shear_wavenumber(omega) * radius_m
            z_t = bessel_pair("J", orders, x_t, spherical=spherical, keep=keep)
            xt = x_t[:, None]
            gamma = 1.0 / (xt * xt)
            matrix[..., 1, 1] = (2.0 * m_sq * gamma - 1.0) * z_l.value - q * gamma * xl * z_l.derivative
            matrix[..., 0, 2] = delta * m * z_t.value
            matrix[..., 1, 2] = 2.0 * m * gamma * (xt * z_t.derivative - z_t.value)
            if spherical:
                matrix[..., 2, 1] = 2.0 * (xl * z_l.derivative - z_l.value)
                matrix[..., 2, 2] = (2.0 * m - xt * xt - 2.0) * z_t.value - 2.0 * xt * z_t.derivative
            else:
                matrix[..., 2, 1] = 2.0 * n * (z_l.value - xl * z_l.derivative)
                matrix[..., 2, 2] = (xt * xt - 2.0 * n * n) * z_t.value + 2.0 * xt * z_t.derivative
            # n = 0 (orders start at 0): the shear potential does not couple to the water (c = 0).
            matrix[:, 0, :, :] = _decoupled_shear(matrix[:, 0])
    matrix[~keep] = np.eye(3)  # orders beyond a bin's truncation: the identity (in place: no copy)
    rhs[~keep] = 0.0
    return matrix, rhs


def _decoupled_shear(systems: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """The order-0 systems (bins, 3, 3) with the shear unknown decoupled: column and row 2 = e_2."""
    out = systems.copy()
    out[:, :, 2] = 0.0
    out[:, 2, :] = 0.0
    out[:, 2, 2] = 1.0
    return out
