"""Independent references for the elastic modal series (tests only).

- ``boundary_residuals_cylinder`` / ``_sphere``: the solved fields put back into the boundary
  conditions written directly from continuum mechanics: displacement from the potentials by
  finite differences, strain and stress sigma = lambda tr(eps) I + 2 mu eps from finite
  differences of the displacement, in Cartesian coordinates, with ``scipy.special``'s Bessel
  functions (not the package's recurrences). Also the Navier equation in the solid.
- ``cramer_coefficients``: A_n of the solid cylinder or sphere from the 3 x 3 system
  eliminated by hand (Cramer's rule on the solid's 2 x 2 block: the surface-impedance form of
  Faran 1951), with ``scipy.special`` functions, one scalar formula per order.
- ``closed_form``: rigid, pressure-release and fluid bodies in closed form.
"""

from __future__ import annotations

import numpy as np
from scipy import special

WEIGHTS = np.array([1.0, -8.0, 8.0, -1.0]) / 12.0
OFFSETS = np.array([-2.0, -1.0, 1.0, 2.0])


def derivative(function, point, axis, step):
    """4th-order central difference of ``function`` (R^d -> C) along ``axis`` at ``point``."""
    total = 0.0
    for weight, offset in zip(WEIGHTS, OFFSETS):
        shifted = np.array(point, dtype=float)
        shifted[axis] += offset * step
        total = total + weight * function(shifted)
    return total / step


def cylinder_fields(n, k, k_l, k_t, a_coef, b_pot, c_pot):
    """Scalar functions of (x, y): water pressure, potentials Phi, Psi (order n)."""
    def polar(p):
        return np.hypot(p[0], p[1]), np.arctan2(p[1], p[0])

    def pressure(p):
        r, phi = polar(p)
        return (special.jv(n, k * r) + a_coef * special.hankel1(n, k * r)) * np.cos(n * phi)

    def phi_pot(p):
        r, phi = polar(p)
        return b_pot * special.jv(n, k_l * r) * np.cos(n * phi)

    def psi_pot(p):
        r, phi = polar(p)
        return c_pot * special.jv(n, k_t * r) * np.sin(n * phi)

    return pressure, phi_pot, psi_pot


def cylinder_displacement(phi_pot, psi_pot, step):
    """u = grad Phi + curl(Psi e_z) = (Phi_x + Psi_y, Phi_y - Psi_x), as a function of (x, y)."""
    def displacement(p):
        return np.array([derivative(phi_pot, p, 0, step) + derivative(psi_pot, p, 1, step),
                         derivative(phi_pot, p, 1, step) - derivative(psi_pot, p, 0, step)])
    return displacement


def stress_tensor(displacement, point, lam, mu, step, dims):
    """sigma = lambda tr(eps) I + 2 mu eps from finite differences of the displacement."""
    grad = np.array([[derivative(lambda p, i=i: displacement(p)[i], point, j, step) for j in range(dims)]
                     for i in range(dims)])
    strain = 0.5 * (grad + grad.T)
    return lam * np.trace(strain) * np.eye(dims) + 2.0 * mu * strain


def boundary_residuals_cylinder(n, omega, a, rho_w, k, body, a_coef, b_scaled, c_scaled, angle=0.3):
    """Relative residuals (normal displacement, normal stress, shear stress) at r = a."""
    k_l, k_t = body.compressional_wavenumber(omega), body.shear_wavenumber(omega)
    lam, mu = body.lame_moduli()
    rho_s = body.density_kg_m3
    b_pot, c_pot = b_scaled / (rho_s * omega**2), c_scaled / (rho_s * omega**2)
    pressure, phi_pot, psi_pot = cylinder_fields(n, k, k_l, k_t, a_coef, b_pot, c_pot)
    step = 2e-3 / abs(k_t)
    point = a * np.array([np.cos(angle), np.sin(angle)])
    normal, tangent = point / a, np.array([-np.sin(angle), np.cos(angle)])
    displacement = cylinder_displacement(phi_pot, psi_pot, step)
    sigma = stress_tensor(displacement, point, lam, mu, step, 2)
    u_solid = displacement(point) @ normal
    u_water = (normal[0] * derivative(pressure, point, 0, step) + normal[1] * derivative(pressure, point, 1, step)
               ) / (rho_w * omega**2)
    p = pressure(point)
    s_rr, s_rt = normal @ sigma @ normal, tangent @ sigma @ normal
    scale_u = max(abs(u_solid), abs(u_water))
    scale_s = max(abs(s_rr), abs(p))
    # Navier equation inside: mu lap u + (lambda + mu) grad div u + rho w^2 u = 0; third
    # derivatives of the potentials by nested differences: a larger step (truncation
    # ~(k h)^4 = 1e-6 at k h = 0.03, rounding 1e-16 / (k h)^3 ~ 4e-12)
    step = 3e-2 / abs(k_t)
    displacement = cylinder_displacement(phi_pot, psi_pot, step)
    inner = 0.6 * point
    lap = sum(derivative(lambda q, j=j: derivative(lambda s: displacement(s), q, j, step), inner, j, step)
              for j in range(2))
    div = lambda q: derivative(lambda s: displacement(s)[0], q, 0, step) + derivative(  # noqa: E731
        lambda s: displacement(s)[1], q, 1, step)
    grad_div = np.array([derivative(div, inner, j, step) for j in range(2)])
    navier = mu * lap + (lam + mu) * grad_div + rho_s * omega**2 * displacement(inner)
    navier_scale = abs(rho_s * omega**2) * np.linalg.norm(displacement(inner))
    return (abs(u_solid - u_water) / scale_u, abs(s_rr + p) / scale_s, abs(s_rt) / scale_s,
            np.linalg.norm(navier) / navier_scale)


def boundary_residuals_sphere(n, omega, a, rho_w, k, body, a_coef, b_scaled, c_scaled, angle=0.7):
    """As for the cylinder, for the sphere (axisymmetric fields in 3-D, points with y = 0)."""
    k_l, k_t = body.compressional_wavenumber(omega), body.shear_wavenumber(omega)
    lam, mu = body.lame_moduli()
    rho_s = body.density_kg_m3
    b_pot, c_pot = b_scaled / (rho_s * omega**2), c_scaled / (rho_s * omega**2)

    def spherical(p):
        r = np.linalg.norm(p)
        return r, p[2] / r

    def pressure(p):
        r, mu_ = spherical(p)
        hn = special.spherical_jn(n, k * r) + 1j * special.spherical_yn(n, k * r)
        return (special.spherical_jn(n, k * r) + a_coef * hn) * special.eval_legendre(n, mu_)

    def phi_pot(p):
        r, mu_ = spherical(p)
        return b_pot * special.spherical_jn(n, k_l * r) * special.eval_legendre(n, mu_)

    def psi_pot(p):
        r, mu_ = spherical(p)
        return c_pot * special.spherical_jn(n, k_t * r) * special.eval_legendre(n, mu_)

    def g_pot(p):  # d(r psi)/dr, analytic in r
        r, mu_ = spherical(p)
        x = k_t * r
        return c_pot * (special.spherical_jn(n, x) + x * special.spherical_jn(n, x, derivative=True)) * \
            special.eval_legendre(n, mu_)

    step = 2e-3 / abs(k_t)

    def displacement(p):
        # u = grad Phi + curl curl (r Psi) = grad Phi + grad(d(r Psi)/dr) + k_T^2 r Psi
        return np.array([derivative(phi_pot, p, j, step) + derivative(g_pot, p, j, step) for j in range(3)]) + \
            k_t**2 * np.asarray(p) * psi_pot(p)

    point = a * np.array([np.sin(angle), 0.0, np.cos(angle)])
    normal, tangent = point / a, np.array([np.cos(angle), 0.0, -np.sin(angle)])
    sigma = stress_tensor(displacement, point, lam, mu, step, 3)
    u_solid = displacement(point) @ normal
    u_water = sum(normal[j] * derivative(pressure, point, j, step) for j in range(3)) / (rho_w * omega**2)
    p = pressure(point)
    s_rr, s_rt = normal @ sigma @ normal, tangent @ sigma @ normal
    scale_u = max(abs(u_solid), abs(u_water))
    scale_s = max(abs(s_rr), abs(p))
    return abs(u_solid - u_water) / scale_u, abs(s_rr + p) / scale_s, abs(s_rt) / scale_s


def _cyl(n, x):
    return special.jv(n, x), special.jvp(n, x), special.hankel1(n, x), special.h1vp(n, x)


def _sph(n, x):
    j, jp = special.spherical_jn(n, x), special.spherical_jn(n, x, derivative=True)
    h = j + 1j * special.spherical_yn(n, x)
    hp = jp + 1j * special.spherical_yn(n, x, derivative=True)
    return j, jp, h, hp


def closed_form(shape, kind, n, x, impedance_ratio=None, x_inner=None):
    """A_n of rigid (-Z'/H'), soft (-Z/H) and fluid bodies (Z = J or j; impedance_ratio =
    rho_w c_w / (rho_1 c_1), x_inner = k_1 a)."""
    z, zp, h, hp = (_cyl if shape == "cylinder" else _sph)(n, x)
    if kind == "rigid":
        return -zp / hp
    if kind == "soft":
        return -z / h
    zi, zip_, _, _ = (_cyl if shape == "cylinder" else _sph)(n, x_inner)
    g = impedance_ratio * zip_ / zi
    return -(zp - g * z) / (hp - g * h)


def cramer_coefficients(shape, n, x, x_l, x_t, density_ratio):
    """A_n of a solid cylinder or sphere, eliminated by hand from the boundary conditions.

    The solid's 2 x 2 block (normal stress and shear stress in b, c) relates the normal
    displacement at the surface to the pressure there: for unit surface pressure (sigma_rr =
    -1, zero shear) the solid's normal displacement (scaled by rho_w w^2 a^2) is Y_s; then
    A_n = -(x Z'(x) + Y_s Z(x)) / (x H'(x) + Y_s H(x)).
    """
    z_l, zp_l = (special.jv(n, x_l), special.jvp(n, x_l)) if shape == "cylinder" else (
        special.spherical_jn(n, x_l), special.spherical_jn(n, x_l, derivative=True))
    z_t, zp_t = (special.jv(n, x_t), special.jvp(n, x_t)) if shape == "cylinder" else (
        special.spherical_jn(n, x_t), special.spherical_jn(n, x_t, derivative=True))
    m = n if shape == "cylinder" else n * (n + 1)
    gamma = 1.0 / x_t**2
    if shape == "cylinder":
        s_b = (2 * n * n * gamma - 1.0) * z_l - 2.0 * gamma * x_l * zp_l
        s_c = 2.0 * n * gamma * (x_t * zp_t - z_t)
        t_b = 2.0 * n * (z_l - x_l * zp_l)
        t_c = (x_t**2 - 2.0 * n * n) * z_t + 2.0 * x_t * zp_t
    else:
        s_b = (2 * m * gamma - 1.0) * z_l - 4.0 * gamma * x_l * zp_l
        s_c = 2.0 * m * gamma * (x_t * zp_t - z_t)
        t_b = 2.0 * (x_l * zp_l - z_l)
        t_c = (2.0 * m - x_t**2 - 2.0) * z_t - 2.0 * x_t * zp_t
    axial = np.asarray(n) == 0  # order 0: the shear potential does not couple
    t_b, t_c, s_c = np.where(axial, 0.0, t_b), np.where(axial, 1.0, t_c), np.where(axial, 0.0, s_c)
    det = s_b * t_c - s_c * t_b
    # sigma_rr block = -p_surface = -1 (unit pressure), shear = 0
    b = -t_c / det
    c = t_b / det
    displacement = density_ratio * (b * x_l * zp_l + c * m * z_t)  # rho_w w^2 a^2 u_r / a per unit p
    z, zp, h, hp = (_cyl if shape == "cylinder" else _sph)(n, x)
    # continuity: x (Z' + A H') = Y (Z + A H)  ->  A = -(x Z' - Y Z) / (x H' - Y H)
    return -(x * zp - displacement * z) / (x * hp - displacement * h)
