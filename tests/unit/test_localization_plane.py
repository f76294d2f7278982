"""Planes: image-source path lengths, gradient, and the wall fit."""

import numpy as np
import pytest

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.circle import circle_path_lengths
from binsonar.localization.plane import fit_plane, plane_foot, plane_path_lengths


def test_plane_path_equals_law_of_reflection_path():
    # Independent construction: find the reflection point on the wall by minimising over the wall line.
    psi, p = np.radians(15.0), 1.4
    g = ArrayGeometry.seed(0.065)
    lengths, _ = plane_path_lengths(psi, p, np.zeros((3, 3)), g.receivers_m)
    n = np.array([np.sin(psi), np.cos(psi)])
    tangent = np.array([n[1], -n[0]])
    s = np.linspace(-1.0, 1.0, 2000001)[:, None]
    pts = p * n + s * tangent
    for i, rec in enumerate(g.receivers_m):
        total = np.linalg.norm(pts, axis=1) + np.linalg.norm(pts - rec[:2], axis=1)
        assert lengths[i] == pytest.approx(total.min(), abs=1e-10)  # 1 um grid, quadratic minimum


def test_plane_is_the_large_radius_limit_of_the_circle():
    psi, p = np.radians(-8.0), 2.0
    g = ArrayGeometry.seed(0.065)
    wall, _ = plane_path_lengths(psi, p, np.zeros((3, 3)), g.receivers_m)
    rc = 1e5
    centre = (p + rc) * np.array([np.sin(psi), np.cos(psi)])
    big, _ = circle_path_lengths(centre, rc, np.zeros((3, 3)), g.receivers_m)
    # Sagitta over the ~d footprint: d^2 / (8 rc) ~ 5e-9 m.
    np.testing.assert_allclose(big, wall, atol=1e-8)


def test_plane_gradient_matches_finite_differences():
    g = ArrayGeometry(np.array([0.01, 0.0, 0.0]), np.array([[-0.05, 0.0, 0.02], [0.0, 0.0, 0.0], [0.09, 0.01, -0.01]]))
    tx = np.broadcast_to(g.transmitter_m, (3, 3))
    x = np.array([0.3, 1.7])
    _, grad = plane_path_lengths(*x, tx, g.receivers_m)
    h = 1e-6
    for k in range(2):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd = (plane_path_lengths(*xp, tx, g.receivers_m)[0] - plane_path_lengths(*xm, tx, g.receivers_m)[0]) / (2 * h)
        np.testing.assert_allclose(grad[:, k], fd, atol=1e-8)  # central differences: ~1e-10


@pytest.mark.parametrize("psi_deg, p", [(0.0, 0.5), (20.0, 2.0), (-35.0, 4.0)])
def test_plane_fit_recovers_wall(psi_deg, p):
    g = ArrayGeometry(np.zeros(3), np.array([[-0.06, 0.0, 0.01], [0.0, 0.0, 0.0], [0.07, 0.0, -0.01]]))
    lengths, _ = plane_path_lengths(np.radians(psi_deg), p, np.zeros((3, 3)), g.receivers_m)
    fit = fit_plane(lengths, np.full(3, 1e-4), g)
    assert fit.ok and fit.dof == 1
    np.testing.assert_allclose(fit.parameters, [np.radians(psi_deg), p], atol=1e-10)
    foot = plane_foot(fit, g.transmitter_m)
    np.testing.assert_allclose(foot[:2], p * np.array([np.sin(np.radians(psi_deg)), np.cos(np.radians(psi_deg))]),
                               atol=1e-10)


def test_plane_behind_transducer_is_nan_and_bad_fit_input_is_status():
    lengths, _ = plane_path_lengths(0.0, -0.5, np.zeros((1, 3)), np.zeros((1, 3)))
    assert np.isnan(lengths[0])
    fit = fit_plane([np.nan, np.nan, 1.0], np.full(3, 1e-4), ArrayGeometry.seed(0.065))
    assert fit.status == "invalid-input"
