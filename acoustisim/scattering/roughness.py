"""Coherent reflection from a rough surface and where the lost energy goes.

Physics
-------
Kirchhoff approximation for a surface of Gaussian height distribution, rms height h (Eckart,
JASA 25, 566, 1953; physics.md section 8): a ray reflected at grazing angle theta_g picks up
the phase 2 k zeta sin(theta_g) from the local height zeta, so the mean (coherent) reflected
pressure is the height distribution's characteristic function at 2 k sin(theta_g):

    R_coh = R chi,   chi = <exp(2 i k zeta sin theta_g)> = exp(-2 (k h sin theta_g)^2).

The reflected energy |R|^2 is unchanged by the roughness in this approximation (each facet
reflects with |R|); the coherent part carries |R|^2 chi^2 and the rest,
|R|^2 (1 - chi^2), is scattered incoherently (diffusely). For the simulator's Lambert model
(I_s / I_i = mu sin g_i sin g_s dA / r^2, physics.md section 5), the power scattered into the
half space per unit incident power on the area is pi mu, so the lost coherent energy is carried
by the extra Lambert strength mu_extra = |R|^2 (1 - chi^2) / pi (per frequency and grazing
angle): energy is conserved, coherent + diffuse = |R|^2.

Example: h = 0.5 mm, 500 kHz in water (k = 2120 /m), 30 deg grazing: chi = exp(-2 (0.53)^2),
-4.9 dB (issue 17: "about 5 dB").

Method
------
Closed forms, broadcast over rows (grazing angles) and bins (wavenumbers).

Accuracy
--------
Exact within the Kirchhoff approximation (valid for correlation lengths well above the
wavelength and moderate slopes); the Monte-Carlo check in ``tests/physics/test_elastic_roughness.py``
samples Gaussian heights.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError

__all__ = ("RoughReflection", "coherent_factor", "rough_reflection")


def coherent_factor(wavenumber: ArrayLike, rms_height_m: float, sin_grazing: ArrayLike) -> NDArray[np.float64]:
    """chi = exp(-2 (k h sin theta_g)^2), shape (n_rows, n_bins).

    Parameters
    ----------
    wavenumber : array_like, shape (n_bins,)
        k = 2 pi f / c (1/m).
    rms_height_m : float
        h (m), >= 0.
    sin_grazing : array_like, shape (n_rows,)
        sin(theta_g) of each reflection (0 grazing .. 1 normal).
    """
    if not (np.isfinite(rms_height_m) and rms_height_m >= 0.0):
        raise InputError(f"rms_height_m = {rms_height_m!r}: must be finite and >= 0")
    k = np.atleast_1d(np.asarray(wavenumber, dtype=float))
    s = np.atleast_1d(np.asarray(sin_grazing, dtype=float))
    phase = np.multiply.outer(s, k) * rms_height_m
    return np.exp(-2.0 * phase * phase)


class RoughReflection(NamedTuple):
    """A rough reflection split into its coherent and diffuse parts, (n_rows, n_bins) each.

    Attributes
    ----------
    coherent : ndarray of complex
        R chi: the specular row's factor.
    diffuse_energy : ndarray
        |R|^2 (1 - chi^2): fraction of the incident energy scattered diffusely.
    lambert_mu : ndarray
        diffuse_energy / pi: the Lambert strength that carries it.
    """

    coherent: NDArray[np.complex128]
    diffuse_energy: NDArray[np.float64]
    lambert_mu: NDArray[np.float64]


def rough_reflection(reflection: ArrayLike, wavenumber: ArrayLike, rms_height_m: float,
                     sin_grazing: ArrayLike) -> RoughReflection:
    """Split a reflection coefficient R (n_rows,) into coherent and diffuse parts per bin.

    Returns
    -------
    RoughReflection
        With ``|coherent|^2 + diffuse_energy = |R|^2`` (energy conserved).
    """
    chi = coherent_factor(wavenumber, rms_height_m, sin_grazing)
    r = np.atleast_1d(np.asarray(reflection, dtype=complex))[:, None]
    diffuse = np.abs(r) ** 2 * (1.0 - chi * chi)
    return RoughReflection(r * chi, diffuse, diffuse / np.pi)
