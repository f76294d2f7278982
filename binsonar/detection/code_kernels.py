"""Compiled statistics of int16 ADC codes (numba, cached on disk, GIL released).

Imported by :mod:`binsonar.detection.inputs` when a record arrives as ADC codes (never by
``import binsonar``). Codes are integers in a bounded range, so their order statistics come
from counting, not sorting:

- :func:`row_extremes`: each row's largest and smallest code in one pass (the clipping test:
  a code at the ADC's rails), reading 2 bytes per sample instead of the 8 of the volts;
- :func:`median_and_mad`: each row's median code and the median of |code - median| by a
  histogram of the row's codes (one pass over the few thousand samples of the robust
  subsample, then a walk over at most the codes' range), exactly the elements
  ``numpy.partition`` selects (``noise.row_median``'s convention: element ``k = n // 2`` of the
  sorted values), without its two selections per row;
- :func:`code_statistics`: both, for every row of a record, in one call (one dispatch instead
  of some fifteen numpy calls).

``tests/unit/test_detection_codes.py`` checks them against numpy.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray



@njit(cache=True, nogil=True)
def row_extremes(rows: NDArray[np.int16], largest: NDArray[np.int64], smallest: NDArray[np.int64]) -> None:
    """Largest and smallest value of each row.

    Parameters
    ----------
    rows : ndarray of int16, shape (n_rows, n_samples), n_samples >= 1, C-contiguous
    largest, smallest : ndarray of int64, shape (n_rows,), written
    """
    for r in range(rows.shape[0]):
        row = rows[r]
        high = row[0]
        low = row[0]
        for i in range(1, row.size):  # integer min/max: vectorised by LLVM, exact in any order
            high = max(high, row[i])
            low = min(low, row[i])
        largest[r] = high
        smallest[r] = low


@njit(cache=True, nogil=True)
def median_and_mad(sample: NDArray[np.int16], median: NDArray[np.int64], mad: NDArray[np.int64]) -> None:
    """Each row's median and median absolute deviation about it, in codes.

    Parameters
    ----------
    sample : ndarray of int16, shape (n_rows, k), k >= 1
    median : ndarray of int64, shape (n_rows,), written
        Element ``k // 2`` of the sorted row (the upper middle value for an even k).
    mad : ndarray of int64, shape (n_rows,), written
        Element ``k // 2`` of the sorted |row - median|.
    """
    n_rows, k = sample.shape
    target = k // 2  # the selected element: the first value whose cumulative count exceeds it
    for r in range(n_rows):
        row = sample[r]
        low = row[0]
        high = row[0]
        for i in range(1, k):
            low = min(low, row[i])
            high = max(high, row[i])
        lo = np.int64(low)
        counts = np.zeros(np.int64(high) - lo + 1, dtype=np.int64)
        for i in range(k):
            counts[np.int64(row[i]) - lo] += 1
        seen = 0
        m = 0
        for v in range(counts.size):
            seen += counts[v]
            if seen > target:
                m = v
                break
        median[r] = m + lo
        # |x - median| <= d for the codes m - d .. m + d: widen d until more than ``target``.
        seen = counts[m]
        d = 0
        while seen <= target:
            d += 1
            if m - d >= 0:
                seen += counts[m - d]
            if m + d < counts.size:
                seen += counts[m + d]
        mad[r] = d


@njit(cache=True, nogil=True)
def code_statistics(rows: NDArray[np.int16], scale: NDArray[np.void], full_scales_v: NDArray[np.float64],
                    out: NDArray[np.float64]) -> None:
    """Each row's median (DC offset) and robust noise estimate from its robust subsample, and
    its clipping, in volts.

    Parameters
    ----------
    rows : ndarray of int16, shape (n_rows, n_samples), C-contiguous
    scale : ndarray of ``kernel_types.CODE_SCALE``, shape (1,)
        The robust subsample's stretches (``noise.robust_subsample``), volts per code and the
        MAD-to-sigma factor.
    full_scales_v : ndarray, shape (k,)
        Full scales (V) to test for clipping (none: no pass over the whole record).
    out : ndarray, shape (n_rows, 3), written
        Median code times volts per code (V), the factor times the MAD in codes times volts
        per code (V), and 1.0 where the volts reach a full scale within a part in 1e9
        (``inputs.clipped_by_full_scale``: largest >= limit or smallest <= -limit), else 0.0.
    """
    p = scale[0]
    period, length, segments = p.period, p.length, p.segments
    step, factor = p.volts_per_code, p.mad_to_sigma
    full_scales = full_scales_v
    n_rows = rows.shape[0]
    sample = np.empty((n_rows, segments * length), dtype=np.int16)
    for r in range(n_rows):
        for g in range(segments):
            sample[r, g * length:(g + 1) * length] = rows[r, g * period:g * period + length]
    median = np.empty(n_rows, dtype=np.int64)
    mad = np.empty(n_rows, dtype=np.int64)
    median_and_mad(sample, median, mad)
    largest = np.zeros(n_rows, dtype=np.int64)
    smallest = np.zeros(n_rows, dtype=np.int64)
    if full_scales.size > 0:
        row_extremes(rows, largest, smallest)
    for r in range(n_rows):
        out[r, 0] = median[r] * step
        out[r, 1] = factor * (mad[r] * step)
        clipped = 0.0
        for q in range(full_scales.size):
            limit = full_scales[q] * (1.0 - 1e-9)
            if largest[r] * step >= limit or smallest[r] * step <= -limit:
                clipped = 1.0
        out[r, 2] = clipped
