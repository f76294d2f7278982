"""Discrete-wavelet-transform detector (the seed's suggested future work, section 5.2.1).

It needs only the echo's band, not its waveform (Zhang's DWT detector idea):

1. An orthogonal DWT (PyWavelets, ``sym8`` by default, periodised) of each channel to
   ``levels`` levels. For white Gaussian noise the detail coefficients of an orthogonal
   transform are independent N(0, sigma_j^2); sigma_j is estimated per level and channel by
   the MAD (robust to the echoes).
2. The levels holding the echo's energy are weighted by the fraction w_j of the template's
   energy they hold (levels under 2 % are dropped). The statistic lives on the grid of the
   finest kept level j0 (cells of 2^j0 samples): each coefficient of level j spans
   r_j = 2^(j - j0) cells and adds w_j (d / sigma_j)^2 / r_j to each; it is summed over
   ``window`` cells (4 RMS durations of the template, ~95 % of a Gaussian pulse's energy). For noise each (d / sigma)^2 is
   chi-square(1): the window sum has mean window sum_j w_j / r_j and variance
   2 window sum_j w_j^2 / r_j (up to the coefficients the window only partly covers), and the
   threshold is the Gamma law with those moments at pfa / n_cells.
3. Each region above the threshold gives one echo at the statistic's maximum (parabolic
   interpolation), minus an offset calibrated on the clean template (averaged over the 2^J
   positions of the template relative to the DWT's dyadic grid, since the DWT is not shift
   invariant). Its timing is therefore coarse (a fraction of a cell, ~0.1-1 us), the price of
   not using the waveform's phase.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.inputs import template_rms_duration_s
from binsonar.detection.matched import check_pfa
from binsonar.detection.noise import MAD_TO_SIGMA
from binsonar.detection.peaks import parabolic_offset, peaks_above
from binsonar.recording import RecordingError, Template

# Levels holding less than this fraction of the template's energy are ignored.
MIN_LEVEL_FRACTION = 0.02


def _details(rows: NDArray[np.float64], wavelet: str, levels: int) -> list[NDArray[np.float64]]:
    """Detail coefficients of levels 1..levels (finest first), each (n_rows, n / 2^j)."""
    import pywt

    coefficients = pywt.wavedec(rows, wavelet, mode="periodization", level=levels, axis=-1)
    return coefficients[:0:-1]  # wavedec returns [cA_L, cD_L, ..., cD_1]


def _statistic(
    details: list[NDArray[np.float64]],
    weights: NDArray[np.float64],
    sigma: list[NDArray[np.float64]],
    finest: int,
) -> NDArray[np.float64]:
    """Per-cell statistic on the grid of level ``finest`` (cells of 2^finest samples).

    A coefficient of level j >= finest spans r_j = 2^(j - finest) cells; it is repeated over
    them with weight w_j / r_j, so that it contributes w_j (d / sigma_j)^2 to a window sum
    covering it.
    """
    total = None
    for j, w in enumerate(weights, start=1):  # loop over a few wavelet levels
        if w == 0.0:
            continue
        repeat = 2 ** (j - finest)
        term = np.repeat((details[j - 1] / sigma[j - 1][:, np.newaxis]) ** 2 * (w / repeat), repeat, axis=1)
        if total is None:
            total = term
        else:
            size = min(total.shape[1], term.shape[1])
            total = total[:, :size] + term[:, :size]
    if total is None:
        raise ValueError("_statistic: all level weights are zero")
    return total


def _window_sum(x: NDArray[np.float64], length: int) -> NDArray[np.float64]:
    """Centred moving sum along the last axis (length odd; zero outside)."""
    half = length // 2
    c = np.cumsum(np.pad(x, ((0, 0), (half + 1, half))), axis=-1)
    return c[:, length:] - c[:, :-length]


def detect_dwt(
    rows: NDArray[np.float64],
    template: Template,
    *,
    sample_rate_hz: float,
    t0_s: float,
    wavelet: str = "sym8",
    levels: int | None = None,
    pfa: float = 1e-3,
    where: str = "record",
    noise_floor_v: float = 0.0,
) -> list[list[tuple[float, float, float, float, float]]]:
    """DWT-detector echoes of each row.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    template : Template
        Gives the level weights and the calibrated offset.
    sample_rate_hz, t0_s : float
    wavelet : str
        Any orthogonal PyWavelets wavelet name.
    levels : int, optional
        Decomposition depth (default: enough levels to go below the template's band).
    pfa : float
        False-alarm probability per record.
    noise_floor_v : float
        Least noise standard deviation (V), the ADC's quantisation noise: the orthogonal
        transform keeps white noise's variance at every level, so each level's sigma is
        floored at it.

    Returns
    -------
    list (n_rows) of list of (tof_s, amplitude, snr_db, score, tof_std_s)
        snr_db: excess normalised energy in the window (rough 2E/N0); amplitude: the
        corresponding peak (V); tof_std_s: NaN.
    """
    import pywt
    from scipy.special import gammainccinv

    pfa = check_pfa(pfa)
    if wavelet not in pywt.wavelist(kind="discrete") or not pywt.Wavelet(wavelet).orthogonal:
        raise RecordingError(f"{where}: wavelet must be an orthogonal discrete PyWavelets wavelet, got {wavelet!r}")
    fs = sample_rate_hz
    s = template.samples
    m = s.size
    n_rows, n = rows.shape
    if levels is None:
        # Deep enough that the coarsest detail band (fs / 2^(J+1) .. fs / 2^J) reaches down to
        # half the template's centroid frequency: 2^J >= fs / centroid.
        spectrum = np.abs(np.fft.rfft(s, 8 * m)) ** 2
        centroid = float(np.sum(np.fft.rfftfreq(8 * m, 1 / fs) * spectrum) / np.sum(spectrum))
        levels = max(1, int(math.ceil(math.log2(fs / centroid))))
    if not (isinstance(levels, (int, np.integer)) and 1 <= levels <= 20 and 2 ** levels * 4 <= n):
        raise RecordingError(f"{where}: levels={levels!r} is not usable for {n} samples")
    block = 2 ** levels
    # Zero padding of at least two template lengths keeps the periodised transform from
    # wrapping the record's start (the main bang) onto its end.
    n_pad = int(math.ceil((n + 2 * s.size) / block)) * block
    # Level weights from the template's energy per level, averaged over its dyadic phase.
    cal_n = int(math.ceil(6 * m / block)) * block + block
    start = 2 * int(math.ceil(m / block)) * block
    cal = np.zeros((block, cal_n))
    phases = np.arange(block)
    cal[phases[:, np.newaxis], start + phases[:, np.newaxis] + np.arange(m)] = s
    cal_details = _details(cal, wavelet, levels)
    level_energy = np.array([float(np.sum(d ** 2)) for d in cal_details])
    weights = level_energy / level_energy.sum()
    weights[weights < MIN_LEVEL_FRACTION] = 0.0
    weights /= weights.sum()
    finest = int(np.flatnonzero(weights)[0]) + 1
    cell = 2 ** finest
    cell_s = cell / fs
    window = max(1, int(round(4.0 * template_rms_duration_s(template) / cell_s)))
    window += 1 - window % 2
    # Calibrated offset: maximum of the clean template's statistic, averaged over phases.
    unit_sigma = [np.ones(block) for _ in range(levels)]
    cal_stat = _window_sum(_statistic(cal_details, weights, unit_sigma, finest), window)
    j = np.clip(np.argmax(cal_stat, axis=1), 1, cal_stat.shape[1] - 2)
    k = np.arange(block)
    off, _ = parabolic_offset(cal_stat[k, j - 1], cal_stat[k, j], cal_stat[k, j + 1])
    peak_time = (j + off + 0.5) * cell_s  # cell c covers samples [c cell, (c + 1) cell)
    reference_time = (start + phases) / fs - template.t0_s
    calibration_s = float(np.mean(peak_time - reference_time))
    # Data.
    padded = np.zeros((n_rows, n_pad))
    padded[:, :n] = rows
    details = _details(padded, wavelet, levels)
    # Noise scale of each level from the coefficients over the record only (not the padding).
    sigma = [np.maximum(MAD_TO_SIGMA * np.median(np.abs(d[:, : int(math.ceil(n / 2.0 ** (j + 1)))]), axis=1),
                        max(float(noise_floor_v), np.finfo(float).tiny)) for j, d in enumerate(details)]
    stat = _window_sum(_statistic(details, weights, sigma, finest), window)
    # The periodised transform wraps the record's start (the main bang) onto the zero padding:
    # cells past the record's end are not data.
    stat[:, int(math.ceil(n * 2.0 ** -finest)):] = 0.0
    n_cells = stat.shape[1]
    repeats = 2.0 ** (np.arange(1, levels + 1) - finest)
    mean = window * float(np.sum(weights / repeats))
    var = 2.0 * window * float(np.sum(weights ** 2 / repeats))
    threshold = float(gammainccinv(mean * mean / var, pfa / n_cells) * var / mean)  # Gamma upper quantile
    # The clean template's statistic (unit sigma), the scale of an echo's excess statistic.
    template_stat = float(np.mean(cal_stat.max(axis=1)))
    peak_template = float(np.max(np.abs(s)))
    energy_template = float(np.sum(s ** 2))
    out: list[list[tuple[float, float, float, float, float]]] = [[] for _ in range(n_rows)]
    for r in range(n_rows):  # per channel: its few regions above the threshold
        _, indices, offsets, peaks = peaks_above(stat[r], threshold)
        for c, o_f, p_f in zip(indices.tolist(), offsets.tolist(), peaks.tolist()):
            tof = t0_s + (c + o_f + 0.5) * cell_s - calibration_s
            # An echo a * s raises the statistic by about a^2 T_s / sigma^2 (T_s: the clean
            # template's statistic with unit sigma), so a = sqrt(excess sigma^2 / T_s) and
            # 2E/N0 = a^2 E_s / sigma^2 = excess E_s / T_s.
            excess = max(p_f - mean, 0.0)
            snr = max(excess * energy_template / template_stat, 1e-3)
            sigma2 = float(np.sum(weights * np.array([sg[r] ** 2 for sg in sigma])))
            amplitude = math.sqrt(excess * sigma2 / template_stat) * peak_template
            out[r].append((tof, amplitude, 10.0 * math.log10(snr), p_f / threshold, float("nan")))
    return out
