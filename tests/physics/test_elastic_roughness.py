"""Coherent reflection from a rough surface (Kirchhoff / Eckart) and its energy bookkeeping."""

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.scattering.roughness import coherent_factor, rough_reflection

C = 1482.4


def test_issue_example_half_millimetre_floor_loses_about_5_db_at_30_degrees():
    # h = 0.5 mm, 500 kHz, 30 deg grazing: chi = exp(-2 (k h / 2)^2), k = 2119.4 /m:
    # 20 log10 chi = -4.88 dB (issue 17: "about 5 dB").
    k = 2 * np.pi * 500e3 / C
    chi = coherent_factor([k], 0.5e-3, [np.sin(np.radians(30.0))])[0, 0]
    assert chi == pytest.approx(np.exp(-2 * (k * 0.5e-3 * 0.5) ** 2), rel=1e-14)
    assert 20 * np.log10(chi) == pytest.approx(-4.88, abs=0.01)


def test_factor_is_the_mean_phase_of_gaussian_heights():
    # Independent: the mean of exp(2 i k zeta sin g) over sampled Gaussian heights (seeded,
    # 400000 samples: standard error 1/sqrt(2 N) ~ 1.1e-3) against the closed form, over bins
    # and angles; tolerance 5 standard errors.
    rng = np.random.default_rng(2024)
    heights = rng.normal(0.0, 0.4e-3, 400_000)
    k = 2 * np.pi * np.array([200e3, 500e3, 800e3]) / C
    sin_g = np.sin(np.radians([10.0, 30.0, 60.0, 90.0]))
    mean_phase = np.array([[np.mean(np.exp(2j * kk * s * heights)) for kk in k] for s in sin_g])
    chi = coherent_factor(k, 0.4e-3, sin_g)
    assert np.max(np.abs(mean_phase - chi)) < 5 * 1.1e-3
    # the incoherent part of the sampled field: <|e|^2> - |<e>|^2 = 1 - chi^2 (energy kept)
    np.testing.assert_allclose(1.0 - np.abs(mean_phase) ** 2, 1.0 - chi**2, atol=1e-2)


def test_energy_is_conserved_coherent_plus_diffuse_is_the_reflected_energy():
    # |R chi|^2 + |R|^2 (1 - chi^2) = |R|^2 per row and bin (to rounding), and the Lambert
    # strength that carries the diffuse part scatters exactly that energy: the Lambert pattern
    # mu sin(g_i) sin(g_s) integrated over the half space (numerical quadrature over the
    # scattered direction) gives pi mu sin(g_i), i.e. diffuse_energy times the incident power
    # per unit area sin(g_i).
    r = np.array([0.38 + 0.0j, -1.0, 0.72 * np.exp(0.3j)])
    k = 2 * np.pi * np.linspace(300e3, 700e3, 9) / C
    sin_g = np.sin(np.radians([15.0, 45.0, 80.0]))
    split = rough_reflection(r, k, 0.5e-3, sin_g)
    total = np.abs(split.coherent) ** 2 + split.diffuse_energy
    np.testing.assert_allclose(total, np.broadcast_to(np.abs(r[:, None]) ** 2, total.shape), rtol=1e-14)
    elevation = np.linspace(0.0, np.pi / 2, 20001)  # grazing angle of the scattered direction
    weights = np.sin(elevation) * np.cos(elevation)  # sin(g_s) times the solid-angle element / d(azimuth)
    lambert_integral = 2 * np.pi * np.trapezoid(weights, elevation)  # = pi
    assert lambert_integral == pytest.approx(np.pi, rel=1e-8)
    np.testing.assert_allclose(split.lambert_mu * lambert_integral, split.diffuse_energy, rtol=1e-8)


def test_smooth_surface_and_normal_limits():
    k = np.array([1000.0, 3000.0])
    np.testing.assert_array_equal(coherent_factor(k, 0.0, [0.5, 1.0]), 1.0)
    np.testing.assert_array_equal(coherent_factor(k, 1e-3, [0.0]), 1.0)  # grazing: no loss
    assert np.all(np.diff(coherent_factor(k, 1e-3, [0.2, 0.5, 1.0])[:, 0]) < 0)  # steeper loses more
    with pytest.raises(InputError, match="rms_height_m"):
        coherent_factor(k, -1e-3, [0.5])
