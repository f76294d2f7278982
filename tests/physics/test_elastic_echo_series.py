"""Echo transfer functions of many rows from one coefficient table, and the tools they use.

Checked against phase 1's independent per-call implementation (``scattering.echo``), against
``scipy.special`` and ``numpy.linalg.solve``, and the chirp-z evaluation against the direct sum.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import special

from acoustisim.errors import InputError
from acoustisim.materials import get_material
from acoustisim.scattering.bodies import AIR, Fluid, Shell, body_from_material
from acoustisim.scattering.echo import EchoGeometry, EchoTarget, echo_transfer
from acoustisim.scattering.echo_series import hankel_start, series_transfer
from acoustisim.scattering.kernels import solve_small_systems
from acoustisim.scattering.modal import modal_coefficients
from acoustisim.scattering.spectral_resampling import response_spectrum

WATER = Fluid(998.2, 1482.4)
PVC = get_material("pvc")


def rows(n: int, seed: int, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    source = np.c_[rng.uniform(-3, 3, n), rng.uniform(0.5, 3, n), np.full(n, 0.5)]
    receiver = source + np.c_[rng.uniform(-0.2, 0.2, (n, 2)), np.full(n, offset)]
    return source, receiver


def test_hankel_start_matches_scipy_on_both_sides_of_the_switch() -> None:
    # the asymptotic expansion from x = 40 (12 terms, remainder < 1e-16) and scipy below; scipy's
    # own hankel1 is accurate to about 1e-13 relative here
    x = np.array([0.3, 5.0, 39.99, 40.0, 40.5, 123.4, 2.0e3, 4.4e4])
    h0, h1 = hankel_start(x)
    np.testing.assert_allclose(h0, special.hankel1(0, x), rtol=1e-11)
    np.testing.assert_allclose(h1, special.hankel1(1, x), rtol=1e-11)


@pytest.mark.parametrize("case", ["solid post", "pipe", "steel sphere"])
def test_series_transfer_reproduces_echo_transfer(case: str) -> None:
    # Same formulas, coefficients once instead of per call, Hankel functions by recurrence from
    # the asymptotic H0, H1 and a compiled sum: equal to rounding (1e-9 of the largest |H|;
    # measured 1e-11, the Hankel functions' own accuracy).
    shape, body, radius, material = {
        "solid post": ("post", body_from_material(PVC), 0.025, PVC),
        "pipe": ("post", Shell(body_from_material(PVC), 0.004, AIR), 0.075, PVC),
        "steel sphere": ("sphere", body_from_material(get_material("steel")), 0.03, get_material("steel")),
    }[case]
    source, receiver = rows(12, 3)
    geometry = EchoGeometry.from_points(source, receiver, [0.0, -0.2, 0.5], [0, 0, 1] if shape == "post" else None)
    target = EchoTarget(shape, radius, body, material)
    f = np.linspace(20e3, 1.3e6, 40)
    coefficients = modal_coefficients("sphere" if shape == "sphere" else "cylinder", body, radius, f, WATER)
    mine = series_transfer(target, geometry, WATER, coefficients)
    reference = echo_transfer(target, geometry, WATER, f)
    assert np.max(np.abs(mine - reference)) < 1e-9 * np.max(np.abs(reference))
    # each row at its own frequencies: the same numbers
    picks = np.arange(12)[:, None] * 3 % 40 + np.array([0, 1])[None, :]
    chosen = series_transfer(target, geometry, WATER, coefficients, row_bins=picks)
    np.testing.assert_array_equal(chosen, np.take_along_axis(mine, picks, axis=1))


def test_series_transfer_refuses_rows_off_the_plane_and_wrong_tables() -> None:
    source, receiver = rows(3, 4, offset=0.2)
    target = EchoTarget("post", 0.025, body_from_material(PVC), PVC)
    coefficients = modal_coefficients("cylinder", target.body, 0.025, [500e3], WATER)
    with pytest.raises(InputError, match="flat"):
        series_transfer(target, EchoGeometry.from_points(source, receiver, [0, -0.2, 0.5], [0, 0, 1]), WATER,
                        coefficients)
    sphere = EchoTarget("sphere", 0.025, target.body, PVC)
    with pytest.raises(InputError, match="sphere"):
        series_transfer(sphere, EchoGeometry.from_points(source, receiver, [0, -0.2, 0.5]), WATER, coefficients)


def test_compiled_small_systems_solve_like_numpy() -> None:
    # badly scaled systems like the boundary conditions' (columns 1e-40 .. 1e+40): equilibration
    # and partial pivoting give numpy's answer to 1e-12 relative
    rng = np.random.default_rng(5)
    scale = 10.0 ** rng.uniform(-40, 40, (500, 1, 6))
    matrix = (rng.standard_normal((500, 6, 6)) + 1j * rng.standard_normal((500, 6, 6))) * scale
    rhs = rng.standard_normal((500, 6)) + 1j * rng.standard_normal((500, 6))
    mine = solve_small_systems(matrix, rhs)
    np.testing.assert_allclose(np.einsum("bij,bj->bi", matrix, mine), rhs, rtol=1e-9, atol=1e-9)
    reference = np.linalg.solve(matrix / scale, rhs[..., None])[..., 0] / scale[:, 0, :]
    np.testing.assert_allclose(mine, reference, rtol=1e-10)


@pytest.mark.parametrize("start_s", [0.0, -3.1e-5])
def test_chirp_z_equals_the_direct_sum(start_s: float) -> None:
    # Bluestein on a uniform grid against the plain sum (used for grids that are not uniform):
    # rounding only, 1e-12 of sum |h|
    rng = np.random.default_rng(6)
    samples = rng.standard_normal((4, 700)) + 1j * rng.standard_normal((4, 700))
    scale = np.array([1.0, 0.97, 0.61, 0.999])
    grid = 2.0e3 + 5580.35 * np.arange(233)
    fast = response_spectrum(samples, start_s, 1.0 / 2.857e6, grid, scale)
    jittered = grid.copy()
    jittered[7] += 0.25  # not uniform: the direct sum
    direct = response_spectrum(samples, start_s, 1.0 / 2.857e6, jittered, scale)
    keep = np.arange(grid.size) != 7
    bound = 1e-12 * np.abs(samples).sum(axis=1).max()
    assert np.max(np.abs(fast[:, keep] - direct[:, keep])) < bound
    # and the direct sum is the definition
    t = start_s + np.arange(700) / 2.857e6
    np.testing.assert_allclose(direct[2, 7], np.sum(samples[2] * np.exp(-2j * np.pi * 0.61 * jittered[7] * t)),
                               rtol=1e-12)
