"""Compiled loop of the threshold detector (numba, cached on disk, GIL released).

Imported by :mod:`binsonar.detection.threshold` when the detector runs (never by ``import
binsonar``). ``threshold.first_crossings`` and the test's ``crossing_measures`` are the numpy
definitions: the first reads each searched sample twice (a block's maxima, then its minima)
and pays a few array operations per block, the second a dozen small array operations; this
loop reads each sample once, up to the crossing, stops there and measures the echo after it,
in one call for all rows (``tests/parity/test_detection_threshold_kernels.py`` checks that they agree).
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
    each for the extremes, which LLVM vectorises; floats need four chains, measured 0.17
    against 0.29 ms for 3 x 80,000 samples, while codes take 0.04 with one against 0.08 ms).
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
def first_crossings(rows: NDArray, scale: float, level: NDArray[np.float64], offset: NDArray[np.float64],
                    first: int, stop_at: int, found: NDArray[np.int64]) -> None:
    """Index of the first sample in [first, stop_at) with |x scale - offset| >= level in each
    row (-1 where none).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples), float64 volts or int16 ADC codes, C-contiguous
    scale : float
        Volts per unit of ``rows``: 1.0 for volts, the code step for codes (x scale is then
        exactly the volts ``codes * volts_per_code`` numpy makes).
    level, offset : ndarray, shape (n_rows,)
        Volts.
    first, stop_at : int
        Searched samples (0 <= first <= stop_at <= n_samples).
    found : ndarray of int, shape (n_rows,), written
    """
    n_rows = rows.shape[0]
    n = stop_at
    codes = scale != 1.0  # codes (volts have scale 1): only picks ``_chunk_peak``'s loop, both exact for either
    for r in range(n_rows):
        row = rows[r]
        c = offset[r]
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
def crossings(rows: NDArray, scale: float, level: NDArray[np.float64], offset: NDArray[np.float64], first: int,
              stop_at: int, window: int, found: NDArray[np.int64], measures: NDArray[np.float64]) -> None:
    """``first_crossings``, then the echo measures at each crossing (numpy reference:
    ``crossing_measures`` in ``tests/parity/test_detection_threshold_kernels.py``).

    Parameters
    ----------
    rows, scale, level, offset, first, stop_at, found
        As for ``first_crossings``.
    window : int
        Samples measured from the crossing on (indices past the row's end repeat its last
        sample, as ``numpy.clip`` of the indices does).
    measures : ndarray, shape (n_rows, 4), written
        |x - offset| at the sample before the crossing (at the crossing itself when it is
        sample 0) and at the crossing, the largest |x - offset| and the sum of (x - offset)^2
        over the window (x: the row times ``scale``, volts); NaN for rows without a crossing.
    """
    first_crossings(rows, scale, level, offset, first, stop_at, found)
    n = rows.shape[1]
    for r in range(rows.shape[0]):
        i = found[r]
        if i < 0:
            for q in range(4):
                measures[r, q] = np.nan
            continue
        c = offset[r]
        measures[r, 0] = abs(rows[r, max(i - 1, 0)] * scale - c)
        measures[r, 1] = abs(rows[r, i] * scale - c)
        peak = 0.0
        energy = 0.0
        for j in range(window):
            v = rows[r, min(i + j, n - 1)] * scale - c
            peak = max(peak, abs(v))
            energy += v * v
        measures[r, 2] = peak
        measures[r, 3] = energy


@njit(cache=True, nogil=True)
def threshold_echoes(rows: NDArray, scale: float, per_row: NDArray[np.float64], settings: NDArray[np.int64],
                     constants: NDArray[np.float64], echoes: NDArray[np.float64]) -> None:
    """``crossings``, then each crossing's echo values: the whole threshold detector after its
    noise estimate, in one call (numpy reference: ``threshold_echo_values`` in
    ``tests/parity/test_detection_threshold_kernels.py``, the same operations in the same order).
    Once a new ping has evicted the caches, each numpy call costs tens of microseconds: the
    twenty-odd small ones this replaces cost ~0.2 ms per ping.

    Parameters
    ----------
    rows, scale
        As for ``first_crossings``.
    per_row : ndarray, shape (n_rows, 3)
        Level (V), DC offset (V) and noise standard deviation sigma (V) of each row.
    settings : ndarray of int, shape (3,)
        first, stop_at (searched samples) and window (samples measured from the crossing).
    constants : ndarray, shape (3,)
        Sample rate (Hz), t0_s (time of sample 0, s) and the calibrated offset subtracted from
        the crossing time (s).
    echoes : ndarray, shape (n_rows, 6), written
        1 where the row crosses (0 and NaN values elsewhere), then tof_s (the crossing linearly
        interpolated between the samples around it, minus the offset), amplitude (the largest
        |x - dc| over the window, V), snr_db (the window's energy above the noise over sigma^2,
        at least -30 dB, capped near 200 dB for a noise-free record), score (amplitude /
        level) and tof_std_s (sigma over the crossing's slope).
    """
    n_rows = rows.shape[0]
    level = np.ascontiguousarray(per_row[:, 0])
    offset = np.ascontiguousarray(per_row[:, 1])
    found = np.empty(n_rows, dtype=np.int64)
    measures = np.empty((n_rows, 4))
    window = settings[2]
    crossings(rows, scale, level, offset, settings[0], settings[1], window, found, measures)
    fs, t0_s, offset_s = constants[0], constants[1], constants[2]
    tiny = np.finfo(np.float64).tiny
    for r in range(n_rows):
        i = found[r]
        if i < 0:
            echoes[r, 0] = 0.0
            for q in range(1, 6):
                echoes[r, q] = np.nan
            continue
        before, after, amplitude, total = measures[r, 0], measures[r, 1], measures[r, 2], measures[r, 3]
        sigma = per_row[r, 2]
        frac = 0.0
        if i > 0:  # ``threshold._fraction``
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
