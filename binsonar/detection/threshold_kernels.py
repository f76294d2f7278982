"""Compiled loop of the threshold detector (numba, cached on disk, GIL released).

Imported by :mod:`binsonar.detection.threshold` when the detector runs (never by ``import
binsonar``). ``threshold.first_crossings`` and the test's ``crossing_measures`` are the numpy
definitions: the first reads each searched sample twice (a block's maxima, then its minima)
and pays a few array operations per block, the second a dozen small array operations; this
loop reads each sample once, up to the crossing, stops there and measures the echo after it,
in one call for all rows (``tests/test_detection_threshold_kernels.py`` checks that they agree).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

# Samples per chunk: the largest |x - offset| of a chunk is a reduction over four independent
# running maxima (numba does not vectorise a max reduction; four chains keep the pipeline
# full: 1.3x a numpy read of the record, against 4x for one chain, measured); only the chunk
# where it first reaches the level is scanned sample by sample.
CHUNK = 256


@njit(cache=True, nogil=True, fastmath=True)
def _chunk_peak(x: NDArray[np.float64], offset: float) -> float:
    """max |x - offset| over a chunk (finite samples: fastmath's reordering of max is exact)."""
    p0 = 0.0
    p1 = 0.0
    p2 = 0.0
    p3 = 0.0
    n4 = x.size // 4 * 4
    for i in range(0, n4, 4):
        p0 = max(p0, abs(x[i] - offset))
        p1 = max(p1, abs(x[i + 1] - offset))
        p2 = max(p2, abs(x[i + 2] - offset))
        p3 = max(p3, abs(x[i + 3] - offset))
    for i in range(n4, x.size):
        p0 = max(p0, abs(x[i] - offset))
    return max(max(p0, p1), max(p2, p3))


@njit(cache=True, nogil=True)
def first_crossings(rows: NDArray[np.float64], level: NDArray[np.float64], offset: NDArray[np.float64],
                    first: int, stop_at: int, found: NDArray[np.int64]) -> None:
    """Index of the first sample in [first, stop_at) with |x - offset| >= level in each row
    (-1 where none).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples), float64, C-contiguous
    level, offset : ndarray, shape (n_rows,)
    first, stop_at : int
        Searched samples (0 <= first <= stop_at <= n_samples).
    found : ndarray of int, shape (n_rows,), written
    """
    n_rows = rows.shape[0]
    n = stop_at
    for r in range(n_rows):
        row = rows[r]
        c = offset[r]
        threshold = level[r]
        found[r] = -1
        start = first
        while start < n:
            stop = min(start + CHUNK, n)
            if _chunk_peak(row[start:stop], c) >= threshold:
                for i in range(start, stop):
                    if abs(row[i] - c) >= threshold:
                        found[r] = i
                        break
                break
            start = stop


@njit(cache=True, nogil=True)
def crossings(rows: NDArray[np.float64], level: NDArray[np.float64], offset: NDArray[np.float64], first: int,
              stop_at: int, window: int, found: NDArray[np.int64], measures: NDArray[np.float64]) -> None:
    """``first_crossings``, then the echo measures at each crossing (numpy reference:
    ``crossing_measures`` in ``tests/test_detection_threshold_kernels.py``).

    Parameters
    ----------
    rows, level, offset, first, stop_at, found
        As for ``first_crossings``.
    window : int
        Samples measured from the crossing on (indices past the row's end repeat its last
        sample, as ``numpy.clip`` of the indices does).
    measures : ndarray, shape (n_rows, 4), written
        |x - offset| at the sample before the crossing (at the crossing itself when it is
        sample 0) and at the crossing, the largest |x - offset| and the sum of (x - offset)^2
        over the window; NaN for rows without a crossing.
    """
    first_crossings(rows, level, offset, first, stop_at, found)
    n = rows.shape[1]
    for r in range(rows.shape[0]):
        i = found[r]
        if i < 0:
            for q in range(4):
                measures[r, q] = np.nan
            continue
        c = offset[r]
        measures[r, 0] = abs(rows[r, max(i - 1, 0)] - c)
        measures[r, 1] = abs(rows[r, i] - c)
        peak = 0.0
        energy = 0.0
        for j in range(window):
            v = rows[r, min(i + j, n - 1)] - c
            peak = max(peak, abs(v))
            energy += v * v
        measures[r, 2] = peak
        measures[r, 3] = energy
