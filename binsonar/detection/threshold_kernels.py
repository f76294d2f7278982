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

from binsonar.detection.kernel_types import CodedRows, CrossingSearch, CrossingTiming, RowLevels

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
def first_crossings(rows: CodedRows, level: NDArray[np.float64], search: CrossingSearch,
                    found: NDArray[np.int64]) -> None:
    """Index of the first sample in [search.first, search.stop) with |x scale - dc| >= level in
    each row (-1 where none): ``threshold.first_crossings``.

    Parameters
    ----------
    rows : CodedRows
        x scale is exactly the volts ``codes * volts_per_code`` numpy makes.
    level : ndarray, shape (n_rows,)
        Volts.
    search : CrossingSearch
    found : ndarray of int, shape (n_rows,), written
    """
    samples, scale = rows.samples, rows.scale
    n_rows = samples.shape[0]
    first, n = search.first, search.stop
    codes = scale != 1.0  # codes (volts have scale 1): only picks ``_chunk_peak``'s loop, both exact for either
    for r in range(n_rows):
        row = samples[r]
        c = rows.dc_v[r]
        threshold = level[r]
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
def crossings(rows: CodedRows, level: NDArray[np.float64], search: CrossingSearch, found: NDArray[np.int64],
              measures: NDArray[np.float64]) -> None:
    """``first_crossings``, then the echo measures at each crossing (numpy reference:
    ``threshold.crossing_measures``).

    Parameters
    ----------
    rows, level, search, found
        As for ``first_crossings``; ``search.window`` samples are measured from the crossing on
        (indices past the row's end repeat its last sample, as ``numpy.clip`` of the indices does).
    measures : ndarray, shape (n_rows, 4), written
        |x - dc| at the sample before the crossing (at the crossing itself when it is sample 0)
        and at the crossing, the largest |x - dc| and the sum of (x - dc)^2 over the window (x:
        the row times ``scale``, volts); NaN for rows without a crossing.
    """
    first_crossings(rows, level, search, found)
    samples, scale = rows.samples, rows.scale
    n = samples.shape[1]
    for r in range(samples.shape[0]):
        i = found[r]
        if i < 0:
            for q in range(4):
                measures[r, q] = np.nan
            continue
        c = rows.dc_v[r]
        measures[r, 0] = abs(samples[r, max(i - 1, 0)] * scale - c)
        measures[r, 1] = abs(samples[r, i] * scale - c)
        peak = 0.0
        energy = 0.0
        for j in range(search.window):
            v = samples[r, min(i + j, n - 1)] * scale - c
            peak = max(peak, abs(v))
            energy += v * v
        measures[r, 2] = peak
        measures[r, 3] = energy


@njit(cache=True, nogil=True)
def threshold_echoes(rows: CodedRows, levels: RowLevels, search: CrossingSearch, timing: CrossingTiming,
                     echoes: NDArray[np.float64]) -> None:
    """``crossings``, then each crossing's echo values: the whole threshold detector after its
    noise estimate, in one call (numpy reference: ``threshold.crossing_echo_values``, the same
    operations in the same order).

    Parameters
    ----------
    rows : CodedRows
    levels : RowLevels
    search : CrossingSearch
    timing : CrossingTiming
    echoes : ndarray, shape (n_rows, 6), written
        1 where the row crosses (0 and NaN values elsewhere), then tof_s (the crossing linearly
        interpolated between the samples around it, minus the offset), amplitude (the largest
        |x - dc| over the window, V), snr_db (the window's energy above the noise over sigma^2,
        at least -30 dB, capped near 200 dB for a noise-free record), score (amplitude /
        level) and tof_std_s (sigma over the crossing's slope).
    """
    n_rows = rows.samples.shape[0]
    level = levels.level_v
    found = np.empty(n_rows, dtype=np.int64)
    measures = np.empty((n_rows, 4))
    window = search.window
    crossings(rows, level, search, found, measures)
    fs, t0_s, offset_s = timing.sample_rate_hz, timing.t0_s, timing.offset_s
    tiny = np.finfo(np.float64).tiny
    for r in range(n_rows):
        i = found[r]
        if i < 0:
            echoes[r, 0] = 0.0
            for q in range(1, 6):
                echoes[r, q] = np.nan
            continue
        before, after, amplitude, total = measures[r, 0], measures[r, 1], measures[r, 2], measures[r, 3]
        sigma = levels.sigma_v[r]
        frac = 0.0
        if i > 0:  # ``threshold.crossing_fraction``
            rise = after - before
            frac = (level[r] - before) / rise if rise > 0 else 1.0
            frac = min(max(frac, 0.0), 1.0)
        crossing = t0_s + (i - 1 + frac) / fs
        noise_var = max(sigma ** 2, 1e-20 * total)  # a noise-free record: the SNR capped at 200 dB
        snr = max((total - window * sigma ** 2) / noise_var, 1e-3)
        slope = max((after - before) * fs, tiny)
        echoes[r, 0] = 1.0
        echoes[r, 1] = crossing - offset_s
        echoes[r, 2] = amplitude
        echoes[r, 3] = 10 * np.log10(snr)
        echoes[r, 4] = amplitude / level[r]
        echoes[r, 5] = sigma / slope
