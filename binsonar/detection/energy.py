"""Energy detector (seed section 4.1.2): a bank of contiguous band-pass filters, the output
energy of each summed, integrated over a window, and compared with a threshold.

Implementation: the template's band [f_lo, f_hi] (where its power spectrum is within
``band_db`` of its maximum) is covered by ``n_bands`` contiguous, power-complementary
raised-cosine band-pass filters applied in the frequency domain; each band's analytic output z_k is formed on a
decimated grid (as in ``matched``). The statistic is

    e(t) = moving average over T_int of sum_k |z_k(t)|^2 / mu_k,

mu_k the noise mean of |z_k|^2 (median / ln 2). For Gaussian noise, |z_k|^2 / mu_k is a unit
exponential whose correlation coefficient at lag d is |rho_k(d)|^2, rho_k the band's normalised
autocorrelation, so e has mean K and an exactly computable variance; the threshold is the
Gamma distribution with these moments at the per-cell false-alarm probability pfa / n_cells.

The TOF is the time of the statistic's maximum inside each region above the threshold
(parabolic interpolation), minus a calibrated offset: the same statistic computed on the clean
template gives the delay of its maximum after the template's reference instant. Without noise
and for an echo shaped like the template this makes the TOF unbiased; the noise moves the
maximum of a broad energy bump far more than it moves a matched-filter peak, which is why this
detector is less accurate (the seed's finding).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.matched import LN2, check_pfa
from binsonar.detection.peaks import parabolic_offset
from binsonar.preprocess import template_band_hz
from binsonar.recording import RecordingError, Template


def _moving_average(x: NDArray[np.float64], length: int) -> NDArray[np.float64]:
    """Centred moving average along the last axis (length odd), edges averaged over what exists."""
    half = length // 2
    c = np.cumsum(np.pad(x, [(0, 0)] * (x.ndim - 1) + [(half + 1, half)]), axis=-1)
    total = c[..., length:] - c[..., :-length]
    ones = np.cumsum(np.pad(np.ones(x.shape[-1]), (half + 1, half)))
    count = ones[length:] - ones[:-length]
    return total / count


def filter_bank(frequency_cycles: NDArray[np.float64], low: float, high: float, n_bands: int) -> NDArray[np.float64]:
    """Power-complementary raised-cosine filter bank (times 2, for the analytic outputs).

    Band k is cos(pi/2 (f - c_k) / D) for |f - c_k| < D, centres c_k spaced D apart from
    ``low`` to ``high`` (one band: centred, half-width (high - low) / 2): adjacent bands add up
    to a flat total power response, and the smooth edges keep each filter's impulse response
    short (no long sinc tails from ideal edges).

    Parameters
    ----------
    frequency_cycles : ndarray, shape (k,)
        Frequencies of the FFT bins (any unit shared with low and high).
    low, high : float
    n_bands : int

    Returns
    -------
    ndarray, shape (n_bands, k)
    """
    if n_bands == 1:
        centres = np.array([0.5 * (low + high)])
        spacing = 0.5 * (high - low)
    else:
        centres = np.linspace(low, high, n_bands)
        spacing = (high - low) / (n_bands - 1)
    x = (frequency_cycles[np.newaxis, :] - centres[:, np.newaxis]) / spacing
    return 2.0 * np.where(np.abs(x) < 1.0, np.cos(0.5 * np.pi * x), 0.0)


def _band_statistic(
    spectrum: NDArray[np.complex128],
    masks: NDArray[np.float64],
    n_env: int,
    scale: float,
    mu: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """sum_k |z_k|^2 / mu_k on the decimated grid, and mu (estimated if not given)."""
    import scipy.fft as sfft

    z = sfft.ifft(spectrum[:, np.newaxis, :] * masks[np.newaxis], n_env, axis=-1) * scale  # (rows, K, n_env)
    power = z.real ** 2 + z.imag ** 2
    if mu is None:
        mu = np.maximum(np.median(power, axis=-1) / LN2, np.finfo(float).tiny)  # (rows, K)
    return (power / mu[..., np.newaxis]).sum(axis=1), mu


def _calibration_s(
    template: Template, sample_rate_hz: float, band_cycles: tuple[float, float], n_bands: int, integration_s: float
) -> float:
    """Delay (s) of the statistic's maximum after the reference instant, for the clean template.

    Computed with equal band weights on a grid 8 times finer than the data's, with the same
    bank (band in cycles per sample) and integration time.
    """
    import scipy.fft as sfft

    s = template.samples
    m = s.size
    n = 6 * m
    n_fft = sfft.next_fast_len(n + 2 * m, real=True)
    row = np.zeros((1, n))
    row[0, 2 * m: 3 * m] = s
    spacing = (band_cycles[1] - band_cycles[0]) / max(n_bands - 1, 2)
    k_hi = min(int(math.ceil((band_cycles[1] + spacing) * n_fft)) + 1, n_fft // 2 + 1)
    masks = filter_bank(np.arange(k_hi) / n_fft, band_cycles[0], band_cycles[1], n_bands)
    n_env = sfft.next_fast_len(8 * k_hi)
    spectrum = sfft.rfft(row, n_fft, axis=-1)[:, :k_hi]
    band, _ = _band_statistic(spectrum, masks, n_env, n_env / n_fft, np.ones((1, n_bands)))
    cell_s = n_fft / n_env / sample_rate_hz
    length = max(1, int(round(integration_s / cell_s)))
    length += 1 - length % 2
    stat = _moving_average(band[:, : int(n / (n_fft / n_env))], length)[0]
    j = int(np.clip(np.argmax(stat), 1, stat.size - 2))
    off, _ = parabolic_offset(stat[j - 1:j], stat[j:j + 1], stat[j + 1:j + 2])
    return float((j + off[0]) * cell_s - (2 * m / sample_rate_hz - template.t0_s))


def detect_energy(
    rows: NDArray[np.float64],
    template: Template,
    *,
    sample_rate_hz: float,
    t0_s: float,
    n_bands: int = 4,
    band_db: float = -20.0,
    integration_s: float | None = None,
    pfa: float = 1e-3,
    where: str = "record",
) -> list[list[tuple[float, float, float, float, float]]]:
    """Energy-detector echoes of each row.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    template : Template
        Sets the band, the default integration time and the calibrated offset.
    sample_rate_hz, t0_s : float
    n_bands : int
        Number of contiguous filters in the bank.
    band_db : float
        The bank spans the template's band down to this level relative to its peak (dB).
    integration_s : float, optional
        Integration window (s); default: the template's RMS duration times 4 (about the span
        holding 95 % of a Gaussian pulse's energy).
    pfa : float
        False-alarm probability per record (Bonferroni over the cells).

    Returns
    -------
    list (n_rows) of list of (tof_s, amplitude, snr_db, score, tof_std_s)
        amplitude: estimated peak (V) from the excess band energy; snr_db: that energy over
        the noise's (2E/N0, rough); tof_std_s: NaN (no model).
    """
    import scipy.fft as sfft
    from scipy.special import gammainccinv

    pfa = check_pfa(pfa)
    if not (isinstance(n_bands, (int, np.integer)) and 1 <= n_bands <= 64):
        raise RecordingError(f"{where}: n_bands must be an integer in [1, 64], got {n_bands!r}")
    fs = sample_rate_hz
    s = template.samples
    m = s.size
    n_rows, n = rows.shape
    low, high = template_band_hz(s, fs, band_db)
    if integration_s is None:
        t = np.arange(m) / fs
        weight = s ** 2 / np.sum(s ** 2)
        centre = np.sum(t * weight)
        integration_s = 4.0 * math.sqrt(np.sum((t - centre) ** 2 * weight))
    if not (math.isfinite(integration_s) and integration_s > 0):
        raise RecordingError(f"{where}: integration_s must be > 0, got {integration_s!r}")
    pad = 2 * m
    n_fft = sfft.next_fast_len(n + pad, real=True)
    spacing = (high - low) / max(n_bands - 1, 2)
    k_hi = min(int(math.ceil((high + spacing) * n_fft / fs)) + 1, n_fft // 2 + 1)
    band_cycles = (low / fs, high / fs)
    masks = filter_bank(np.arange(k_hi) / n_fft, band_cycles[0], band_cycles[1], n_bands)
    n_env = sfft.next_fast_len(k_hi)
    decimation = n_fft / n_env
    scale = n_env / n_fft
    cell_s = decimation / fs
    length = max(1, int(round(integration_s / cell_s)))
    length += 1 - length % 2  # odd, centred
    spectrum = sfft.rfft(rows, n_fft, axis=-1)[:, :k_hi]
    n_cells = int(math.floor((n - 1) / decimation)) + 1
    band, mu = _band_statistic(spectrum, masks, n_env, scale, None)
    stat = _moving_average(band[:, :n_cells], length)
    # Noise moments of the statistic: mean K; variance from each band's autocorrelation.
    rho = sfft.ifft(masks ** 2, n_env, axis=-1)  # band noise PSD is proportional to mask^2
    rho_power = np.abs(rho) ** 2 / (np.abs(rho[:, :1]) ** 2)
    d = np.arange(-(length - 1), length)
    var = float(np.sum((length - np.abs(d)) * rho_power[:, d % n_env].sum(axis=0)) / length ** 2)
    mean = float(n_bands)
    threshold = float(gammainccinv(mean * mean / var, pfa / n_cells) * var / mean)  # Gamma upper quantile
    calibration_s = _calibration_s(template, fs, band_cycles, n_bands, integration_s)
    # White-noise variance per sample from the bands' noise: E|z_k|^2 = sigma^2 sum(mask_k^2) / n_fft.
    sigma2 = mu.sum(axis=1) * n_fft / float(np.sum(masks ** 2))  # (rows,)
    energy_template = float(np.sum(s ** 2))
    peak_template = float(np.max(np.abs(s)))
    out: list[list[tuple[float, float, float, float, float]]] = [[] for _ in range(n_rows)]
    for r in range(n_rows):  # per channel: its few regions above the threshold
        above = stat[r] > threshold
        if not above.any():
            continue
        edges_r = np.flatnonzero(np.diff(np.concatenate([[0], above.astype(np.int8), [0]])))
        for a, b in zip(edges_r[::2], edges_r[1::2]):
            j = a + int(np.argmax(stat[r, a:b]))
            if 0 < j < n_cells - 1:
                off, peak = parabolic_offset(stat[r, j - 1:j], stat[r, j:j + 1], stat[r, j + 1:j + 2])
                off_f, peak_f = float(off[0]), float(peak[0])
            else:
                off_f, peak_f = 0.0, float(stat[r, j])
            tof = t0_s + (j + off_f) * cell_s - calibration_s
            # Echo energy sum(x^2): half the excess analytic energy, summed at full rate
            # (D samples per cell) over the window, taking the bands' mean noise level.
            excess = 0.5 * max(peak_f - mean, 0.0) * length * decimation * float(np.mean(mu[r]))
            snr = max(excess / sigma2[r], 1e-3)
            amplitude = math.sqrt(excess / energy_template) * peak_template
            out[r].append((tof, amplitude, 10.0 * math.log10(snr), peak_f / threshold, float("nan")))
    return out
