"""Fluid-filled elastic cylindrical shells (pipes): the exact solution and the thin-shell model."""

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.scattering.bodies import Elastic, Fluid, Shell
from acoustisim.scattering.form_function import cross_sections, form_function
from acoustisim.scattering.modal import modal_coefficients
from acoustisim.scattering.shell import shell_coefficients, thin_shell_coefficients

WATER = Fluid(998.2, 1482.4)
AIR = Fluid(1.2, 343.0)
STEEL = Elastic(7850.0, 5900.0, 3200.0)
PVC = Elastic(1380.0, 2380.0, 1060.0)
RADIUS = 0.025
LOW_BAND = np.linspace(2e3, 60e3, 120)  # ka 0.2-6: k_L h << 1, the thin-shell regime


def backscatter(coefficients):
    return form_function(coefficients, [np.pi])[:, 0]


@pytest.mark.parametrize("wall", [STEEL, PVC], ids=["steel", "pvc"])
def test_exact_shell_converges_to_the_thin_shell_model_as_the_wall_thins(wall):
    # Air-filled pipes (the wall's stiffness and inertia dominate: the thin-shell regime).
    # Thin-shell theory neglects O(h / a) terms (thickness variation of the stress, rotary
    # inertia, loads applied at a and b rather than across the wall): the median relative
    # difference of the backscatter form function must fall below h / a and decrease as the
    # wall thins (measured: steel 0.030, 0.009, 0.0035, 0.0012 for h/a = 0.04 ... 0.005).
    medians = []
    for h_over_a in (0.04, 0.02, 0.01, 0.005):
        shell = Shell(wall, h_over_a * RADIUS, AIR)
        exact = backscatter(shell_coefficients(shell, RADIUS, LOW_BAND, WATER))
        thin = backscatter(thin_shell_coefficients(shell, RADIUS, LOW_BAND, WATER))
        medians.append(np.median(np.abs(exact - thin) / np.abs(exact)))
        assert medians[-1] < h_over_a
    assert all(later < earlier for earlier, later in zip(medians, medians[1:]))


def test_shell_of_water_in_water_is_transparent():
    # An annulus with the water's density and speeds (shear speed ~0) around water scatters
    # nothing: |A_n| below 1e-6 (measured 1e-8, from the residual shear modulus
    # rho c_S^2 = 1e-3 Pa; a real wall of 0.4 mm gives |A_n| of order 1e-2).
    shell = Shell(Elastic(WATER.density_kg_m3, WATER.sound_speed_m_s, 1e-3), 0.01, WATER)
    got = shell_coefficients(shell, RADIUS, np.array([300e3, 500e3, 700e3]), WATER)
    assert np.max(np.abs(got.coefficients)) < 1e-6


@pytest.mark.parametrize("fill", [WATER, AIR], ids=["water", "air"])
def test_lossless_shell_conserves_energy(fill):
    # Lossless wall and fill: per order |1 + 2 A_n| = 1, extinction = scattered power (rounding).
    shell = Shell(PVC, 0.003, fill)
    got = shell_coefficients(shell, RADIUS, np.linspace(300e3, 700e3, 41), WATER)
    np.testing.assert_allclose(np.abs(1 + 2 * got.coefficients), 1.0, atol=1e-11)
    sections = cross_sections(got)
    np.testing.assert_allclose(sections.extinction, sections.scattering, rtol=1e-10)


def test_shell_is_the_package_body_of_a_cylinder_and_rejects_bad_walls():
    shell = Shell(PVC, 0.003, AIR)
    a = modal_coefficients("cylinder", shell, RADIUS, [500e3], WATER)
    b = shell_coefficients(shell, RADIUS, [500e3], WATER)
    np.testing.assert_array_equal(a.coefficients, b.coefficients)
    with pytest.raises(InputError, match="thickness"):
        shell_coefficients(Shell(PVC, 0.03, AIR), RADIUS, [500e3], WATER)
    with pytest.raises(InputError, match="solid"):
        Shell(Elastic(1000.0, 1500.0), 0.003, AIR)
    with pytest.raises(InputError, match="cylinder"):
        modal_coefficients("sphere", shell, RADIUS, [500e3], WATER)
