"""Compiled loop of the threshold detector (numba, cached on disk, GIL released).

Imported by :mod:`binsonar.detection.threshold` when the detector runs (never by ``import
binsonar``). The numpy definitions are ``threshold.first_crossings``,
``threshold.crossing_measures`` and ``threshold.crossing_echo_values``; this loop reads each
searched sample once, up to the crossing, stops there and measures the echo after it, in one
call for all rows (``tests/parity/test_detection_threshold_kernels.py`` checks that they agree).
The arguments are the bundles of ``kernel_types``.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

# Samples per chunk: the largest |x - offset| of a chunk comes from its largest and smallest
# sample (``_chunk_peak``); only the chunk where it first reaches the level is scanned sample
# by sample.
CHUNK = 256


@njit(cache=True, nogil=True, fastmath=True)
def _chunk_peak(x: NDArray, scale: float, offset: float, codes: bool) -> float:
    """max |x scale - offset| over a chunk, from the chunk's largest and smallest raw value:
    fl(x scale - offset) does not decrease as x grows (scale > 0), so the largest deviation
    is at one of them. The extremes are plain min/max reductions over the raw values (int16
    codes or float64 volts; finite samples: fastmath's reordering of max is exact), which
    vectorise without converting each code to a float. fastmath may fuse the final
    multiply-add, rounding it otherwise than numpy's product then difference by an ulp of
    |x scale|: ``first_crossings`` allows for that. ``codes``: x holds integers (one chain
    each for the extremes, which LLVM vectorises); floats take four independent chains.
    """
    if codes:  # integer min/max: one chain each, vectorised by LLVM (16 codes a vector)
        high = x[0]
        low = x[0]
        for i in range(1, x.size):
            high = max(high, x[i])
            low = min(low, x[i])
        return max(high * scale - offset, offset - low * scale)
    h0 = h1 = h2 = h3 = x[0]
    l0 = l1 = l2 = l3 = x[0]
    n4 = x.size // 4 * 4
    for i in range(0, n4, 4):  # four independent chains (a float max is not vectorised)
        h0 = max(h0, x[i])
        h1 = max(h1, x[i + 1])
        h2 = max(h2, x[i + 2])
        h3 = max(h3, x[i + 3])
        l0 = min(l0, x[i])
        l1 = min(l1, x[i + 1])
        l2 = min(l2, x[i + 2])
        l3 = min(l3, x[i + 3])
    for i in range(n4, x.size):
        h0 = max(h0, x[i])
        l0 = min(l0, x[i])
    high = max(max(h0, h1), max(h2, h3))
    low = min(min(l0, l1), min(l2, l3))
    return max(high * scale - offset, offset - low * scale)


@njit(cache=True, nogil=True)
def first_crossings(samples: NDArray, dc_v: NDArray[np.float64], level_v: NDArray[np.float64],
                    search: NDArray[np.void], found: NDArray[np.int64]) -> None:
    """Index of the first sample in [first, stop) with |x scale - dc| >= level in each row (-1
    where none): ``threshold.first_crossings``.

    Parameters
    ----------
    samples : ndarray, shape (n_rows, n_samples), C-contiguous
        float64 volts or int16 ADC codes; x scale is exactly the volts ``codes * volts_per_code``
        numpy makes.
    dc_v : ndarray, shape (n_rows,)
        Each row's DC offset (V) still in the samples.
    level_v : ndarray, shape (n_rows,)
        Each row's threshold on |x - dc| (V).
    search : ndarray of ``kernel_types.CROSSING_SEARCH``, shape (1,)
    found : ndarray of int, shape (n_rows,), written
    """
    scale = search[0].scale
    n_rows = samples.shape[0]
    first, n = search[0].first, search[0].stop
    codes = scale != 1.0  # codes (volts have scale 1): only picks ``_chunk_peak``'s loop, both exact for either
    for r in range(n_rows):
        row = samples[r]
        c = dc_v[r]
        threshold = level_v[r]
        # The chunk test may be off by an ulp of |x scale| (``_chunk_peak``): a chunk within
        # that of the level is scanned exactly, sample by sample (unfused, as numpy computes).
        coarse = threshold - (threshold + abs(c)) * 1e-12
        found[r] = -1
        start = first
        while start < n and found[r] < 0:
            stop = min(start + CHUNK, n)
            if _chunk_peak(row[start:stop], scale, c, codes) >= coarse:
                for i in range(start, stop):
                    if abs(row[i] * scale - c) >= threshold:
                        found[r] = i
                        break
            start = stop


@njit(cache=True, nogil=True)
def crossings(samples: NDArray, dc_v: NDArray[np.float64], level_v: NDArray[np.float64], search: NDArray[np.void],
              found: NDArray[np.int64], measures: NDArray[np.float64]) -> None:
    """``first_crossings``, then the echo measures at each crossing (numpy reference:
    ``threshold.crossing_measures``).

    Parameters
    ----------
    samples, dc_v, level_v, search, found
        As for ``first_crossings``; ``window`` samples are measured from the crossing on
        (indices past the row's end repeat its last sample, as ``numpy.clip`` of the indices does).
    measures : ndarray, shape (n_rows, 4), written
        |x - dc| at the sample before the crossing (at the crossing itself when it is sample 0)
        and at the crossing, the largest |x - dc| and the sum of (x - dc)^2 over the window (x:
        the row times ``scale``, volts); NaN for rows without a crossing.
    """
    first_crossings(samples, dc_v, level_v, search, found)
    window = search[0].window
    scale = search[0].scale
    n = samples.shape[1]
    for r in range(samples.shape[0]):
        i = found[r]
        if i < 0:
            for q in range(4):
                measures[r, q] = np.nan
            continue
        c = dc_v[r]
        measures[r, 0] = abs(samples[r, max(i - 1, 0)] * scale - c)
        measures[r, 1] = abs(samples[r, i] * scale - c)
        peak = 0.0
        energy = 0.0
        for j in range(window):
            v = samples[r, min(i + j, n - 1)] * scale - c
            peak = max(peak, abs(v))
            energy += v * v
        measures[r, 2] = peak
        measures[r, 3] = energy


@njit(cache=True, nogil=True)
def threshold_echoes(samples: NDArray, dc_v: NDArray[np.float64], level_v: NDArray[np.float64],
                     sigma_v: NDArray[np.float64], search: NDArray[np.void], found: NDArray[np.int64],
                     echoes: NDArray[np.void]) -> None:
    """``crossings``, then each crossing's echo values: the whole threshold detector after its
    noise estimate, in one call (numpy reference: ``threshold.crossing_echo_values``, the same
    operations in the same order).

    Parameters
    ----------
    samples, dc_v, level_v
        As for ``first_crossings``.
    sigma_v : ndarray, shape (n_rows,)
        Each row's noise standard deviation (V), for the SNR and the TOF std.
    search : ndarray of ``kernel_types.CROSSING_SEARCH``, shape (1,)
    found : ndarray of int, shape (n_rows,), written
        Each row's crossing sample (-1: none).
    echoes : ndarray of ``kernel_types.ECHO``, shape (n_rows,), written
        Where the row crosses (NaN elsewhere): tof_s (the crossing linearly interpolated between
        the samples around it, minus the offset), amplitude (the largest |x - dc| over the
        window, V), snr_db (the window's energy above the noise over sigma^2, at least -30 dB,
        capped near 200 dB for a noise-free record), score (amplitude / level) and tof_std_s
        (sigma over the crossing's slope).
    """
    n_rows = samples.shape[0]
    measures = np.empty((n_rows, 4))
    p = search[0]
    window = p.window
    crossings(samples, dc_v, level_v, search, found, measures)
    fs, t0_s, offset_s = p.sample_rate_hz, p.t0_s, p.offset_s
    tiny = np.finfo(np.float64).tiny
    for r in range(n_rows):
        i = found[r]
        echo = echoes[r]
        if i < 0:
            echo.tof_s = echo.amplitude = echo.snr_db = echo.score = echo.tof_std_s = np.nan
            continue
        before, after, amplitude, total = measures[r, 0], measures[r, 1], measures[r, 2], measures[r, 3]
        sigma = sigma_v[r]
        level = level_v[r]
        frac = 0.0
        if i > 0:  # ``threshold.crossing_fraction``
            rise = after - before
            frac = (level - before) / rise if rise > 0 else 1.0
            frac = min(max(frac, 0.0), 1.0)
        crossing = t0_s + (i - 1 + frac) / fs
        noise_var = max(sigma ** 2, 1e-20 * total)  # a noise-free record: the SNR capped at 200 dB
        snr = max((total - window * sigma ** 2) / noise_var, 1e-3)
        slope = max((after - before) * fs, tiny)
        echo.tof_s = crossing - offset_s
        echo.amplitude = amplitude
        echo.snr_db = 10 * np.log10(snr)
        echo.score = amplitude / level
        echo.tof_std_s = sigma / slope
