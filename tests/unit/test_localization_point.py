"""Point targets: exact seed inverse, the printed eq. 4.31 erratum, general WLS, covariance."""

import numpy as np
import pytest

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.point import (
    DIFFERENCE_TOO_LARGE, NOT_FINITE, POINT_OK, SHORTER_THAN_BASELINE, fit_point, point_from_path_lengths,
    point_path_lengths, range_bearing_from_position, seed_bearing_eq_4_31, seed_path_lengths,
    seed_point_covariance, seed_point_status)


def test_round_trip_recovers_range_and_bearing():
    r = np.geomspace(0.1, 9.0, 40)[:, None, None]
    theta = np.radians(np.linspace(-30.0, 30.0, 61))[None, :, None]
    d = np.array([0.004, 0.01, 0.04, 0.065, 0.15])[None, None, :]
    r, theta, d = np.broadcast_arrays(r, theta, d)
    r1, r2 = seed_path_lengths(r, theta, d)
    got_r, got_t = point_from_path_lengths(r1, r2, d)
    # Range: relative 1e-9 (rounding of R^2 sums is ~1e-16 relative).
    np.testing.assert_allclose(got_r, r, rtol=1e-9, atol=0)
    # Bearing: relative 1e-9 where |theta| >= 1 deg. Near 0 the absolute error is set by rounding of
    # R1 - R2 (eps R / (2 d cos theta) <= 2.2e-16 x 18 m / 8 mm = 5e-13 rad), far below 1e-9 x 1 deg.
    tol = 1e-9 * np.maximum(np.abs(theta), np.radians(1.0))
    assert np.all(np.abs(got_t - theta) <= tol)


def test_printed_eq_4_31_doubles_the_bearing():
    # Erratum (physics.md section 7): the seed's printed denominator d (R1 R2 - 2 d^2) is about half
    # the correct d (R1^2 + R2^2 - 2 d^2), so sin(theta) comes out about doubled: 5 deg -> 10.05 deg.
    r1, r2 = seed_path_lengths(1.0, np.radians(5.0), 0.065)
    printed = np.degrees(seed_bearing_eq_4_31(r1, r2, 0.065))
    assert printed == pytest.approx(10.05, abs=0.01)
    _, exact = point_from_path_lengths(r1, r2, 0.065)
    assert np.degrees(exact) == pytest.approx(5.0, abs=1e-10)


def test_exact_formulas_against_brute_force_ellipse_intersection():
    # Independent method: intersect the two ellipses numerically on a fine bearing grid.
    d, r_true, th_true = 0.05, 2.3, np.radians(-17.0)
    r1, r2 = seed_path_lengths(r_true, th_true, d)
    th = np.radians(np.linspace(-40, 40, 400001))
    # On the left ellipse: |p| + |p - (-d, 0)| = R1 with p = rho (sin th, cos th): rho solves a quadratic.
    rho = (r1**2 - d**2) / (2 * (r1 + d * np.sin(th)))
    p = rho * np.stack([np.sin(th), np.cos(th)])
    mismatch = rho + np.hypot(p[0] - d, p[1]) - r2
    k = np.argmin(np.abs(mismatch))
    got_r, got_t = point_from_path_lengths(r1, r2, d)
    assert got_t == pytest.approx(th[k], abs=np.radians(80 / 400000))  # one grid step
    assert got_r == pytest.approx(rho[k], rel=1e-5)


@pytest.mark.parametrize(
    "r1, r2, expected",
    [(1.0, 1.0, POINT_OK), (np.nan, 1.0, NOT_FINITE), (0.05, 1.0, SHORTER_THAN_BASELINE),
     (1.0, 1.2, DIFFERENCE_TOO_LARGE), (1.0, 1.0 + 0.13 * 0.999, POINT_OK), (1.0, 1.0 + 0.13 * 1.001, DIFFERENCE_TOO_LARGE)],
)
def test_seed_status_of_bad_inputs(r1, r2, expected):
    # d = 65 mm: a path must exceed d and |R1 - R2| <= 2 d; at |R1 - R2| = 2 d the exact formula gives
    # |sin(theta)| = 2 (R2 + d)^2 / (2 (R2 + d)^2) = 1 exactly, so just inside is valid (bearing ~ -87 deg).
    assert str(seed_point_status(r1, r2, 0.065)) == expected
    r, th = point_from_path_lengths(r1, r2, 0.065)
    assert np.isnan(r) == (expected != POINT_OK) and np.isnan(th) == (expected != POINT_OK)


def test_seed_covariance_matches_monte_carlo():
    # 20000 draws: the sample variance of a unit-variance quantity has relative std sqrt(2/N) = 1 %, so
    # 10 % is a 10-sigma band; the linearisation error at sigma/d = 3e-3 is far smaller.
    rng = np.random.default_rng(7)
    d, r, th, sig = 0.065, 2.0, np.radians(20.0), 2e-4
    r1, r2 = seed_path_lengths(r, th, d)
    n = 20000
    gr, gt = point_from_path_lengths(r1 + sig * rng.standard_normal(n), r2 + sig * rng.standard_normal(n), d)
    cov = seed_point_covariance(r, th, d, sig, sig)
    z_r = (gr - r) / np.sqrt(cov[0, 0])
    z_t = (gt - th) / np.sqrt(cov[1, 1])
    assert np.var(z_r) == pytest.approx(1.0, rel=0.1)
    assert np.var(z_t) == pytest.approx(1.0, rel=0.1)
    e = np.stack([gr - r, gt - th], axis=1)
    maha = np.einsum("ni,ij,nj->n", e, np.linalg.inv(cov), e)
    assert np.mean(maha) == pytest.approx(2.0, rel=0.05)  # chi-square(2) mean; std of the mean 0.7 %


@pytest.mark.parametrize(
    "receivers",
    [
        [[-0.05, 0.0, 0.0], [0.0, 0.0, 0.0], [0.09, 0.0, 0.0]],       # unequal offsets
        [[-0.065, 0.0, 0.02], [0.0, 0.0, 0.0], [0.065, 0.0, -0.01]],  # receivers at different heights
        [[-0.065, 0.01, 0.0], [0.0, 0.0, 0.0], [0.065, -0.02, 0.0]],  # receivers not on the x axis
    ],
)
def test_general_wls_recovers_point_for_any_geometry(receivers):
    g = ArrayGeometry(np.zeros(3), np.array(receivers))
    for truth in ([0.4, 1.7, 0.0], [-0.9, 3.0, 0.0], [0.0, 0.3, 0.0]):
        lengths, _ = point_path_lengths(truth, g)
        fit = fit_point(lengths, np.full(3, 1e-4), g)
        assert fit.ok and fit.dof == 1
        # Noise-free: the WLS converges to rounding (1e-12 m on metre-scale positions).
        np.testing.assert_allclose(fit.parameters, truth[:2], atol=1e-11)


def test_general_wls_solves_height_when_the_array_is_not_collinear():
    g = ArrayGeometry(np.zeros(3), np.array([[-0.065, 0.0, 0.03], [0.0, 0.0, 0.0], [0.065, 0.0, -0.03]]))
    g2 = ArrayGeometry(np.zeros(3), np.array([[-0.065, 0.0, 0.03], [0.0, 0.0, 0.05], [0.065, 0.0, -0.03]]))
    for geom in (g2,):
        truth = np.array([0.3, 1.5, 0.1])
        lengths, _ = point_path_lengths(truth, geom)
        fit = fit_point(lengths, np.full(3, 1e-5), geom, solve_z=True, initial_m=[0.25, 1.45, 0.05])
        assert fit.ok and fit.dof == 0
        np.testing.assert_allclose(fit.parameters, truth, atol=1e-9)
    assert g.half_baseline_m == pytest.approx(np.hypot(0.13, 0.06) / 2)


def test_wls_covariance_matches_monte_carlo_with_centre_channel():
    # Centre channel as a third measurement (1 degree of freedom). 1000 trials: the variance of a
    # normalised error has relative std sqrt(2/1000) = 4.5 %, so 10 % is a 2.2-sigma band; the mean
    # Mahalanobis distance (chi-square 2) has relative std 3.2 %, checked to 10 %.
    rng = np.random.default_rng(3)
    g = ArrayGeometry(np.zeros(3), np.array([[-0.05, 0.0, 0.0], [0.0, 0.0, 0.0], [0.08, 0.0, 0.01]]))
    truth = np.array([0.5, 1.8, 0.0])
    lengths, _ = point_path_lengths(truth, g)
    sig = np.array([2e-4, 1e-4, 3e-4])
    errs, covs, chi2 = [], [], []
    for _ in range(1000):
        fit = fit_point(lengths + sig * rng.standard_normal(3), sig, g)
        errs.append(fit.parameters - truth[:2])
        covs.append(fit.covariance)
        chi2.append(fit.chi2)
    errs = np.array(errs)
    cov = np.mean(covs, axis=0)
    for k in range(2):
        assert np.var(errs[:, k] / np.sqrt(cov[k, k])) == pytest.approx(1.0, rel=0.1)
    maha = np.einsum("ni,ij,nj->n", errs, np.linalg.inv(cov), errs)
    assert np.mean(maha) == pytest.approx(2.0, rel=0.1)
    assert np.mean(chi2) == pytest.approx(1.0, rel=0.15)  # chi-square(1): std of the mean 4.5 %


def test_wls_matches_seed_solution_and_covariance_with_two_channels():
    g = ArrayGeometry.seed(0.065)
    r, th = 1.3, np.radians(12.0)
    r1, r2 = seed_path_lengths(r, th, 0.065)
    fit = fit_point([r1, np.nan, r2], [2e-4, np.nan, 2e-4], g)
    assert fit.ok and fit.dof == 0
    cov3 = np.zeros((3, 3))
    cov3[:2, :2] = fit.covariance
    rng_m, brg_deg, rng_sd, brg_sd = range_bearing_from_position([*fit.parameters, 0.0], cov3, g)
    c = seed_point_covariance(r, th, 0.065, 2e-4, 2e-4)
    assert rng_m == pytest.approx(r, rel=1e-12) and brg_deg == pytest.approx(12.0, rel=1e-10)
    # Two derivations of the same linearised covariance agree to rounding.
    assert rng_sd == pytest.approx(np.sqrt(c[0, 0]), rel=1e-6)
    assert brg_sd == pytest.approx(np.degrees(np.sqrt(c[1, 1])), rel=1e-6)


@pytest.mark.parametrize("lengths", [[np.nan, np.nan, 1.0], [0.01, 0.02, 0.03], [1.0, np.inf, 1.01]])
def test_wls_bad_input_gives_status_not_exception(lengths):
    fit = fit_point(lengths, [1e-4, 1e-4, 1e-4], ArrayGeometry.seed(0.065))
    assert not fit.ok and fit.status in ("invalid-input", "fit-failed") and fit.message
