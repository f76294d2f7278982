"""The elastic reflection model (water on an elastic solid half-space) of ``acoustisim.materials``
against its limits, energy conservation, the Rayleigh wave and the boundary conditions solved
numerically (``support.elastic_interface``, an independent derivation)."""

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.materials import Material, get_material, material_library, upper_root
from acoustisim.medium import Medium
from support.elastic_interface import ElasticHalfSpace, solve_interface

WATER = Medium(water="fresh", temperature_c=20.0)
RHO_W, C_W = WATER.density, WATER.sound_speed
SOLIDS = ("pvc", "steel", "aluminium", "glass", "concrete")
GRID_RAD = np.radians(np.linspace(0.0, 89.95, 1800))


def lossless(material: Material) -> Material:
    return replace(material, compressional_loss_factor=0.0, shear_loss_factor=0.0)


def half_space(material: Material) -> ElasticHalfSpace:
    return ElasticHalfSpace(RHO_W, C_W, material.density_kg_m3, material.sound_speed_m_s, material.shear_speed_m_s,
                            material.compressional_loss_factor, material.shear_loss_factor)


def critical_angles(material: Material) -> list[float]:
    """The compressional and shear critical angles (rad) that exist (speed above the water's)."""
    return [float(np.arcsin(C_W / c)) for c in (material.sound_speed_m_s, material.shear_speed_m_s) if c > C_W]


def away_from_critical(material: Material, margin_rad: float = 1e-4) -> np.ndarray:
    """GRID_RAD without the angles within ``margin_rad`` of a critical angle."""
    keep = np.ones(GRID_RAD.size, dtype=bool)
    for angle in critical_angles(material):
        keep &= np.abs(GRID_RAD - angle) > margin_rad
    return GRID_RAD[keep]


def rayleigh_speed(material: Material) -> float:
    """c_R of the free (lossless) half-space: the root in (0, 1) of Rayleigh's cubic in
    x = (c_R / c_S)^2, x^3 - 8 x^2 + (24 - 16 k) x - 16 (1 - k) = 0, k = (c_S / c_L)^2
    (Viktorov, *Rayleigh and Lamb Waves*, 1967, eq. 1.9)."""
    k = (material.shear_speed_m_s / material.sound_speed_m_s) ** 2
    roots = np.roots([1.0, -8.0, 24.0 - 16.0 * k, -16.0 * (1.0 - k)])
    (x,) = [r.real for r in roots if abs(r.imag) < 1e-12 and 0.0 < r.real < 1.0]
    return material.shear_speed_m_s * float(np.sqrt(x))


def test_the_built_in_solids_reflect_elastically_and_the_others_keep_their_models():
    library = material_library()
    assert {name for name, m in library.items() if m.model == "elastic"} == {*SOLIDS, "steel-machined", "rubber"}
    assert library["sand"].model == "fluid" and library["pvc-pipe-air"].model == "fixed"
    assert library["rigid"].model == "rigid" and library["air"].model == "pressure-release"


def test_upper_root_picks_the_wave_that_decays_into_the_solid():
    # Im >= 0 whatever the sign of a zero imaginary part (numpy's sqrt(-4 - 0j) is -2j), and the
    # principal root (Re > 0) where it already has Im >= 0.
    values = np.array([complex(-4.0, -0.0), complex(-4.0, 0.0), 4.0, complex(3.0, -4.0), complex(3.0, 4.0)])
    np.testing.assert_array_equal(upper_root(values), [2j, 2j, 2.0, complex(-2.0, 1.0), complex(2.0, 1.0)])


def test_shapes_follow_the_cosines():
    steel = get_material("steel")
    assert np.shape(steel.reflection_coefficient(0.5, RHO_W, C_W)) == ()
    assert steel.reflection_coefficient(np.full((4, 3), 0.5), RHO_W, C_W).shape == (4, 3)


@pytest.mark.parametrize("name", [*SOLIDS, "rubber"])
def test_normal_incidence_is_the_compressional_impedance_formula(name):
    # R(0) = (Z_L - Z_w) / (Z_L + Z_w) with the complex Z_L = rho c~_L of the lossy solid: shear
    # plays no part at normal incidence. The closed form takes other operations: 1e-14 is rounding.
    material = get_material(name)
    z_l = material.density_kg_m3 * material.sound_speed_m_s / (1.0 + 0.5j * material.compressional_loss_factor)
    z_w = RHO_W * C_W
    r = material.reflection_coefficient(1.0, RHO_W, C_W)
    assert abs(r - (z_l - z_w) / (z_l + z_w)) < 1e-14
    # The losses change Z_L by the factor 1 / (1 + i eta_L / 2), hence R by at most eta_L / 4 to
    # first order (dR / dln Z_L = 2 Z_L Z_w / (Z_L + Z_w)^2 <= 1/2): eta_L / 2 bounds it.
    eta = material.compressional_loss_factor
    assert 0.0 < abs(r - lossless(material).reflection_coefficient(1.0, RHO_W, C_W)) < 0.5 * eta


def test_without_shear_it_is_the_fluid_formula():
    # c_S = 0: the same coefficient as the fluid model at every angle, past the critical angle
    # too (different operations: rounding, a few 1e-16).
    fluid = Material("pvc-fluid", 1380.0, 2380.0, 0.0, "fluid")
    elastic = replace(fluid, model="elastic")
    cosines = np.cos(GRID_RAD)
    np.testing.assert_allclose(elastic.reflection_coefficient(cosines, RHO_W, C_W),
                               fluid.reflection_coefficient(cosines, RHO_W, C_W), rtol=0.0, atol=1e-14)


def test_as_the_shear_speed_vanishes_it_tends_to_the_fluid_formula_as_its_square():
    # The shear terms of the Rayleigh function G are 4 v^2 sin^2 t (from cos^2 2 t_S) and
    # 4 v^3 sin^2 t cos t_S a_L (v = c_S / c_w): R - R_fluid = O(c_S^2). Over three decades of
    # c_S the worst difference over the angles, divided by c_S^2, stays constant to 1 % (the
    # next term is O(c_S^3), 1e-3 of it at c_S = 10 m/s), and it vanishes with c_S.
    fluid = Material("pvc-fluid", 1380.0, 2380.0, 0.0, "fluid")
    cosines = np.cos(GRID_RAD)
    exact = fluid.reflection_coefficient(cosines, RHO_W, C_W)
    scaled = []
    for shear in (10.0, 1.0, 0.1):
        solid = replace(fluid, shear_speed_m_s=shear, model="elastic")
        difference = np.max(np.abs(solid.reflection_coefficient(cosines, RHO_W, C_W) - exact))
        scaled.append(difference / shear**2)
    assert scaled[0] > 0.0
    np.testing.assert_allclose(scaled, scaled[0], rtol=0.01)


@pytest.mark.parametrize("losses", [False, True])
@pytest.mark.parametrize("name", SOLIDS)
def test_against_the_boundary_conditions_solved_numerically(name, losses):
    # Independent method: the 3 x 3 system of u_z, sigma_zz and sigma_xz continuity, from the
    # displacement fields (support.elastic_interface), with and without the materials' losses.
    # Both are exact; they differ by rounding, amplified by the conditioning of the 3 x 3 system
    # (measured below 1e-13 relative; the system degenerates at the critical angles, left out
    # within 1e-4 rad): 1e-11 relative.
    material = get_material(name) if losses else lossless(get_material(name))
    angles = away_from_critical(material)
    expected = solve_interface(half_space(material), angles).reflection
    got = material.reflection_coefficient(np.cos(angles), RHO_W, C_W)
    np.testing.assert_allclose(got, expected, rtol=1e-11)


@pytest.mark.parametrize("name", SOLIDS)
def test_lossless_energy_is_conserved(name):
    # |R|^2 + the compressional and shear energy fluxes into the solid (from the amplitudes of
    # the numerical solution, 0 for an evanescent wave) = 1 below, between and past the critical
    # angles: an invariant the formula cannot meet by construction. Rounding only: 1e-12.
    material = lossless(get_material(name))
    angles = away_from_critical(material)
    solution = solve_interface(half_space(material), angles)
    r = material.reflection_coefficient(np.cos(angles), RHO_W, C_W)
    balance = np.abs(r) ** 2 + solution.compressional_flux + solution.shear_flux
    np.testing.assert_allclose(balance, 1.0, rtol=0.0, atol=1e-12)
    # Shear carries energy wherever it propagates: |R| < 1 below the last critical angle.
    last = max(critical_angles(material), default=np.pi / 2)
    assert np.all(solution.shear_flux[(angles > 0.01) & (angles < last)] > 0.0)


def test_total_reflection_past_the_shear_critical_angle_of_steel():
    # c_S (3200 m/s) > c_w: past asin(c_w / c_S) both waves are evanescent and a lossless solid
    # reflects everything, |R| = 1 to rounding; between the critical angles the shear wave
    # carries energy away (|R| < 1, down to -0.8 dB for steel).
    steel = lossless(get_material("steel"))
    compressional, shear = critical_angles(steel)
    past = np.linspace(shear + 1e-6, np.pi / 2 - 1e-6, 400)
    np.testing.assert_allclose(np.abs(steel.reflection_coefficient(np.cos(past), RHO_W, C_W)), 1.0, atol=1e-13)
    between = np.linspace(compressional + 1e-3, shear - 1e-3, 100)
    level = 20 * np.log10(np.abs(steel.reflection_coefficient(np.cos(between), RHO_W, C_W)))
    assert np.all(level < -0.01) and level.min() < -0.5


def test_pvc_never_reflects_totally():
    # c_S (1060 m/s) < c_w: the shear wave propagates at every angle, so |R| < 1 up to grazing,
    # where the fluid model (shear ignored) claims |R| = 1 past 38.5 deg (R -> -1 at grazing
    # only, as for any interface).
    pvc = lossless(get_material("pvc"))
    assert critical_angles(pvc) == [pytest.approx(np.arcsin(C_W / 2380.0))]
    angles = np.linspace(0.0, np.radians(89.9), 900)
    assert np.all(np.abs(pvc.reflection_coefficient(np.cos(angles), RHO_W, C_W)) < 1.0 - 1e-4)


def test_the_rayleigh_wave_of_steel():
    steel = get_material("steel")
    free = lossless(steel)
    theta_r = float(np.arcsin(C_W / rayleigh_speed(steel)))  # 30.01 deg
    # 1. Exactly at the free Rayleigh slowness sin t = c_w / c_R the Rayleigh function G of the
    #    formula vanishes and R = -1 (the cubic's root is exact to rounding; dR/dt there is about
    #    300 /rad, so 1e-9 leaves room for the root's last digits).
    assert abs(free.reflection_coefficient(np.cos(theta_r), RHO_W, C_W) + 1.0) < 1e-9
    # 2. The phase of R turns by -2 pi through the leaky Rayleigh angle, more than half of it
    #    within +/-0.5 deg; the fastest turn lies within 0.05 deg of t_R (the water loading moves
    #    the leaky pole off the free Rayleigh slowness to second order in rho_w / rho only: 0.02 deg).
    near = np.linspace(theta_r - np.radians(0.5), theta_r + np.radians(0.5), 20001)
    phase = np.unwrap(np.angle(free.reflection_coefficient(np.cos(near), RHO_W, C_W)))
    assert phase[-1] - phase[0] < -np.pi
    steepest = near[np.argmax(np.abs(np.gradient(phase, near)))]
    assert abs(np.degrees(steepest - theta_r)) < 0.05
    # 3. With steel's small losses the leaky wave absorbs: |R| dips there (the Rayleigh dip, about
    #    -2.4 dB at the library's eta), while elsewhere past the shear critical angle it stays
    #    within 0.3 dB of total reflection.
    shear = critical_angles(steel)[1]
    past = np.linspace(shear + 1e-4, np.radians(89.0), 200001)
    level = 20 * np.log10(np.abs(steel.reflection_coefficient(np.cos(past), RHO_W, C_W)))
    deepest = past[np.argmin(level)]
    assert abs(np.degrees(deepest - theta_r)) < 0.05 and level.min() < -2.0
    assert level[np.abs(past - theta_r) > np.radians(1.0)].min() > -0.3


def test_fluid_model_overstates_the_oblique_echoes_of_pvc_and_concrete():
    # The reason for the model (physics.md section 3): past the compressional critical angle the
    # fluid model gives |R| = 1; the elastic model keeps PVC below -3 dB from 40 to 80 deg and
    # concrete below -1 dB everywhere (the Rayleigh dip at 42-45 deg: below -8 dB, losses
    # eta_S = 0.08). Figures from the formula, checked against the 3 x 3 solution above.
    angles = np.radians(np.linspace(40.0, 80.0, 81))
    for name, bound in (("pvc", -3.0), ("concrete", -1.0)):
        material = get_material(name)
        elastic = 20 * np.log10(np.abs(material.reflection_coefficient(np.cos(angles), RHO_W, C_W)))
        fluid = 20 * np.log10(np.abs(replace(material, model="fluid").reflection_coefficient(np.cos(angles), RHO_W,
                                                                                                C_W)))
        np.testing.assert_allclose(fluid, 0.0, atol=1e-12)
        assert elastic.max() < bound
    dip = np.radians([42.0, 45.0])
    assert np.all(20 * np.log10(np.abs(get_material("concrete").reflection_coefficient(np.cos(dip), RHO_W, C_W)))
                  < -8.0)
