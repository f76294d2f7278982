"""Pre-processing of pings before detection: averaging (seed eq. 4.33) and band-pass filtering.

The band-pass is zero-phase (a real, non-negative frequency response applied in the frequency
domain, with enough zero padding that the circular convolution is linear), so it delays nothing
and a TOF measured after it is not biased. Its magnitude is the squared analog Butterworth
band-pass response, i.e. what ``filtfilt`` with a Butterworth filter of that order would give.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from binsonar.recording import RecordingError


def average_pings(waveforms: NDArray[np.float64]) -> NDArray[np.float64]:
    """Average of N pings, X = sum x_i / N (seed eq. 4.33).

    For echoes that repeat exactly and independent noise, the noise variance drops by N.

    Parameters
    ----------
    waveforms : ndarray, shape (n_pings, n_channels, n_samples)

    Returns
    -------
    ndarray, shape (1, n_channels, n_samples)
    """
    w = np.asarray(waveforms, dtype=float)
    if w.ndim != 3 or w.shape[0] < 1:
        raise RecordingError(f"average_pings: waveforms must be (n_pings, n_channels, n_samples), got {w.shape}")
    return w.mean(axis=0, keepdims=True)


def butterworth_bandpass_power(frequency_hz: NDArray[np.float64], low_hz: float, high_hz: float, order: int) -> NDArray[np.float64]:
    """|H(f)|^2 of an analog Butterworth band-pass of the given order (0 dB at sqrt(low high)).

    |H|^2 = 1 / (1 + ((f^2 - f0^2) / (f B))^(2 order)), f0 = sqrt(low high), B = high - low; it is
    -3 dB at ``low_hz`` and ``high_hz``.
    """
    f = np.maximum(np.abs(np.asarray(frequency_hz, dtype=float)), 1e-3)
    f0_sq = low_hz * high_hz
    bandwidth = high_hz - low_hz
    # Clipping the normalised frequency at 1e8 keeps x^(2 order) finite (<= 1e256) for order <= 16.
    x = np.minimum(np.abs(f * f - f0_sq) / (f * bandwidth), 1e8)
    return 1.0 / (1.0 + x ** (2 * order))


def bandpass(
    waveforms: NDArray[np.float64],
    sample_rate_hz: float,
    low_hz: float,
    high_hz: float,
    order: int = 4,
) -> NDArray[np.float64]:
    """Zero-phase band-pass filter along the last axis.

    Parameters
    ----------
    waveforms : ndarray, shape (..., n_samples)
    sample_rate_hz : float
    low_hz, high_hz : float
        -3 dB edges of the one-pass Butterworth response (the applied zero-phase response is its
        square, -6 dB there), 0 < low < high < fs / 2.
    order : int
        Butterworth order of one pass.

    Returns
    -------
    ndarray, same shape
        No delay: a symmetric pulse keeps the time of its envelope peak.
    """
    import scipy.fft as sfft

    if not (0.0 < low_hz < high_hz < sample_rate_hz / 2.0):
        raise RecordingError(
            f"bandpass: need 0 < low_hz < high_hz < fs/2 = {sample_rate_hz / 2:.6g} Hz, got ({low_hz!r}, {high_hz!r})"
        )
    if not (isinstance(order, (int, np.integer)) and 1 <= order <= 16):
        raise RecordingError(f"bandpass: order must be an integer in [1, 16], got {order!r}")
    x = np.asarray(waveforms, dtype=float)
    n = x.shape[-1]
    # The response decays within a few (order / bandwidth); 4 order / B of padding keeps the
    # circular wrap below the numerical noise floor.
    pad = int(math.ceil(4.0 * order * sample_rate_hz / (high_hz - low_hz)))
    n_fft = sfft.next_fast_len(n + pad, real=True)
    gain = butterworth_bandpass_power(np.fft.rfftfreq(n_fft, 1.0 / sample_rate_hz), low_hz, high_hz, order)
    spectrum = sfft.rfft(x, n_fft, axis=-1)
    spectrum *= gain
    return sfft.irfft(spectrum, n_fft, axis=-1)[..., :n]


def template_band_hz(template: NDArray[np.float64], sample_rate_hz: float, level_db: float = -20.0) -> tuple[float, float]:
    """Frequencies (Hz) where the template's power spectrum first and last reaches ``level_db``
    relative to its maximum: a default pass band for ``bandpass``."""
    import scipy.fft as sfft

    s = np.asarray(template, dtype=float)
    n = sfft.next_fast_len(max(8 * s.size, 4096), real=True)
    power = np.abs(sfft.rfft(s, n)) ** 2
    inside = np.flatnonzero(power >= power.max() * 10.0 ** (level_db / 10.0))
    f = np.fft.rfftfreq(n, 1.0 / sample_rate_hz)
    low = max(float(f[inside[0]]), sample_rate_hz / n)
    high = min(float(f[inside[-1]]), 0.499 * sample_rate_hz)
    return low, high
