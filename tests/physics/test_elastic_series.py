"""The exact modal series of elastic cylinders and spheres against independent references.

References (coded independently in ``tests/support/elastic_references.py``): the boundary
conditions and the Navier equation written directly in Cartesian coordinates with finite
differences; the coefficients eliminated by hand (the surface-impedance form, scalar formula per
order, scipy's Bessel functions); the closed forms of the rigid, soft and fluid limits; the
optical theorem.
"""

import numpy as np
import pytest
from scipy import special

from acoustisim.scattering.bodies import Elastic, Fluid, PressureRelease, Rigid
from acoustisim.scattering.form_function import cross_sections, form_function
from acoustisim.scattering.linear_systems import solve_equilibrated
from acoustisim.scattering.modal import boundary_system, modal_coefficients
from acoustisim.scattering.series import order_keep_mask
from acoustisim.scattering.special import bessel_pair
from support.elastic_references import (boundary_residuals_cylinder, boundary_residuals_sphere, closed_form,
                                        cramer_coefficients)

WATER = Fluid(998.2, 1482.4)
PVC = Elastic(1380.0, 2380.0, 1060.0, 0.03, 0.05)
PVC_LOSSLESS = Elastic(1380.0, 2380.0, 1060.0)
STEEL = Elastic(7850.0, 5900.0, 3200.0, 0.002, 0.003)
ALUMINIUM = Elastic(2700.0, 6320.0, 3130.0)
BAND = np.linspace(300e3, 700e3, 201)
RADIUS = 0.025
SHAPES = ("cylinder", "sphere")


def weights(shape, n):
    return 2.0 * n + 1.0 if shape == "sphere" else np.where(n == 0, 1.0, 2.0)


@pytest.mark.parametrize("spherical", [False, True])
@pytest.mark.parametrize("kind", ["J", "Y", "H"])
def test_bessel_recurrences_match_scipy(kind, spherical):
    # The package's recurrences against scipy's direct evaluation at the arguments the series
    # uses (water ka, complex solid arguments, far-field k rho): agreement to about 1e-13
    # relative (rounding accumulated over ~100 recurrence steps); 1e-11 allows for it.
    orders = np.arange(0, 106)
    x = np.array([3.3 + 0.1j, 20.0, 55.5 + 0.5j, 104.0 + 2.6j, 0.9, 13.0])
    if kind == "J":
        x = x if not spherical else x
    if kind == "Y" and spherical:
        x = x.real
    value, derivative = bessel_pair(kind, orders, x, spherical=spherical)
    n, z = orders[None, :], x[:, None]
    if spherical:
        base = {"J": special.spherical_jn, "Y": special.spherical_yn}
        if kind == "H":
            ref = special.spherical_jn(n, z) + 1j * special.spherical_yn(n, z.real)
            ref_d = special.spherical_jn(n, z, True) + 1j * special.spherical_yn(n, z.real, True)
            value, derivative = bessel_pair(kind, orders, x.real, spherical=True)
            ref = special.spherical_jn(n, z.real) + 1j * special.spherical_yn(n, z.real)
            ref_d = special.spherical_jn(n, z.real, True) + 1j * special.spherical_yn(n, z.real, True)
        else:
            ref, ref_d = base[kind](n, z), base[kind](n, z, True)
    else:
        f, fp = {"J": (special.jv, special.jvp), "Y": (special.yv, special.yvp),
                 "H": (special.hankel1, special.h1vp)}[kind]
        ref, ref_d = f(n, z), fp(n, z)
    ok = np.isfinite(ref) & (np.abs(ref) > 1e-200) & (np.abs(ref) < 1e200)
    assert np.max(np.abs(value - ref)[ok] / np.abs(ref)[ok]) < 1e-11
    assert np.max(np.abs(derivative - ref_d)[ok] / np.abs(ref_d)[ok]) < 1e-11


@pytest.mark.parametrize("shape", SHAPES)
def test_rigid_soft_and_fluid_limits_match_the_closed_forms(shape):
    # Same assembly and solve as the elastic body (rows replaced); closed forms with scipy:
    # agreement to rounding (1e-12 absolute on |A_n| <= 1).
    band = BAND[::4]
    k = 2 * np.pi * band / WATER.sound_speed_m_s
    fluid = Elastic(1030.0, 1540.0)  # a fluid body: c_S = 0
    x_inner = 2 * np.pi * band / fluid.compressional_speed_m_s * RADIUS
    ratio = WATER.density_kg_m3 * WATER.sound_speed_m_s / (fluid.density_kg_m3 * fluid.compressional_speed_m_s)
    for body, kind in ((Rigid(), "rigid"), (PressureRelease(), "soft"), (fluid, "fluid")):
        got = modal_coefficients(shape, body, RADIUS, band, WATER)
        n = got.orders[None, :]
        want = closed_form(shape, kind, n, (k * RADIUS)[:, None], ratio, x_inner[:, None])
        keep = got.coefficients != 0
        np.testing.assert_allclose(got.coefficients[keep], want[keep], rtol=0, atol=1e-12)


@pytest.mark.parametrize("shape", SHAPES)
def test_elastic_body_tends_to_rigid_and_soft_limits(shape):
    # A very dense body is immovable, a very light one is pressure-release: |A - A_limit| falls
    # like the density ratio (the solid's admittance scales as rho_w / rho_s).
    f = np.array([350e3, 520e3, 690e3])
    rigid = modal_coefficients(shape, Rigid(), RADIUS, f, WATER).coefficients
    soft = modal_coefficients(shape, PressureRelease(), RADIUS, f, WATER).coefficients
    errors = []
    for density in (1e7, 1e9):
        dense = modal_coefficients(shape, Elastic(density, 5900.0, 3200.0), RADIUS, f, WATER).coefficients
        errors.append(np.max(np.abs(dense - rigid)))
    assert errors[1] < errors[0] / 30.0 and errors[1] < 1e-4
    errors = []
    for density in (1e-2, 1e-4):
        light = modal_coefficients(shape, Elastic(density, 2380.0, 1060.0), RADIUS, f, WATER).coefficients
        errors.append(np.max(np.abs(light - soft)))
    assert errors[1] < errors[0] / 30.0 and errors[1] < 1e-4


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("body", [PVC, STEEL, ALUMINIUM], ids=["pvc", "steel", "aluminium"])
def test_form_function_matches_the_hand_eliminated_series_to_a_hundredth_of_a_db(shape, body):
    # Independent formulation (scalar surface-impedance formula per order, scipy Bessel
    # functions) over 300-700 kHz, backscatter and a bistatic angle: the 0.1 dB, met
    # with margin (differences are rounding, ~1e-9 dB; 0.01 dB would flag any real error).
    got = modal_coefficients(shape, body, RADIUS, BAND, WATER)
    n = got.orders[None, :]
    omega = 2 * np.pi * BAND
    x = (2 * np.pi * BAND / WATER.sound_speed_m_s * RADIUS)[:, None]
    x_l = (body.compressional_wavenumber(omega) * RADIUS)[:, None]
    x_t = (body.shear_wavenumber(omega) * RADIUS)[:, None]
    with np.errstate(all="ignore"):  # beyond the truncation scipy's Y_n may overflow: masked
        reference = np.where(got.coefficients != 0,
                             cramer_coefficients(shape, n, x, x_l, x_t, WATER.density_kg_m3 / body.density_kg_m3), 0)
    angles = np.array([np.pi, np.pi - np.radians(3.0)])
    mine = form_function(got, angles)
    theirs = form_function(got._replace(coefficients=reference), angles)
    level = 20 * np.log10(np.abs(mine) / np.abs(theirs))
    assert np.max(np.abs(level)) < 0.01
    assert np.max(np.abs(mine - theirs) / np.abs(mine)) < 1e-8


@pytest.mark.parametrize("n", [0, 1, 3, 17, 40])
def test_cylinder_solution_satisfies_the_boundary_conditions_in_cartesian_form(n):
    # The solved (A, b, c) put back into the boundary conditions computed from scratch: the
    # displacement from the potentials, strain and stress (sigma = lambda tr(eps) I + 2 mu eps)
    # by 4th-order finite differences (step 2e-3 / |k_T|: truncation ~(k h)^4 ~ 1e-11,
    # rounding ~1e-16 / (k h)^2 ~ 1e-10; measured 1e-9); residuals below 1e-6 relative (the
    # system's own rounding is 1e-14). Also the Navier equation inside, with third derivatives
    # by nested differences (truncation ~1e-6 at its step: tolerance 1e-4; a wrong Lame
    # modulus or wavenumber leaves O(eta) ~ 1e-2), which checks the complex Lame moduli
    # against the complex wavenumbers.
    f = np.array([500e3])
    omega = 2 * np.pi * f
    k = omega / WATER.sound_speed_m_s
    x = k * RADIUS
    orders, keep = order_keep_mask(x.astype(complex), 30)
    matrix, rhs = boundary_system("cylinder", PVC, x.astype(complex), omega, RADIUS, WATER, orders, keep)
    solution = solve_equilibrated(matrix, rhs)[0, n]
    residuals = boundary_residuals_cylinder(n, omega[0], RADIUS, WATER.density_kg_m3, k[0], PVC, *solution)
    assert max(residuals[:3] if n else residuals[:2]) < 1e-6
    assert residuals[3] < 1e-4


@pytest.mark.parametrize("n", [0, 1, 2, 9, 30])
def test_sphere_solution_satisfies_the_boundary_conditions_in_cartesian_form(n):
    # As for the cylinder, in 3-D: u = grad Phi + curl curl (r Psi); tolerance as there.
    f = np.array([450e3])
    omega = 2 * np.pi * f
    k = omega / WATER.sound_speed_m_s
    x = (k * RADIUS).astype(complex)
    orders, keep = order_keep_mask(x, 30)
    matrix, rhs = boundary_system("sphere", STEEL, x, omega, RADIUS, WATER, orders, keep)
    solution = solve_equilibrated(matrix, rhs)[0, n]
    residuals = boundary_residuals_sphere(n, omega[0], RADIUS, WATER.density_kg_m3, k[0], STEEL, *solution)
    assert max(residuals if n else residuals[:2]) < 1e-6


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("body", [PVC_LOSSLESS, ALUMINIUM, Rigid(), PressureRelease()],
                         ids=["pvc", "aluminium", "rigid", "soft"])
def test_optical_theorem_lossless_extinction_equals_scattered_power(shape, body):
    # Extinction from the forward amplitude against the scattered power integrated over all
    # directions by quadrature of |form function|^2 (exact for the truncated series: the
    # integrand is a trigonometric / Legendre polynomial of degree 2N): equal to rounding.
    got = modal_coefficients(shape, body, RADIUS, BAND[::40], WATER)
    k = np.real(got.wavenumber)
    n_max = got.orders[-1]
    if shape == "cylinder":
        theta = np.arange(4 * n_max + 4) * (2 * np.pi / (4 * n_max + 4))
        g = form_function(got, theta) * np.sqrt(np.pi * k * RADIUS)[:, None] / 2.0  # sum eps A cos
        scattered = 2.0 / (np.pi * k) * np.sum(np.abs(g) ** 2, axis=1) * (2 * np.pi / theta.size)
    else:
        mu, w = np.polynomial.legendre.leggauss(2 * n_max + 2)
        f_amp = form_function(got, np.arccos(mu)) * RADIUS / 2.0
        scattered = 2 * np.pi * np.sum(w * np.abs(f_amp) ** 2, axis=1)
    sections = cross_sections(got)
    np.testing.assert_allclose(sections.extinction, scattered, rtol=1e-11)
    np.testing.assert_allclose(sections.scattering, scattered, rtol=1e-11)
    # per order: |1 + 2 A_n| = 1 (unitarity)
    np.testing.assert_allclose(np.abs(1 + 2 * got.coefficients), 1.0, atol=1e-12)


@pytest.mark.parametrize("shape", SHAPES)
def test_lossy_bodies_absorb(shape):
    # With losses the extinction exceeds the scattered power (a passive body absorbs), by a
    # fraction that grows with the loss factors.
    absorbed = []
    for eta in (0.01, 0.05):
        body = Elastic(1380.0, 2380.0, 1060.0, eta, eta)
        sections = cross_sections(modal_coefficients(shape, body, RADIUS, BAND[::50], WATER))
        assert np.all(sections.absorption > 0.0)
        absorbed.append(np.mean(sections.absorption / sections.extinction))
    assert absorbed[1] > absorbed[0]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("body", [PVC_LOSSLESS, PVC, STEEL], ids=["pvc-lossless", "pvc", "steel"])
def test_series_converges_faster_than_exponentially_beyond_ka(shape, body):
    # Backscatter form function truncated at n = ka + e against e = 50, worst over 300-700 kHz.
    # Measured (cylinder, lossless PVC): e = 10: 5e-3, 15: 2e-5, 20: 1e-10, 25 and 30: 5e-13
    # (rounding). Shear whispering-gallery terms between ka and k_T a need about ka + 20; the
    # default ka + 30 sits at rounding. Tolerances: an order of magnitude above those.
    band = BAND[::2]
    reference = form_function(modal_coefficients(shape, body, RADIUS, band, WATER, 50), [np.pi])[:, 0]
    errors = {}
    for extra in (10, 15, 20, 30):
        short = form_function(modal_coefficients(shape, body, RADIUS, band, WATER, extra), [np.pi])[:, 0]
        errors[extra] = np.max(np.abs(short - reference) / np.abs(reference))
    assert errors[10] < 5e-2 and errors[20] < 1e-7 and errors[30] < 1e-11
    assert errors[15] < 1e-2 * errors[10] and errors[20] < 1e-2 * errors[15]  # faster than exponential
