"""Bounds on the range and bearing of a point target from the bounds on its times of flight.

Physics
-------
The seed's point localiser (``localization.point``) turns the left and right path lengths
L_i = c tau_i into range and bearing. With independent TOF errors of standard deviation
sigma_i, the linearised covariance of (range, bearing) is C = A^-1 diag(c^2 sigma_1^2,
c^2 sigma_2^2) A^-T, A = d(L_1, L_2)/d(r, theta) (``localization.point.seed_point_covariance``).
Fed with Cramer-Rao bounds on the TOFs (``estimation.tof``, ``binsonar.bounds``), it bounds
any unbiased estimator of range and bearing from those two channels (the bound of a function of
parameters: the Jacobian's sandwich, Kay, *Fundamentals of Statistical Signal Processing* I,
sec. 3.8).

Method
------
``point_bound``: the covariance at the given range and bearing, square roots of its diagonal.
``noise_bound`` and ``reverberation_bound``: the TOF bounds of a simulated echo in its noise (and
reverberation) on the left and right channels, then ``point_bound``.

Accuracy
--------
Linearisation: exact to first order in sigma / range (sigmas of nanoseconds at ranges of metres:
terms of 1e-6 relative are neglected); the centre channel is not used (the seed's localiser).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from binsonar.estimation.tof import echo_tof_crlb_s, interference_snr, matched_snr


class PointBound(NamedTuple):
    """Standard deviations of a point target's range and bearing.

    Attributes
    ----------
    range_m : float
    bearing_deg : float
    """

    range_m: float
    bearing_deg: float


def point_bound(left_tof_std_s: float, right_tof_std_s: float, range_m: float, bearing_deg: float,
                sound_speed_m_s: float, half_baseline_m: float) -> PointBound:
    """Range and bearing standard deviations of the seed's point solution from the left and right TOF stds.

    Parameters
    ----------
    left_tof_std_s, right_tof_std_s : float
        TOF standard deviations (s) on the left and right channels.
    range_m, bearing_deg : float
        Where the covariance is linearised (the target's range and bearing).
    sound_speed_m_s : float
    half_baseline_m : float
        Centre-to-side receiver separation d (m).
    """
    from binsonar.localization.point import seed_point_covariance

    cov = seed_point_covariance(range_m, math.radians(bearing_deg), half_baseline_m,
                                sound_speed_m_s * left_tof_std_s, sound_speed_m_s * right_tof_std_s)
    return PointBound(float(math.sqrt(cov[0, 0])), float(math.degrees(math.sqrt(cov[1, 1]))))


class NoiseBound(NamedTuple):
    """``noise_bound``'s result.

    Attributes
    ----------
    measured : PointBound
        With the template's RMS bandwidth at the matched filter's output SNR of the echo in this
        noise (``estimation.tof.matched_snr``): the bound the detector reports
        (``Echo.tof_std_s``), with the true noise in its floor.
    snr_db : tuple of float, one per channel
        That SNR (2E/N0, dB).
    optimal : PointBound
        With the echo's own shape in the noise's own spectrum (``estimation.tof.echo_tof_crlb_s``):
        what a whitened filter matched to the received echo would reach.
    optimal_snr_db : tuple of float, one per channel
    """

    measured: PointBound
    snr_db: tuple[float, ...]
    optimal: PointBound
    optimal_snr_db: tuple[float, ...]


def noise_bound(echo: ArrayLike, noise: ArrayLike, template: ArrayLike, fs_hz: float, range_m: float,
                bearing_deg: float, sound_speed_m_s: float, half_baseline_m: float) -> NoiseBound:
    """Range and bearing bounds of a point target from its noise-free echo and the noise, on the left and right channels.

    Parameters
    ----------
    echo, noise : array_like, shape (3, n)
        The target's noise-free echo and the noise over the same record (V); channels left,
        centre, right.
    template : array_like, shape (m,)
        The matched filter's template (the transmitted pulse).
    fs_hz : float
    range_m, bearing_deg, sound_speed_m_s, half_baseline_m : float
        As ``point_bound``.
    """
    from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s

    snr = matched_snr(echo, noise, template)
    measured = tof_crlb_s(snr, rms_bandwidth_hz(np.asarray(template, dtype=float), fs_hz))
    optimal, optimal_snr_db = echo_tof_crlb_s(echo, noise, fs_hz)
    geometry = (range_m, bearing_deg, sound_speed_m_s, half_baseline_m)
    return NoiseBound(
        measured=point_bound(measured[0], measured[2], *geometry),
        snr_db=tuple(float(v) for v in 10.0 * np.log10(snr)),
        optimal=point_bound(optimal[0], optimal[2], *geometry),
        optimal_snr_db=tuple(float(v) for v in optimal_snr_db),
    )


class ReverberationBound(NamedTuple):
    """``reverberation_bound``'s result.

    Attributes
    ----------
    bound : PointBound
    snr_db : tuple of float, one per channel
        2E/N0 with the reverberation's local level counted as noise (dB).
    reverb_to_noise_db : tuple of float, one per channel
        The reverberation's level at the echo over the noise's, at the filter's output (dB).
    """

    bound: PointBound
    snr_db: tuple[float, ...]
    reverb_to_noise_db: tuple[float, ...]


def reverberation_bound(echo: ArrayLike, noise: ArrayLike, reverberation: list[ArrayLike], template: ArrayLike,
                        fs_hz: float, range_m: float, bearing_deg: float, sound_speed_m_s: float,
                        half_baseline_m: float) -> ReverberationBound:
    """``noise_bound``'s measured bound with the reverberation counted as Gaussian interference at its level at the echo.

    Parameters
    ----------
    echo, noise : array_like, shape (3, n)
        As ``noise_bound``.
    reverberation : list of array_like, shape (3, n)
        Realisations of the reverberation alone over the same record (V)
        (``estimation.tof.interference_snr``: its level is averaged over them).
    template, fs_hz, range_m, bearing_deg, sound_speed_m_s, half_baseline_m
        As ``noise_bound``.
    """
    from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s

    snr = interference_snr(echo, noise, reverberation, template)
    std_s = tof_crlb_s(snr.snr, rms_bandwidth_hz(np.asarray(template, dtype=float), fs_hz))
    return ReverberationBound(
        bound=point_bound(std_s[0], std_s[2], range_m, bearing_deg, sound_speed_m_s, half_baseline_m),
        snr_db=tuple(float(v) for v in 10.0 * np.log10(snr.snr)),
        reverb_to_noise_db=tuple(float(v) for v in snr.interference_to_noise_db),
    )
