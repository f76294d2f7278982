"""Cramer-Rao bounds for time-of-flight estimation.

For a known pulse in white Gaussian noise, sigma_tau >= 1 / (2 pi beta sqrt(2E/N0)), with beta
the RMS bandwidth of the pulse's envelope (about its centroid frequency) and 2E/N0 the
matched filter's peak SNR, sum(s[n]^2) / sigma^2 for sampled data (``physics.md`` section 6).
Valid above the estimator's threshold SNR.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def rms_bandwidth_hz(template: ArrayLike, sample_rate_hz: float, about_centroid: bool = True) -> float:
    """RMS bandwidth beta (Hz) of a real template.

    Parameters
    ----------
    template : array_like, shape (n,)
        The pulse.
    sample_rate_hz : float
        Its sample rate (Hz).
    about_centroid : bool
        True: the envelope bandwidth, sqrt(int (f - f0)^2 |S|^2 / int |S|^2) over f > 0 with f0
        the centroid (the bound on the envelope peak). False: about f = 0 (the carrier bound,
        subject to cycle ambiguity).
    """
    s = np.asarray(template, dtype=float)
    n_fft = 1 << int(np.ceil(np.log2(max(8 * s.size, 1024))))
    power = np.abs(np.fft.rfft(s, n_fft)) ** 2
    f = np.fft.rfftfreq(n_fft, 1.0 / sample_rate_hz)
    total = power.sum()
    if total <= 0:
        raise ValueError("template has no energy")
    f0 = (f * power).sum() / total if about_centroid else 0.0
    return float(np.sqrt(((f - f0) ** 2 * power).sum() / total))


def tof_crlb_s(snr_2e_n0: ArrayLike, rms_bandwidth: float) -> NDArray[np.float64]:
    """Lower bound on the TOF standard deviation (s) for 2E/N0 (linear, not dB)."""
    snr = np.asarray(snr_2e_n0, dtype=float)
    return 1.0 / (2.0 * np.pi * rms_bandwidth * np.sqrt(snr))


def snr_db_to_linear(snr_db: ArrayLike) -> NDArray[np.float64]:
    """10^(dB/10)."""
    return 10.0 ** (np.asarray(snr_db, dtype=float) / 10.0)
