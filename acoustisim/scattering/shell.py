"""Cylindrical shells (pipes) in water: the exact elastic solution and the thin-shell model.

Physics (time dependence exp(-i w t), normal incidence, unit plane wave; derived from the
boundary conditions)
------------------------------------------------------------------------------------------
Exact (elastic annulus b < r < a, b = a - h; the two-radius generalisation of Faran's solid
cylinder, as in Doolittle & Uberall, JASA 39, 272, 1966, for the exact case): in the wall
Phi = B_J J_n(k_L r) + B_Y Y_n(k_L r), Psi = C_J J_n(k_T r) + C_Y Y_n(k_T r); outside
p = J_n(k r) + A_n H_n(k r); inside the fill (density rho_f, wavenumber k_f)
p = D J_n(k_f r). At r = a and r = b: continuity of normal displacement, sigma_rr = -p, zero
tangential stress: six equations in (A_n, B_J, B_Y, C_J, C_Y, D) per order, with the same
row forms as the solid cylinder of :mod:`.modal` at each radius (x_L = k_L r, x_T = k_T r,
gamma_r = 1 / x_T^2, scaled unknowns b = rho_s w^2 B, c = rho_s w^2 C):

    displacement  (rho_fluid / rho_s) (b x_L Z'(x_L) + c n Z(x_T)) = x_fluid (fluid's p_r term)
    normal stress gamma_r [b ((2 n^2 - x_T^2) Z(x_L) - 2 x_L Z'(x_L)) + c 2 n (x_T Z'(x_T) - Z(x_T))] = -p
    shear stress  b 2 n (Z(x_L) - x_L Z'(x_L)) + c ((x_T^2 - 2 n^2) Z(x_T) + 2 x_T Z'(x_T)) = 0

for Z = J and Z = Y. For n = 0 the shear potentials do not couple (C_J = C_Y = 0).

Thin shell (Junger, JASA 24, 366, 1952; the plane-strain ring of Junger & Feit, *Sound,
Structures and Their Interaction*, ch. 7): mid-surface radius R = a - h/2, radial and
circumferential displacements w = W cos(n phi), v = V sin(n phi), membrane stiffness
K = M h and bending stiffness D = M h^3 / 12 with the plane-strain modulus
M = 4 mu (lambda + mu) / (lambda + 2 mu) (complex: lossy); strain energy
(K (v' + w)^2 / R^2 + D (w'' + w)^2 / R^4) / 2 per area (rigid-body motions n = 0, 1 are free):

    (K / R^2)(n^2 V + n W) - rho_s h w^2 V = 0
    (K / R^2)(n V + W) + (D / R^4)(n^2 - 1)^2 W - rho_s h w^2 W = p_in - p_out

with W equal to the water's radial displacement at r = a and the fill's at r = b.

Method
------
All orders and bins at once, equilibrated batched solves (:mod:`.linear_systems`), truncation as
in :mod:`.modal`.

Accuracy
--------
The exact solution is exact to rounding (tests: its water-filled, zero-thickness-contrast and
solid limits). The thin-shell model differs from it by O((h / a)) relative in the wall's
stiffness and inertia and by the neglected thickness modes; it is a check only where
k_L h << 1 (its regime): ``tests/physics/test_elastic_shell.py`` shows the difference falling
as the wall gets thinner.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError
from acoustisim.scattering.bodies import Fluid, Shell
from acoustisim.scattering.linear_systems import solve_equilibrated
from acoustisim.scattering.series import DEFAULT_EXTRA_ORDERS, ModalCoefficients, check_band, order_keep_mask
from acoustisim.scattering.special import BesselPair, bessel_pair

__all__ = ("shell_coefficients", "thin_shell_coefficients")


def _wall_rows(pair_l: BesselPair, pair_t: BesselPair, x_l: NDArray[np.complex128], x_t: NDArray[np.complex128],
               n: NDArray[np.float64]) -> tuple[NDArray[np.complex128], ...]:
    """Row entries (b-column, c-column) of displacement, normal stress and shear stress at one
    radius for one kind of cylinder function: six (bins, orders) arrays."""
    xl, xt = x_l[:, None], x_t[:, None]
    gamma = 1.0 / (xt * xt)
    disp_b = xl * pair_l.derivative
    disp_c = n * pair_t.value
    stress_b = gamma * ((2.0 * n * n - xt * xt) * pair_l.value - 2.0 * xl * pair_l.derivative)
    stress_c = gamma * 2.0 * n * (xt * pair_t.derivative - pair_t.value)
    shear_b = 2.0 * n * (pair_l.value - xl * pair_l.derivative)
    shear_c = (xt * xt - 2.0 * n * n) * pair_t.value + 2.0 * xt * pair_t.derivative
    return disp_b, disp_c, stress_b, stress_c, shear_b, shear_c


def _check(shell: Shell, radius_m: float, frequencies_hz: ArrayLike) -> tuple[NDArray[np.float64], float]:
    f = check_band(radius_m, frequencies_hz)
    inner = radius_m - shell.thickness_m
    if not inner > 0.0:
        raise InputError(f"shell thickness_m = {shell.thickness_m!r} must be below the radius {radius_m!r}")
    return f, inner


def shell_coefficients(shell: Shell, radius_m: float, frequencies_hz: ArrayLike, water: Fluid,
                       extra_orders: int = DEFAULT_EXTRA_ORDERS) -> ModalCoefficients:
    """Exact A_n of a fluid-filled elastic cylindrical shell (normal incidence).

    Parameters
    ----------
    shell : Shell
    radius_m : float
        Outer radius a (m).
    frequencies_hz : array_like, shape (n_bins,)
    water : Fluid
    extra_orders : int

    Returns
    -------
    ModalCoefficients
        ``shape`` "cylinder".
    """
    f, inner = _check(shell, radius_m, frequencies_hz)
    omega = 2.0 * np.pi * f
    k = water.wavenumber(omega)
    x = k * radius_m
    orders, keep = order_keep_mask(x, extra_orders)
    n = orders[None, :].astype(float)
    wall = shell.wall
    k_l, k_t = wall.compressional_wavenumber(omega), wall.shear_wavenumber(omega)
    k_f = shell.fill.wavenumber(omega)
    systems = np.zeros(keep.shape + (6, 6), dtype=complex)
    rhs = np.zeros(keep.shape + (6,), dtype=complex)
    j_x = bessel_pair("J", orders, x, keep=keep)
    h_x = bessel_pair("H", orders, x, keep=keep)
    xf = (k_f * inner)
    j_f = bessel_pair("J", orders, xf, keep=keep)
    inner_y = bessel_pair("Y", orders, k_l * inner, keep=keep)
    if not np.all(np.isfinite(inner_y.value) & np.isfinite(inner_y.derivative)):
        raise InputError(f"shell thickness_m = {shell.thickness_m!r} of radius {radius_m!r}: the wall is too thick "
                         "for the shell series (Y_n of the inner radius overflows); describe it as a solid")
    delta_w = water.density_kg_m3 / wall.density_kg_m3
    delta_f = shell.fill.density_kg_m3 / wall.density_kg_m3
    # unknowns: 0 A, 1 B_J, 2 B_Y, 3 C_J, 4 C_Y, 5 D; rows 0-2 at r = a, 3-5 at r = b
    for row0, r, delta in ((0, radius_m, delta_w), (3, inner, delta_f)):
        x_l, x_t = k_l * r, k_t * r
        for column_b, column_c, kind in ((1, 3, "J"), (2, 4, "Y")):
            pair_l = bessel_pair(kind, orders, x_l, keep=keep)
            pair_t = bessel_pair(kind, orders, x_t, keep=keep)
            disp_b, disp_c, stress_b, stress_c, shear_b, shear_c = _wall_rows(pair_l, pair_t, x_l, x_t, n)
            systems[..., row0, column_b] = delta * disp_b
            systems[..., row0, column_c] = delta * disp_c
            systems[..., row0 + 1, column_b] = stress_b
            systems[..., row0 + 1, column_c] = stress_c
            systems[..., row0 + 2, column_b] = shear_b
            systems[..., row0 + 2, column_c] = shear_c
    xx = x[:, None]
    systems[..., 0, 0] = -xx * h_x.derivative
    systems[..., 1, 0] = h_x.value
    rhs[..., 0] = xx * j_x.derivative
    rhs[..., 1] = -j_x.value
    systems[..., 3, 5] = -xf[:, None] * j_f.derivative
    systems[..., 4, 5] = j_f.value
    # n = 0: shear potentials decoupled (C_J = C_Y = 0)
    order0 = systems[:, 0]
    order0[:, (2, 5), :] = 0.0
    order0[:, 2, 3] = 1.0
    order0[:, 5, 4] = 1.0
    systems[~keep] = np.eye(6)  # orders beyond a bin's truncation: the identity (in place: no copy)
    rhs[~keep] = 0.0
    solution = solve_equilibrated(systems, rhs)
    return ModalCoefficients("cylinder", orders, np.where(keep, solution[..., 0], 0.0), k, float(radius_m))


def thin_shell_coefficients(shell: Shell, radius_m: float, frequencies_hz: ArrayLike, water: Fluid,
                            extra_orders: int = DEFAULT_EXTRA_ORDERS) -> ModalCoefficients:
    """A_n of the thin-shell (plane-strain ring) model of the module docstring.

    Parameters and returns as :func:`shell_coefficients`.
    """
    f, inner = _check(shell, radius_m, frequencies_hz)
    omega = 2.0 * np.pi * f
    k = water.wavenumber(omega)
    x = k * radius_m
    orders, keep = order_keep_mask(x, extra_orders)
    n = orders[None, :].astype(float)
    h = shell.thickness_m
    mid = radius_m - 0.5 * h
    lam, mu = shell.wall.lame_moduli()
    modulus = 4.0 * mu * (lam + mu) / (lam + 2.0 * mu)
    membrane = modulus * h / mid**2
    bending = modulus * h**3 / 12.0 / mid**4
    inertia = (shell.wall.density_kg_m3 * h * omega**2)[:, None]
    k_f = shell.fill.wavenumber(omega)
    j_x = bessel_pair("J", orders, x, keep=keep)
    h_x = bessel_pair("H", orders, x, keep=keep)
    j_f = bessel_pair("J", orders, k_f * inner, keep=keep)
    out_admittance = (k / (water.density_kg_m3 * omega**2))[:, None]
    in_admittance = (k_f / (shell.fill.density_kg_m3 * omega**2))[:, None]
    systems = np.zeros(keep.shape + (4, 4), dtype=complex)
    rhs = np.zeros(keep.shape + (4,), dtype=complex)
    # unknowns: 0 A, 1 W, 2 V, 3 D
    systems[..., 0, 0] = -out_admittance * h_x.derivative
    systems[..., 0, 1] = 1.0
    rhs[..., 0] = out_admittance * j_x.derivative
    systems[..., 1, 1] = 1.0
    systems[..., 1, 3] = -in_admittance * j_f.derivative
    systems[..., 2, 1] = -membrane * n
    systems[..., 2, 2] = inertia - membrane * n * n
    systems[..., 3, 0] = h_x.value
    systems[..., 3, 1] = membrane + bending * (n * n - 1.0) ** 2 - inertia
    systems[..., 3, 2] = membrane * n
    systems[..., 3, 3] = -j_f.value
    rhs[..., 3] = -j_x.value
    identity = np.broadcast_to(np.eye(4, dtype=complex), systems.shape)
    systems = np.where(keep[..., None, None], systems, identity)
    rhs = np.where(keep[..., None], rhs, 0.0)
    solution = solve_equilibrated(systems, rhs)
    return ModalCoefficients("cylinder", orders, np.where(keep, solution[..., 0], 0.0), k, float(radius_m))
